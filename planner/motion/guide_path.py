"""A guide path around obstacles before section 9: a traversability map and a graph search.

Section 9 searches tau as sine series around a straight tau0; behind a wall every
candidate near the straight line dead-ends and each costs a whole local plan. Here a
cost map of the terrain for the robot and a shortest path over it give a tau0 that
already goes around walls and through openings, in well under a second; section 9
(:mod:`planner.planning.global_plan`) refines around it.

The map (one cell every ``resolution_m``, over the terrain's bounds), from the sharp
heights, with every length derived from the robot:

- *blocked*: a cell standing more than ``max_step`` above the terrain on both sides of
  it along x or y within ``4 rho`` (rho the foot radius): a wall or rock too thin to
  stand on and too tall to step onto (a wall at 45 degrees is thinner than 8 rho along
  x still). Diagonals would also block the corners of stepping stones in a pit. Also
  blocked: a cell more than ``max_step`` above the ground level, the 60th percentile of
  the heights over a square of half-side ``GROUND_REACH_FRACTION`` of the leg reach
  (14 cm for LittleDog): a tall rock whose flanks are too gentle for the first test.
  The percentile keeps trench rims and step tops free (half their square or more is at
  their own level) where a minimum would block them; stones filling less than 40 % of
  a pit are blocked (no path: the straight line is kept). A drop (trench rim,
  step edge, stone edge) is not blocked: it is on the level of one of its sides, and
  crossing it is the local planner's job. ``max_step`` = ``STEP_FRACTION`` of the
  shortest leg reach: 8.1 cm for LittleDog, between the edges its course table walks and
  those it stalls at (bench/notes/2026-11-25-courses-hard.md).
- blocked cells grow by the robot's half-width (its feet at theta_nor, plus the foot
  radius and ``CLEARANCE_M``): the path is where the body's centre may go; the course's
  border grows the same way.
- *cost* of a free cell: 1 + ``RELIEF_WEIGHT`` (relief / max_step)^2, relief the height
  range within ``4 rho`` (edges, steps, rough ground cost more), + ``NEAR_WEIGHT``
  exp(-d / ``NEAR_SCALE_M``), d the distance beyond the grown obstacles (the path keeps
  to the middle of an opening).

The path: Dijkstra (scipy's ``csgraph``) on the 8-connected grid, an edge costing its
length times the mean of its cells' costs; simplified (Douglas-Peucker, ``SIMPLIFY_M``,
less where the simplified corners would cross blocked cells),
smoothed (a cubic spline through the kept points where it stays on free cells, then
its corners rounded by relaxation over free cells) and returned as a
:class:`~planner.motion.trajectory.Trajectory` at the COM height over the terrain, as the
straight tau0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import distance_transform_edt, maximum_filter, minimum_filter, percentile_filter
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from planner.core.errors import InputError
from planner.motion.trajectory import Trajectory

__all__ = ["GuidePath", "TraversabilityMap", "guide_path", "traversability_map"]

_Array = NDArray[np.float64]
STEP_FRACTION = 0.45  # max_step / shortest leg reach (module docstring)
GROUND_REACH_FRACTION = 0.8  # half-side of the ground level's square / shortest leg reach
GROUND_STRIDE = 3  # the ground level is computed on every 3rd cell
GROUND_PERCENTILE = 60.0  # of the heights around: a step edge's top is at its own level
CLEARANCE_M = 0.02  # beyond the feet's half-width, from a blocked cell
RELIEF_WEIGHT = 2.0
NEAR_WEIGHT = 2.0
NEAR_SCALE_M = 0.1
SIMPLIFY_M = 0.02  # Douglas-Peucker tolerance of the grid path
SPACING_M = 0.02  # the returned path's vertex spacing
RELAX_ROUNDS = 100  # corner rounding where the spline through the corners is not free
MAX_CELLS = 2_000_000  # coarser cells beyond this many


@dataclass
class TraversabilityMap:
    """Cost map of a terrain for one robot (module docstring); row i is y, column j is x.

    ``origin`` (x, y) [m] of cell (0, 0); ``resolution_m``; ``cost`` (ny, nx), inf where
    ``blocked`` (grown); ``obstacle`` (ny, nx): the blocked cells before growing;
    ``max_step_m``, ``half_width_m``: the robot's numbers used.
    """

    origin: _Array
    resolution_m: float
    cost: _Array
    obstacle: NDArray[np.bool_]
    blocked: NDArray[np.bool_]
    max_step_m: float
    half_width_m: float

    def cell(self, xy) -> tuple[int, int]:
        """(row, column) of the cell holding ``xy`` (clipped to the map)."""
        j = int(round((float(xy[0]) - self.origin[0]) / self.resolution_m))
        i = int(round((float(xy[1]) - self.origin[1]) / self.resolution_m))
        ny, nx = self.cost.shape
        return min(max(i, 0), ny - 1), min(max(j, 0), nx - 1)

    def xy(self, cells: NDArray[np.int_]) -> _Array:
        """World xy (N, 2) of cells (N, 2) given as (row, column)."""
        c = np.asarray(cells, float).reshape(-1, 2)
        return self.origin + self.resolution_m * c[:, ::-1]

    def free(self, xy: _Array) -> NDArray[np.bool_]:
        """Whether each point (N, 2) lies on a free cell."""
        pts = np.asarray(xy, float).reshape(-1, 2)
        ji = np.rint((pts - self.origin) / self.resolution_m).astype(int)
        ny, nx = self.cost.shape
        inside = (ji[:, 0] >= 0) & (ji[:, 0] < nx) & (ji[:, 1] >= 0) & (ji[:, 1] < ny)
        out = np.zeros(len(pts), bool)
        out[inside] = ~self.blocked[ji[inside, 1], ji[inside, 0]]
        return out

    def segment_free(self, a_xy, b_xy) -> bool:
        """Whether the straight segment from ``a_xy`` to ``b_xy`` stays on free cells."""
        ends = np.array([np.asarray(a_xy, float)[:2], np.asarray(b_xy, float)[:2]])
        return bool(self.free(_dense(ends, 0.5 * self.resolution_m)).all())


@dataclass
class GuidePath:
    """A guide path: ``tau`` (or None), the map, the path's cost, ``message`` (why not)."""

    tau: Trajectory | None
    map: TraversabilityMap
    cost: float
    xy_W: _Array
    message: str = ""

    @property
    def straight(self) -> bool:
        """Whether the path keeps within a grid cell and a half of the start-goal line."""
        a, b = self.xy_W[0], self.xy_W[-1]
        d = b - a
        n = np.array([-d[1], d[0]]) / max(float(np.linalg.norm(d)), 1e-12)
        return bool(np.max(np.abs((self.xy_W - a) @ n)) <= 1.5 * self.map.resolution_m)


def _robot_numbers(robot) -> tuple[float, float, float]:
    """(max_step, half-width, thin-obstacle window) [m] of the robot."""
    from planner.body.kinematics import kinematics_of

    feet = kinematics_of(robot).feet_B(robot.theta_nor)
    rho = float(robot.foot_radius_m)
    half_width = float(np.max(np.abs(feet[:, 1]))) + rho + CLEARANCE_M
    return STEP_FRACTION * float(np.min(robot.reach_m)), half_width, 4.0 * rho


def _protrusion(h: _Array, k: int) -> _Array:
    """Height above the terrain on both sides within k cells, the most over x and y."""
    ny, nx = h.shape
    pad = np.pad(h, k, mode="edge")
    out = np.full(h.shape, -np.inf)
    for di, dj in ((0, 1), (1, 0)):
        lo = np.full(h.shape, np.inf)
        hi = np.full(h.shape, np.inf)
        for s in range(1, k + 1):
            lo = np.minimum(lo, pad[k - s * di : k - s * di + ny, k - s * dj : k - s * dj + nx])
            hi = np.minimum(hi, pad[k + s * di : k + s * di + ny, k + s * dj : k + s * dj + nx])
        out = np.maximum(out, h - np.maximum(lo, hi))
    return out


def _ground(h: _Array, res: float, radius_m: float) -> _Array:
    """The ground level: the 60th percentile of heights over a square of half-side ``radius_m``.

    Computed on every ``GROUND_STRIDE``-th cell (scipy's ``percentile_filter``) and spread
    back to its neighbours: a rank among a few hundred heights, not thousands.
    """
    step = GROUND_STRIDE
    coarse = h[::step, ::step]
    size = 2 * max(1, int(round(radius_m / (step * res)))) + 1
    med = percentile_filter(coarse, GROUND_PERCENTILE, size=size, mode="nearest")
    full = np.repeat(np.repeat(med, step, axis=0), step, axis=1)
    return full[: h.shape[0], : h.shape[1]]


def traversability_map(robot, terrain, resolution_m: float = 0.01) -> TraversabilityMap:
    """The cost map of ``terrain`` (its bounds) for ``robot`` (module docstring)."""
    x0, x1, y0, y1 = terrain.bounds
    res = float(resolution_m)
    if not res > 0:
        raise InputError(f"guide path: resolution_m must be > 0, got {resolution_m!r}")
    while ((x1 - x0) / res + 1) * ((y1 - y0) / res + 1) > MAX_CELLS:
        res *= 2.0
    xs = np.arange(x0, x1 + 0.5 * res, res)
    ys = np.arange(y0, y1 + 0.5 * res, res)
    X, Y = np.meshgrid(xs, ys)
    height = getattr(terrain, "height_sharp", None) or terrain.height
    h = np.asarray(height(X, Y), float).reshape(X.shape)
    max_step, half_width, window = _robot_numbers(robot)
    ground_radius = GROUND_REACH_FRACTION * float(np.min(robot.reach_m))
    k = max(1, int(round(window / res)))
    obstacle = (_protrusion(h, k) > max_step) | (h - _ground(h, res, ground_radius) > max_step)
    # distance [m] to the nearest obstacle or beyond the course's border
    border = np.zeros(h.shape, bool)
    border[0, :] = border[-1, :] = border[:, 0] = border[:, -1] = True
    dist = distance_transform_edt(~(obstacle | border)) * res
    blocked = dist < half_width
    size = 2 * k + 1
    relief = maximum_filter(h, size=size) - minimum_filter(h, size=size)
    cost = (
        1.0
        + RELIEF_WEIGHT * (relief / max_step) ** 2
        + NEAR_WEIGHT * np.exp(-np.maximum(dist - half_width, 0.0) / NEAR_SCALE_M)
    )
    cost[blocked] = np.inf
    return TraversabilityMap(np.array([x0, y0]), res, cost, obstacle, blocked, max_step, half_width)


def _grid_graph(cost: _Array, res: float) -> coo_matrix:
    """8-connected graph over the finite cells: edge = length x mean of its cells' costs."""
    ny, nx = cost.shape
    idx = np.arange(ny * nx).reshape(ny, nx)
    rows, cols, w = [], [], []
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
        sl_a = (slice(0, ny - di), slice(max(0, -dj), nx - max(0, dj)))
        sl_b = (slice(di, ny), slice(max(0, dj), nx - max(0, -dj)))
        a, b = idx[sl_a], idx[sl_b]
        ca, cb = cost[sl_a], cost[sl_b]
        ok = np.isfinite(ca) & np.isfinite(cb)
        length = res * float(np.hypot(di, dj))
        rows.append(a[ok])
        cols.append(b[ok])
        w.append(length * 0.5 * (ca[ok] + cb[ok]))
    r, c, v = (np.concatenate(x) for x in (rows, cols, w))
    return coo_matrix((v, (r, c)), shape=(ny * nx, ny * nx))


def _simplify(pts: _Array, tol: float) -> _Array:
    """Douglas-Peucker: the points of ``pts`` (N, 2) that keep it within ``tol``."""
    keep = np.zeros(len(pts), bool)
    keep[[0, -1]] = True
    stack = [(0, len(pts) - 1)]
    while stack:
        a, b = stack.pop()
        if b <= a + 1:
            continue
        d = pts[b] - pts[a]
        n = np.array([-d[1], d[0]]) / max(float(np.linalg.norm(d)), 1e-12)
        off = np.abs((pts[a + 1 : b] - pts[a]) @ n)
        m = int(np.argmax(off))
        if off[m] > tol:
            keep[a + 1 + m] = True
            stack += [(a, a + 1 + m), (a + 1 + m, b)]
    return pts[keep]


def _dense(points: _Array, spacing: float) -> _Array:
    """The polyline through ``points`` (N, 2) resampled every ``spacing`` of its length."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    u = np.linspace(0.0, s[-1], max(2, int(np.ceil(s[-1] / spacing)) + 1))
    return np.column_stack([np.interp(u, s, points[:, 0]), np.interp(u, s, points[:, 1])])


def _relax(xy: _Array, tmap: TraversabilityMap) -> _Array:
    """Round the corners of a path (N, 2) without leaving the free cells.

    ``RELAX_ROUNDS`` rounds of moving each inner point halfway to its neighbours' mean,
    kept only where the point stays free; the ends stay. A Dijkstra path's corners make
    the body turn on the spot (the local planner's heading follows tau's tangent): the
    tall_rocks plan along the unrounded path got stuck.
    """
    out = np.array(xy, float)
    for _ in range(RELAX_ROUNDS):
        new = out.copy()
        new[1:-1] += 0.5 * (0.5 * (out[:-2] + out[2:]) - out[1:-1])
        ok = tmap.free(new)
        ok[[0, -1]] = False
        out[ok] = new[ok]
    even = _dense(out, SPACING_M)  # evenly spaced again, where that stays free
    return even if tmap.free(even).all() else out


def guide_path(
    robot, terrain, start_xy, goal_xy, height_m: float, resolution_m: float = 0.01
) -> GuidePath:
    """The least-cost path from ``start_xy`` to ``goal_xy`` on the robot's cost map.

    ``height_m``: the path's height over the terrain (the COM height, as the straight
    tau0). ``tau`` is None, with ``message`` saying why, when start or goal is on a
    blocked cell or no free path joins them.
    """
    a, b = np.asarray(start_xy, float)[:2], np.asarray(goal_xy, float)[:2]
    x0, x1, y0, y1 = terrain.bounds
    for name, p in (("start", a), ("goal", b)):
        if not (np.all(np.isfinite(p)) and x0 <= p[0] <= x1 and y0 <= p[1] <= y1):
            raise InputError(
                f"guide path: the {name} ({p[0]:g}, {p[1]:g}) is outside the terrain "
                f"{terrain.name} (x {x0:g}..{x1:g}, y {y0:g}..{y1:g}); move it inside"
            )
    tmap = traversability_map(robot, terrain, resolution_m)
    ia, ib = tmap.cell(a), tmap.cell(b)
    ny, nx = tmap.cost.shape
    for name, p, c in (("start", a, ia), ("goal", b, ib)):
        if not np.isfinite(tmap.cost[c]):
            why = f"the {name} ({p[0]:.2f}, {p[1]:.2f}) is next to an obstacle or the border"
            return GuidePath(None, tmap, np.inf, np.array([a, b]), why)
    graph = _grid_graph(tmap.cost, tmap.resolution_m)
    src, dst = ia[0] * nx + ia[1], ib[0] * nx + ib[1]
    dist, pred = dijkstra(graph, directed=False, indices=src, return_predecessors=True)
    if not np.isfinite(dist[dst]):
        why = "no path around the obstacles joins start and goal"
        return GuidePath(None, tmap, np.inf, np.array([a, b]), why)
    chain = [dst]
    while chain[-1] != src:
        chain.append(int(pred[chain[-1]]))
    cells = np.array([divmod(v, nx) for v in chain[::-1]])
    pts = tmap.xy(cells)
    pts[0], pts[-1] = a, b
    for tol in (SIMPLIFY_M, 0.5 * SIMPLIFY_M, 0.0):  # corners cut only over free cells
        kept = _simplify(pts, tol) if tol > 0 else pts
        xy = _dense(kept, SPACING_M)
        if tmap.free(xy).all():
            break
    if 2 < len(kept) < len(pts):  # a spline through the kept corners, if it stays free
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(kept, axis=0), axis=1))])
        from scipy.interpolate import CubicSpline  # imported here: ~0.5 s

        smooth = CubicSpline(s, kept, axis=0, bc_type="natural")(
            np.linspace(0.0, s[-1], max(2, int(np.ceil(s[-1] / SPACING_M)) + 1))
        )
        if tmap.free(smooth).all():
            xy = smooth
    xy = _relax(xy, tmap)
    tau = Trajectory.over_terrain(xy, terrain, height_m, kind="guide")
    return GuidePath(tau, tmap, float(dist[dst]), xy)
