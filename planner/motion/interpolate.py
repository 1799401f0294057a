"""Interpolation along a leaf of a stratum (paper section 7.1, eq. 6a/6b) and swing paths.

On a leaf of the paper the stance feet's contact points r_j are fixed (here they roll, see
:mod:`planner.body.rolling`: the sphere centres move by rho w x n as the shanks turn, which is
what MuJoCo's rigid sphere feet do); the base pose g moves linearly in
compact exponential coordinates (section 4.7),

    g(nu) = g~((1 - nu) eps~(g_1) + nu eps~(g_2)),   nu in [0, 1],

and the joints at each sample come from inverse kinematics (section 5.1.2) of the stance
feet's sphere centres r_j + rho n(r_j) (:mod:`planner.body.contact`).

On S_i, i != 0, eq. 6a moves the swing foot linearly from r_i^1 to r_i^2, which drags it
through the ground whenever the terrain between them rises. Beyond the paper,
:func:`swing_path` lifts the foot along the terrain normal, rises vertically to a travel
height ``clearance_m`` above the highest terrain under its track, travels there, descends
vertically and comes down onto the new foothold along its normal.

Swing-foot convention: a foot in the air is stored (``State.feet_W``, the ``points_W`` of a
:class:`SwingPath`) as the point one radius *below* its sphere centre, ``centre - rho e_z``
(the sphere's lowest point). A foot on the terrain is stored as its contact point, centre
``r + rho n(r)``. A swing path is planned in sphere-centre space, so the centres (what the
leg reaches) are continuous from lift-off to touch-down; the stored point at the two ends
is the contact point.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.body.contact import E_Z, foot_centre_from_contact
from planner.body.kinematics import IKResult, kinematics_of
from planner.body.rolling import leg_rotations_W, roll_stance_feet
from planner.body.state import State
from planner.core.lie import interpolate_coords, pose_from_coords

if TYPE_CHECKING:
    from planner.body.robot import Robot

__all__ = [
    "SwingPath",
    "swing_path",
    "default_clearance_m",
    "smootherstep",
    "interpolate_leaf",
    "interpolate_swing",
    "between_q",
]

_Array = NDArray[np.float64]
DEFAULT_CLEARANCE_M = 0.03  # [m] swing clearance when no robot is given (LittleDog)
CLEARANCE_FRACTION_OF_REACH = 0.167  # default clearance = 0.167 * leg reach (0.030 m, LittleDog)
ON_TERRAIN_TOL_M = 1e-6  # a foot point within this of height(x, y) is on the terrain
STANCE_TOL_M = 1e-9  # stance feet of the two ends of a leaf must agree to this
BETWEEN_SAMPLES_RAD = 0.2  # a joint moving more in one sample interval has its leg links
BETWEEN_STEP_RAD = 0.05  # checked this often between the samples (planner and check)


class _Terrain(Protocol):
    def height(self, x: ArrayLike, y: ArrayLike) -> _Array: ...

    def height_sharp(self, x: ArrayLike, y: ArrayLike) -> _Array: ...

    def normal(self, p_W: ArrayLike) -> _Array: ...


def between_q(q_a: NDArray[np.float64], q_b: NDArray[np.float64], u: float) -> NDArray:
    """Pinocchio q a share ``u`` from ``q_a`` to ``q_b``: linear, the quaternion normalised.

    What the executor commands between two samples (the base moves little in one).
    """
    q = (1.0 - u) * np.asarray(q_a, float) + u * np.asarray(q_b, float)
    q[3:7] /= np.linalg.norm(q[3:7])
    return q


def default_clearance_m(robot: Robot) -> float:
    """Default swing clearance: ``0.167 * mean leg reach`` [m] (0.030 m for LittleDog)."""
    return float(CLEARANCE_FRACTION_OF_REACH * np.mean(robot.reach_m))


def smootherstep(u: _Array) -> _Array:
    """6u^5 - 15u^4 + 10u^3: 0 -> 1 with zero velocity and acceleration at both ends."""
    u = np.clip(u, 0.0, 1.0)
    return u * u * u * (u * (6.0 * u - 15.0) + 10.0)


# ---- swing path -----------------------------------------------------------------------------
@dataclass
class SwingPath:
    """A swing-foot path sampled at n values of s in [0, 1].

    Attributes
    ----------
    s : (n,) path parameter, uniform in [0, 1].
    points_W : (n, 3) stored foot points [m]: the contact points at both ends, the point one
        radius below the sphere centre in between.
    centres_W : (n, 3) sphere centres [m], continuous along the path.
    phase : (n,) phase of each sample: 0 liftoff, 1 rise, 2 travel, 3 descend,
        4 touchdown.
    travel_z_m : highest height of the stored point during the travel phase [m].
    corners_W : (6, 3) sphere-centre corners: lift centre, end of liftoff, top of rise, end
        of travel, start of touchdown, touch centre.

    """

    s: _Array
    points_W: _Array
    centres_W: _Array
    phase: _Array
    travel_z_m: float
    corners_W: _Array


def _on_terrain(terrain: _Terrain, p: _Array) -> bool:
    return abs(p[2] - float(np.asarray(terrain.height(p[0], p[1])))) <= ON_TERRAIN_TOL_M


def _travel_profile(
    terrain: _Terrain,
    a1: _Array,
    a4: _Array,
    clearance_m: float,
    rho: float,
    track_step_m: float,
    slope: float,
) -> _Array:
    """Sphere-centre points (m, 3) of the travel piece from above a1 to above a4.

    z(u) = max over track points u' of (z_req(u') - slope |u - u'|), with z_req the highest
    terrain within rho + track_step of the track point plus clearance + rho, and the liftoff
    corners a1, a4 as requirements at the two ends.
    """
    length = float(np.linalg.norm(a4[:2] - a1[:2]))
    m = max(2, int(np.ceil(length / track_step_m)) + 1)
    u = np.linspace(0.0, 1.0, m)
    xy = a1[:2] + u[:, None] * (a4[:2] - a1[:2])
    margin = rho + track_step_m
    ang = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    dirs = np.column_stack([np.cos(ang), np.sin(ang)])
    ring = np.concatenate([np.zeros((1, 2)), 0.5 * margin * dirs, margin * dirs])
    pts = (xy[:, None, :] + ring[None, :, :]).reshape(-1, 2)
    h = np.asarray(terrain.height(pts[:, 0], pts[:, 1]), dtype=float)
    sharp = getattr(terrain, "height_sharp", None)
    if sharp is not None:
        h = np.maximum(h, np.asarray(sharp(pts[:, 0], pts[:, 1]), dtype=float))
    z_req = h.reshape(m, -1).max(axis=1) + clearance_m + rho
    z_req[0] = max(z_req[0], a1[2])
    z_req[-1] = max(z_req[-1], a4[2])
    dist = np.abs(u[:, None] - u[None, :]) * length
    z = (z_req[None, :] - slope * dist).max(axis=1)
    return np.column_stack([xy, z])


def _along_polyline(poly: _Array, w: _Array) -> _Array:
    """Points at arc-length fractions ``w`` in [0, 1] along a polyline (m, 3)."""
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if cum[-1] <= 0.0:
        return np.repeat(poly[:1], len(w), axis=0)
    t = np.clip(w, 0.0, 1.0) * cum[-1]
    return np.column_stack([np.interp(t, cum, poly[:, k]) for k in range(3)])


def swing_path(
    terrain: _Terrain,
    lift_W: ArrayLike,
    touch_W: ArrayLike,
    clearance_m: float = DEFAULT_CLEARANCE_M,
    n: int = 21,
    radius_m: float = 0.0,
    liftoff_m: float | None = None,
    track_step_m: float = 0.002,
    slope: float = 1.0,
) -> SwingPath:
    """Plan a swing foot's path from ``lift_W`` to ``touch_W`` (beyond eq. 6a).

    In sphere-centre space (centre = contact + rho n at a foot on the terrain, stored point
    + rho e_z in the air) the path has five pieces: liftoff along the lift point's normal
    by ``liftoff_m``; vertical rise to the travel profile; travel along the profile above
    the straight xy track; vertical descent; touchdown along the touch point's normal. The
    travel profile follows the terrain: above each track point the stored point (the
    sphere's lowest point) is at least ``clearance_m`` above the highest terrain (max of
    ``height_sharp`` and ``height``, sampled every ``track_step_m`` and widened by the foot
    radius), and it rises and falls no steeper than ``slope`` (dz per metre of track), so
    the foot lifts only as high as the ground ahead needs: a leg stepping onto a step
    from far behind folds less than with one travel height over the whole track. Each
    piece is traversed with a smootherstep in s, its share of s proportional to its
    length, so the path is C2 in s and stops at each corner (quasi-static; corners are not
    cut, so a foot next to a step face does not hit it).

    An end point more than 1e-6 m above ``height(x, y)`` is taken as already in the air
    (stored point convention): it has no liftoff/touchdown piece.

    Parameters
    ----------
    terrain : Terrain
        Provides ``height``, ``height_sharp`` and ``normal``.
    lift_W, touch_W : array_like, shape (3,)
        Lift-off and touch-down contact points [m], world frame.
    clearance_m : float
        Travel clearance above the terrain [m].
    n : int
        Number of samples (>= 2), both ends included.
    radius_m : float
        Foot sphere radius rho [m] (0: the path of a point foot).
    liftoff_m : float, optional
        Distance travelled along the normals at both ends [m]; default ``clearance_m / 2``.
    track_step_m : float
        Sampling step of the terrain under the track [m].
    slope : float
        Steepest rise or fall of the travel profile [m per m of track].

    Returns
    -------
    SwingPath
        Points, centres and phases of the n samples.

    """
    if int(n) != n or n < 2:
        raise ValueError(f"swing_path: n must be an integer >= 2, got {n!r}")
    if not (clearance_m >= 0 and radius_m >= 0 and track_step_m > 0):
        raise ValueError("swing_path: need clearance_m >= 0, radius_m >= 0, track_step_m > 0")
    rho = float(radius_m)
    h_off = 0.5 * float(clearance_m) if liftoff_m is None else float(liftoff_m)
    ends = []
    for p in (lift_W, touch_W):
        p = np.asarray(p, dtype=float).reshape(3)
        if not np.all(np.isfinite(p)):
            raise ValueError(f"swing_path: end points must be finite, got {p!r}")
        if _on_terrain(terrain, p):
            nrm = np.asarray(terrain.normal(p), dtype=float).reshape(3)
            c = foot_centre_from_contact(terrain, p, rho)
            ends.append((p, c, c + h_off * nrm))
        else:
            c = p + rho * E_Z
            ends.append((p, c, c))
    (p0, c0, a1), (p1, c1, a4) = ends
    prof = _travel_profile(terrain, a1, a4, float(clearance_m), rho, track_step_m, slope)
    travel_z = float(prof[:, 2].max()) - rho
    a2, a3 = prof[0], prof[-1]
    corners = np.array([c0, a1, a2, a3, a4, c1])
    travel_len = float(np.linalg.norm(np.diff(prof, axis=0), axis=1).sum())
    lengths = np.linalg.norm(np.diff(corners, axis=0), axis=1)
    lengths[2] = travel_len
    total = lengths.sum()
    if total <= 0.0:
        frac = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])  # no motion: all "travel"
    else:
        frac = np.concatenate([[0.0], np.cumsum(lengths) / total])
    s = np.linspace(0.0, 1.0, int(n))
    phase = np.clip(np.searchsorted(frac, s, side="right") - 1, 0, 4)
    width = np.maximum(frac[phase + 1] - frac[phase], 1e-300)
    u = np.where(frac[phase + 1] > frac[phase], (s - frac[phase]) / width, 1.0)
    w = smootherstep(u)[:, None]
    centres = corners[phase] + w * (corners[phase + 1] - corners[phase])
    travel = phase == 2
    if np.any(travel):
        centres[travel] = _along_polyline(prof, w[travel, 0])
    centres[0], centres[-1] = c0, c1
    points = centres - rho * E_Z
    points[0], points[-1] = p0, p1
    return SwingPath(s, points, centres, phase, float(travel_z), corners)


# ---- interpolation along a leaf ---------------------------------------------------------------
def _check_stance(state_a: State, state_b: State, stance: list[int]) -> None:
    from planner.body.robot import LEG_NAMES

    for i in stance:
        d = float(np.linalg.norm(state_a.feet_W[i] - state_b.feet_W[i]))
        if d > STANCE_TOL_M:
            raise ValueError(
                f"interpolate: stance foot {LEG_NAMES[i]} (leg {i + 1}) differs by {d:.3g} m "
                "between the two states; they are not on the same leaf"
            )


def _leaf_stratum(state_a: State, state_b: State) -> int:
    sa, sb = int(state_a.stratum), int(state_b.stratum)
    if sa == sb or sb == 0:
        return sa
    if sa == 0:
        return sb
    raise ValueError(f"interpolate: states on different strata S{sa} and S{sb}, no common leaf")


def kept_knee_branches(kin, results, reference_rad, base_position_W, base_rotation_W, centres_W):
    """IK ``results`` of one sample with no leg jumping to its other knee branch.

    A leg's result on the other branch than its ``reference_rad`` (``knee_flipped``: the
    target lies beyond the joint limits of its own branch) would be a jump of the path
    through the leg's straight pose: a stance leg measured at its knee stop (8.3, its
    contact a millimetre off the terrain the planner sees) gets the other branch at the
    path's first sample, and the servos, asked to turn the standing knee by some 145
    degrees, drop the robot. Such a leg
    keeps its reference joints and is out of reach by its miss [m] (``reachable`` False).
    ``None`` results (legs not solved at this sample) stay None.
    """
    p = np.asarray(base_position_W, float)
    R = np.asarray(base_rotation_W, float)
    ref = np.asarray(reference_rad, float).reshape(4, 3)
    out = list(results)
    for i, r in enumerate(results):
        if r is not None and r.knee_flipped:
            miss = float(np.linalg.norm(R @ kin.foot_B(i, ref[i]) + p - np.asarray(centres_W[i])))
            out[i] = IKResult(ref[i].copy(), False, miss, "kept", reason="the other knee branch")
    return out


def _interpolate(
    robot: Robot,
    terrain: _Terrain,
    state_a: State,
    state_b: State,
    n: int,
    stratum: int,
    swing: str,
    clearance_m: float | None,
    liftoff_m: float | None,
    rolling: bool = True,
) -> list[State]:
    if int(n) != n or n < 2:
        raise ValueError(f"interpolate: n must be an integer >= 2, got {n!r}")
    n = int(n)
    if swing not in ("path", "linear"):
        raise ValueError(f"interpolate: swing must be 'path' or 'linear', got {swing!r}")
    rho = robot.foot_radius_m
    i_sw = stratum - 1 if stratum else None
    stance = [i for i in range(4) if i != i_sw]
    _check_stance(state_a, state_b, stance)

    nus = np.linspace(0.0, 1.0, n)
    eps = interpolate_coords(state_a.coords, state_b.coords, nus)
    poses = [pose_from_coords(e) for e in eps]
    poses[0], poses[-1] = state_a.pose, state_b.pose

    feet = np.repeat(state_a.feet_W[None], n, axis=0)
    centres = np.repeat(foot_centre_from_contact(terrain, state_a.feet_W, rho)[None], n, axis=0)
    if i_sw is not None:
        clr = default_clearance_m(robot) if clearance_m is None else float(clearance_m)
        a, b = state_a.feet_W[i_sw], state_b.feet_W[i_sw]
        if swing == "path":
            sp = swing_path(terrain, a, b, clr, n, rho, liftoff_m)
            feet[:, i_sw], centres[:, i_sw] = sp.points_W, sp.centres_W
        else:  # eq. 6a, linear in sphere centres
            ca, cb = (
                foot_centre_from_contact(terrain, p, rho)
                if _on_terrain(terrain, p)
                else p + rho * E_Z
                for p in (a, b)
            )
            centres[:, i_sw] = (1.0 - nus)[:, None] * ca + nus[:, None] * cb
            feet[:, i_sw] = centres[:, i_sw] - rho * E_Z
            feet[0, i_sw], feet[-1, i_sw] = a, b

    kin = kinematics_of(robot)
    ref = state_a.joints_rad
    out: list[State] = []
    rot_prev = None
    for k in range(n):
        p, R = poses[k][:3, 3], poses[k][:3, :3]
        if rolling and k > 0 and stance:
            if k > 1:  # first guess: the previous sample's rolling again
                centres[k, stance] = 2.0 * centres[k - 1, stance] - centres[k - 2, stance]
            centres[k], feet[k, stance], results, rot_prev = roll_stance_feet(
                kin, terrain, p, R, centres[k - 1], feet[k - 1], rot_prev, stance, centres[k], ref
            )
        else:
            results = kin.ik(p, R, centres[k], reference_rad=ref)
            rot_prev = leg_rotations_W(kin, R, np.array([r.joints_rad for r in results]))
        kept = kept_knee_branches(kin, results, ref, p, R, centres[k])
        joints = np.array([r.joints_rad for r in kept])
        if any(r is not q for r, q in zip(kept, results, strict=True)):
            rot_prev = leg_rotations_W(kin, R, joints)  # the rolling goes on from these
        results = kept
        bad = [i for i, r in enumerate(results) if not r.reachable]
        end = state_a if k == 0 else state_b if k == n - 1 else None
        info = {} if end is None else dict(end.info)
        info.update(
            nu=float(nus[k]),
            ik_ok=not bad,
            ik_error_m=float(max(r.error_m for r in results)),
            unreachable_legs=bad,
        )
        out.append(
            State(
                base_position_W=p.copy(),
                base_rotation_W=R.copy(),
                feet_W=feet[k].copy(),
                joints_rad=joints,
                stratum=stratum if end is None else end.stratum,
                support=(tuple(stance) if i_sw is not None else state_a.support)
                if end is None
                else end.support,
                forces_W=None
                if end is None or end.forces_W is None
                else np.array(end.forces_W, dtype=float),
                info=info,
            )
        )
        ref = joints
    return out


def interpolate_leaf(
    robot: Robot,
    terrain: _Terrain,
    state_a: State,
    state_b: State,
    n: int,
    swing: str = "path",
    clearance_m: float | None = None,
    liftoff_m: float | None = None,
    rolling: bool = True,
) -> list[State]:
    """Sample the leaf between two states at n values of nu in [0, 1] (section 7.1).

    The leaf's stratum is the states' common stratum; a state on S0 may pair with one on
    S_i (S0 ∩ S_i bounds S_i's leaves), the leaf is then S_i's. The base pose follows eq.
    6a/6b (linear in compact exponential coordinates, ends exact). Stance feet must agree
    between the states (ValueError naming the leg otherwise); they do not slide, they roll
    (``rolling``, :mod:`planner.body.rolling`: each centre moves by rho w x n as its shank turns,
    so the last state's stance feet and joints differ from ``state_b``'s by the rolling;
    ``rolling=False`` keeps the paper's fixed contact points). On S_i the swing
    foot follows :func:`swing_path` (``swing="path"``) or, as eq. 6a, moves linearly in
    sphere-centre space (``swing="linear"``, which may cut through the terrain).

    Joints come from leg IK of the sphere centres at every sample, each seeded by the
    previous sample's joints (the first by ``state_a.joints_rad``). A sample with a leg out
    of reach keeps finite closest-reach joints and gets ``info["ik_ok"] = False``
    (``info["unreachable_legs"]`` lists them, ``info["ik_error_m"]`` the worst miss).

    Returns
    -------
    list of State
        n states; the end ones carry the given states' stratum, support, forces and info
        (plus the IK keys); interior ones are on the leaf's stratum with no forces.

    """
    return _interpolate(
        robot,
        terrain,
        state_a,
        state_b,
        n,
        _leaf_stratum(state_a, state_b),
        swing,
        clearance_m,
        liftoff_m,
        rolling,
    )


def interpolate_swing(
    robot: Robot,
    terrain: _Terrain,
    state_lift: State,
    state_touch: State,
    n: int,
    clearance_m: float | None = None,
    swing_leg: int | None = None,
    liftoff_m: float | None = None,
    rolling: bool = True,
) -> list[State]:
    """Swing one leg from ``state_lift`` to ``state_touch`` while the base interpolates.

    The swing leg (0-based) is ``swing_leg`` when given, else the leg of a non-zero stratum
    of either state, else the only foot that moves. Base pose as eq. 6a; the swing foot
    follows :func:`swing_path` with ``clearance_m`` (default :func:`default_clearance_m`);
    the other three feet must agree between the states and stay put. See
    :func:`interpolate_leaf` for IK and the returned states (interior ones on S_{leg+1}).
    """
    if swing_leg is None:
        strata = {int(s.stratum) for s in (state_lift, state_touch)} - {0}
        if len(strata) > 1:
            raise ValueError(f"interpolate_swing: states on different strata {sorted(strata)}")
        if strata:
            swing_leg = strata.pop() - 1
        else:
            moved = [
                i
                for i in range(4)
                if np.linalg.norm(state_lift.feet_W[i] - state_touch.feet_W[i]) > STANCE_TOL_M
            ]
            if len(moved) != 1:
                raise ValueError(
                    "interpolate_swing: cannot tell the swing leg (both states on S0 and "
                    f"{len(moved)} feet move); pass swing_leg"
                )
            swing_leg = moved[0]
    if int(swing_leg) not in range(4):
        raise ValueError(f"interpolate_swing: swing_leg must be 0..3, got {swing_leg!r}")
    return _interpolate(
        robot,
        terrain,
        state_lift,
        state_touch,
        n,
        int(swing_leg) + 1,
        "path",
        clearance_m,
        liftoff_m,
        rolling,
    )
