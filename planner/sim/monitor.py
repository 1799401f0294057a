"""What a run measures against the plan it executes (paper section 10).

A :class:`Monitor` follows a run tick by tick against its reference (set-points, planned
base pose, planned contacts) and fills its :class:`Metrics`: stance feet that do not slip
(motion along a leaf), no body-terrain contact, the base where the plan puts it, servo
tracking and load; it records the executed samples and keyframes.

What the plan's model leaves out shows up here: a rigid sphere foot fixed to the shank
*rolls* when the shank turns, so a stance foot's centre moves by rho times the shank's
rotation (2-4 mm per body move for LittleDog) although its contact point does not slide;
open loop this accumulates (a flat 2 m walk ended 2.8 cm off, rolling and landings
together; 0.6 cm at a third of the speed). The metrics keep the
two apart: ``max_slip_m`` (the centre's travel since touchdown) and ``max_sliding_m``
(the contact point's sliding, what friction must prevent).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.core.units import GRAVITY_M_S2
from planner.planfile.plan import Keyframe

if TYPE_CHECKING:
    from planner.planfile.plan import Plan
    from planner.sim.simulator import Simulator

__all__ = ["Metrics", "Monitor"]

_Array = NDArray[np.float64]


def _up_angle_deg(Ra: _Array, Rb: _Array) -> float:
    """Angle [deg] between the body up axes of two rotations."""
    c = float(np.clip(Ra[:, 2] @ Rb[:, 2], -1.0, 1.0))
    return math.degrees(math.acos(c))


def _roll_pitch_deg(R: _Array) -> tuple[float, float]:
    """Roll and pitch (ZYX Euler) [deg]."""
    pitch = math.asin(float(np.clip(-R[2, 0], -1.0, 1.0)))
    roll = math.atan2(float(R[2, 1]), float(R[2, 2]))
    return math.degrees(roll), math.degrees(pitch)


def _quat_to_R(q_xyzw: _Array) -> _Array:
    x, y, z, w = (float(v) for v in q_xyzw)
    s = 1.0 / math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x * s, y * s, z * s, w * s
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@dataclass
class Metrics:
    """What a run measured (section 10). Lengths in metres, angles in degrees, times in s."""

    mode: str
    # no fall, and the final base within reach_tol_m (xy) of the plan's final base (feedback,
    # which plans its own way to the plan's goal: the COM within reach_tol_m of the goal)
    reached: bool = False
    final_error_m: float = math.nan  # final base vs the plan's final base, xy
    final_error_3d_m: float = math.nan
    com_to_goal_m: float = math.nan  # final whole-body COM to the plan's goal, xy
    plan_com_to_goal_m: float = math.nan  # what the plan itself promised
    max_slip_m: float = 0.0  # largest xy travel of a stance foot's centre since touchdown
    max_slip_leg: str = ""
    max_sliding_m: float = 0.0  # largest sliding of a stance foot's contact point since then
    max_sliding_leg: str = ""  # (travel minus rolling: a rigid sphere foot rolls)
    slipped: bool = False
    fell: bool = False
    fall_reason: str = ""
    fall_time_s: float = math.nan  # since the walk started (after settling)
    tipped: bool = False
    max_tilt_error_deg: float = 0.0  # body up axis vs the plan's
    max_roll_pitch_deg: float = 0.0
    body_contact: bool = False  # the body link touched the terrain
    leg_contact_s: float = 0.0  # time a leg link (not a foot) touched the terrain
    swing_touch_s: float = 0.0  # time a swing foot touched the terrain
    lost_contact_s: float = 0.0  # time a planned stance foot was off the terrain
    joint_rms_rad: float = 0.0  # set-point tracking
    joint_max_rad: float = 0.0
    saturation_frac: float = 0.0  # fraction of control ticks with a servo at its limit
    # on three planned stance legs: the largest |servo torque| / URDF effort of their joints,
    # and its largest excess over the feed-forward's (the planned commanded distribution's)
    max_three_leg_load: float = 0.0
    max_load_over_plan: float = 0.0
    cycles: int = 0
    replans: int = 0  # feedback: planning failures that cost a cycle
    ik_misses: int = 0  # correction: set-points out of reach (closest taken)
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    message: str = ""

    @property
    def ok(self) -> bool:
        """Reached, no fall, no tipping, no slip, no body contact."""
        return self.reached and not (self.fell or self.tipped or self.slipped or self.body_contact)

    def to_dict(self) -> dict:
        """JSON-ready dict (with ``ok``)."""
        d = asdict(self)
        d["ok"] = self.ok
        return d

    def summary(self) -> str:
        """A few lines for the terminal."""
        yn = {True: "yes", False: "no"}
        lines = [
            f"mode {self.mode}: {'OK' if self.ok else 'NOT OK'} - {self.message}",
            f"  reached: {yn[self.reached]}; final base {100 * self.final_error_m:.1f} cm (xy) "
            f"from the plan's final base ({100 * self.final_error_3d_m:.1f} cm 3-D); COM "
            f"{100 * self.com_to_goal_m:.1f} cm from the goal (the plan's: "
            f"{100 * self.plan_com_to_goal_m:.1f} cm)",
            f"  max stance-foot slip {1000 * self.max_slip_m:.1f} mm ({self.max_slip_leg or '-'}"
            f"), of which sliding {1000 * self.max_sliding_m:.1f} mm "
            f"({self.max_sliding_leg or '-'}; the rest is the sphere foot rolling)",
            f"  fell: {yn[self.fell]}{' (' + self.fall_reason + ')' if self.fell else ''}; "
            f"tipped: {yn[self.tipped]} (max tilt vs plan {self.max_tilt_error_deg:.1f} deg)",
            f"  body-terrain contact: {yn[self.body_contact]}; leg links on terrain "
            f"{self.leg_contact_s:.2f} s; swing foot on terrain {self.swing_touch_s:.2f} s; "
            f"stance foot off terrain {self.lost_contact_s:.2f} s",
            f"  joint tracking rms {math.degrees(self.joint_rms_rad):.2f} deg, max "
            f"{math.degrees(self.joint_max_rad):.2f} deg; servos saturated "
            f"{100 * self.saturation_frac:.1f} % of ticks; on three legs up to "
            f"{100 * self.max_three_leg_load:.0f} % of a stance joint's effort, "
            f"{100 * self.max_load_over_plan:.0f} % over the feed-forward",
            f"  {self.cycles} cycles, {self.sim_time_s:.1f} s simulated in {self.wall_time_s:.1f}"
            " s",
        ]
        return "\n".join(lines)


class Monitor:
    """Follows a run tick by tick against the reference it was asked to execute.

    The reference is a growing list of samples on the simulator's clock: set-points
    (joints), the planned base pose and the planned contact flags. A foot is a planned
    stance foot on a reference segment whose two ends both have it in contact, a planned
    swing foot when neither has; its slip is measured from where it first touches the
    terrain in that stance interval.
    """

    def __init__(self, sim: Simulator, mode: str):
        self.sim = sim
        self.settings = sim.settings
        self.metrics = Metrics(mode=mode)
        self.t0 = sim.time  # the walk starts now (after settling)
        self.t: list[float] = []
        self.q: list[_Array] = []
        self.contact: list[NDArray[np.bool_]] = []
        self.torque_ff: list[_Array] = []
        self._anchor: list[_Array | None] = [None] * 4
        self._sliding = np.zeros((4, 3))  # integral of the contact point's tangential velocity
        weight = sim.robot.total_mass_kg * GRAVITY_M_S2
        self._min_load = self.settings.sliding_min_load_frac * weight
        self._sq, self._n, self._sat = 0.0, 0, 0
        self.rec_t: list[float] = []
        self.rec_q: list[_Array] = []
        self.rec_c: list[NDArray[np.bool_]] = []
        self.keyframes: list[Keyframe] = []
        self._next_rec = -math.inf

    # ---- reference --------------------------------------------------------------------
    def extend(
        self, t: _Array, q: _Array, contact: NDArray[np.bool_], torque_ff: _Array | None = None
    ) -> None:
        """Append reference samples (simulator times, strictly after the last one).

        ``torque_ff`` (N, 12): the servos' feed-forward torques at the samples (zeros if None).
        """
        if torque_ff is None:
            torque_ff = np.zeros((len(t), 12))
        for ti, qi, ci, fi in zip(t, q, contact, torque_ff, strict=True):
            if self.t and ti <= self.t[-1] + 1e-12:
                self.q[-1], self.contact[-1] = np.asarray(qi, float), np.asarray(ci, bool)
                self.torque_ff[-1] = np.asarray(fi, float)
                continue
            self.t.append(float(ti))
            self.q.append(np.asarray(qi, float))
            self.contact.append(np.asarray(ci, bool))
            self.torque_ff.append(np.asarray(fi, float))

    def _bracket(self, t: float) -> tuple[int, int, float]:
        """Reference samples (k, k2) around simulator time ``t`` and the weight u of k2."""
        ts = self.t
        k = int(np.searchsorted(ts, t, side="right")) - 1
        if k < 0:
            return 0, 0, 0.0
        if k >= len(ts) - 1:
            return len(ts) - 1, len(ts) - 1, 0.0
        return k, k + 1, (t - ts[k]) / (ts[k + 1] - ts[k])

    def feedforward_at(self, t: float) -> _Array:
        """(12,) feed-forward torques [N m] at simulator time ``t`` (linear between samples)."""
        k, k2, u = self._bracket(t)
        return (1.0 - u) * self.torque_ff[k] + u * self.torque_ff[k2]

    def reference_at(self, t: float) -> tuple[_Array, _Array, NDArray, NDArray]:
        """(set-point joints (12,), base q (7,), planned stance (4,), planned swing (4,))."""
        k, k2, u = self._bracket(t)
        q = (1.0 - u) * self.q[k] + u * self.q[k2]
        ca, cb = self.contact[k], self.contact[k2]
        return q[self.sim._pin_idx], q[:7], ca & cb, ~ca & ~cb

    # ---- measuring --------------------------------------------------------------------
    def update(self) -> None:
        """Measure after a control tick."""
        sim, m, s = self.sim, self.metrics, self.settings
        dt = s.control_dt_s
        t = sim.time
        joints_ref, base_ref, stance, swing = self.reference_at(t)
        err = np.abs(sim.joints() - sim.targets())
        self._sq += float(np.sum(err**2)) / 12.0
        self._n += 1
        m.joint_max_rad = max(m.joint_max_rad, float(err.max()))
        self._sat += int(sim.saturated())
        if int(stance.sum()) == 3:  # the servos' load against the commanded (planned) one
            j = (3 * np.flatnonzero(stance)[:, None] + np.arange(3)).ravel()
            load = np.abs(sim.data.actuator_force[j]) / sim.effort[j]
            planned = np.abs(self.feedforward_at(t)[j]) / sim.effort[j]
            m.max_three_leg_load = max(m.max_three_leg_load, float(load.max()))
            m.max_load_over_plan = max(m.max_load_over_plan, float((load - planned).max()))
        touch = sim.touches()
        feet, body, legs = touch.feet, touch.body, touch.legs
        R = sim.base_rotation()
        m.max_tilt_error_deg = max(m.max_tilt_error_deg, _up_angle_deg(R, _quat_to_R(base_ref[3:])))
        roll, pitch = _roll_pitch_deg(R)
        m.max_roll_pitch_deg = max(m.max_roll_pitch_deg, abs(roll), abs(pitch))
        m.tipped = m.max_tilt_error_deg > s.tip_angle_deg
        if legs:
            m.leg_contact_s += dt
        if body:
            m.body_contact = True
        centres = sim.foot_centres_W()
        for i in range(4):
            if stance[i]:
                if not feet[i]:
                    m.lost_contact_s += dt
                if self._anchor[i] is None:
                    if feet[i]:
                        self._anchor[i] = centres[i, :2].copy()
                        self._sliding[i] = 0.0
                else:
                    dx, dy = centres[i, :2] - self._anchor[i]
                    slip = math.hypot(dx, dy)
                    if slip > m.max_slip_m:
                        m.max_slip_m, m.max_slip_leg = slip, self.sim.robot.legs[i].name
                    if feet[i] and touch.forces[i] @ touch.normals[i] >= self._min_load:
                        n = touch.normals[i]
                        v = sim.contact_point_velocity(i, n)
                        self._sliding[i] += dt * (v - (v @ n) * n)
                        slid = math.sqrt(float(self._sliding[i] @ self._sliding[i]))
                        if slid > m.max_sliding_m:
                            m.max_sliding_m = slid
                            m.max_sliding_leg = self.sim.robot.legs[i].name
            else:
                self._anchor[i] = None
                if swing[i] and feet[i]:
                    m.swing_touch_s += dt
        m.slipped = m.max_sliding_m > s.slip_tol_m
        if not m.fell:
            if max(abs(roll), abs(pitch)) > s.fall_angle_deg:
                m.fell, m.fall_reason = (
                    True,
                    f"base roll/pitch {max(abs(roll), abs(pitch)):.0f} deg",
                )
            elif body:
                m.fell, m.fall_reason = True, "body on the ground"
            if m.fell:
                m.fall_time_s = t - self.t0
        if t >= self._next_rec - 1e-9:
            self.record(feet)
            self._next_rec = t + 1.0 / s.record_hz

    def record(self, feet: NDArray[np.bool_] | None = None) -> None:
        """Store the current configuration and foot contacts as an executed sample."""
        if feet is None:
            feet = self.sim.touches().feet
        self.rec_t.append(self.sim.time)
        self.rec_q.append(self.sim.q())
        self.rec_c.append(np.asarray(feet, bool))

    def keyframe(self, stratum: int = 0) -> None:
        """Store the measured configuration as a keyframe (support and forces measured)."""
        from planner.body.contact import swing_point_from_centre

        sim = self.sim
        touch = sim.touches()
        feet, forces = touch.feet, touch.forces
        q = sim.q()
        c = sim.foot_centres_W()
        rho = sim.robot.foot_radius_m
        pts = swing_point_from_centre(c, rho)
        for i in np.flatnonzero(feet):
            pts[i] = c[i] - rho * touch.normals[i]
        self.keyframes.append(
            Keyframe(
                stratum=int(stratum),
                base_position=q[:3].copy(),
                base_quaternion=q[3:7] / np.linalg.norm(q[3:7]),
                joints=sim.robot.joints_from_q(q).ravel(),
                feet=pts,
                forces=forces,
                support=[int(i) + 1 for i in np.flatnonzero(feet)],
            )
        )

    def finish(self, plan: Plan, wall_s: float, sim_t0: float) -> None:
        """Final metrics against the plan's last sample and goal."""
        m, sim = self.metrics, self.sim
        self.record()
        end = plan.samples.q[-1]
        base = sim.q()[:3]
        m.final_error_m = float(np.linalg.norm(base[:2] - end[:2]))
        m.final_error_3d_m = float(np.linalg.norm(base - end[:3]))
        m.com_to_goal_m = float(np.linalg.norm(sim.com_W()[:2] - plan.goal[:2]))
        m.plan_com_to_goal_m = float(plan.outcome.get("distance_to_goal", math.nan))
        tol = self.settings.reach_tol_m
        # feedback walks to the goal itself: there, reaching is the COM at the goal (ending
        # where a partial plan ended is not reaching); open loop: the plan's final base
        if m.mode == "feedback":
            m.reached = bool(m.com_to_goal_m <= tol and not m.fell)
        else:
            m.reached = bool(m.final_error_m <= tol and not m.fell)
        m.joint_rms_rad = math.sqrt(self._sq / max(self._n, 1))
        m.saturation_frac = self._sat / max(self._n, 1)
        m.sim_time_s = sim.time - sim_t0
        m.wall_time_s = wall_s
