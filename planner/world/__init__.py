"""The world the robot walks on.

Terrain as an implicit surface with pseudo-normals (section 5), height fields, the course
generator.
"""
