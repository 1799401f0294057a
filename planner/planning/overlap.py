"""A swing that starts before its body move ends: the crawl's overlap.

The paper's step (figure 6, section 8.5) moves the body on four feet to a pose on the three
other legs, and only then lifts the leg: the body rests during every swing. Yet the stance
is a leaf of S_i all the same (section 4.3: three feet fixed, the base free), so the leg may
lift as soon as the body's path has entered the three-leg support with margin, and swing
while the body finishes its move. This is the usual crawl's overlap of body motion and
swing, and it hides most of the swing's time in the body move's deceleration.

:func:`overlap_step` lifts the leg at the earliest sample of the body path from which the
rest of the path, now on three legs, passes every check of a planned path
(:meth:`LocalPlanner.path_problem`: reach, body and link clearance, friction cones,
joint torques), with the COM the balance margin (``settings.theta``, a chosen pose's) inside the
triangle and the three-leg stance holding on the servos (the sway stiffness floor of
Theta2, :mod:`planner.body.stiffness`) wherever the body still moves. The leg never lifts at
the body move's first sample: its load moves to the other feet over a four-feet interval.
The swing foot follows the same terrain-following path
(:func:`planner.motion.interpolate.swing_path`) from where it lifts, in world coordinates,
while the base continues along the body path's leaf (eq. 6b); the swing leg's joints
come from IK in the moving body frame. Timing: the body keeps its time law
(:mod:`planner.motion.time_law`), its acceleration bound now carried by three legs; the foot
keeps its own, with the swing leg's joint speeds taken in the moving frame; the foot
lands no earlier than the body comes to rest on the certified Theta2 pose, so the
touch-down keyframe is the one the planner solved. The body still rests at every
touch-down and at the start of every body move; keyframes stay the Theta solutions (the
body-move end, on four feet, is now passed with the leg already in the air).

Not overlapped: swings searched in the leg's joint space around an edge (they pass it by
millimetres, :mod:`planner.motion.leg_swing`), and body moves through a via pose (not one leaf).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import NDArray

from planner.body.contact import unique_contact_points
from planner.body.rolling import leg_rotations_W, roll_stance_feet, sliding
from planner.body.stability import support_margin_m
from planner.body.state import State
from planner.body.stiffness import sway_stiffness_of
from planner.core.failures import FailureKind, Problem, kind_of
from planner.core.lie import interpolate_coords, pose_from_coords
from planner.motion.interpolate import kept_knee_branches, swing_path
from planner.planning.step import Step

if TYPE_CHECKING:
    from planner.body.kinematics import LegKinematics
    from planner.body.robot_model import Robot
    from planner.body.torques import TorqueCheck
    from planner.problems.base import ConstraintCheck
    from planner.problems.options import LocalSettings
    from planner.world.terrain import Terrain

__all__ = ["Overlap", "OverlapPlanner", "overlap_step", "SLIDING_BUDGET_M"]

_Array = NDArray[np.float64]
_NU_TOL = 1e-9
# the stance feet roll from the body path's samples (see _merged); between two swing samples
# that leaves them sliding by the rolling's sampling error, at most this [m] (check: 1e-6)
SLIDING_BUDGET_M = 5e-7


class OverlapPlanner(Protocol):
    """What :func:`overlap_step` uses of a local planner, and no more.

    The robot, its terrain and friction, the leg kinematics, the settings
    (``swing_overlap``, ``theta.sway_stiffness``), the COM (``check.com_W``), the joint
    torques (``torques.solve``); the planner's path checks, the time law of its body paths
    and swings, and its swing height. :class:`planner.planning.local.LocalPlanner` has them.
    """

    robot: Robot
    terrain: Terrain
    mu: float
    kin: LegKinematics
    settings: LocalSettings
    check: ConstraintCheck
    torques: TorqueCheck

    def path_problem(self, path: list[State]) -> str:
        """Why a sampled path is not executable, or "" (section 8's checks per sample)."""
        ...

    def body_offsets_s(self, path: list[State]) -> _Array:
        """Times [s] of a body path's samples 1.. after its first."""
        ...

    def swing_offsets_s(self, path: list[State], leg: int) -> _Array:
        """Times [s] of a swing's samples 1.. after its first."""
        ...

    def swing_clearance_m(self, state: State, leg: int, touch_W) -> float:
        """The swing height [m] of ``leg`` from ``state`` to ``touch_W``."""
        ...


class Overlap:
    """A step's samples with its swing overlapping the body move's end.

    ``lift``: the body-path sample at which the leg lifts; ``states`` and ``times_s``: the
    step's samples and their times [s] from its start (as
    :meth:`LocalPlanner.step_samples`). The step lands on its own ``end``.
    """

    def __init__(self, lift: int, states: list, times_s: _Array):
        self.lift = lift
        self.states = states
        self.times_s = times_s


def _one_leaf(body: list[State]) -> _Array | None:
    """The body path's nu (section 7.1) at each sample, if it is a single leaf, else None."""
    nus = [s.info.get("nu") for s in body]
    if any(v is None for v in nus):
        return None
    nus = np.asarray(nus, float)
    if abs(nus[0]) > _NU_TOL or abs(nus[-1] - 1.0) > _NU_TOL or np.any(np.diff(nus) <= 0.0):
        return None  # a via pose (Theta1) restarts nu: two leaves
    return nus


def _lifted_copy(s: State, leg: int) -> State:
    """``s`` with ``leg`` in the air (for the time law's carried margin on three legs)."""
    out = s.copy()
    out.stratum = leg + 1
    out.support = tuple(i for i in range(4) if i != leg)
    out.info = {k: v for k, v in s.info.items() if k != "margin_N"}
    return out


def _earliest_lift(planner: OverlapPlanner, body: list[State], leg: int) -> int:
    """The first body sample from which the COM stays inside three feet with margin.

    A cheap screen for :func:`overlap_step` (the balance margin, the swing leg at its
    stance joints), never the first sample: the load moves off the leg over a four-feet
    interval (:func:`planner.planfile.plan.loaded_feet`), and a touch-down is no lift-off.
    """
    sup = [i for i in range(4) if i != leg]
    margin_m = planner.settings.theta.balance_margin_m
    n = len(body)
    first = n - 1
    for k in range(n - 1, 0, -1):
        s = body[k]
        if support_margin_m(s.feet_W[sup], planner.check.com_W(s)) < margin_m:
            break
        first = k
    return first


def _moving(path: list[State]) -> range:
    """Indices of ``path``'s samples before the body comes to rest on its last pose.

    From there on the stance is the Theta2 pose, certified by Theta2.
    """
    last = path[-1].base_position_W
    for k in range(1, len(path) - 1):
        if np.linalg.norm(path[k].base_position_W - last) < 1e-9:
            return range(k)
    return range(len(path) - 1)


def _tips(planner: OverlapPlanner, path: list[State], leg: int) -> str:
    """Why a sample of ``path`` with the body moving lacks a chosen pose's tip margin, or "".

    While the body moves on three legs the COM keeps ``settings.theta.balance_margin_m`` (Theta2's
    at the pose where the paper lifts the leg; the swing's own samples keep 20 mm once the
    body rests). This is also the margin of a step corrected from a measured state (8.4).
    """
    sup = [i for i in range(4) if i != leg]
    for k in _moving(path):
        s = path[k]
        tip = support_margin_m(s.feet_W[sup], planner.check.com_W(s))
        if tip < planner.settings.theta.balance_margin_m:
            why = f"the COM is {tip * 1000:.1f} mm inside the triangle at sample {k}"
            return Problem(why, FailureKind.TIP)
    return ""


def _merged(
    planner: OverlapPlanner,
    step: Step,
    lift: int,
    body_t: _Array,
    nus: _Array,
    swing_t: _Array,
    clearance_m: float,
) -> list[State]:
    """The swing from body sample ``lift`` with the base on the body path at ``swing_t``.

    The base follows the body path's leaf (eq. 6b, linear in compact exponential
    coordinates) at the nu the executor reaches at each swing time (it interpolates the
    body samples linearly in time). The stance feet roll (:mod:`planner.body.rolling`) from the
    body path's own sample before each swing sample, not from the previous swing sample:
    rolling depends a little on how a path is sampled, and so every stance foot is where
    the body path puts it at each of its samples (to rounding at the end, where the body
    rests on the Theta2 pose and the foot lands on the keyframe the planner solved), and
    between two swing samples it rolls as ``check`` computes to a fraction of a micrometre.
    The swing foot follows :func:`planner.motion.interpolate.swing_path` from where it lifts.
    """
    body, leg = step.body_path, step.leg
    robot, terrain, kin = planner.robot, planner.terrain, planner.kin
    rho = robot.foot_radius_m
    stance = [i for i in range(4) if i != leg]
    sp = swing_path(terrain, body[lift].feet_W[leg], step.end.feet_W[leg], clearance_m,
                    len(swing_t), rho)  # fmt: skip
    nu_at = np.interp(body_t[lift] + swing_t, body_t, nus)  # the executor's interpolation
    nu_at[0], nu_at[-1] = nus[lift], 1.0
    eps = interpolate_coords(body[0].coords, body[-1].coords, nu_at)
    out = [_lifted_copy(body[lift], leg)]
    rolled_from: dict[int, tuple] = {}
    for k in range(1, len(swing_t)):
        j = int(np.searchsorted(nus, nu_at[k], side="right")) - 1  # body sample at or before
        src = body[j]
        on_sample = abs(nu_at[k] - nus[j]) <= _NU_TOL
        g = src.pose if on_sample else pose_from_coords(eps[k])
        p, R = g[:3, 3], g[:3, :3]
        centres = np.array(src.feet_W, float)
        centres[stance] = _centres_W(kin, src, stance)
        centres[leg] = sp.centres_W[k]
        ref = np.array(src.joints_rad, float)
        ref[leg] = out[-1].joints_rad[leg]
        if on_sample:  # on a body sample: its stance legs as they are
            c_B = (centres[leg] - p) @ R
            results = [None] * 4
            results[leg] = kin.ik_leg_near(leg, c_B, ref[leg])
            results = kept_knee_branches(kin, results, ref, p, R, centres)
            joints = np.array(src.joints_rad, float)
            joints[leg] = results[leg].joints_rad
            feet = np.array(src.feet_W, float)
            bad = [] if results[leg].reachable else [leg]
            err = float(results[leg].error_m)
        else:
            if j not in rolled_from:
                rolled_from[j] = leg_rotations_W(kin, src.base_rotation_W, src.joints_rad)
            _, contacts, results, _ = roll_stance_feet(
                kin, terrain, p, R, centres, src.feet_W, rolled_from[j], stance, centres, ref
            )
            results = kept_knee_branches(kin, results, ref, p, R, centres)  # as in a leaf path
            joints = np.array([r.joints_rad for r in results])
            feet = np.array(src.feet_W, float)
            feet[stance] = contacts
            bad = [i for i, r in enumerate(results) if not r.reachable]
            err = float(max(r.error_m for r in results))
        feet[leg] = sp.points_W[k]
        out.append(
            State(
                base_position_W=p.copy(),
                base_rotation_W=R.copy(),
                feet_W=feet,
                joints_rad=joints,
                stratum=leg + 1,
                support=tuple(stance),
                info={"ik_ok": not bad, "ik_error_m": err, "unreachable_legs": bad},
            )
        )
    out[-1] = step.end
    return out


def _max_sliding_m(planner: OverlapPlanner, path: list[State], leg: int) -> float:
    """The stance feet's largest sliding [m] between two samples of ``path`` (``check``'s).

    As ``check`` measures it: the terrain normal at each sample's own contact points (of
    its sphere centres). With the first sample's normals for every pair, a relief can
    hide a 1.8 um slide under the 0.5 um budget that check then refuses (limit 1 um).
    """
    kin, rho = planner.kin, planner.robot.foot_radius_m
    stance = [i for i in range(4) if i != leg]
    c = np.array([_centres_W(kin, s, stance) for s in path])
    rot = np.array([leg_rotations_W(kin, s.base_rotation_W, s.joints_rad)[stance] for s in path])
    contacts, _ = unique_contact_points(planner.terrain, c[:-1].reshape(-1, 3), rho)
    normals = np.asarray(planner.terrain.normal(contacts), float).reshape(len(path) - 1, -1, 3)
    worst = 0.0
    for k in range(len(path) - 1):
        slid = sliding(c[k], c[k + 1], rot[k], rot[k + 1], normals[k], rho)
        worst = max(worst, float(np.max(slid)))
    return worst


def _centres_W(kin, s: State, legs: list[int]) -> _Array:
    """Foot sphere centres [m] of ``legs`` at ``s`` (forward kinematics, world frame)."""
    fb = np.array([kin.foot_B(i, s.joints_rad[i]) for i in legs])
    return fb @ s.base_rotation_W.T + s.base_position_W


def _swings_with_body(planner: OverlapPlanner, path: list[State], leg: int) -> str:
    """Why a three-leg stance of ``path`` with the body still moving sways, or ""."""
    bound = planner.settings.theta.sway_stiffness
    if bound is None:
        return ""
    sway = sway_stiffness_of(planner.robot)
    need = sway.bound_n_per_m(bound)
    sup = np.array([i for i in range(4) if i != leg])
    for k in _moving(path):
        s = path[k]
        q = planner.robot.q_from(s.base_position_W, s.base_quaternion_xyzw, s.joints_rad)
        tq = planner.torques.solve(
            q, sup, planner.mu, planner.terrain.normal(s.feet_W), least_squares=True
        )
        have = sway.stance(
            s.base_position_W, s.base_rotation_W, s.joints_rad, sup, np.nan_to_num(tq.torques_nm)
        ).least
        if not have >= need:
            why = f"the stance sways at sample {k} ({have:.0f} N/m < {need:.0f} N/m)"
            return Problem(why, FailureKind.SWAY)
    return ""


def overlap_step(planner: OverlapPlanner, step: Step) -> Overlap | None:
    """``step``'s samples with its swing starting inside its body move, or None.

    None where no earlier lift-off passes the checks (or the step is not a placement, its
    swing runs in joint space, or its body move is not a single leaf): the step is then
    executed as body move, then swing.
    """
    share = float(planner.settings.swing_overlap)
    body, swing, leg = step.body_path, step.swing_path, step.leg
    if not step.ok or share <= 0.0 or len(body) < 3 or len(swing) < 2:
        return None
    if any(s.info.get("over_edge") for s in swing):
        return None
    nus = _one_leaf(body)
    if nus is None:
        return None
    swing_alone = np.concatenate([[0.0], planner.swing_offsets_s(swing, leg)])
    n = len(body)
    first = _earliest_lift(planner, body, leg)
    clearance = planner.swing_clearance_m(step.moved, leg, step.end.feet_W[leg])
    for lift in range(first, n - 1):
        timing = body[:lift] + [_lifted_copy(s, leg) for s in body[lift:]]
        body_t = np.concatenate([[0.0], planner.body_offsets_s(timing)])
        tail_s = body_t[-1] - body_t[lift]
        if tail_s > share * body_t[-1] + 1e-12:
            continue
        for clr in (clearance, 0.5 * clearance):
            path, swing_t = _timed_merge(planner, step, lift, body_t, nus, swing_alone, clr)
            slid = _max_sliding_m(planner, path, leg)
            if slid > SLIDING_BUDGET_M:
                break  # the rolling's sampling error would eat check's tolerance: lift later
            why = (
                _tips(planner, path, leg)
                or planner.path_problem([body[lift - 1], *path])  # the lift sample in full
                or _swings_with_body(planner, path, leg)
            )
            if not why:
                states = list(body[: lift + 1]) + list(path[1:])
                times = np.concatenate([body_t[: lift + 1], body_t[lift] + swing_t[1:]])
                return Overlap(lift, states, times)
            if kind_of(why) in (FailureKind.BALANCE, FailureKind.TIP):
                break  # a lower swing does not move the COM less
    return None


def _timed_merge(planner, step, lift, body_t, nus, swing_alone, clr):
    """(merged path, its times from lift-off [s]).

    The swing keeps its own time law (:meth:`LocalPlanner.swing_offsets_s`: the foot's
    speed and acceleration caps along the same path), stretched so that the foot lands no
    earlier than the body rests. In the moving body frame the legs' joints move at other
    speeds: an interval where a joint would pass its share of the URDF limit (or the foot
    its cap) is lengthened, the samples kept (the body then moves a little slower there
    than its own law allows, never faster).
    """
    tail_s = body_t[-1] - body_t[lift]
    swing_t = np.array(swing_alone, float)
    if swing_t[-1] < tail_s:  # the foot lands no earlier than the body comes to rest
        swing_t = swing_t * (tail_s / swing_t[-1])
    path = _merged(planner, step, lift, body_t, nus, swing_t, clr)
    dt = np.diff(swing_t)
    need = _least_intervals_s(planner, path, step.leg)
    return path, np.concatenate([[0.0], np.cumsum(np.maximum(need, dt))])


def _least_intervals_s(planner: OverlapPlanner, path: list[State], leg: int) -> _Array:
    """Least durations [s] of a path's intervals under the joint and swing-foot speed caps."""
    from planner.body.robot_scale import time_scale
    from planner.motion.time_law import (
        FOOT_SPEED_M_S,
        LANDING_SPEED_M_S,
        joint_speed_limits_rad_s,
        swing_caps,
    )

    k = time_scale(planner.robot)
    ell, caps = swing_caps(
        np.array([s.feet_W[leg] for s in path]),
        np.array([s.joints_rad.ravel() for s in path]),
        foot_speed_m_s=FOOT_SPEED_M_S * k,
        landing_speed_m_s=LANDING_SPEED_M_S * k,
        vmax_rad_s=joint_speed_limits_rad_s(planner.robot),
    )
    return ell / caps
