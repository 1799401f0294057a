"""Joint servos of the simulated robot, scaled from LittleDog's by dynamic similarity (sec. 10).

LittleDog's servos in MuJoCo (:class:`planner.sim.model.SimSettings`: stiffness 20 N m/rad,
damping 0.25 N m s/rad, reflected rotor inertia 5e-4 kg m^2, joint friction 0.01 N m s/rad)
were checked against its walks (open loop and feedback on the named and generated courses).
Another robot gets the dynamically similar values. With M its total mass and L its mean
leg reach (hip centre to foot centre, stretched), lengths scale with L, times with
sqrt(L / g) and masses with M, so

- a stiffness (torque per radian) scales with M g L: the joints sag by the same angle under
  the robot's weight, and a servo error moves the body by the same share of the leg;
- a damping (torque per rad/s) with M L sqrt(g L): the same damping ratio;
- an inertia with M L^2.

ANYmal C (52.1 kg, L 0.64 m) gets 20 x 17.4 x 3.58 = 1244 N m/rad; Solo12 (2.5 kg,
L 0.33 m) 30 N m/rad. The effort limits stay the URDF's (what the motors give): a robot whose limits
are small next to M g L saturates, as it would. Explicit values in ``SimSettings`` win.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from planner.body.robot_scale import REFERENCE_MASS_KG, REFERENCE_REACH_M

if TYPE_CHECKING:
    from planner.body.robot import Robot

__all__ = ["LITTLEDOG_SERVOS", "ServoModel", "servo_model"]


@dataclass(frozen=True)
class ServoModel:
    """One robot's servo stiffness, damping, rotor inertia and joint friction (every joint)."""

    kp_nm_per_rad: float
    kv_nm_s_per_rad: float
    armature_kg_m2: float
    damping_nm_s_per_rad: float


LITTLEDOG_SERVOS = ServoModel(20.0, 0.25, 5e-4, 0.01)


def servo_model(robot: Robot, reference: ServoModel = LITTLEDOG_SERVOS) -> ServoModel:
    """``reference`` (LittleDog's) scaled to ``robot``'s mass and leg reach (module doc)."""
    m = float(robot.total_mass_kg) / REFERENCE_MASS_KG
    length = float(np.mean(robot.reach_m)) / REFERENCE_REACH_M
    return ServoModel(
        kp_nm_per_rad=reference.kp_nm_per_rad * m * length,
        kv_nm_s_per_rad=reference.kv_nm_s_per_rad * m * length**1.5,
        armature_kg_m2=reference.armature_kg_m2 * m * length**2,
        damping_nm_s_per_rad=reference.damping_nm_s_per_rad * m * length**1.5,
    )
