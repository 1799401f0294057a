"""The margins a plan keeps so that it holds up on the body, chosen from MuJoCo runs.

Their own module (no import) because they are the defaults of the settings
(:mod:`planner.problems.options`) as well as of the checks that use them: the support margins
(:mod:`planner.body.stability`), the sway stiffness (:mod:`planner.body.stiffness`) and the
commanded
torques (:mod:`planner.body.torques`), which re-export them.
"""

BALANCE_MARGIN_M = 0.025  # three-leg keyframes: COM this far inside the support triangle
PATH_BALANCE_MARGIN_M = 0.020  # three-leg path samples (the swing leg's mass moves the COM)
SWAY_STIFFNESS_MIN_MG_PER_L = 0.8  # least sway stiffness of a three-leg stance [m g / L]
SWAY_STIFFNESS_AIM_MG_PER_L = 1.2  # ... and what Theta2 aims for where it can [m g / L]
# joint torque / URDF effort the servos may need to hold a planned stance, in the force
# distribution the feed-forward commands (least sum of (torque / effort)^2): the least
# achievable ratio relies on internal foot forces no servo produces (a stance at 49 %
# achievable needed 102 % commanded: the knee saturated and the body yawed).
# Chosen from MuJoCo runs (bench/notes/2026-11-27-torque-fraction.md): a servo at this
# fraction saturates after (1 - f) effort / kp of error (LittleDog's knee, 0.6 N m at
# 20 N m/rad: 0.34 degrees at 0.8, 0.52 at 0.7), and on three legs the servos' loads
# exceed the feed-forward by up to 0.3-0.4 of the effort in healthy runs (internal forces
# of the stance: feet a millimetre off their set-points); at 0.8 a front knee saturated
# and the body sagged towards it within one swing
COMMANDED_TORQUE_FRACTION = 0.7

__all__ = [
    "BALANCE_MARGIN_M",
    "COMMANDED_TORQUE_FRACTION",
    "PATH_BALANCE_MARGIN_M",
    "SWAY_STIFFNESS_AIM_MG_PER_L",
    "SWAY_STIFFNESS_MIN_MG_PER_L",
]
