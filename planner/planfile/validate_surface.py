"""The sharp terrain surface as the validator sees it: distances and bounds.

Euclidean distance to the graph of ``height_sharp`` closed by vertical faces at its jumps
(:func:`sharp_surface_distance`), cheap upper bounds of the terrain over rectangles
(:class:`_TileMax`) and the body box P's faces (paper, section 4.2) sampled for the
body clearance check.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from planner.body.robot import Robot
    from planner.world.terrain import Terrain

_Array = NDArray[np.float64]


def _rotations_from_quats(q_xyzw: _Array) -> _Array:
    """(N, 3, 3) rotation matrices of (N, 4) unit quaternions (x, y, z, w)."""
    q = q_xyzw / np.linalg.norm(q_xyzw, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def sharp_surface_distance(
    terrain: Terrain, points_W: _Array, radius_m: float, step_m: float = 1e-3
) -> _Array:
    """Signed Euclidean distance [m] of points to the sharp terrain surface.

    The surface is the graph of ``terrain.height_sharp`` closed by vertical faces at its
    jumps. It is sampled on a square grid of ``step_m`` covering ``radius_m`` around each
    point; where two neighbouring nodes differ by more than ``2 step_m`` the face between
    them is located by bisection. The sign is that of ``p_z - height_sharp(p_x, p_y)``
    (negative: under the surface). The magnitude is at most the vertical gap and is
    clipped to ``radius_m`` (nothing nearer). Error ~ step^2 / (4 d) on smooth parts
    (2.5e-5 m at 1 mm and d = 1 cm); faces are exact to step / 4096.

    Parameters
    ----------
    terrain : Terrain
        Provides ``height_sharp``.
    points_W : array (N, 3)
        Points [m], world frame.
    radius_m : float
        Search radius [m].
    step_m : float
        Grid step [m].

    Returns
    -------
    ndarray (N,)
        Signed distances [m].

    """
    p = np.asarray(points_W, dtype=float).reshape(-1, 3)
    if len(p) == 0:
        return np.zeros(0)
    gap = p[:, 2] - np.asarray(terrain.height_sharp(p[:, 0], p[:, 1]), dtype=float).reshape(-1)
    k = int(math.ceil(radius_m / step_m))
    u = step_m * np.arange(-k, k + 1)
    m = len(u)
    ux, uy = np.meshgrid(u, u)  # [iy, ix]
    r2 = ux**2 + uy**2
    best = np.minimum(np.abs(gap), radius_m)
    chunk = max(1, 200_000 // (m * m))
    jump = 2.0 * step_m
    for a in range(0, len(p), chunk):
        pc = p[a : a + chunk]
        n = len(pc)
        hx = pc[:, 0, None, None] + ux[None]
        hy = pc[:, 1, None, None] + uy[None]
        h = terrain.height_sharp_offsets(pc[:, 0], pc[:, 1], ux, uy).reshape(n, m, m)
        d_graph = np.sqrt(r2[None] + (pc[:, 2, None, None] - h) ** 2)
        d = d_graph.reshape(n, -1).min(axis=1)
        for axis in (2, 1):  # faces between x-neighbours, then y-neighbours
            h0 = h[:, :, :-1] if axis == 2 else h[:, :-1, :]
            h1 = h[:, :, 1:] if axis == 2 else h[:, 1:, :]
            sel = np.nonzero(np.abs(h1 - h0) > jump)
            if not sel[0].size:
                continue
            ip, iy, ix = sel
            xa, ya = hx[ip, iy, ix], hy[ip, iy, ix]
            dx, dy = (step_m, 0.0) if axis == 2 else (0.0, step_m)
            xb, yb = xa + dx, ya + dy
            ha, hb = h0[sel], h1[sel]
            for _ in range(12):
                xm, ym = 0.5 * (xa + xb), 0.5 * (ya + yb)
                hm = np.asarray(terrain.height_sharp(xm, ym), dtype=float).reshape(-1)
                left = np.abs(hm - ha) > np.abs(hm - hb)  # the jump is in [a, m]
                xb, yb, hb = np.where(left, xm, xb), np.where(left, ym, yb), np.where(left, hm, hb)
                xa, ya, ha = np.where(left, xa, xm), np.where(left, ya, ym), np.where(left, ha, hm)
            lo, hi = np.minimum(ha, hb), np.maximum(ha, hb)
            z = pc[ip, 2]
            dz = np.maximum(np.maximum(lo - z, z - hi), 0.0)
            dface = np.sqrt(
                (0.5 * (xa + xb) - pc[ip, 0]) ** 2 + (0.5 * (ya + yb) - pc[ip, 1]) ** 2 + dz**2
            )
            np.minimum.at(d, ip, dface)
        best[a : a + n] = np.minimum(best[a : a + n], d)
    return np.where(gap >= 0.0, 1.0, -1.0) * best


class _TileMax:
    """Upper bounds of the sharp terrain over rectangles, from lazily evaluated tiles.

    The plane is cut into ``TILE_M`` square tiles; a tile's bound is the largest
    ``height_sharp`` at its nodes (``NODE_M`` apart, borders included), evaluated once
    when a query first touches it. ``max_in`` returns the largest bound over the tiles a
    rectangle meets: the terrain's maximum there, up to features narrower than ``NODE_M``
    and, on slopes, ``slope * NODE_M`` (callers subtract ``SLACK_M``). Used to skip the
    exact tests far from the ground.
    """

    TILE_M = 0.02
    NODE_M = 0.005
    SLACK_M = 0.005

    def __init__(self, terrain: Terrain):
        self.terrain = terrain
        self.tiles: dict[tuple[int, int], float] = {}

    def max_in(self, boxes: _Array) -> _Array:
        """Bound (K,) over rectangles (K, 4) ``[x0, x1, y0, y1]`` [m]."""
        t = self.TILE_M
        idx = np.column_stack(
            [np.floor(boxes[:, 0] / t), np.floor(boxes[:, 1] / t),
             np.floor(boxes[:, 2] / t), np.floor(boxes[:, 3] / t)]
        ).astype(int)  # fmt: skip
        ix0, iy0 = idx[:, 0].min(), idx[:, 2].min()
        shape = (idx[:, 3].max() - iy0 + 1, idx[:, 1].max() - ix0 + 1)
        need = np.zeros(shape, dtype=bool)
        for a, b, c, d in idx:
            need[c - iy0 : d - iy0 + 1, a - ix0 : b - ix0 + 1] = True
        todo = [
            (int(ix + ix0), int(iy + iy0))
            for iy, ix in zip(*np.nonzero(need), strict=True)
            if (int(ix + ix0), int(iy + iy0)) not in self.tiles
        ]
        if todo:
            n = int(round(t / self.NODE_M)) + 1
            u = np.linspace(0.0, t, n)
            ux, uy = (g.ravel() for g in np.meshgrid(u, u))
            tix = np.array(todo, dtype=float)
            h = self.terrain.height_sharp(tix[:, :1] * t + ux[None], tix[:, 1:] * t + uy[None])
            hmax = np.asarray(h, dtype=float).reshape(len(todo), -1).max(axis=1)
            self.tiles.update(zip(todo, hmax.tolist(), strict=True))
        grid = np.full(shape, -np.inf)
        for iy, ix in zip(*np.nonzero(need), strict=True):
            grid[iy, ix] = self.tiles[(int(ix + ix0), int(iy + iy0))]
        return np.array([grid[c - iy0 : d - iy0 + 1, a - ix0 : b - ix0 + 1].max()
                         for a, b, c, d in idx])  # fmt: skip


def _body_points_B(robot: Robot, spacing_m: float) -> list[tuple[_Array, _Array]]:
    """Faces of the body box P: (outward normal, (K, 3) points incl. edges) in body frame."""
    lo, hi = robot.body_box_B
    faces = []
    for axis in range(3):
        a, b = [j for j in range(3) if j != axis]
        ua = np.linspace(lo[a], hi[a], max(2, int(math.ceil((hi[a] - lo[a]) / spacing_m)) + 1))
        ub = np.linspace(lo[b], hi[b], max(2, int(math.ceil((hi[b] - lo[b]) / spacing_m)) + 1))
        ga, gb = (g.ravel() for g in np.meshgrid(ua, ub))
        for side, value in ((-1.0, lo[axis]), (1.0, hi[axis])):
            pts = np.empty((len(ga), 3))
            pts[:, axis], pts[:, a], pts[:, b] = value, ga, gb
            normal = np.zeros(3)
            normal[axis] = side
            faces.append((normal, pts))
    return faces


def _smoothing_width_m(spec: dict) -> float:
    """Largest ``smoothing_m`` of a terrain spec and its segments [m]."""
    from planner.world.terrain import DEFAULT_SMOOTHING_M

    widths = [float(spec.get("smoothing_m", DEFAULT_SMOOTHING_M))]
    for seg in spec.get("segments", []) or []:
        if isinstance(seg, dict) and "smoothing_m" in seg:
            widths.append(float(seg["smoothing_m"]))
    return max(widths)
