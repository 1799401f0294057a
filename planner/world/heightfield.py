"""Height-field terrain data: reading grids from files and a smooth CasADi interpolant.

A height field is a uniform grid of terrain heights ``heights[iy][ix]`` at
``(x0 + ix * resolution, y0 + iy * resolution)`` (the same layout as the plan file's
``terrain_grid``). It defines z_T(x, y) of the paper's section 4.4 by a bicubic B-spline
through the samples (``casadi.interpolant(..., "bspline", ...)``), which is C2, so IPOPT gets
exact first and second derivatives. The numpy side evaluates the *same* CasADi function, so
the two agree to rounding.

Files
-----
``.npy``
    A 2-D float array ``heights[iy][ix]``.
``.csv``
    Either a plain matrix (no header; row ``iy``, column ``ix``) or three columns with the
    header ``x,y,z`` listing every node of a uniform grid (origin and resolution are then
    read from the coordinates).
``.png``
    A greyscale image (16-bit preferred); row ``iy = 0`` is the first image row (``y0``),
    i.e. the image shows +y downwards. ``metres_per_unit`` is required.

Every raw value becomes ``raw * metres_per_unit + offset`` metres.
"""

from __future__ import annotations

import csv
import hashlib
from collections.abc import Sequence
from pathlib import Path

import casadi as ca
import numpy as np

from planner.core.errors import TerrainError

#: Edge cells added on every side (edge values repeated) before fitting the spline, so the
#: spline flattens out at the border; queries are clamped to the padded grid.
PAD_CELLS = 2

_INTERPOLANT_CACHE: dict[str, ca.Function] = {}


def _fail(source: str, field: str, message: str) -> TerrainError:
    """Build a one-line :class:`TerrainError` naming the file and the field."""
    text = f"{source}: field '{field}': {message}"
    return TerrainError(" ".join(text.split()))


def read_height_file(
    path: Path, source: str, field: str
) -> tuple[np.ndarray, tuple[float, float] | None, float | None]:
    """Read raw grid values from a ``.npy``, ``.csv`` or ``.png`` file.

    Parameters
    ----------
    path
        The file to read.
    source, field
        Where the request came from, for error messages.

    Returns
    -------
    raw, origin, resolution
        ``raw[iy][ix]`` (float, not yet scaled), and for an ``x,y,z`` csv the grid origin
        ``(x0, y0)`` and resolution read from the coordinates (else ``None``).

    Raises
    ------
    TerrainError
        The file is missing, unreadable, of an unknown type, or its grid is not uniform.

    """
    suffix = path.suffix.lower()
    if suffix not in (".npy", ".csv", ".png"):
        raise _fail(
            source, field, f"unknown height-field file type '{path.name}'; use .npy, .csv or .png"
        )
    if not path.is_file():
        raise _fail(source, field, f"cannot read '{path}': no such file; check the path")
    try:
        if suffix == ".npy":
            raw = np.load(path, allow_pickle=False)
            return as_grid(raw, source, field, path), None, None
        if suffix == ".png":
            return _read_png(path, source, field), None, None
        return _read_csv(path, source, field)
    except TerrainError:
        raise
    except Exception as exc:  # noqa: BLE001 - any reader failure is reported the same way
        raise _fail(
            source, field, f"cannot read '{path}' ({type(exc).__name__}: {exc}); fix or replace it"
        ) from exc


def as_grid(raw: np.ndarray, source: str, field: str, path: Path | str) -> np.ndarray:
    """Check that ``raw`` is a 2-D numeric grid of at least 2 x 2 and return it as float."""
    arr = np.asarray(raw)
    if arr.dtype.kind not in "biuf" or arr.ndim != 2:
        raise _fail(
            source,
            field,
            f"'{path}' must hold a 2-D numeric grid heights[iy][ix], got shape {arr.shape} "
            f"of type {arr.dtype}",
        )
    if arr.shape[0] < 2 or arr.shape[1] < 2:
        raise _fail(source, field, f"'{path}' grid is {arr.shape}; give at least 2 x 2 nodes")
    return arr.astype(float)


def _read_png(path: Path, source: str, field: str) -> np.ndarray:
    """Read a greyscale PNG as a float grid of raw units."""
    from PIL import Image

    with Image.open(path) as img:
        mode = img.mode
        if mode not in ("I;16", "I;16B", "I;16L", "I", "L"):
            raise _fail(
                source,
                field,
                f"'{path}' has image mode {mode}; save it as a greyscale (16-bit) PNG",
            )
        arr = np.array(img)
    return as_grid(arr, source, field, path)


def _read_csv(
    path: Path, source: str, field: str
) -> tuple[np.ndarray, tuple[float, float] | None, float | None]:
    """Read a csv matrix, or an ``x,y,z`` node list that must form a uniform grid."""
    with path.open(newline="") as fh:
        rows = [r for r in csv.reader(fh) if r and any(c.strip() for c in r)]
    if not rows:
        raise _fail(source, field, f"'{path}' is empty; give a height grid")
    header = [c.strip().lower() for c in rows[0]]
    if not any(c and c[0].isalpha() for c in header):
        return as_grid(np.array(rows, dtype=float), source, field, path), None, None
    if header != ["x", "y", "z"]:
        raise _fail(
            source,
            field,
            f"'{path}' header is {','.join(header)}; use no header (a matrix) or exactly x,y,z",
        )
    data = np.array(rows[1:], dtype=float)
    if data.ndim != 2 or data.shape[1] != 3 or data.shape[0] < 4:
        raise _fail(source, field, f"'{path}' needs at least 4 rows of x,y,z")
    if not np.all(np.isfinite(data[:, :2])):
        raise _fail(source, field, f"'{path}' has non-finite x or y coordinates; fix them")
    xs = np.unique(data[:, 0])
    ys = np.unique(data[:, 1])
    res = []
    for axis, vals in (("x", xs), ("y", ys)):
        if vals.size < 2:
            raise _fail(source, field, f"'{path}' has a single {axis} value; give a 2-D grid")
        steps = np.diff(vals)
        step = (vals[-1] - vals[0]) / (vals.size - 1)
        worst = int(np.argmax(np.abs(steps - step)))
        if abs(steps[worst] - step) > 1e-6 * max(step, 1e-12) + 1e-12:
            raise _fail(
                source,
                field,
                f"'{path}' {axis} coordinates are not uniformly spaced (step {steps[worst]:.6g} "
                f"between {axis}={vals[worst]:.6g} and {vals[worst + 1]:.6g}, mean {step:.6g}); "
                "resample to a uniform grid",
            )
        res.append(step)
    if abs(res[0] - res[1]) > 1e-6 * max(res):
        raise _fail(
            source,
            field,
            f"'{path}' has x step {res[0]:.6g} but y step {res[1]:.6g}; "
            "resample to square cells (one resolution)",
        )
    ix = np.rint((data[:, 0] - xs[0]) / res[0]).astype(int)
    iy = np.rint((data[:, 1] - ys[0]) / res[0]).astype(int)
    grid = np.full((ys.size, xs.size), np.nan)
    count = np.zeros_like(grid, dtype=int)
    np.add.at(count, (iy, ix), 1)
    if np.any(count != 1):
        bad = np.argwhere(count != 1)[0]
        raise _fail(
            source,
            field,
            f"'{path}' node x={xs[bad[1]]:.6g}, y={ys[bad[0]]:.6g} appears {count[tuple(bad)]} "
            "times; list every grid node exactly once",
        )
    grid[iy, ix] = data[:, 2]
    return grid, (float(xs[0]), float(ys[0])), float(res[0])


def check_finite(heights: np.ndarray, source: str, field: str) -> None:
    """Raise a :class:`TerrainError` naming the first NaN or infinite height, if any."""
    bad = ~np.isfinite(heights)
    if np.any(bad):
        iy, ix = (int(v) for v in np.argwhere(bad)[0])
        raise _fail(
            source,
            field,
            f"height values must be finite, found {heights[iy, ix]} at heights[{iy}][{ix}] "
            f"({int(bad.sum())} bad values); fill or remove them",
        )


def build_interpolant(
    heights_m: np.ndarray, origin: Sequence[float], resolution: float
) -> tuple[ca.Function, tuple[float, float, float, float]]:
    """Fit the bicubic B-spline ``z(x, y)`` through a height grid (CasADi ``bspline``).

    The grid is padded by :data:`PAD_CELLS` edge copies; callers clamp queries to the
    returned padded bounds, so beyond the grid the terrain continues at its edge values.
    Fitting costs about 0.2 s for a 200 x 100 grid and 4 s for 600 x 240 (CasADi's lsqr);
    results are cached per grid within the process.

    Parameters
    ----------
    heights_m
        ``heights_m[iy][ix]`` in metres, finite.
    origin
        ``(x0, y0)`` of node ``[0][0]`` in metres.
    resolution
        Node spacing in metres.

    Returns
    -------
    fun, bounds
        ``fun`` maps a 2-vector ``[x; y]`` to z (SX/MX/DM; callable on 2 x N for N points);
        ``bounds`` is ``(xmin, xmax, ymin, ymax)`` of the padded grid.

    """
    padded = np.pad(np.asarray(heights_m, dtype=float), PAD_CELLS, mode="edge")
    ny, nx = padded.shape
    x0 = float(origin[0]) - PAD_CELLS * resolution
    y0 = float(origin[1]) - PAD_CELLS * resolution
    grid_x = x0 + resolution * np.arange(nx)
    grid_y = y0 + resolution * np.arange(ny)
    key = hashlib.sha1(
        padded.tobytes() + np.array([x0, y0, resolution, nx, ny], dtype=float).tobytes()
    ).hexdigest()
    fun = _INTERPOLANT_CACHE.get(key)
    if fun is None:
        fun = ca.interpolant(
            "z_heightfield",
            "bspline",
            [grid_x.tolist(), grid_y.tolist()],
            padded.ravel().tolist(),  # x fastest: CasADi's column-major order
        )
        _INTERPOLANT_CACHE[key] = fun
    return fun, (float(grid_x[0]), float(grid_x[-1]), float(grid_y[0]), float(grid_y[-1]))
