"""The planners.

Local planners (sections 8.1, 8.2, 8.5), the search Omega, the walk, global planning (9).
"""
