"""The measured state that feedback starts from (paper section 8.3).

A :class:`StateSource` measures the robot: base pose, joint angles and which feet touch
(on LittleDog: motion capture and joint encoders). :class:`SimulatedMocap` stands in for
it with the MuJoCo simulator (:class:`planner.sim.simulator.Simulator`), optionally with
Gaussian noise and a latency. :func:`measured_state` is the planner's
:class:`~planner.body.state.State` of a measurement: every foot on the terrain under its
measured sphere centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import NDArray

from planner.core.errors import InputError

if TYPE_CHECKING:
    from planner.sim.simulator import Simulator

__all__ = ["Measurement", "SimulatedMocap", "StateSource", "measured_state"]

_Array = NDArray[np.float64]


@dataclass
class Measurement:
    """A measured configuration: time [s], Pinocchio ``q`` (19,), feet touching (4,)."""

    time_s: float
    q: _Array
    contact: NDArray[np.bool_]


class StateSource(Protocol):
    """What feedback needs from the robot: its measured configuration (section 8.3)."""

    def measure(self) -> Measurement:
        """The latest available measurement."""


class SimulatedMocap:
    """The simulator as motion capture plus joint encoders, with noise and latency.

    Base position noise ``position_noise_m`` (per axis), base orientation noise
    ``angle_noise_rad`` (a random rotation vector per axis), joint noise
    ``joint_noise_rad``, all Gaussian; ``latency_s``: the measurement returned is the
    configuration that many seconds old (from the simulator's history, recorded every
    control tick).
    """

    def __init__(
        self,
        sim: Simulator,
        position_noise_m: float = 0.0,
        angle_noise_rad: float = 0.0,
        joint_noise_rad: float = 0.0,
        latency_s: float = 0.0,
        seed: int = 0,
    ):
        for name, v in (
            ("position_noise_m", position_noise_m),
            ("angle_noise_rad", angle_noise_rad),
            ("joint_noise_rad", joint_noise_rad),
            ("latency_s", latency_s),
        ):
            if not (math.isfinite(v) and v >= 0.0):
                raise InputError(f"simulate: {name} must be a number >= 0, got {v!r}")
        self.sim = sim
        self.position_noise_m = position_noise_m
        self.angle_noise_rad = angle_noise_rad
        self.joint_noise_rad = joint_noise_rad
        self.latency_s = latency_s
        self.rng = np.random.default_rng(seed)
        if latency_s > 0.0:
            sim.history_s = max(sim.history_s, latency_s)

    def measure(self) -> Measurement:
        """The simulator's configuration ``latency_s`` ago, with noise."""
        sim = self.sim
        if self.latency_s > 0.0 and sim.history:
            want = sim.time - self.latency_s
            older = [h for h in sim.history if h[0] <= want + 1e-9]
            t, q, contact = older[-1] if older else sim.history[0]
            q, contact = q.copy(), contact.copy()
        else:
            t, q, contact = sim.time, sim.q(), sim.touches().feet
        q[:3] += self.rng.normal(0.0, self.position_noise_m, 3) if self.position_noise_m else 0.0
        if self.angle_noise_rad:
            import pinocchio as pin

            R = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
            R = pin.exp3(self.rng.normal(0.0, self.angle_noise_rad, 3)) @ R
            qq = pin.Quaternion(R)
            q[3:7] = [qq.x, qq.y, qq.z, qq.w]
        if self.joint_noise_rad:
            q[7:] += self.rng.normal(0.0, self.joint_noise_rad, len(q) - 7)
        return Measurement(float(t), q, np.asarray(contact, bool))


def _foot_centres(robot, q: _Array) -> _Array:
    """(4, 3) foot sphere centres of a Pinocchio configuration."""
    from planner.body.kinematics import kinematics_of
    from planner.core.lie import rotation_from_quat

    kin = kinematics_of(robot)
    return kin.feet_W(q[:3], rotation_from_quat(q[3:7]), robot.joints_from_q(q))


def measured_state(robot, terrain, meas: Measurement):
    """The planner's :class:`~planner.body.state.State` of a measurement (section 8.3).

    Base pose and joints as measured; every foot taken as a stance foot (a cycle starts
    on S0) at the contact point under its measured sphere centre, put on the terrain the
    planner sees (``terrain.height``), so that the Theta problems start on a leaf.
    """
    from planner.body.contact import contact_from_foot_centre
    from planner.body.state import State
    from planner.core.lie import rotation_from_quat

    q = meas.q
    centres = _foot_centres(robot, q)
    feet = contact_from_foot_centre(terrain, centres, robot.foot_radius_m)
    feet[:, 2] = np.asarray(terrain.height(feet[:, 0], feet[:, 1]), float)
    return State(
        base_position_W=q[:3].copy(),
        base_rotation_W=rotation_from_quat(q[3:7] / np.linalg.norm(q[3:7])),
        feet_W=feet,
        joints_rad=robot.joints_from_q(q),
        stratum=0,
        support=(0, 1, 2, 3),
        info={"measured_at_s": meas.time_s},
    )


def _source(sim: Simulator, source: StateSource | None, **noise) -> StateSource:
    return source if source is not None else SimulatedMocap(sim, **noise)
