"""Foothold candidates over the leg's reachable, safe region (beyond paper section 8.2.2).

Lambda_t (eq. 13) proposes one target: the leg's normal position a fixed stride ahead.
Where that target cannot be used (a barrier whose far side is only reachable with the
shank over the edge, a trench wider than the stride, an IPOPT start on the wrong side of an
edge), the planner needs other footholds. :func:`foothold_candidates` lists them: contact
points on a grid around the target, inside the leg's workspace zeta_i (section 4.4) at the
body pose the body move aims for, kept only where the sharp terrain is safe under the foot
(:func:`planner.motion.heuristics.foothold_hazard`) and ahead of the foot's current contact, and
ordered by a score of

- progress along tau: the shortfall against the stride (a foothold behind the target costs
  ``SHORT_COST`` per metre, one beyond it ``LONG_COST``),
- lateral offset from the target (``LATERAL_COST`` per metre),
- leg posture: distance of the sphere centre from the hip beyond ``REACH_COMFORT`` of the
  leg's reach (``STRETCH_COST`` per metre),
- slope of the ground (``SLOPE_COST`` x (1 - n_z)).

Candidates closer than ``min_spacing_m`` to a better one are dropped, so a few of them
span the region. The body move (Theta2, landing-ready) then decides which one the robot
can really step to (:meth:`planner.planning.local.LocalPlanner.step`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.body.kinematics import hip_point_B
from planner.motion.heuristics import foothold_hazard, horizontal_axes

__all__ = ["foothold_candidates", "best_and_shortest"]

_Array = NDArray[np.float64]
GRID_M = 0.01  # spacing of the candidate grid [m]
SHORT_COST = 1.0  # per metre of stride short of the target
LONG_COST = 0.6  # per metre beyond the target (a longer step is the way over a gap)
LATERAL_COST = 1.5  # per metre sideways of the target
STRETCH_COST = 2.0  # per metre of hip-to-foot distance beyond REACH_COMFORT x reach
REACH_COMFORT = 0.9
SLOPE_COST = 0.2  # x (1 - n_z) of the ground under the foot
MIN_ADVANCE_M = 0.01  # a candidate is at least this far ahead of the foot's contact
REACH_FRACTION = 1.0  # the sphere centre within the leg's reach of the hip ...
BODY_SLACK_M = 0.03  # ... where the body may end up this far from the pose aimed for
DEFAULT_BACK_M = 0.06  # candidates reach this far behind the target (or back to the foot)
HIP_FOLLOW = 0.5  # ... and the hip follows this share of a foothold's height change


def foothold_candidates(
    robot,
    terrain,
    leg: int,
    target_W: ArrayLike,
    forward_W: ArrayLike,
    body_position_W: ArrayLike,
    body_rotation_W: ArrayLike,
    mu: float,
    not_behind_W: ArrayLike | None = None,
    max_back_m: float | None = None,
    max_ahead_m: float | None = None,
    max_lateral_m: float = 0.05,
    min_spacing_m: float = 0.02,
    limit: int = 6,
    accept=None,
) -> list[_Array]:
    """Up to ``limit`` safe, reachable contact points near ``target_W``, best first.

    ``body_position_W``/``body_rotation_W``: the body pose the move before the swing aims
    for (the hip's position there bounds the reach). ``not_behind_W``: the foot's current
    contact; candidates less than ``MIN_ADVANCE_M`` ahead of it along ``forward_W`` are
    skipped (the grid reaches back to it: ``max_back_m`` None), and a candidate higher or
    lower than it moves the hip up or down by ``HIP_FOLLOW`` of the difference (the body
    follows its footholds' plane, in which a pair of legs shares a step:
    :func:`planner.motion.heuristics.support_body_target_W`). ``accept(point)`` False drops a
    candidate (before ``limit`` is counted).
    """
    t = np.asarray(target_W, float).reshape(3)
    f, side = horizontal_axes(forward_W)
    hip_B = hip_point_B(robot.legs[leg])
    hip_W = np.asarray(body_rotation_W, float) @ hip_B + np.asarray(body_position_W, float)
    reach = float(robot.reach_m[leg])
    rho = float(robot.foot_radius_m)

    if max_ahead_m is None:  # a leg's reach beyond the target (the far side of a trench)
        max_ahead_m = float(robot.reach_m[leg])
    if max_back_m is None:  # back to the foot (the nearest safe point past an edge), or 6 cm
        max_back_m = DEFAULT_BACK_M
        if not_behind_W is not None:
            gap = float((t[:2] - np.asarray(not_behind_W, float).reshape(3)[:2]) @ f[:2])
            max_back_m = max(max_back_m, gap)
    d = np.arange(-max_back_m, max_ahead_m + 1e-9, GRID_M)
    lat = np.arange(-max_lateral_m, max_lateral_m + 1e-9, GRID_M)
    D, L = np.meshgrid(d, lat, indexing="ij")
    D, L = D.ravel(), L.ravel()
    xy = t[:2] + D[:, None] * f[:2] + L[:, None] * side[:2]
    keep = np.ones(len(D), bool)
    if not_behind_W is not None:
        back = np.asarray(not_behind_W, float).reshape(3)[:2]
        keep &= (xy - back) @ f[:2] >= MIN_ADVANCE_M
    z = np.asarray(terrain.height(xy[:, 0], xy[:, 1]), float)
    n = np.asarray(terrain.normal(np.column_stack([xy, z])), float).reshape(-1, 3)
    centres = np.column_stack([xy, z]) + rho * n
    hips = np.repeat(hip_W[None, :], len(D), axis=0)
    if not_behind_W is not None:
        hips[:, 2] += HIP_FOLLOW * (z - float(np.asarray(not_behind_W, float).reshape(3)[2]))
    dist = np.linalg.norm(centres - hips, axis=1)
    keep &= dist <= REACH_FRACTION * reach + BODY_SLACK_M
    cost = (
        SHORT_COST * np.maximum(-D, 0.0)
        + LONG_COST * np.maximum(D, 0.0)
        + LATERAL_COST * np.abs(L)
        + STRETCH_COST * np.maximum(dist - REACH_COMFORT * reach, 0.0)
        + SLOPE_COST * (1.0 - n[:, 2])
    )
    out: list[_Array] = []
    for k in np.argsort(np.where(keep, cost, np.inf), kind="stable"):
        if not keep[k] or len(out) >= limit:
            break
        c = np.array([xy[k, 0], xy[k, 1], z[k]])
        if any(np.linalg.norm(c[:2] - o[:2]) < min_spacing_m for o in out):
            continue
        if foothold_hazard(terrain, c, rho, mu, forward_W=f):
            continue
        if accept is not None and not accept(c):
            continue
        out.append(c)
    return out


def best_and_shortest(
    candidates: list[_Array], foot_W: ArrayLike, forward_W: ArrayLike, n: int
) -> list[_Array]:
    """``n`` of ``candidates`` (best first), alternating best-scored and shortest steps.

    The score prefers a full stride; where the body cannot follow that far (a leg at the
    foot of a riser, the hind legs still below a step) the way on is the nearest safe
    point past the edge, which the score ranks last. Alternating the two orders tries both
    within a few attempts.
    """
    f, _ = horizontal_axes(forward_W)
    foot = np.asarray(foot_W, float).reshape(3)
    by_advance = sorted(candidates, key=lambda c: float((c[:2] - foot[:2]) @ f[:2]))
    out: list[_Array] = []
    for a, b in zip(candidates, by_advance, strict=True):
        for c in (a, b):
            if len(out) < n and not any(c is o for o in out):
                out.append(c)
    return out
