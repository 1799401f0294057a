"""The time law of a planned path: when each of its samples is reached.

The paper plans geometric paths (the leaves of section 7) and leaves their timing open; it
asks only that the motion be slow enough to be quasi-static. A path here is the planner's
samples of one leaf: a body move on four feet (eq. 6a/6b) or a swing. Its time law gives
every sample interval the least duration under

- a speed cap on each interval: the base's speed (``body_speed_m_s``) in a body move, the
  swing foot's (:data:`FOOT_SPEED_M_S`, and :data:`LANDING_SPEED_M_S` over the landing
  third of the intervals) in a swing, and every joint at most a fraction of its URDF
  velocity limit;
- an acceleration bound along the path: the base's ``body_accel_m_s2``, lowered where the
  stance could not carry the body's inertial force with half its friction-cone margin to
  spare (:func:`carried_accel_m_s2`: the quasi-static check of section 6 with gravity
  g - a u, so the motion stays quasi-static in the sense that matters), and
  :data:`FOOT_ACCEL_M_S2`, which lets the servos follow a swing;
- near the terrain, the body's speed at most its clearance to spare over the time it lags
  (:func:`near_terrain_caps`): MuJoCo's body trails and overshoots a fast move, and over
  an edge that error is the margin;
- rest at both ends: every keyframe is a static equilibrium (section 6). A swing may
  start before its body move has come to rest (:mod:`planner.planning.overlap`); the body
  still rests on its Theta2 pose when the foot lands.

It is the discrete time-optimal parameterisation of a sampled path: the speed at each
sample is the largest the forward pass (v_{k+1}^2 <= v_k^2 + 2 a l_k from rest) and the
backward pass (to rest) allow under the caps, and each interval is crossed at the mean
speed of its two ends (constant acceleration), never faster than its cap. The executor
interpolates between samples, so a path's motion is only as smooth as its sampling.
Speeds scale with sqrt(s) and accelerations not at all between robots of leg-length ratio
s (the same Froude number, :mod:`planner.body.robot_scale`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "body_profile",
    "swing_caps",
    "swing_durations_s",
    "rest_to_rest_durations_s",
    "rest_to_rest_profile",
    "carried_accel_m_s2",
    "near_terrain_caps",
    "timed_settings",
    "joint_speed_limits_rad_s",
    "hip_arm_m",
    "BODY_LAG_S",
    "BODY_SPEED_M_S",
    "BODY_ACCEL_M_S2",
    "SWING_TIME_S",
    "JOINT_SPEED_FRACTION",
    "OVER_EDGE_SPEED_FRACTION",
]

_Array = NDArray[np.float64]

# every joint at most this share of its URDF velocity limit in an interval. Chosen from
# MuJoCo runs: flat walks asked up to 0.92 of LittleDog's limits (HR knee, in
# swings) and MuJoCo tracked them; a joint-space swing that flipped a knee (3 rad) at 1.3x
# lagged 92 degrees.
JOINT_SPEED_FRACTION = 0.9
# a swing searched in joint space passes an edge by millimetres, less than the servos' lag
# at 0.9 of the limit (MuJoCo, open loop: the joints lagged up to 14 degrees over a
# barrier and the foot caught it): its joints go at this share of their limits
OVER_EDGE_SPEED_FRACTION = 0.4
FOOT_SPEED_M_S = 1.0  # LittleDog's swing foot, peak [m/s] (x sqrt(s))
FOOT_ACCEL_M_S2 = 10.0  # ... its acceleration along the swing path [m/s^2]
LANDING_SPEED_M_S = 0.5  # ... over the landing third of the intervals [m/s] (x sqrt(s))
LANDING_FRACTION = 1.0 / 3.0  # the last third of a swing's intervals is its landing
CARRIED_SHARE = 0.5  # a body move's inertia may use at most this share of a sample's
# friction-cone margin (MuJoCo: a 10 cm climb at 1.0 m/s^2 everywhere slid and fell
# where a body move's margin halves below 1 m/s^2)
ACCEL_FLOOR_M_S2 = 0.05  # ... but a sample at the cone's edge may still move slowly
MIN_INTERVAL_S = 1e-4  # no interval is shorter (repeated samples) [s]
# the executed body is off its path by up to its speed x this [s] (x sqrt(s)) in MuJoCo.
# Chosen from MuJoCo runs: a body moved 3.3 cm back at up to 0.13 m/s with its underside
# 16 mm over a barrier's edge overshot by 15 mm and 4 degrees as it braked (joints within
# 1.7 degrees of their set-points), came down on the edge and fell; capping the speed at
# the clearance to spare over 0.1 s of lag still fell, over 0.2 s held, over 0.3 s reached
BODY_LAG_S = 0.3
LEAST_SPARE_M = 0.002  # a body already nearer than its margin still moves, slowly
# the local planners' defaults (timed_settings), chosen from MuJoCo runs at time scale 1:
BODY_SPEED_M_S = 0.25  # LittleDog's body moves, peak [m/s] (x sqrt(s) for another robot)
# ... their acceleration bound [m/s^2], lower where the stance cannot carry it: the 10 cm
# climb slid and fell open loop at 1.0 and 1.5 (its body overshot a
# fast move by 2 cm before a swing), and was executed as planned at 0.5
BODY_ACCEL_M_S2 = 0.5
SWING_TIME_S = 0.25  # LittleDog's least swing [s] (x sqrt(s))


def rest_to_rest_durations_s(lengths: _Array, caps: _Array, accel) -> _Array:
    """Least durations [s] of the intervals of a path from rest to rest.

    ``lengths`` (K,) are the intervals' lengths in the path coordinate, ``caps`` (K,) their
    speed caps and ``accel`` the bound on the acceleration along the path, one for all or
    (K,) per interval (units of the coordinate per s and s^2). A single interval takes
    max(2 sqrt(l / a), l / cap).
    """
    return rest_to_rest_profile(lengths, caps, accel)[0]


def rest_to_rest_profile(lengths: _Array, caps: _Array, accel) -> tuple[_Array, _Array]:
    """(durations (K,) [s], accelerations (K,)) of :func:`rest_to_rest_durations_s`'s law.

    The accelerations are signed along the path (negative: braking), constant over each
    interval, (v_{k+1}^2 - v_k^2) / (2 l_k); a single interval's is its bound (it speeds up
    and brakes at it).
    """
    ell = np.maximum(np.asarray(lengths, float), 0.0)
    cap = np.asarray(caps, float)
    k = len(ell)
    if k == 0:
        return np.zeros(0), np.zeros(0)
    acc = np.broadcast_to(np.asarray(accel, float), (k,))
    if not (np.all(acc > 0.0) and np.all(cap > 0.0)):
        raise ValueError("time law: speed caps and acceleration bounds must be > 0")
    if k == 1:
        dt = max(2.0 * math.sqrt(ell[0] / acc[0]), ell[0] / cap[0], MIN_INTERVAL_S)
        return np.array([dt]), acc.copy()
    node = np.zeros(k + 1)
    node[1:-1] = np.minimum(cap[:-1], cap[1:])
    v = np.zeros(k + 1)
    for i in range(k):  # forward: from rest, accelerate at most accel
        v[i + 1] = min(node[i + 1], math.sqrt(v[i] ** 2 + 2.0 * acc[i] * ell[i]))
    v[k] = 0.0
    for i in range(k - 1, -1, -1):  # backward: to rest
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2.0 * acc[i] * ell[i]))
    mean = np.minimum(0.5 * (v[:-1] + v[1:]), cap)
    with np.errstate(divide="ignore", invalid="ignore"):
        dt = np.where(mean > 0.0, ell / np.maximum(mean, 1e-300), 0.0)
        a_k = np.where(ell > 0.0, (v[1:] ** 2 - v[:-1] ** 2) / (2.0 * np.maximum(ell, 1e-300)), 0.0)
    return np.maximum(dt, MIN_INTERVAL_S), a_k


def near_terrain_caps(clearance_m: _Array, margin_m: float, lag_s: float) -> _Array:
    """Speed caps [m/s] of body intervals ``clearance_m`` [m] over the sharp terrain.

    An interval whose body (its bottom face, the least over its two samples) is c above
    the terrain goes at most (c - ``margin_m``) / ``lag_s``, at least ``LEAST_SPARE_M`` /
    ``lag_s``: the clearance the path keeps beyond its margin is what the executed body's
    lag behind and overshoot of a fast move may use (:data:`BODY_LAG_S`). High above the
    terrain the cap exceeds any body speed.
    """
    c = np.asarray(clearance_m, float)
    return np.maximum(c - margin_m, LEAST_SPARE_M) / lag_s


def carried_accel_m_s2(margin_n, cap_m_s2: float, need_n: float, iters: int = 6) -> float:
    """The largest acceleration in [floor, cap] (m/s^2) whose balance margin stays >= ``need_n``.

    ``margin_n(a)``: the friction-cone margin [N] of a sample accelerating at ``a`` along
    its path, both ways (eq. 4 with gravity g - a u: d'Alembert's inertial force at the
    COM). It is concave in a (the margin is concave in the load), so the test at the cap
    covers every smaller acceleration; otherwise bisection, ``iters`` halvings.
    """
    if margin_n(cap_m_s2) >= need_n:
        return cap_m_s2
    lo, hi = 0.0, cap_m_s2
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        if margin_n(mid) >= need_n:
            lo = mid
        else:
            hi = mid
    return max(lo, ACCEL_FLOOR_M_S2)


def _joint_caps(
    joints_rad: _Array, lengths: _Array, vmax_rad_s: _Array | None, fraction: float
) -> _Array:
    """(K,) path-speed caps that keep every joint within ``fraction`` of its limit."""
    caps = np.full(len(lengths), np.inf)
    if vmax_rad_s is None or len(joints_rad) < 2:
        return caps
    vmax = np.asarray(vmax_rad_s, float)
    ok = np.isfinite(vmax) & (vmax > 0.0)
    if not ok.any():
        return caps
    need = np.abs(np.diff(joints_rad, axis=0))[:, ok] / (fraction * vmax[ok])  # s per interval
    worst = need.max(axis=1)
    with np.errstate(divide="ignore"):
        return np.where(worst > 0.0, lengths / np.maximum(worst, 1e-300), np.inf)


def body_profile(
    positions_W: _Array,
    rotations_W: Sequence[_Array],
    joints_rad: _Array,
    *,
    speed_m_s,
    accel_m_s2,
    arm_m: float,
    vmax_rad_s: _Array | None,
    fraction: float = JOINT_SPEED_FRACTION,
) -> tuple[_Array, _Array]:
    """(durations [s], signed accelerations [m/s^2]) of a body move's intervals.

    Samples: base positions (N, 3) and rotations. The path coordinate is the base's
    travel, a turn counting as the travel of a point ``arm_m`` from the base (a hip):
    l_k = max(|dp_k|, arm |d phi_k|). ``speed_m_s`` and ``accel_m_s2``: one bound, or
    (K,) per interval.
    """
    p = np.asarray(positions_W, float)
    if len(p) < 2:
        return np.zeros(0), np.zeros(0)
    dp = np.linalg.norm(np.diff(p, axis=0), axis=1)
    R = [np.asarray(r, float) for r in rotations_W]
    turn = np.array([_angle(a, b) for a, b in zip(R[:-1], R[1:], strict=True)])
    ell = np.maximum(np.maximum(dp, arm_m * turn), 1e-9)
    caps = np.minimum(
        np.broadcast_to(np.asarray(speed_m_s, float), ell.shape),
        _joint_caps(joints_rad, ell, vmax_rad_s, fraction),
    )
    return rest_to_rest_profile(ell, caps, accel_m_s2)


def swing_durations_s(
    foot_W: _Array,
    joints_rad: _Array,
    *,
    foot_speed_m_s: float,
    landing_speed_m_s: float,
    foot_accel_m_s2: float,
    least_s: float,
    vmax_rad_s: _Array | None,
    fraction: float = JOINT_SPEED_FRACTION,
) -> _Array:
    """Durations [s] of a swing's intervals (samples: the swing foot's points (N, 3)).

    The landing third of the intervals is capped at ``landing_speed_m_s``: landings with
    speed turned the body in MuJoCo (a walk's end error: slowing the landing third 3x
    more than halved it, slowing the lift-off third did not). A swing shorter than
    ``least_s`` is stretched to it.
    """
    if len(foot_W) < 2:
        return np.zeros(0)
    ell, caps = swing_caps(
        foot_W, joints_rad, foot_speed_m_s=foot_speed_m_s,
        landing_speed_m_s=landing_speed_m_s, vmax_rad_s=vmax_rad_s, fraction=fraction,
    )  # fmt: skip
    dt = rest_to_rest_durations_s(ell, caps, foot_accel_m_s2)
    total = float(dt.sum())
    return dt * (least_s / total) if 0.0 < total < least_s else dt


def swing_caps(
    foot_W: _Array,
    joints_rad: _Array,
    *,
    foot_speed_m_s: float,
    landing_speed_m_s: float,
    vmax_rad_s: _Array | None,
    fraction: float = JOINT_SPEED_FRACTION,
) -> tuple[_Array, _Array]:
    """(lengths [m], speed caps [m/s]) of a swing's intervals (:func:`swing_durations_s`).

    The foot's cap, ``landing_speed_m_s`` over the landing third of the intervals, and
    every joint within ``fraction`` of its limit; ``lengths / caps`` is each interval's
    least duration.
    """
    f = np.asarray(foot_W, float)
    ell = np.maximum(np.linalg.norm(np.diff(f, axis=0), axis=1), 1e-9)
    caps = np.full(len(ell), foot_speed_m_s)
    caps[len(ell) - max(1, round(len(ell) * LANDING_FRACTION)) :] = landing_speed_m_s
    return ell, np.minimum(caps, _joint_caps(joints_rad, ell, vmax_rad_s, fraction))


def timed_settings(settings, robot):
    """``settings`` (:class:`planner.problems.options.LocalSettings`) with unset timing set.

    ``body_speed_m_s``, ``body_accel_m_s2`` and ``swing_time_s`` where None: LittleDog's
    :data:`BODY_SPEED_M_S`, :data:`BODY_ACCEL_M_S2` and :data:`SWING_TIME_S`, speeds and
    times scaled to ``robot`` by dynamic similarity (:mod:`planner.body.robot_scale`).
    """
    from planner.body.robot_scale import time_scale

    k = time_scale(robot)
    if settings.body_speed_m_s is None:
        settings = replace(settings, body_speed_m_s=BODY_SPEED_M_S * k)
    if settings.body_accel_m_s2 is None:
        settings = replace(settings, body_accel_m_s2=BODY_ACCEL_M_S2)
    if settings.swing_time_s is None:
        settings = replace(settings, swing_time_s=SWING_TIME_S * k)
    return settings


def joint_speed_limits_rad_s(robot) -> _Array | None:
    """The URDF's velocity limits of ``robot``'s 12 leg joints [rad/s] (None where none is set)."""
    vmax = np.asarray(robot.model.velocityLimit, float)[-12:]
    return vmax if len(vmax) == 12 else None


def hip_arm_m(robot) -> float:
    """Mean horizontal distance of ``robot``'s hips from the base [m] (a turn's lever)."""
    hips = np.array([leg.points_B[0] for leg in robot.legs])
    return float(np.mean(np.linalg.norm(hips[:, :2], axis=1)))


def _angle(Ra: _Array, Rb: _Array) -> float:
    """Angle [rad] of the rotation Ra^T Rb."""
    c = 0.5 * (float(np.trace(Ra.T @ Rb)) - 1.0)
    return math.acos(min(1.0, max(-1.0, c)))
