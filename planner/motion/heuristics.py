"""Target heuristics Lambda_c and Lambda_t (paper sections 8.2.1-8.2.2, eq. 12-13).

- :func:`lambda_c` gives r_c*, the body target of the soft-persuasion problem Theta_2
  (section 7.3) before leg i_f swings: the support triangle's centroid lifted above the
  terrain (eq. 12).
- :func:`lambda_t` gives r_{i_f}^t, the foothold target of the foot-placement problem
  Theta_3 (section 7.4): the leg's normal position (joints at theta_nor) with the body on
  the trajectory, moved a stride ahead along it (eq. 13).
- :func:`reference_directions` and :func:`body_pose_on_trajectory` give the reference
  forward and normal directions u_f, u_n of the objectives sigma_1, sigma_2 (section 7.2-7.3)
  and the body pose they describe.

Legs are 0-based here (FL=0 .. HR=3); the paper's leg i_f is ``i_f + 1``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.body.kinematics import kinematics_of, robot_cached
from planner.body.links import leg_links
from planner.body.stability import support_margin_m

if TYPE_CHECKING:
    from planner.body.robot import Robot
    from planner.body.state import State
    from planner.motion.trajectory import Trajectory

__all__ = [
    "nominal_height_m",
    "default_step_m",
    "normal_smoothing_radius_m",
    "support_centroid_W",
    "support_incentre_W",
    "support_plane_W",
    "support_body_target_W",
    "body_clearance_height_m",
    "reach_height_cap_m",
    "lambda_c",
    "two_beat_xy_W",
    "chebyshev_centre_xy",
    "lambda_t",
    "reference_directions",
    "body_pose_on_trajectory",
    "normal_foot_centre_W",
    "frame_from_directions",
    "foothold_hazard",
    "LegRoom",
    "leg_room",
    "horizontal_axes",
    "safe_foothold",
]

_Array = NDArray[np.float64]
STEP_FRACTION_OF_REACH = 0.35  # default stride = 0.35 * leg reach (0.063 m for LittleDog)
DEFAULT_NORMAL_RADIUS_M = 0.1  # [m] smoothing radius of u_n when no robot is given
EDGE_MARGIN_M = 0.015  # a foothold keeps this much beyond the foot radius from an edge [m]
WALL_RADIUS_M = 0.04  # a foothold this close to a higher edge (a riser, a pit wall) is refused
# (and a leg whose links reach further ahead of its foot keeps their room: leg_room)
WALL_HEIGHT_M = 0.01  # ... when the top of that edge is this much higher [m]
HAZARD_GRID_M = 0.003  # sampling step of the sharp terrain around a foothold [m]
# a foothold with terrain PIT_DEPTH_M higher both within PIT_HALF_WIDTH_M ahead of it and
# within that behind it lies in a trench or a pit: a hind foot left on a trench's floor
# cannot climb out once the body has moved on
PIT_HALF_WIDTH_M = 0.07
PIT_DEPTH_M = 0.03
MAX_SUPPORT_TILT_RAD = np.radians(30.0)  # the body follows the footholds' plane up to this tilt
BODY_TARGET_CLEARANCE_M = 0.02  # body target: box bottom this high over the terrain (as Theta2)
BODY_FOOTPRINT_GRID_M = 0.01  # sampling of the terrain under the body box (a thin barrier)


class _Terrain(Protocol):
    def height(self, x: ArrayLike, y: ArrayLike) -> _Array: ...

    def smoothed_normal(self, p_W: ArrayLike, radius: float) -> _Array: ...


# ---- robot-derived defaults ---------------------------------------------------------------
def nominal_height_m(robot: Robot) -> float:
    """Body origin height above flat ground with every leg at theta_nor [m].

    ``-min_i z_B(foot centre_i at theta_nor) + rho``: the body level, the lowest foot sphere
    touching the ground. 0.152 m for LittleDog. The default d_c of :func:`lambda_c`.
    """
    feet_B = kinematics_of(robot).feet_B(robot.theta_nor)
    return float(-feet_B[:, 2].min() + robot.foot_radius_m)


def default_step_m(robot: Robot) -> float:
    """Default stride of :func:`lambda_t`: ``0.35 * mean leg reach`` [m] (0.063 m, LittleDog)."""
    return float(STEP_FRACTION_OF_REACH * np.mean(robot.reach_m))


def normal_smoothing_radius_m(robot: Robot) -> float:
    """Smoothing radius of the pseudo-normal u_n [m]: the largest hip distance in xy.

    About half the body length (0.107 m for LittleDog).
    """
    hips = np.array([leg.points_B[0][:2] for leg in robot.legs])
    return float(np.linalg.norm(hips, axis=1).max())


# ---- Lambda_c, eq. 12 ---------------------------------------------------------------------
def _check_leg(i_f: int) -> int:
    if int(i_f) not in range(4) or int(i_f) != i_f:
        raise ValueError(f"swing leg i_f must be 0..3 (FL, FR, HL, HR), got {i_f!r}")
    return int(i_f)


def _support(state: State, i_f: int) -> _Array:
    others = [i for i in range(4) if i != _check_leg(i_f)]
    return np.asarray(state.feet_W, dtype=float)[others]


def support_centroid_W(state: State, i_f: int) -> _Array:
    """Mean of the three contact points other than leg ``i_f``'s (r_c^+ of eq. 12) [m].

    The paper writes r_c^+ = sum_{i != i_f} r_i; a sum of positions is not a position, the
    mean (the support triangle's centroid) is what is meant.
    """
    return _support(state, i_f).mean(axis=0)


def support_incentre_W(state: State, i_f: int) -> _Array:
    """Incentre of the support triangle of the legs other than ``i_f``, in xy (z: mean).

    The incentre is the point of the (horizontally projected) triangle farthest from its
    nearest edge: the largest static stability margin for a COM over it. A degenerate
    (collinear) triangle gives its centroid.
    """
    tri = _support(state, i_f)
    xy = tri[:, :2]
    # side lengths opposite each vertex
    a = np.linalg.norm(xy[[1, 2, 0]] - xy[[2, 0, 1]], axis=1)
    if a.sum() <= 1e-12:
        return tri.mean(axis=0)
    out = tri.mean(axis=0)
    out[:2] = (a[:, None] * xy).sum(axis=0) / a.sum()
    return out


def lambda_c(
    robot: Robot,
    terrain: _Terrain,
    state: State,
    i_f: int,
    d_c_m: float | None = None,
    shrink: float = 0.0,
    feet_plane_W: ArrayLike | None = None,
    heading_W: ArrayLike | None = None,
    centre_xy_W: ArrayLike | None = None,
) -> _Array:
    """Body target r_c* = Lambda_c(Psi, i_f) (section 8.2.1, eq. 12).

    Step 1: r_c^+ = the centroid of the three contact points r_i, i != i_f (the paper's sum
    means their mean). A COM at the centroid has only a third of each altitude as margin
    to the support triangle's edges, and moving onto three legs shrinks that margin further
    under modelling errors (section 8.2.1's argument); ``shrink`` in [0, 1] moves r_c^+ that
    fraction of the way from the centroid toward the triangle's incentre (the point with
    the largest distance to the nearest edge, :func:`support_incentre_W`). 0 is the paper.
    Step 2: lift to ``d_c_m`` above the terrain, r_c* = (x, y, height(x, y) + d_c); where
    the terrain under r_c^+ is lower than the support feet (a gap, a hole, a pit between
    stones) the body would sink into it, so the height lifted from is the higher of
    height(x, y) and the support centroid's z. With ``feet_plane_W`` (footholds, beyond the
    paper) the height follows the footholds instead (:func:`support_body_target_W`).

    Parameters
    ----------
    robot : Robot
        Gives the default ``d_c_m`` (:func:`nominal_height_m`).
    terrain : Terrain
        Provides ``height(x, y)`` (the "simple terrain" z = z_T(x, y) of the paper).
    state : State
        Psi; its ``feet_W`` are the contact points.
    i_f : int
        Leg about to swing, 0-based.
    d_c_m : float, optional
        Height above the terrain [m]; default the nominal standing height.
    shrink : float
        Fraction of the way from the centroid to the incentre, in [0, 1].
    feet_plane_W : array_like, shape (4, 3), optional
        Footholds (contact points, one per leg) whose plane the body height follows.
    heading_W : array_like, shape (3,), optional
        The body's forward direction there (tau's u_f); default its current x axis.
    centre_xy_W : array_like, shape (2,), optional
        A horizontal point to lift instead of step 1's (e.g. :func:`two_beat_xy_W`).

    Returns
    -------
    ndarray, shape (3,)
        r_c* [m], world frame.

    """
    if not 0.0 <= shrink <= 1.0:
        raise ValueError(f"lambda_c: shrink must lie in [0, 1], got {shrink!r}")
    d_c = nominal_height_m(robot) if d_c_m is None else float(d_c_m)
    r = support_centroid_W(state, i_f)
    if centre_xy_W is not None:
        r[:2] = np.asarray(centre_xy_W, float).reshape(2)
    elif shrink > 0.0:
        r = (1.0 - shrink) * r + shrink * support_incentre_W(state, i_f)
    if feet_plane_W is not None:
        heading = state.base_rotation_W[:, 0] if heading_W is None else heading_W
        up = np.array([0.0, 0.0, 1.0])  # the height does not depend on the roll
        z, _ = support_body_target_W(robot, terrain, feet_plane_W, r, d_c, heading, up)
        return np.array([r[0], r[1], z])
    z = float(np.asarray(terrain.height(r[0], r[1]), dtype=float))
    z = max(z, float(support_centroid_W(state, i_f)[2]))  # over a gap: from the feet
    return np.array([r[0], r[1], z + d_c])


def chebyshev_centre_xy(triangles_W: list[ArrayLike]) -> tuple[_Array, float]:
    """(point, radius [m]) of the largest horizontal disc inside every triangle given.

    The Chebyshev centre of the triangles' intersection in xy (a linear programme, scipy's
    HiGHS): the point whose nearest edge is farthest. The radius is negative where the
    triangles do not intersect (then the point is the least bad one); degenerate triangles
    give (nan, -inf).
    """
    from scipy.optimize import linprog

    rows, rhs = [], []
    for tri in triangles_W:
        xy = np.asarray(tri, dtype=float).reshape(3, 3)[:, :2]
        e1, e2 = xy[1] - xy[0], xy[2] - xy[0]
        area2 = e1[0] * e2[1] - e1[1] * e2[0]
        if abs(area2) < 1e-12:
            return np.full(2, np.nan), -np.inf
        for a, b in ((0, 1), (1, 2), (2, 0)):
            e = xy[b] - xy[a]
            n = np.sign(area2) * np.array([-e[1], e[0]]) / float(np.linalg.norm(e))  # inward
            rows.append([-n[0], -n[1], 1.0])  # n . (p - a) >= t
            rhs.append(-float(n @ xy[a]))
    res = linprog([0.0, 0.0, -1.0], A_ub=rows, b_ub=rhs, bounds=[(None, None)] * 3,
                  method="highs")  # fmt: skip
    if res.status != 0:
        return np.full(2, np.nan), -np.inf
    return np.asarray(res.x[:2], float), float(res.x[2])


def two_beat_xy_W(
    state: State,
    i_f: int,
    i_next: int,
    swing_target_W: ArrayLike | None,
    com_W: ArrayLike,
    margin_m: float,
) -> _Array | None:
    """The horizontal COM target of a two-beat crawl before leg ``i_f`` swings, or None.

    Beyond the paper's Lambda_c (the support centroid, eq. 12), which moves the body into
    the middle of every support triangle: four body moves per crawl cycle, with the body
    swaying back and forth between a hind and the following front swing. Here the body
    stays where it is when the COM is already ``margin_m`` inside the triangle of the legs
    other than ``i_f`` (the second swing of a pair); otherwise it moves to the point
    deepest inside both that triangle and the next leg's ``i_next`` (with ``i_f`` on its
    target ``swing_target_W``), so that the next swing needs no body move: two body moves
    per cycle, each carrying the body across the support. None where neither applies (no
    target known, or the two triangles share less than a ``margin_m`` disc): Lambda_c's.
    """
    feet = np.asarray(state.feet_W, dtype=float).reshape(4, 3)
    com = np.asarray(com_W, dtype=float).reshape(3)
    here = [i for i in range(4) if i != _check_leg(i_f)]
    if support_margin_m(feet[here], com) >= margin_m:
        return com[:2].copy()
    if swing_target_W is None or int(i_next) == int(i_f):
        return None
    after = feet.copy()
    after[i_f] = np.asarray(swing_target_W, dtype=float).reshape(3)
    nxt = [i for i in range(4) if i != _check_leg(i_next)]
    xy, radius = chebyshev_centre_xy([feet[here], after[nxt]])
    return xy if radius >= margin_m else None


def support_plane_W(points_W: ArrayLike) -> tuple[_Array, _Array]:
    """Least-squares plane z = c_z + g . (xy - c_xy) through points: (gradient g, centre c)."""
    P = np.asarray(points_W, dtype=float).reshape(-1, 3)
    c = P.mean(axis=0)
    g, *_ = np.linalg.lstsq(P[:, :2] - c[:2], P[:, 2] - c[2], rcond=None)
    return np.asarray(g, float), c


def support_body_target_W(
    robot: Robot,
    terrain,
    feet_W: ArrayLike,
    xy: ArrayLike,
    d_c_m: float,
    heading_W: ArrayLike,
    terrain_normal_W: ArrayLike,
) -> tuple[float, _Array]:
    """COM height over ``xy`` and body normal that follow the footholds.

    Beyond the paper, whose body is d_c above the terrain under it and parallel to the
    terrain's smoothed normal (sections 7.2, 8.2.1): over a step the terrain under the
    body is flat on either side of the edge while the feet that carry it stand on both
    levels. Here each leg asks for the body where its foot (contact point of ``feet_W``,
    all four legs) sits at its standing position (theta_nor) in the body frame: the body
    origin over that foot's point of the body, the standing height above the foot. The
    least-squares plane through those four points (the body's xy at ``xy``, yawed along
    ``heading_W``) gives the origin's height at ``xy`` and the body's pitch, at most
    ``MAX_SUPPORT_TILT_RAD``; the roll stays the terrain's (``terrain_normal_W``): with one
    foot on another level a plane through the feet also rolls the body, which helps no leg.
    Climbing or descending, the body pitches and sits between the levels, and front and
    hind legs bend alike instead of one pair being stretched and the other folded. The
    height is raised where the body box (its footprint around ``xy``) would come nearer
    than ``BODY_TARGET_CLEARANCE_M`` to the highest terrain under it (a barrier, an edge).
    Returns (COM height [m], unit normal u_n).
    """
    feet = np.asarray(feet_W, dtype=float).reshape(4, 3)
    f_B = kinematics_of(robot).feet_B(robot.theta_nor)
    ex = np.asarray(heading_W, float)[:2]
    ex = ex / max(float(np.linalg.norm(ex)), 1e-9)
    ey = np.array([-ex[1], ex[0]])
    x, y = float(xy[0]), float(xy[1])
    pts = np.column_stack(
        [
            x + f_B[:, 0] * ex[0] + f_B[:, 1] * ey[0],
            y + f_B[:, 0] * ex[1] + f_B[:, 1] * ey[1],
            feet[:, 2] + robot.foot_radius_m - f_B[:, 2],
        ]
    )
    g, c = support_plane_W(pts)
    z = c[2] + float(g @ (np.array([x, y]) - c[:2])) + float(d_c_m) - nominal_height_m(robot)
    limit = float(np.tan(MAX_SUPPORT_TILT_RAD))
    pitch_slope = float(np.clip(g @ ex, -limit, limit))
    n_t = np.asarray(terrain_normal_W, float)
    roll_slope = -float(n_t[:2] @ ey) / max(float(n_t[2]), 1e-9)
    grad = pitch_slope * ex + roll_slope * ey
    n = np.array([-grad[0], -grad[1], 1.0])
    n /= np.linalg.norm(n)
    return max(z, body_clearance_height_m(robot, terrain, xy, ex, n)), n


def body_clearance_height_m(
    robot: Robot, terrain, xy: ArrayLike, heading_W: ArrayLike, normal_W: ArrayLike | None = None
) -> float:
    """Least body target height [m] over ``xy`` for the body box to clear the terrain.

    The box's bottom (its footprint around ``xy``, facing ``heading_W``) stays
    ``BODY_TARGET_CLEARANCE_M`` over the highest sharp terrain under it (a barrier, an edge).
    ``normal_W``: the body's up axis (default vertical); the bottom of a pitched body
    lies lower behind the origin (nose up) or ahead of it (nose down), of a rolled one on
    one side.
    """
    n = np.array([0.0, 0.0, 1.0]) if normal_W is None else np.asarray(normal_W, float)
    h = np.asarray(heading_W, float).ravel()
    R = frame_from_directions(np.array([h[0], h[1], 0.0]), n / np.linalg.norm(n))
    lo, hi = np.asarray(robot.body_box_B, float)
    nu, nv = (int(np.ceil((hi[k] - lo[k]) / BODY_FOOTPRINT_GRID_M)) + 1 for k in (0, 1))
    u, v = np.meshgrid(np.linspace(lo[0], hi[0], nu), np.linspace(lo[1], hi[1], nv))
    face_B = np.column_stack([u.ravel(), v.ravel(), np.full(u.size, lo[2])])
    off = face_B @ R.T  # the bottom face's points from the origin, world axes
    top = terrain.height_sharp_offsets(float(xy[0]), float(xy[1]), off[:, 0], off[:, 1])[0]
    return float(np.max(top - off[:, 2])) + BODY_TARGET_CLEARANCE_M


# ---- reference directions and the body pose on tau (sections 7.2-7.3) -----------------------
def reference_directions(
    tau: Trajectory,
    terrain: _Terrain,
    point_W: ArrayLike,
    radius_m: float = DEFAULT_NORMAL_RADIUS_M,
    lam: float | None = None,
) -> tuple[_Array, _Array]:
    """Reference forward and normal directions (u_f, u_n) of sigma_1, sigma_2 (section 7.2).

    u_f = dR_tau/dlambda at the lambda closest to ``point_W`` (xy projection, section 7.3's
    lambda_{r_c*}) or at ``lam`` when given; u_n = the smoothed pseudo-normal
    ``terrain.smoothed_normal(point_W, radius_m)``. Both unit vectors, world frame.
    """
    p = np.asarray(point_W, dtype=float).reshape(3)
    lam_ = tau.closest_lambda(p) if lam is None else float(lam)
    u_f = np.asarray(tau.tangent(lam_), dtype=float).reshape(3)
    u_n = np.asarray(terrain.smoothed_normal(p, radius_m), dtype=float).reshape(3)
    return u_f, u_n / np.linalg.norm(u_n)


def reach_height_cap_m(
    robot: Robot,
    hips_W: ArrayLike,
    centres_W: ArrayLike,
    legs: ArrayLike,
    fraction: float,
) -> float:
    """How far [m] (<= 0) a body pose must sink for every hip to reach its foot's centre.

    ``hips_W`` (4, 3): the hip centres at the pose; ``centres_W`` (4, 3): each leg's foot
    sphere centre (a stance foot, or the swing leg's next foothold); ``legs``: the legs to
    keep within ``fraction`` of their reach. A hip too far sideways of its
    foot to reach it at any height is left out (sinking does not help it). Beyond the
    paper: the body lowers where a leg would be stretched.
    """
    hips = np.asarray(hips_W, float).reshape(4, 3)
    centres = np.asarray(centres_W, float).reshape(4, 3)
    dz = 0.0
    for i in legs:
        r = fraction * float(robot.reach_m[i])
        d = hips[i] - centres[i]
        flat2 = float(d[0] ** 2 + d[1] ** 2)
        if flat2 < r * r and d[2] > 0.0:
            dz = min(dz, float(np.sqrt(r * r - flat2)) - float(d[2]))
    return dz


def frame_from_directions(u_f: _Array, u_n: _Array) -> _Array:
    """Rotation with z_B = u_n and x_B = u_f projected on the plane normal to u_n."""
    z = u_n / np.linalg.norm(u_n)
    x = u_f - np.dot(u_f, z) * z
    if np.linalg.norm(x) < 1e-9:  # u_f along the normal: fall back to the world x axis
        x = np.array([1.0, 0.0, 0.0]) - z[0] * z
        if np.linalg.norm(x) < 1e-9:
            x = np.array([0.0, 1.0, 0.0]) - z[1] * z
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def body_pose_on_trajectory(
    robot: Robot,
    terrain: _Terrain,
    tau: Trajectory,
    lam: float,
    radius_m: float | None = None,
) -> tuple[_Array, _Array]:
    """Body pose g on tau at lambda: position R_tau(lambda), oriented by (u_f, u_n).

    The body z axis is the smoothed terrain normal u_n at R_tau(lambda) (roll and pitch
    parallel to the terrain), its x axis the tangent u_f projected onto the plane normal to
    u_n (yaw along the path): the orientation that maximises sigma_1 and sigma_2 of
    section 7.2 together.

    Returns
    -------
    p_W : ndarray, shape (3,)
        Body origin [m], world frame.
    R_WB : ndarray, shape (3, 3)
        Rotation body -> world.

    """
    rad = normal_smoothing_radius_m(robot) if radius_m is None else float(radius_m)
    p = np.asarray(tau.point(lam), dtype=float).reshape(3)
    u_f, u_n = reference_directions(tau, terrain, p, rad, lam=lam)
    return p, frame_from_directions(u_f, u_n)


# ---- Lambda_t, eq. 13 ---------------------------------------------------------------------
def normal_foot_centre_W(robot: Robot, p_W: ArrayLike, R_WB: ArrayLike, leg: int) -> _Array:
    """Sphere centre of ``leg`` at theta_nor for the body pose (p_W, R_WB): g * FK(theta_nor)."""
    leg = _check_leg(leg)
    foot_B = kinematics_of(robot).foot_B(leg, robot.theta_nor[leg])
    return np.asarray(R_WB, float) @ foot_B + np.asarray(p_W, float).reshape(3)


def lambda_t(
    robot: Robot,
    terrain: _Terrain,
    state: State,
    i_f: int,
    tau: Trajectory,
    step_m: float | None = None,
    radius_m: float | None = None,
) -> _Array:
    """Foothold target r_{i_f}^t = Lambda_t(Psi, i_f, tau) (section 8.2.2, eq. 13).

    1. lambda* = the lambda of tau closest (in xy) to the body position Psi.g.v.
    2. The *normal position* of foot i_f: its sphere centre at theta_nor with the body at
       the pose of :func:`body_pose_on_trajectory`, projected vertically onto the terrain.
    3. Moved ``step_m`` ahead along tau: the body pose is taken at lambda* + step_m instead
       of lambda*, so the foot is carried along the path (on a straight path that is the
       normal position plus step_m times the tangent). Past the end of tau the body stops
       at R_tau(L).

    Parameters
    ----------
    robot, terrain : Robot, Terrain
        The robot (theta_nor, kinematics) and the terrain (``height``, ``smoothed_normal``).
    state : State
        Psi; only its base position is used.
    i_f : int
        Leg to place, 0-based.
    tau : Trajectory
        The trajectory, lambda its arc length.
    step_m : float, optional
        Stride [m]; default :func:`default_step_m`.
    radius_m : float, optional
        Smoothing radius of the terrain normal; default :func:`normal_smoothing_radius_m`.

    Returns
    -------
    ndarray, shape (3,)
        Contact point on the terrain, (x, y, height(x, y)) [m], world frame.

    """
    i_f = _check_leg(i_f)
    step = default_step_m(robot) if step_m is None else float(step_m)
    lam_star = float(tau.closest_lambda(np.asarray(state.base_position_W, float)))
    p, R = body_pose_on_trajectory(robot, terrain, tau, float(tau.clip(lam_star + step)), radius_m)
    c = normal_foot_centre_W(robot, p, R, i_f)
    return np.array([c[0], c[1], float(np.asarray(terrain.height(c[0], c[1]), dtype=float))])


# ---- safe footholds (beyond the paper) -------------------------------------------------------
@dataclass(frozen=True)
class LegRoom:
    """The room a leg's links need before a riser ahead of its foot (:func:`leg_room`).

    ``low_m[k]``: the lowest height of the links above the foot's contact point over the
    distance ``HAZARD_GRID_M * k`` ahead of the foot (inf where no link is).
    """

    low_m: np.ndarray

    @property
    def extent_m(self) -> float:
        """How far ahead of the foot the links reach [m]."""
        finite = np.flatnonzero(np.isfinite(self.low_m))
        return HAZARD_GRID_M * (int(finite[-1]) if len(finite) else 0)

    def height_at(self, d_m: np.ndarray) -> np.ndarray:
        """The links' lowest height at distances ``d_m`` ahead (inf beyond them)."""
        d = np.asarray(d_m, float)
        k = np.clip(np.round(d / HAZARD_GRID_M).astype(int), 0, len(self.low_m) - 1)
        return np.where(d < HAZARD_GRID_M * len(self.low_m), self.low_m[k], np.inf)


def leg_room(robot, leg: int) -> LegRoom:
    """The room ``leg``'s links need before a riser ahead of its foot.

    The silhouette of the leg's thigh and shank ahead of its foot
    (:meth:`planner.body.links.LegLinks.silhouette_m`) in the most forward-leaning
    posture of a stance leg of the crawl: theta_nor with the foot half a stride
    (``STEP_FRACTION_OF_REACH`` x reach / 2) behind its nominal place (the body advances
    a stride over a planted foot that landed half a stride ahead). A riser that reaches
    into it meets the knee as the body moves on (LittleDog's hind knees point ahead of
    their feet: a 5 cm riser 4.4 cm ahead of the foot; a front leg, its knee pointing back,
    meets only a riser as tall as its hip).
    """
    cache = robot_cached(robot, "_leg_rooms", lambda _: {})
    if leg not in cache:
        kin = kinematics_of(robot)
        th = np.asarray(robot.theta_nor[leg], float)
        stride = STEP_FRACTION_OF_REACH * float(robot.reach_m[leg])
        back = kin.foot_B(leg, th) - np.array([0.5 * stride, 0.0, 0.0])
        joints = kin.ik_leg_near(leg, back, th).joints_rad
        low = leg_links(robot).silhouette_m(
            leg, joints, HAZARD_GRID_M, 0.5 * float(robot.reach_m[leg])
        )
        cache[leg] = LegRoom(low)
    return cache[leg]


def foothold_hazard(
    terrain,
    point_W: ArrayLike,
    radius_m: float,
    mu: float = 0.7,
    edge_margin_m: float = EDGE_MARGIN_M,
    forward_W: ArrayLike | None = None,
    room: LegRoom | None = None,
) -> str:
    """Why a contact point is a poor foothold, or "" when it is a good one.

    Judged on the *sharp* terrain (``height_sharp``, what the validator and the world see),
    sampled every ``HAZARD_GRID_M`` on a square around the point: an *edge* is a pair of
    neighbouring samples whose slope exceeds ``mu`` (steeper than the friction cone allows,
    which covers every step, riser, gap and stone edge). Refused: an edge within
    ``radius_m + edge_margin_m`` (the foot would rest on or slip off it), or an edge within
    ``WALL_RADIUS_M`` whose top is ``WALL_HEIGHT_M`` above the point (a toe against a riser
    or at the bottom of a pit). With ``forward_W`` (the walking direction) only such walls
    ahead of the point or beside it count, and with ``room`` (:func:`leg_room`) a riser
    straight ahead that reaches into the leg's links (:func:`_riser_in_room`): one behind
    it is the edge the leg has just
    stepped down from, which the foot leaves behind and whose clearance from the leg's
    links the planner checks exactly (counting it kept a foot stepping down off a step too
    far from the riser, out of the leg's reach); but a point with terrain ``PIT_DEPTH_M``
    higher both ahead and behind it, within ``PIT_HALF_WIDTH_M``, is the floor of a trench
    or a pit, which the foot would have to climb out of. Smooth ground, however rough, has
    no edge.
    """
    p = np.asarray(point_W, float).reshape(3)
    r_edge = float(radius_m) + float(edge_margin_m)
    half = max(r_edge, WALL_RADIUS_M)
    n = int(np.ceil(half / HAZARD_GRID_M))
    u = np.arange(-n, n + 1) * HAZARD_GRID_M
    X, Y = np.meshgrid(p[0] + u, p[1] + u, indexing="xy")
    H = terrain.height_sharp_offsets(p[0] + u, np.full(len(u), p[1]), 0.0, u).T
    R = np.hypot(X - p[0], Y - p[1])
    steep_x = np.abs(np.diff(H, axis=1)) > mu * HAZARD_GRID_M
    steep_y = np.abs(np.diff(H, axis=0)) > mu * HAZARD_GRID_M
    edge = np.zeros(H.shape, bool)
    edge[:, 1:] |= steep_x
    edge[:, :-1] |= steep_x
    edge[1:, :] |= steep_y
    edge[:-1, :] |= steep_y
    if np.any(edge & (R <= r_edge)):
        return f"an edge within {r_edge * 100:.1f} cm"
    near = edge & (R <= WALL_RADIUS_M)
    h0 = float(np.asarray(terrain.height_sharp(p[0], p[1]), float))
    if forward_W is not None:
        f, side = horizontal_axes(forward_W)
        near &= (X - p[0]) * f[0] + (Y - p[1]) * f[1] >= -float(radius_m)
        if room is not None and _riser_in_room(terrain, p, f, side, h0, room, r_edge, mu):
            return f"a riser ahead within the leg's room ({room.extent_m * 100:.1f} cm)"
    if np.any(near) and float(H[near].max()) > h0 + WALL_HEIGHT_M:
        return (
            f"an edge {float(H[near].max()) - h0:.3f} m higher within {WALL_RADIUS_M * 100:.0f} cm"
        )
    if forward_W is not None:
        d = np.arange(1, int(np.ceil(PIT_HALF_WIDTH_M / HAZARD_GRID_M)) + 1) * HAZARD_GRID_M
        ahead = np.asarray(terrain.height_sharp(p[0] + d * f[0], p[1] + d * f[1]), float)
        behind = np.asarray(terrain.height_sharp(p[0] - d * f[0], p[1] - d * f[1]), float)
        if min(float(ahead.max()), float(behind.max())) > h0 + PIT_DEPTH_M:
            return f"the floor of a trench or pit (walls within {PIT_HALF_WIDTH_M * 100:.0f} cm)"
    return ""


def _riser_in_room(terrain, p, f, side, h0, room: LegRoom, r_edge, mu) -> bool:
    """Whether a riser to climb onto reaches into ``room`` ahead of ``p``.

    Five lines along ``f`` (``WALL_RADIUS_M`` either side) sampled every ``HAZARD_GRID_M``
    up to the room's extent: an edge (slope beyond ``mu``) whose top is higher above
    ``h0`` than ``WALL_HEIGHT_M`` and than the links there, where the terrain is higher
    too from the extent on for a foothold's width (``2 r_edge``): a thin barrier the foot
    crosses whole does not count (the room would make the stride over it too long; the
    knee branch flips there, :mod:`planner.planning.landing`).
    """
    reach = room.extent_m
    top = p[:2] + np.outer(reach + np.array([0.0, 1.0, 2.0]) * r_edge, f[:2])
    if not np.all(
        np.asarray(terrain.height_sharp(top[:, 0], top[:, 1]), float) > h0 + WALL_HEIGHT_M
    ):
        return False  # no foothold's width of top past the room: a barrier, crossed whole
    d = np.arange(0.0, reach + 0.5 * HAZARD_GRID_M, HAZARD_GRID_M)
    lat = np.linspace(-WALL_RADIUS_M, WALL_RADIUS_M, 5)
    pts = p[None, None, :2] + d[None, :, None] * f[:2] + lat[:, None, None] * side[:2]
    H = np.asarray(terrain.height_sharp(pts[..., 0].ravel(), pts[..., 1].ravel()), float)
    H = H.reshape(len(lat), len(d))
    steep = np.abs(np.diff(H, axis=1)) > mu * HAZARD_GRID_M
    floor = np.maximum(WALL_HEIGHT_M, room.height_at(d[1:]))[None, :]
    return bool(np.any(steep & (H[:, 1:] > h0 + floor)))


def horizontal_axes(forward_W: ArrayLike) -> tuple[_Array, _Array]:
    """Unit forward (``forward_W`` made horizontal; world x if vertical) and left vectors."""
    f = np.asarray(forward_W, float).reshape(3).copy()
    f[2] = 0.0
    nf = float(np.linalg.norm(f))
    f = np.array([1.0, 0.0, 0.0]) if nf < 1e-9 else f / nf
    return f, np.array([-f[1], f[0], 0.0])


def safe_foothold(
    terrain,
    target_W: ArrayLike,
    forward_W: ArrayLike,
    radius_m: float,
    mu: float = 0.7,
    max_shift_m: float = 0.06,
    step_m: float = 0.01,
    max_lateral_m: float = 0.06,
    lateral_step_m: float = 0.015,
    lateral_cost: float = 1.5,
    not_behind_W: ArrayLike | None = None,
    room: LegRoom | None = None,
) -> tuple[np.ndarray, str]:
    """The foothold nearest ``target_W`` without a :func:`foothold_hazard` (beyond the paper).

    Lambda_t (eq. 13) knows nothing of edges; on steps, stairs, gaps and stones its target
    often lands on an edge, where Theta3 (which sees the smoothed terrain) either fails or
    puts the foot where the real, sharp terrain does not hold it. Candidates are the
    target shifted by ``d`` along ``forward_W`` (|d| <= ``max_shift_m``, every ``step_m``)
    and ``l`` sideways (|l| <= ``max_lateral_m``, every ``lateral_step_m``), tried in the
    order of ``|d| + lateral_cost |l|`` (a shorter stride before a longer one at equal
    cost). With ``not_behind_W`` (the foot's current contact point), candidates that are
    not ahead of it along ``forward_W`` are skipped: a lagging leg must not be sent back
    in front of a gap it has to cross. ``room``: the leg's room before a riser
    (:func:`leg_room`), kept by every candidate; a target that only the room refuses (the
    toe's rule accepts it) is moved ahead, onto the riser's top, before it is moved back.
    Returns (point on the terrain, "") or (the original target, the
    hazard) when none is safe.
    """
    t = np.asarray(target_W, float).reshape(3)
    f, side = horizontal_axes(forward_W)
    k = int(round(max_shift_m / step_m))
    m = int(round(max_lateral_m / lateral_step_m))
    cands = [
        (abs(d) + lateral_cost * abs(lat), d > 0, d, lat)
        for d in step_m * np.arange(-k, k + 1)
        for lat in lateral_step_m * np.arange(-m, m + 1)
    ]
    cands.sort(key=lambda c: c[:2])
    h0 = float(np.asarray(terrain.height_sharp(t[0], t[1]), float))
    r_edge = float(radius_m) + EDGE_MARGIN_M
    if (
        room is not None
        and _riser_in_room(terrain, t, f, side, h0, room, r_edge, mu)
        and not foothold_hazard(terrain, t, radius_m, mu, forward_W=f)
    ):
        # only the room refuses the target (the toe's rule accepts it): cross the riser
        # (a foot stopped short of it is left a longer stride onto it, from where the body
        # has moved on); a target the toe's rule refuses goes to the nearest safe point
        cands = [c for c in cands if c[2] > 0] + [c for c in cands if c[2] <= 0]
    first = ""
    for _, _, d, lat in cands:
        c = t + d * f + lat * side
        if not_behind_W is not None and float((c - np.asarray(not_behind_W, float)) @ f) <= 0:
            continue
        c[2] = float(np.asarray(terrain.height(c[0], c[1]), float))
        why = foothold_hazard(terrain, c, radius_m, mu, forward_W=f, room=room)
        if not why:
            return c, ""
        first = first or why
    return t, first
