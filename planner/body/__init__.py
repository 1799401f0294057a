"""The robot body.

URDF loading, product-of-exponentials kinematics and Paden-Kahan IK (section 4), contact,
equilibrating forces (section 6, eq. 3-5), stability, torques, leg links, rolling feet,
sway stiffness, servos.
"""
