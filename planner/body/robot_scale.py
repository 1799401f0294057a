"""How the planner's LittleDog-tuned lengths and times scale to another robot.

The planner's tunables were chosen on LittleDog, whose legs reach L0 = 0.1795 m (hip centre
to foot centre, stretched). A robot whose mean leg reach is L gets the length scale
s = L / L0 (rounded to 4 digits: LittleDog's is exactly 1, its plans unchanged) and, by
dynamic similarity (the same Froude number v^2 / (g L): a walk as quasi-static as
LittleDog's), the time scale sqrt(s). What scales where:

- **time and speed** (:class:`planner.planning.local.LocalSettings`): a swing lasts
  ``swing_time_s`` x sqrt(s), body moves go at ``body_speed_m_s`` x sqrt(s) (when left at
  their defaults); the URDF's joint speed limits still bound both;
- **stride**: 0.35 x the leg reach (:meth:`LocalPlanner.stride_m`); **swing height**:
  :func:`planner.motion.interpolate.default_clearance_m` (from the leg); foot radius, body box,
  reach and standing height come from the URDF (:mod:`planner.body.robot`);
- **sampling of swings in joint space** (:mod:`planner.motion.leg_swing`): a segment is checked
  every ``SEGMENT_STEP_RAD`` / s, so that the foot moves the same distance between checks
  (ANYmal-B's 58 cm legs moved the foot 8.7 mm between checks, more than the 5 mm margin,
  and a planned swing cut 4.4 mm into a step's edge);
- **servos in MuJoCo**: :mod:`planner.body.servo_model` (stiffness ~ M g L).

Absolute, with their reasons:

- margins against the terrain and balance (``BALANCE_MARGIN_M`` 25 mm, leg-link and foot
  margins of 2-5 mm, the body's 5 mm): chosen from LittleDog's MuJoCo runs; every robot of
  the list is larger (s = 1.8-4.3), for which they are the same or smaller shares of the
  body. Kept absolute until a larger robot's MuJoCo runs show they must grow; the bench
  (``stratawalk bench robots``) shows none falling on flat ground;
- ``goal_tol_m`` (5 cm): the judge's own tolerance (``SimSettings.reach_tol_m``), and the
  arrival move (:meth:`LocalPlanner.arrival`) brings any robot's COM over the goal;
- terrain geometry (edge, wall and pit sizes in :mod:`planner.motion.heuristics`, the foothold
  grid of :mod:`planner.motion.footholds`): properties of the terrain's features and of the foot
  radius, which is the URDF's;
- the validator's tolerances (:mod:`planner.planfile.validate`): numerical (1e-6 m, 1e-4 m), not
  tuned.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from planner.body.robot import Robot

__all__ = ["REFERENCE_MASS_KG", "REFERENCE_REACH_M", "length_scale", "time_scale"]

# LittleDog's model (models/littledog): total mass [kg] and mean leg reach [m]
REFERENCE_MASS_KG = 3.004
REFERENCE_REACH_M = 0.1795267490


def length_scale(robot: Robot) -> float:
    """The length scale s: the robot's mean leg reach / LittleDog's, to 4 digits (LittleDog 1)."""
    return round(float(np.mean(robot.reach_m)) / REFERENCE_REACH_M, 4)


def time_scale(robot: Robot) -> float:
    """sqrt(s): durations scale so (dynamic similarity, same Froude number)."""
    return math.sqrt(length_scale(robot))
