"""Precompute-then-correct (paper section 8.4), and a plan's body shifted on purpose.

:func:`run_corrected`: the precomputed plan is executed cycle by cycle; at each cycle
start the measured foot centres (:mod:`planner.sim.measure`) are compared with the
plan's, the cycle's base path is shifted by their mean offset (the body keeps its planned
place relative to its support, so the centre of mass stays where the plan balanced it),
the stance feet are held where they are, the swing foot blends from where it is to its
planned (world) foothold, and the set-points are re-solved by Paden-Kahan leg IK
(:mod:`planner.body.kinematics`; :func:`correct_cycle`). Footholds return to the plan's,
so errors stay bounded. Feedback (8.3) executes a plan's step so corrected where no step
planned anew is found (:func:`_follow_corrected`, behind the gates of a planned path).

:func:`shift_body` moves a plan's body against its feet (IK again): a plan perturbed on
purpose, to check that the simulator notices a centre of mass outside the support.
"""

from __future__ import annotations

import time as _time

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.planfile.plan import Plan, Samples, states_of_samples
from planner.sim.measure import Measurement, StateSource, _foot_centres, _source
from planner.sim.simulate import SimResult, SimSettings, cycle_starts, finish_run, new_run

__all__ = ["blend_in", "correct_cycle", "run_corrected", "shift_body"]

_Array = NDArray[np.float64]

# a corrected swing sample whose IK joints leave the plan's by more than this [rad] keeps
# the plan's (8.4; chosen from MuJoCo runs: a corrected knee 66 degrees off the plan's put
# the foot on a step edge and the robot fell)
SWING_JUMP_RAD = 0.35
# a corrected cycle whose feet leave their legs' reach (a stance foot measured a few
# millimetres off a plan that has the leg stretched to its reach limit) has its body moved
# toward them by the worst sample's miss, up to this far in all [m], in at most
# REACH_SHIFTS rounds (correct_cycle); the gates of _follow_corrected (balance, leg links,
# path checks) judge the shifted samples
REACH_SHIFT_M = 0.01
REACH_SHIFTS = 3


def correct_cycle(
    robot,
    plan_q: _Array,
    plan_contact: NDArray,
    plan_centres: _Array,
    meas: Measurement,
    times: _Array | None = None,
    current_joints: _Array | None = None,
) -> tuple[_Array, int]:
    """Corrected set-points of one cycle of a plan from a measurement (section 8.4).

    ``plan_q`` (n, 19), ``plan_contact`` (n, 4), ``plan_centres`` (n, 4, 3): the cycle's
    samples, foot sphere centres from FK. With ``times`` (n,) and ``current_joints``
    (12,, robot order; the set-points now), the jump from the current set-points to the
    corrected ones is spread over the cycle's four-feet phase (until the first lift-off).
    The base starts at its measured pose and reaches the plan's (shifted by the feet's
    mean offset) by the end of that four-feet phase: a plan's body attitude 16 degrees
    from the measured one is turned to, not commanded at once. Where feet
    then leave their legs' reach, the body is moved toward them by one offset for the
    cycle (at most ``REACH_SHIFT_M``), taken on over the same phase.
    Returns (corrected q (n, 19), IK misses: legs out of reach summed over samples).
    """
    from planner.body.kinematics import kinematics_of
    from planner.core.lie import (
        quat_from_rotation,
        rotation_from_quat,
        rotation_from_vector,
    )

    kin = kinematics_of(robot)
    c_meas = _foot_centres(robot, meas.q)
    n = len(plan_q)
    out = plan_q.copy()
    # the measured base relative to the plan's first (shifted) one, faded out over the
    # four-feet phase: a world-frame rotation vector and a translation
    k_end = _four_feet_end(plan_contact)
    d, pos_err, rot_err = _base_error(plan_q[0], plan_contact[0], plan_centres[0], c_meas, meas)
    clock = np.arange(n, dtype=float) if times is None else np.asarray(times, float)
    span = max(float(clock[max(k_end, 0)] - clock[0]), 1e-9)
    lift = [None] * 4  # sample of lift-off and of touchdown, per leg
    for i in range(4):
        up = np.flatnonzero(~plan_contact[:, i])
        if up.size:
            ks = int(up[0])
            after = np.flatnonzero(plan_contact[ks:, i])
            kt = ks + int(after[0]) if after.size else n - 1
            lift[i] = (max(ks - 1, 0), kt)
    poses, targets, swinging = [], np.empty((n, 4, 3)), np.zeros((n, 4), bool)
    for k in range(n):
        w = 1.0 - min(float(clock[k] - clock[0]) / span, 1.0) if k_end > 0 else 0.0
        R = rotation_from_vector(w * rot_err) @ rotation_from_quat(plan_q[k, 3:7])
        poses.append((plan_q[k, :3] + d + w * pos_err, R, w, robot.joints_from_q(plan_q[k])))
        for i in range(4):
            if lift[i] is None or k <= lift[i][0]:  # measured start + the planned rolling
                targets[k, i] = plan_centres[k, i] + (c_meas[i] - plan_centres[0, i])
            elif k < lift[i][1]:
                a, b = lift[i]
                u = (k - a) / max(b - a, 1)
                targets[k, i] = plan_centres[k, i] + (1.0 - u) * (c_meas[i] - plan_centres[0, i])
            else:
                targets[k, i] = plan_centres[k, i]
            swinging[k, i] = lift[i] is not None and lift[i][0] < k < lift[i][1]

    def corrected(shift_W):
        """(q (n, 19), reach misses (n, 4, 3)) with the body shifted by ``shift_W``."""
        q, miss = plan_q.copy(), np.zeros((n, 4, 3))
        for k, (p, R, w, ref) in enumerate(poses):
            p = p + (1.0 - w) * shift_W  # the shift grows as the measured error fades
            joints, miss[k] = _corrected_legs(kin, p, R, targets[k], ref, swinging[k])
            q[k] = robot.q_from(p, quat_from_rotation(R) if w > 0.0 else plan_q[k, 3:7], joints)
        return q, miss

    # a foot the plan has at its leg's reach, measured a few millimetres off, is out of
    # reach of the plan's body: the whole cycle's body is moved toward it (one constant
    # offset, reached over the four-feet phase like the measured error's correction)
    shift = np.zeros(3)
    out, miss = corrected(shift)
    for _ in range(REACH_SHIFTS):
        if not miss.any():
            break
        total = miss.sum(axis=1)  # (n, 3): each sample's pull on the body
        trial = shift + total[int(np.argmax(np.linalg.norm(total, axis=1)))]
        if np.linalg.norm(trial) > REACH_SHIFT_M:
            break
        q_t, miss_t = corrected(trial)
        if _misses(miss_t) >= _misses(miss):
            break
        shift, out, miss = trial, q_t, miss_t
    misses = _misses(miss)
    if times is not None and current_joints is not None:
        out = blend_in(robot, out, plan_contact, times, current_joints)
    return out, misses


def _misses(miss: _Array) -> int:
    """Legs out of reach, summed over samples, of reach misses (n, 4, 3)."""
    return int(np.count_nonzero(np.linalg.norm(miss, axis=-1) > 0.0))


def _corrected_legs(kin, p: _Array, R: _Array, targets_W: _Array, ref: _Array, swinging):
    """(joints (4, 3), reach misses (4, 3) world [m]) of the legs for body pose (p, R).

    Each foot's IK on the plan sample's own knee branch: a leg the plan landed on its
    other knee beside an edge (LocalPlanner._other_knee_landing) keeps it; the leg's
    default branch can put its shank into the edge (33 mm deep in MuJoCo). A miss is the
    target less the closest reachable foot centre (zero where reached); a swinging leg
    whose IK jumps to another solution than the plan's keeps the plan's joints (a
    joint-space swing over an edge flips the knee mid-air: the foot off by the body's
    correction until it lands), not a miss.
    """
    joints, miss = np.empty((4, 3)), np.zeros((4, 3))
    for i in range(4):
        target_B = R.T @ (targets_W[i] - p)
        res = kin.ik_leg(i, target_B, reference_rad=ref[i], knee=kin.knee_direction(i, ref[i]))
        if swinging[i] and float(np.max(np.abs(res.joints_rad - ref[i]))) > SWING_JUMP_RAD:
            joints[i] = ref[i]
            continue
        joints[i] = res.joints_rad
        if not res.reachable:
            miss[i] = R @ (target_B - kin.foot_B(i, res.joints_rad))
    return joints, miss


def _base_error(
    plan_q0: _Array, plan_contact0: NDArray, plan_centres0: _Array, c_meas: _Array, meas
):
    """(feet's mean offset d (3,), base position error (3,) [m], rotation vector (3,) [rad]).

    The measured base against the plan's first sample shifted by the mean offset ``d`` of
    the measured stance feet (sphere centres ``c_meas`` (4, 3), :func:`_foot_centres`) from
    the plan's (world frame), as :func:`correct_cycle` uses.
    """
    from planner.core.lie import rotation_from_quat, vector_from_rotation

    down = np.asarray(plan_contact0, bool)
    d = np.mean((c_meas - plan_centres0)[down], axis=0) if down.any() else np.zeros(3)
    rot_err = vector_from_rotation(
        rotation_from_quat(meas.q[3:7]) @ rotation_from_quat(plan_q0[3:7]).T
    )
    return d, meas.q[:3] - (plan_q0[:3] + d), rot_err


def _four_feet_end(contact: NDArray) -> int:
    """Last sample of the four-feet phase that opens a cycle (-1: it opens on three feet)."""
    up = np.flatnonzero(~np.asarray(contact, bool).all(axis=1))
    return int(up[0]) - 1 if up.size else len(contact) - 1


def _four_feet_span_s(times: _Array, contact: NDArray) -> float:
    """Duration [s] of the four-feet phase that opens a cycle (until its first lift-off)."""
    return float(times[max(_four_feet_end(contact), 0)] - times[0])


def _correction_time_s(robot, pos_err: _Array, rot_err: _Array, local=None) -> float:
    """Least time [s] to bring the body from its measured pose to the plan's (8.4).

    The base's error, and its rotation's at the hips (the lever of the farthest hip), moved
    from rest to rest under the planner's body-move time law (``body_speed_m_s``,
    ``body_accel_m_s2`` of ``local``'s settings; the defaults for ``robot`` without it). The plan's
    four-feet phase is timed for the plan's own move (0.2 s for millimetres), too short for
    a body centimetres off: in MuJoCo a body 2.8 cm off the plan, pulled back in 0.2 s,
    tipped the robot as the next foot lifted.
    """
    from planner.body.kinematics import hip_point_B
    from planner.motion.time_law import rest_to_rest_durations_s, timed_settings
    from planner.problems.options import LocalSettings

    # the planner's settings, resolved for the robot once (LocalPlanner); else the defaults
    # resolved the same way
    st = local.settings if local is not None else timed_settings(LocalSettings(), robot)
    speed, accel = st.body_speed_m_s, st.body_accel_m_s2
    lever = max(float(np.linalg.norm(hip_point_B(leg))) for leg in robot.legs)
    err = max(float(np.linalg.norm(pos_err)), lever * float(np.linalg.norm(rot_err)))
    return float(rest_to_rest_durations_s(np.array([err]), np.array([speed]), accel)[0])


def blend_in(robot, q: _Array, contact: NDArray, times: _Array, current_joints: _Array) -> _Array:
    """Set-points ``q`` (n, 19) that start from ``current_joints`` (12,, robot order).

    The difference between the servos' set-points now and the first new sample (the
    servo error that holds the robot up, when the new samples start from a measured
    configuration; a correction's jump) fades out linearly over the four-feet phase
    that opens the cycle (until its first lift-off).
    """
    n = len(q)
    if n < 2:
        return q
    up = np.flatnonzero(~np.asarray(contact, bool).all(axis=1))
    t_end = times[up[0] - 1] if up.size and up[0] > 1 else times[-1]
    span = max(float(t_end - times[0]), 1e-9)
    jump = np.asarray(current_joints, float).reshape(4, 3) - robot.joints_from_q(q[0])
    out = q.copy()
    for k in range(n):
        w = 1.0 - min(float(times[k] - times[0]) / span, 1.0)
        if w > 0.0:
            out[k] = robot.q_from(q[k, :3], q[k, 3:7], robot.joints_from_q(q[k]) + w * jump)
    return out


def _follow_corrected(
    ex,
    meas,
    robot,
    terrain,
    s: Samples,
    centres,
    a: int,
    b: int,
    sim,
    local=None,
    refused=None,
    balance_m: float | None = None,
):
    """Execute plan samples a..b corrected from the measurement ``meas`` (8.4), or None.

    One correction, from the measurement the cycle was planned from, for the whole step.
    None, with nothing executed, when the corrected samples leave a leg's reach, bring
    the COM (Pinocchio, of the corrected joints) too near a three-foot support's edge (the
    plan's balance is kept only where every foot is where the plan had it, up to one
    common offset), or put a thigh or shank on the sharp terrain deeper than at the start
    (the plan's swing over an edge, from a body a few centimetres off, can hit the edge);
    else whether the robot is still standing.

    Balance asks ``balance_m`` at every three-foot sample, by default (None) the keyframes'
    ``BALANCE_MARGIN_M`` (25 mm), 5 mm more than the plan's own path samples keep: the
    step is a fallback, executed open loop from a state the plan was not made for, with
    errors the correction does not model (the feet's rolling, the servos' sag). Chosen from
    MuJoCo runs: at 20 mm a corrected hind-leg swing after a 6 cm step down (21-22 mm all
    along) tipped the body 34 degrees; at 25 mm such a step is refused and the gait queue
    steps instead. :func:`run_feedback` asks the path samples' 20 mm only where no step planned
    anew is found at all.

    With ``local`` (a :class:`~planner.planning.local.LocalPlanner`) the corrected samples,
    before the servo blend, must also pass the check every path planned anew passes
    (:meth:`~planner.planning.local.LocalPlanner.path_problem`: body box, leg links between
    samples, friction cones, joint torques, the final stance's sway), so that a corrected
    step is never held to less than a step planned anew (a corrected step could otherwise
    ask a knee for more of its effort than a planned path may use). A body measured off
    the plan is brought back over a four-feet hold as long as :func:`_correction_time_s`
    asks, where the cycle's own four-feet phase is shorter. Where a gate refuses, its
    reason is appended to the list ``refused``.
    """
    from planner.body import stability
    from planner.body.kinematics import kinematics_of
    from planner.body.links import leg_links
    from planner.core.lie import rotation_from_quat

    balance_m = stability.BALANCE_MARGIN_M if balance_m is None else balance_m
    times, contact = s.time[a : b + 1], s.contact[a : b + 1]
    plan_q, plan_centres = s.q[a : b + 1], centres[a : b + 1]
    c_meas = _foot_centres(robot, meas.q)
    _, pos_err, rot_err = _base_error(plan_q[0], contact[0], plan_centres[0], c_meas, meas)
    hold = _correction_time_s(robot, pos_err, rot_err, local) - _four_feet_span_s(times, contact)
    if hold > 0.0:  # the body is brought back to the plan no faster than the time law allows
        times = np.concatenate([times[:1], times + hold])
        contact, plan_q = np.concatenate([contact[:1], contact]), np.vstack([plan_q[:1], plan_q])
        plan_centres = np.concatenate([plan_centres[:1], plan_centres])
    q_body, misses = correct_cycle(robot, plan_q, contact, plan_centres, meas, times)
    if misses:
        return _refuse(refused, f"the corrected step leaves a leg's reach at {misses} samples")
    q = blend_in(robot, q_body, contact, times, sim.targets())
    kin, links = kinematics_of(robot), leg_links(robot)
    floor = None
    for qk, ck in zip(q, contact, strict=True):
        bare = links.path_margin(terrain, qk, np.flatnonzero(~ck), scale=0.0)
        floor = np.minimum(bare, 0.0) if floor is None else floor
        if np.any(bare < floor - 1e-4):
            c = int(np.argmin(bare - floor))
            return _refuse(refused, f"the corrected step puts the {links.describe(c)} deeper")
        if ck.sum() != 3:
            continue
        R, joints = rotation_from_quat(qk[3:7]), robot.joints_from_q(qk)
        feet = kin.feet_W(qk[:3], R, joints)[ck]
        com = qk[:3] + R @ kin.com_B(joints)
        if (tip := stability.support_margin_m(feet, com)) < balance_m:
            why = f"the corrected step's COM {tip * 1000:.1f} mm inside its support"
            return _refuse(refused, f"{why} (< {balance_m * 1000:.0f} mm)")
    if local is not None:
        centres_W = np.array([_foot_centres(robot, qk) for qk in q_body])
        path = states_of_samples(robot, terrain, q_body, contact, times, centres_W)
        if why := local.path_problem(path):
            return _refuse(refused, f"the corrected step: {why}")
    ex.monitor.keyframe(0)
    return ex.follow(times, q, contact)


def _refuse(refused: list | None, why: str) -> None:
    """None (a corrected step not executed), its reason appended to ``refused`` if given."""
    if refused is not None:
        refused.append(why)
    return None


def run_corrected(
    plan: Plan,
    settings: SimSettings | None = None,
    source: StateSource | None = None,
    **noise,
) -> SimResult:
    """Execute the precomputed plan, correcting it from the measured state (8.4).

    Corrections are made at every cycle start (touchdown) and again at every lift-off, so
    that the swing foot is aimed from where the body really is. ``noise`` as in
    :func:`run_feedback`.
    """
    wall0 = _time.perf_counter()
    sim, ex = new_run(plan, settings, "precompute-then-correct")
    t0 = sim.time
    src = _source(sim, source, **noise)
    robot = plan.load_robot()
    s = plan.samples
    centres = plan.foot_centres_W()
    cycles = set(cycle_starts(s.contact))
    allc = s.contact.all(axis=1)
    lifts = {k for k in range(1, len(s) - 1) if allc[k] and not allc[k + 1]}
    starts = sorted(cycles | lifts | {len(s) - 1})
    m = ex.monitor.metrics
    try:
        for a, b in zip(starts[:-1], starts[1:], strict=True):
            meas = src.measure()
            q, misses = correct_cycle(
                robot,
                s.q[a : b + 1],
                s.contact[a : b + 1],
                centres[a : b + 1],
                meas,
                s.time[a : b + 1],
                sim.targets(),
            )
            m.ik_misses += misses
            if a in cycles:
                ex.monitor.keyframe(0)
                m.cycles += 1
            if not ex.follow(s.time[a : b + 1], q, s.contact[a : b + 1]):
                break
    except KeyboardInterrupt:
        ex.interrupt()
    return finish_run(plan, ex, wall0, t0)


# ------------------------------------------------------------------------------ perturbing
def shift_body(plan: Plan, offset_W: ArrayLike, mask: ArrayLike | None = None) -> Plan:
    """A copy of ``plan`` with the body moved by ``offset_W`` [m] against its feet.

    In the samples selected by ``mask`` (all by default) the base position moves by the
    offset and the joints are re-solved (leg IK) so that every foot stays where the plan
    put it: the centre of mass moves by about the offset relative to the support. Used to
    make a plan that must fail on a body with mass.
    """
    from planner.body.kinematics import kinematics_of
    from planner.core.lie import rotation_from_quat

    robot = plan.load_robot()
    kin = kinematics_of(robot)
    off = np.asarray(offset_W, float).reshape(3)
    sel = np.ones(len(plan.samples), bool) if mask is None else np.asarray(mask, bool)
    centres = plan.foot_centres_W()
    q = plan.samples.q.copy()
    for k in np.flatnonzero(sel):
        p = q[k, :3] + off
        R = rotation_from_quat(q[k, 3:7])
        ref = robot.joints_from_q(q[k])
        joints = np.array(
            [
                kin.ik_leg(i, R.T @ (centres[k, i] - p), reference_rad=ref[i]).joints_rad
                for i in range(4)
            ]
        )
        q[k] = robot.q_from(p, q[k, 3:7], joints)
    out = Plan.from_dict(plan.to_dict(), source=f"{plan.source} (body shifted {off.tolist()})")
    out.samples = Samples(plan.samples.time.copy(), q, plan.samples.contact.copy())
    out._robot_cache, out._terrain_cache = plan._robot_cache, plan._terrain_cache
    return out
