"""Mesh terrain: an STL, OBJ or PLY surface rasterised to a height field z_T(x, y).

The terrain of the paper's section 4.4 is an implicit surface f_T(r) = r_z - z_T(r_x, r_y),
so a mesh can stand for it only where it is a height field: one surface over each (x, y).
:func:`mesh_heights` reads a mesh with ``trimesh`` (imported only here, when a mesh is
loaded), moves it into the world frame and samples its top surface on the uniform grid
``heights[iy][ix]`` at ``(x0 + ix * resolution, y0 + iy * resolution)`` that the
``heightfield`` kind fits with a bicubic B-spline (:mod:`planner.world.heightfield`).

Frame and units
    A vertex ``p`` (file units) becomes ``R_up (metres_per_unit * p) + offset`` metres in the
    world frame (z up); ``up: y`` turns a +y-up file (OBJ from Blender, many CAD exports)
    by +90 degrees about x, so that its +y becomes +z.

Grid
    ``region`` [x0, x1, y0, y1] (default the mesh's xy bounds, to the micrometre) and
    ``resolution`` (default 1 cm, coarsened to whole millimetres past
    :data:`DEFAULT_MAX_NODES`; at most :data:`MAX_NODES`). The B-spline through a sharp
    edge's samples rises over one cell and rings by about 10 % of the jump over two cells
    each side, so a sharp-edged CAD course is best given 5 mm (the plan file's own grid);
    fitting costs about 0.5 s for 40,000 nodes and 5 s for 145,000. Heights are rounded
    to :data:`HEIGHT_QUANTUM_M`.

Rasterising
    Each non-vertical triangle is tested against the grid nodes inside its xy bounding box
    (vectorised barycentric coordinates; a node within :data:`EDGE_TOL_M` of a triangle's
    edge, in xy, counts as on it). The node's height is the highest surface point above
    it; on a vertical wall's line (a step's edge) that is the upper level. Vertical faces
    are walls and are not sampled. Chosen over ray casting: no acceleration structure
    (trimesh's embree or rtree) is needed, a 500,000-triangle scan takes about a second,
    and a node on a shared edge or a wall's line is decided by one rule, not by which
    triangle a ray happens to hit.

Height-field test (overhangs)
    Along the vertical line through each node the mesh is split into solid intervals: a
    closed component (every edge shared by two of its faces: a CAD solid) is solid between
    alternate crossings (even-odd, so its winding and normals do not matter, and its bottom
    face is not a second surface); an open component (a scanned sheet, or a shell without
    a bottom) is a surface of no thickness at each crossing. Where a component touches the
    node only on a triangle's edge its crossings are filled as one interval (a wall's line).
    The components' intervals are united (overlapping solids are one), intervals less than
    :data:`OVERHANG_TOL_M` apart are joined, and a node left with two or more is under an
    overhang, a roof, a cave or a floating part: the mesh is refused, naming the node.
    So a box resting on, sunk into or floating up to 1 cm above a floor is accepted; a
    slab floating higher is not, and neither is a bottomless box on a floor (close it
    with a bottom face).

Coverage
    Every node of the region must lie under the mesh: a node with nothing above or below it
    is an error naming it (no fill rule: a silently invented terrain would be wrong).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planner.core.errors import TerrainError
from planner.world.terrain_spec import _error

MESH_SUFFIXES = (".stl", ".obj", ".ply")
DEFAULT_RESOLUTION_M = 0.01  # the grid step when none is given [m]
DEFAULT_MAX_NODES = 100_000  # the default step is coarsened (whole mm) to stay under this
MAX_NODES = 300_000  # the largest grid accepted (its B-spline takes ~25 s to fit)
OVERHANG_TOL_M = 0.01  # solid intervals closer than this along a vertical are one [m]
HEIGHT_QUANTUM_M = 1e-6  # rasterised heights are rounded to this [m]
EDGE_TOL_M = 1e-5  # a node this close to a triangle (in xy) is on its edge [m]
_VERTICAL_NZ = 1e-9  # |n_z| of a unit normal below this: a vertical face, not sampled
_SAME_Z_M = 1e-9  # two crossings of one component this close are one (a shared edge)
_CHUNK_PAIRS = 500_000  # (triangle, node) candidates tested at a time (~130 MB)


@dataclass(frozen=True)
class MeshGrid:
    """A rasterised mesh: ``heights[iy][ix]`` [m] at ``origin + (ix, iy) * resolution``."""

    heights: np.ndarray
    origin: tuple[float, float]
    resolution: float
    region: tuple[float, float, float, float]  # (x0, x1, y0, y1) [m]
    triangles: int


def is_mesh_path(path: str | Path) -> bool:
    """Whether ``path`` names an STL, OBJ or PLY file (by its suffix)."""
    return Path(str(path)).suffix.lower() in MESH_SUFFIXES


def read_mesh(path: Path, source: str, field: str) -> tuple[np.ndarray, np.ndarray]:
    """Read a mesh's vertices (V, 3) [file units] and triangles (F, 3) with ``trimesh``.

    Raises
    ------
    TerrainError
        A missing or unreadable file, an unknown suffix, a file that holds no triangles, or
        non-finite coordinates (one line naming the file).

    """
    if not is_mesh_path(path):
        raise _error(source, field, f"'{path.name}' is not a mesh; use .stl, .obj or .ply")
    if not path.is_file():
        raise _error(source, field, f"cannot read '{path}': no such file; check the path")
    try:
        import trimesh
    except ImportError as exc:
        raise _error(
            source, field, f"reading '{path.name}' needs trimesh; pip install trimesh ({exc})"
        ) from exc
    try:
        mesh = trimesh.load(str(path), force="mesh")
        vertices = np.asarray(mesh.vertices, dtype=float).reshape(-1, 3)
        faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    except Exception as exc:  # noqa: BLE001 - any reader failure is reported the same way
        raise _error(
            source,
            field,
            f"cannot read '{path}' as a mesh ({type(exc).__name__}: {exc}); "
            f"check that it is a valid {path.suffix.lower()[1:].upper()} file",
        ) from exc
    if len(faces) == 0:
        raise _error(
            source,
            field,
            f"'{path}' holds no triangles (empty, or not a mesh file); export the terrain "
            "surface as triangles",
        )
    if not np.all(np.isfinite(vertices)):
        raise _error(source, field, f"'{path}' has non-finite vertex coordinates; fix them")
    return vertices, faces


def to_world(
    vertices: np.ndarray, metres_per_unit: float, up: str, offset: Sequence[float]
) -> np.ndarray:
    """Vertices [file units] to the world frame [m]: scaled, turned so ``up`` is +z, moved."""
    v = np.asarray(vertices, dtype=float) * metres_per_unit
    if up == "y":  # +90 degrees about x: (x, y, z) -> (x, -z, y)
        v = np.column_stack([v[:, 0], -v[:, 2], v[:, 1]])
    return v + np.asarray(offset, dtype=float)


def grid_shape(region: Sequence[float], resolution: float) -> tuple[int, int]:
    """(ny, nx) nodes of a grid from (x0, y0) every ``resolution`` up to (x1, y1)."""
    x0, x1, y0, y1 = region
    nx = int(math.floor((x1 - x0) / resolution + 1e-9)) + 1
    ny = int(math.floor((y1 - y0) / resolution + 1e-9)) + 1
    return ny, nx


def default_resolution(region: Sequence[float]) -> float:
    """1 cm, or the next whole millimetre that keeps the grid within DEFAULT_MAX_NODES."""
    x0, x1, y0, y1 = region
    res = max(DEFAULT_RESOLUTION_M, math.sqrt((x1 - x0) * (y1 - y0) / DEFAULT_MAX_NODES))
    res = math.ceil(res * 1000.0 - 1e-9) / 1000.0
    while math.prod(grid_shape(region, res)) > DEFAULT_MAX_NODES:
        res += 0.001
    return res


def component_labels(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Connected components of the triangles (through shared edges) and which are closed.

    Returns
    -------
    labels, closed
        ``labels[f]`` the component of face f; ``closed[c]`` whether every edge of
        component c is shared by an even number (two) of its faces.

    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(faces)
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    key = edges[:, 0] * (int(faces.max()) + 1) + edges[:, 1]
    face_of_edge = np.repeat(np.arange(n), 3)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    order = np.argsort(inverse, kind="stable")
    same = inverse[order][1:] == inverse[order][:-1]
    a, b = face_of_edge[order][:-1][same], face_of_edge[order][1:][same]
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    n_comp, labels = connected_components(graph, directed=False)
    open_face = np.zeros(n, dtype=bool)
    np.logical_or.at(open_face, face_of_edge, counts[inverse] % 2 == 1)
    closed = np.ones(n_comp, dtype=bool)
    closed[labels[open_face]] = False
    return labels, closed


def _hits(
    tri: np.ndarray, origin: Sequence[float], resolution: float, shape: tuple[int, int]
) -> tuple[np.ndarray, ...]:
    """Every (node, triangle) crossing: node index, triangle index, z [m], on an edge.

    ``tri`` is (F, 3, 3) in the world frame; vertical triangles are skipped.
    """
    ny, nx = shape
    p = (tri[:, :, :2] - np.asarray(origin, dtype=float)) / resolution  # grid units
    z = tri[:, :, 2]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    tol = EDGE_TOL_M / resolution  # grid units
    normal = np.cross(e1, e2)
    size = np.linalg.norm(normal, axis=1)
    keep = np.flatnonzero(np.abs(normal[:, 2]) > _VERTICAL_NZ * np.maximum(size, 1e-300))
    lo, hi = p[keep].min(axis=1), p[keep].max(axis=1)
    ix0 = np.clip(np.ceil(lo[:, 0] - tol), 0, nx).astype(np.int64)
    ix1 = np.clip(np.floor(hi[:, 0] + tol), -1, nx - 1).astype(np.int64)
    iy0 = np.clip(np.ceil(lo[:, 1] - tol), 0, ny).astype(np.int64)
    iy1 = np.clip(np.floor(hi[:, 1] + tol), -1, ny - 1).astype(np.int64)
    wx, wy = np.maximum(ix1 - ix0 + 1, 0), np.maximum(iy1 - iy0 + 1, 0)
    count = wx * wy
    keep, ix0, iy0, wx, count = (a[count > 0] for a in (keep, ix0, iy0, wx, count))
    out: list[list[np.ndarray]] = [[], [], [], []]
    ends = np.cumsum(count)
    start = 0
    while start < len(keep):
        stop = max(int(np.searchsorted(ends, ends[start] - count[start] + _CHUNK_PAIRS)), start + 1)
        sel = slice(start, stop)
        c = count[sel]
        t = np.repeat(np.arange(start, stop), c)
        k = np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c)
        gx = ix0[t] + k % wx[t]
        gy = iy0[t] + k // wx[t]
        a, b, cc = (p[keep[t], i] for i in range(3))
        d = (b[:, 1] - cc[:, 1]) * (a[:, 0] - cc[:, 0]) + (cc[:, 0] - b[:, 0]) * (
            a[:, 1] - cc[:, 1]
        )
        l1 = ((b[:, 1] - cc[:, 1]) * (gx - cc[:, 0]) + (cc[:, 0] - b[:, 0]) * (gy - cc[:, 1])) / d
        l2 = ((cc[:, 1] - a[:, 1]) * (gx - cc[:, 0]) + (a[:, 0] - cc[:, 0]) * (gy - cc[:, 1])) / d
        l3 = 1.0 - l1 - l2
        # signed xy distances to the three edges: l_i times the altitude |d| / |edge_i|
        length = np.stack([np.hypot(*(b - cc).T), np.hypot(*(cc - a).T), np.hypot(*(a - b).T)])
        dist = np.stack([l1, l2, l3]) * np.abs(d) / np.maximum(length, 1e-300)
        least = dist.min(axis=0)
        inside = least >= -tol
        zt = z[keep[t]]
        zz = l1 * zt[:, 0] + l2 * zt[:, 1] + l3 * zt[:, 2]
        zz = np.clip(zz, zt.min(axis=1), zt.max(axis=1))
        out[0].append((gy * nx + gx)[inside])
        out[1].append(keep[t][inside])
        out[2].append(zz[inside])
        out[3].append(least[inside] <= tol)
        start = stop
    if not out[0]:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool)
    return tuple(np.concatenate(o) for o in out)


def _solid_intervals(
    node: np.ndarray, comp: np.ndarray, z: np.ndarray, edge: np.ndarray, closed: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(node, lo, hi) of the solid intervals [m] along the vertical through each node.

    Crossings are grouped by (node, component): a group touched on a triangle's edge is one
    interval over its crossings; else a closed component is solid between alternate
    crossings (an odd count, which a valid solid never gives, is filled as one interval)
    and an open one is a surface at each crossing.
    """
    order = np.lexsort((-z, comp, node))
    node, comp, z, edge = node[order], comp[order], z[order], edge[order]
    group_start = np.r_[True, (node[1:] != node[:-1]) | (comp[1:] != comp[:-1])]
    gid = np.cumsum(group_start) - 1
    n_groups = int(gid[-1]) + 1 if len(gid) else 0
    g_edge = np.zeros(n_groups, dtype=bool)
    np.logical_or.at(g_edge, gid, edge)
    dup = ~group_start & (np.r_[np.inf, z[:-1] - z[1:]] <= _SAME_Z_M)  # a shared edge's twin
    node, comp, z, gid, group_start = (a[~dup] for a in (node, comp, z, gid, group_start))
    g_count = np.bincount(gid, minlength=n_groups)
    g_node = node[group_start]
    g_closed = closed[comp[group_start]]
    g_hi = z[group_start]
    g_lo = np.full(n_groups, np.inf)
    np.minimum.at(g_lo, gid, z)
    hull = g_edge | (g_closed & (g_count % 2 == 1))
    rank = np.arange(len(z)) - np.flatnonzero(group_start)[gid]
    h = hull[gid]
    pairs = ~h & g_closed[gid] & (rank % 2 == 0)  # the upper crossing of each solid part
    points = ~h & ~g_closed[gid]
    up = np.flatnonzero(pairs)
    nodes = np.concatenate([g_node[hull], node[up], node[points]])
    los = np.concatenate([g_lo[hull], z[up + 1], z[points]])
    his = np.concatenate([g_hi[hull], z[up], z[points]])
    return nodes, los, his


def _overhangs(
    node: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes whose solid intervals leave a gap over OVERHANG_TOL_M; (node, gap bottom, top)."""
    order = np.lexsort((-hi, node))
    node, lo, hi = node[order], lo[order], hi[order]
    span = float(np.max(hi) - np.min(lo)) + 1.0
    shifted = lo - node * 4.0 * span  # later nodes lower: a running minimum restarts per node
    run = np.minimum.accumulate(shifted) + node * 4.0 * span
    below = np.r_[False, node[1:] == node[:-1]]
    prev = np.r_[np.inf, run[:-1]]
    gap = below & (hi < prev - OVERHANG_TOL_M)
    return node[gap], hi[gap], prev[gap]


def rasterise(
    vertices_m: np.ndarray,
    faces: np.ndarray,
    region: Sequence[float],
    resolution: float,
    source: str,
    name: str,
    prefix: str = "",
) -> np.ndarray:
    """Top-surface heights ``heights[iy][ix]`` [m] of a world-frame mesh over ``region``.

    ``source``, ``name`` (the mesh file's) and ``prefix`` (of the spec's field paths) are
    for error messages.

    Raises
    ------
    TerrainError
        A node not under the mesh, or a node under more than one surface (module docstring).

    """
    x0, x1, y0, y1 = (float(v) for v in region)
    shape = grid_shape(region, resolution)
    ny, nx = shape
    tri = vertices_m[faces]
    node, face, z, edge = _hits(tri, (x0, y0), resolution, shape)
    top = np.full(ny * nx, -np.inf)
    np.maximum.at(top, node, z)
    missing = ~np.isfinite(top)
    if np.any(missing):
        first = int(np.flatnonzero(missing)[0])
        bx, by = tri[..., 0], tri[..., 1]
        raise _error(
            source,
            f"{prefix}region",
            f"{int(missing.sum())} of {ny * nx} grid nodes are not under the mesh '{name}', "
            f"first at (x, y) = ({x0 + (first % nx) * resolution:.4g}, "
            f"{y0 + (first // nx) * resolution:.4g}) m; give a 'region' [x0, x1, y0, y1] "
            f"inside the mesh (its xy bounds are [{bx.min():.4g}, {bx.max():.4g}, "
            f"{by.min():.4g}, {by.max():.4g}] m) or close the mesh's holes",
        )
    labels, closed = component_labels(faces)
    bad, gap_lo, gap_hi = _overhangs(*_solid_intervals(node, labels[face], z, edge, closed))
    if len(bad):
        worst = int(np.argmax(gap_hi - gap_lo))
        k = int(bad[worst])
        raise _error(
            source,
            f"{prefix}file",
            f"'{name}' is not a height field: at (x, y) = ({x0 + (k % nx) * resolution:.4g}, "
            f"{y0 + (k // nx) * resolution:.4g}) m there is open space from z = "
            f"{gap_lo[worst]:.4g} to {gap_hi[worst]:.4g} m under a surface at "
            f"{top[k]:.4g} m (an overhang, roof or floating part; {len(np.unique(bad))} grid "
            "nodes); remove it, close open shells with a bottom face, or give a 'region' "
            "without it",
        )
    return np.round(top.reshape(ny, nx) / HEIGHT_QUANTUM_M) / (1.0 / HEIGHT_QUANTUM_M) + 0.0


def mesh_heights(
    path: Path,
    source: str,
    prefix: str = "",
    *,
    metres_per_unit: float = 1.0,
    up: str = "z",
    offset: Sequence[float] = (0.0, 0.0, 0.0),
    region: Sequence[float] | None = None,
    resolution: float | None = None,
) -> MeshGrid:
    """Read a mesh file and rasterise its top surface (the whole procedure).

    Parameters
    ----------
    path
        The .stl, .obj or .ply file.
    source, prefix
        Where the request came from (the file, the spec's field path before ``file``), for
        error messages.
    metres_per_unit, up, offset
        File units to the world frame (module docstring).
    region
        ``(x0, x1, y0, y1)`` [m], world frame; default the mesh's xy bounds.
    resolution
        Grid step [m]; default :func:`default_resolution` of the region.

    Raises
    ------
    TerrainError
        Any of the failures of :func:`read_mesh` and :func:`rasterise`, or a grid over
        :data:`MAX_NODES` nodes.

    """
    field = f"{prefix}file"
    vertices, faces = read_mesh(path, source, field)
    v = to_world(vertices, metres_per_unit, up, offset)
    if region is None:
        lo, hi = v.min(axis=0), v.max(axis=0)  # to the micrometre (float32 files)
        region = tuple(round(float(c), 6) for c in (lo[0], hi[0], lo[1], hi[1]))
        if region[1] - region[0] <= 0.0 or region[3] - region[2] <= 0.0:
            raise _error(
                source,
                field,
                f"'{path}' spans no area in x and y ({region}); check 'up' (z or y) and units",
            )
    region = tuple(float(r) for r in region)
    if resolution is None:
        resolution = default_resolution(region)
    ny, nx = grid_shape(region, resolution)
    if nx < 2 or ny < 2 or nx * ny > MAX_NODES:
        raise _error(
            source,
            f"{prefix}resolution",
            f"{resolution:g} m over region {list(region)} gives a {nx} x {ny} grid; keep it "
            f"between 2 x 2 and {MAX_NODES} nodes by changing 'resolution' or 'region'",
        )
    heights = rasterise(v, faces, region, resolution, source, path.name, prefix)
    return MeshGrid(heights, (region[0], region[2]), float(resolution), region, len(faces))


__all__ = [
    "DEFAULT_MAX_NODES",
    "DEFAULT_RESOLUTION_M",
    "MAX_NODES",
    "MESH_SUFFIXES",
    "OVERHANG_TOL_M",
    "MeshGrid",
    "TerrainError",
    "default_resolution",
    "grid_shape",
    "is_mesh_path",
    "mesh_heights",
    "rasterise",
    "read_mesh",
    "to_world",
]
