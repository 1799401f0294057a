"""Terrain as the implicit function f_T(r) = r_z - z_T(r_x, r_y) (paper, section 4.4).

f_T is positive above the surface, zero on it and negative below. The same z_T is built
once, from one generic expression per terrain kind, for numpy (vectorised over arrays of
any shape) and for CasADi (SX/MX, exact derivatives for IPOPT); the two agree to rounding.
Pseudo-normals grad f_T / |grad f_T| and smoothed pseudo-normals follow section 4.5.

Kinds (``kind:`` in a spec; x fields are world x at top level and relative to the
segment start inside a ``course``):

``flat``
    z = 0.
``slope``
    ``angle_deg``, ``direction_deg`` (uphill direction in the xy plane, 0 = +x), ``start``
    (where the ramp begins, measured along the direction), optional ``ramp_length``
    (level again after it).
``step``
    ``x``, ``height`` (positive up, negative down).
``stairs``
    ``x_start``, ``rise``, ``run``, ``count``.
``gap``
    A trench: ``x_start``, ``width``, ``depth`` (finite, positive down).
``barrier``
    ``x`` (near face), ``height``, ``thickness``; optional ``opening`` [y0, y1], a gap in
    the wall (no barrier for y0 <= y < y1).
``stepping_stones``
    A pit ``depth`` deep over ``x_start..x_end`` x ``y_start..y_end`` holding a centred grid of
    square stones (``size``, ``gap``) whose tops are at ``height`` + U(-1, 1) *
    ``height_jitter`` (``seed``); or, instead of ``gap``, hand-placed stones: ``stones``, a
    list of [x, y] centres or [x, y, top].
``rough``
    Band-limited random relief: ``terms`` (<= 60) seeded 2-D cosines with wavelengths in
    [``wavelength``, ``wavelength_max``], amplitudes proportional to wavelength, scaled so
    that max |z| over the patch (``x_start..x_end`` x the course's y span, sampled every
    ``wavelength`` / 10) equals ``amplitude``; faded in and out over ``taper`` at
    ``x_start`` and ``x_end``.
``rocks``
    ``count`` seeded elliptic Gaussian bumps (heights ``height_min..height_max``, standard
    deviations ``radius_min..radius_max``) inside a region, centres kept apart; where
    tails overlap the heights add.
``logs``
    ``count`` half-cylinders lying across y, axes at ``x_start + i * spacing``, ``radius``
    (+- ``radius_jitter``), yawed by up to ``yaw_jitter_deg``.
``heightfield``
    A grid from a file (``.npy``, ``.csv``, 16-bit ``.png``) or inline ``heights``; see
    :mod:`planner.world.heightfield`.
``mesh``
    An STL, OBJ or PLY surface (``file``) rasterised to a height field: ``metres_per_unit``
    (default 1; 0.001 for a mesh in mm), ``up`` (the file's up axis, ``z`` or ``y``),
    ``offset`` [dx, dy, dz] (metres, added after scaling), ``region`` [x0, x1, y0, y1]
    (default the mesh's xy bounds), ``resolution`` (default 1 cm, coarser past 100,000
    nodes). Its top surface is sampled; a node not under the mesh, or under an overhang,
    is an error (:mod:`planner.world.mesh_terrain`). The normalised spec holds the grid
    (``heights``), so a plan file needs no mesh. A mesh path also loads directly
    (:func:`load_terrain`).
``course``
    ``segments``: a list of kinds, each with a ``length``, laid end to end along x from
    ``x_min``. z is the sum of the segments' contributions, each evaluated at x minus its
    segment's start. Every kind contributes zero before its features, so level changes
    (step, stairs, slope) stack: later segments start at the level the earlier ones left.

Smoothing (``smoothing_m``, w, default 5 mm)
    The solver sees C-infinity heights (:meth:`Terrain.height`, :meth:`Terrain.height_ca`);
    the validator judges against the real sharp ones (:meth:`Terrain.height_sharp`). A
    sharp jump of size h at an edge becomes h * (1 + tanh(d / w)) / 2 for signed distance d
    past the edge, so |smooth - sharp| <= |h| exp(-2 |d| / w) (h/2 on the edge, 0.25 % of h
    at 3 w, 5e-5 h at 5 w). A slope's kinks are rounded by the integral of that sigmoid,
    (w / 2) log(1 + exp(2 d / w)) (off by at most tan(angle) w ln2 / 2 at the kink). A log's
    vertical sides are rounded by sqrt(softplus(R^2 - d^2)) with softplus width R w / 2: it
    is never below the circle (but for 1 um), reaches sqrt(R w ln2 / 2) at the edge (8 mm
    for R = 4 cm), and exceeds 0 by at most about sqrt(R w / 2) exp(-2 d / w) at d outside
    the edge.
    Rough, rocks and height fields have no edges: sharp and smooth are identical.

Cost
    f_T at 12 points with its Jacobian and Hessian (CasADi SX virtual machine, one call):
    about 5-10 us for flat/slope/step/stairs/gap/barrier, 40 us logs, 60 us a height field,
    105 us rough (40 terms), 150 us rocks (30), 165 us stepping stones (80),
    230 us ``course_rough``; ``jit`` compilation of the NLP cuts these about 8x.

Spec (YAML)
    ``name``, ``description``, ``friction`` (mu, default 0.7), ``x_min`` (default -0.5),
    ``length``, ``y_min``/``y_max`` (default -0.6/0.6), ``smoothing_m``, ``kind`` and its
    fields (or ``segments``). Unknown fields are errors. :attr:`Terrain.spec` is the
    normalised spec with every default filled in; ``Terrain.from_spec(t.spec)`` rebuilds it.

The kinds are in :mod:`planner.world.terrain_kinds`, the numpy and CasADi backends in
:mod:`planner.world.terrain_backends`, the reading of spec fields in
:mod:`planner.world.terrain_spec`; this module holds :class:`Terrain` and the loading.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import yaml

import planner
from planner.world.mesh_terrain import is_mesh_path
from planner.world.terrain_backends import _CHUNK, CA
from planner.world.terrain_backends import NP as NP  # re-exported
from planner.world.terrain_kinds import KINDS, _Heightfield, _Kind
from planner.world.terrain_kinds import MAX_ROUGH_CELLS as MAX_ROUGH_CELLS  # re-exported
from planner.world.terrain_kinds import MAX_STONES as MAX_STONES  # re-exported
from planner.world.terrain_spec import _Context, _error, _Fields, _show, _YamlLoader

__all__ = [
    "DEFAULT_FRICTION",
    "DEFAULT_SMOOTHING_M",
    "KINDS",
    "Terrain",
    "list_terrains",
    "load_terrain",
    "terrains_dir",
]

DEFAULT_SMOOTHING_M = 0.005
DEFAULT_FRICTION = 0.7
DEFAULT_X_MIN = -0.5
DEFAULT_Y_MIN = -0.6
MAX_EXTENT_M = 10_000.0  # |x_min|, |y_min|, |y_max| and length at most this [m]
DEFAULT_Y_MAX = 0.6

_COMMON = (
    "name",
    "description",
    "friction",
    "x_min",
    "length",
    "y_min",
    "y_max",
    "smoothing_m",
    "kind",
)


# ----------------------------------------------------------------------------------------
# Terrain.


def _smoothing_pattern(n_rings: int = 3, n_angles: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Unit-disc sample offsets (K, 2) and Gaussian weights (K,) summing to 1.

    The centre plus ``n_rings`` rings at radii k / n_rings, each with ``n_angles`` samples
    (alternate rings rotated by half a step); weight exp(-rho^2 / (2 sigma^2)), sigma = 1/2
    of the disc radius.
    """
    pts = [(0.0, 0.0)]
    for k in range(1, n_rings + 1):
        rho = k / n_rings
        for j in range(n_angles):
            ang = 2.0 * math.pi * (j + 0.5 * (k % 2)) / n_angles
            pts.append((rho * math.cos(ang), rho * math.sin(ang)))
    off = np.array(pts)
    wts = np.exp(-0.5 * np.sum(off**2, axis=1) / 0.5**2)
    return off, wts / wts.sum()


_PATTERN_OFFSETS, _PATTERN_WEIGHTS = _smoothing_pattern()


class Terrain:
    """A terrain z_T(x, y) and its implicit function f_T(r) = r_z - z_T (paper 4.4-4.5).

    Build with :meth:`from_spec` or :func:`load_terrain`. Attributes: ``name``,
    ``description``, ``friction`` (mu), ``bounds`` ``(xmin, xmax, ymin, ymax)`` of the course
    in metres, ``smoothing_m`` and ``spec`` (normalised; rebuilds the same terrain).
    """

    def __init__(
        self, spec: Mapping[str, Any], *, source: str = "<spec>", base_dir: str | Path | None = None
    ):
        base = Path(base_dir) if base_dir is not None else None
        top = _Fields(spec, source, "")
        self.source = source
        self.name = top.string("name", "terrain")
        self.description = top.string("description", "")
        self.friction = top.number("friction", DEFAULT_FRICTION, lo=0.0, lo_open=True, hi=5.0)
        self.smoothing_m = top.number("smoothing_m", DEFAULT_SMOOTHING_M, lo=1e-4, hi=0.1)
        kind = top.string("kind")
        if kind != "course" and kind not in KINDS:
            raise top.fail(
                "kind",
                f"unknown kind {kind!r}; use one of: {', '.join(sorted([*KINDS, 'course']))}",
            )
        # a course lies within 10 km of the origin and is at most 10 km long: a quasi-static
        # walker covers a few cm/s, and numbers past that are typing errors (1e300)
        x_min = top.number("x_min", None, lo=-MAX_EXTENT_M, hi=MAX_EXTENT_M, hint="metres")
        length = top.number("length", None, lo=0.0, lo_open=True, hi=MAX_EXTENT_M)
        y_min = top.number("y_min", DEFAULT_Y_MIN, lo=-MAX_EXTENT_M, hi=MAX_EXTENT_M)
        y_max = top.number("y_max", DEFAULT_Y_MAX, lo=-MAX_EXTENT_M, hi=MAX_EXTENT_M)
        if y_max <= y_min:
            raise top.fail("y_max", f"must be > y_min ({y_min}), got {y_max}; change it")
        self._segments: list[tuple[float, _Kind]] = []
        body: dict[str, Any] = {}
        if kind == "course":
            x_min, length = self._read_course(top, base, x_min, length, y_min, y_max, body)
        else:
            x_min, length, y_min, y_max, body = self._read_kind(
                top, kind, base, x_min, length, y_min, y_max
            )
        self.kind = kind
        self.bounds = (float(x_min), float(x_min + length), float(y_min), float(y_max))
        self.spec: dict[str, Any] = {
            "name": self.name,
            "description": self.description,
            "friction": self.friction,
            "x_min": float(x_min),
            "length": float(length),
            "y_min": float(y_min),
            "y_max": float(y_max),
            "smoothing_m": self.smoothing_m,
            "kind": kind,
            **body,
        }
        self._build_functions()

    def _read_course(
        self,
        top: _Fields,
        base: Path | None,
        x_min: float | None,
        length: float | None,
        y_min: float,
        y_max: float,
        body: dict[str, Any],
    ) -> tuple[float, float]:
        """Read a ``course``'s segments, laid end to end from ``x_min``; (x_min, length).

        Appends each segment to ``_segments`` and its normalised spec to ``body``.
        """
        source = self.source
        x_min = DEFAULT_X_MIN if x_min is None else x_min
        segs = top.raw("segments", hint="a list of {kind, length, ...}")
        if not isinstance(segs, list) or not segs:
            raise top.fail("segments", f"expected a non-empty list, got {_show(segs)}")
        top.finish([*_COMMON, "segments"])
        offset, seg_specs = x_min, []
        for i, seg in enumerate(segs):
            sf = _Fields(seg, source, f"segments[{i}].")
            s_kind = sf.string("kind")
            if s_kind not in KINDS:
                raise sf.fail(
                    "kind", f"unknown kind {s_kind!r}; use one of: {', '.join(sorted(KINDS))}"
                )
            s_len = sf.number("length", lo=0.0, lo_open=True, hint="metres along x")
            w = sf.number("smoothing_m", self.smoothing_m, lo=1e-4, hi=0.1)
            ctx = _Context(0.0, s_len, y_min, y_max, w, base)
            k = KINDS[s_kind](sf, ctx)
            sf.finish()
            self._segments.append((offset, k))
            seg_specs.append({"kind": s_kind, "length": s_len, "smoothing_m": w, **k.spec})
            offset += s_len
        total = offset - x_min
        if length is not None and abs(length - total) > 1e-9:
            raise top.fail(
                "length",
                f"{length} differs from the sum of segment lengths "
                f"{total:.6g}; make them equal or drop 'length'",
            )
        length = total
        body["segments"] = seg_specs
        return x_min, length

    def _read_kind(
        self,
        top: _Fields,
        kind: str,
        base: Path | None,
        x_min: float | None,
        length: float | None,
        y_min: float,
        y_max: float,
    ) -> tuple[float, float, float, float, dict[str, Any]]:
        """Read a single kind at top level; (x_min, length, y_min, y_max, its spec fields).

        A height field without ``x_min``, ``length`` or a y span takes them from its grid.
        """
        ctx_x0 = DEFAULT_X_MIN if x_min is None else x_min
        ctx_x1 = ctx_x0 + (length if length is not None else 3.0)
        ctx = _Context(ctx_x0, ctx_x1, y_min, y_max, self.smoothing_m, base)
        k = KINDS[kind](top, ctx)
        top.finish([*_COMMON, *k.spec])
        if isinstance(k, _Heightfield):
            ex = k.extent
            x_min = ex[0] if x_min is None else x_min
            length = ex[1] - x_min if length is None else length
            if not top.has("y_min") and not top.has("y_max"):
                y_min, y_max = ex[2], ex[3]
        if x_min is None:
            x_min = DEFAULT_X_MIN
        if length is None:
            raise top.fail("length", "missing; add the course length along x in metres")
        self._segments.append((0.0, k))
        body = dict(k.spec)
        return x_min, length, y_min, y_max, body

    def _build_functions(self) -> None:
        """CasADi functions of the summed height z_T and its gradient (exact derivatives)."""
        xs, ys = ca.SX.sym("x"), ca.SX.sym("y")
        z = 0.0
        for off, k in self._segments:
            z = z + k.expr(xs - off, ys, CA)
        z = ca.SX(z)
        self._z_fun = ca.Function("z_T", [xs, ys], [z], ["x", "y"], ["z"])
        self._zgrad_fun = ca.Function(
            "grad_z_T",
            [xs, ys],
            [ca.gradient(z, xs), ca.gradient(z, ys)],
            ["x", "y"],
            ["dz_dx", "dz_dy"],
        )

    @classmethod
    def from_spec(
        cls, spec: Mapping[str, Any], *, source: str = "<spec>", base_dir: str | Path | None = None
    ) -> Terrain:
        """Build a terrain from a spec mapping (as in a terrain YAML, or :attr:`spec`).

        Parameters
        ----------
        spec
            The spec; see the module docstring for fields.
        source
            Name used in error messages (usually the YAML file).
        base_dir
            Directory that relative height-field and mesh paths are resolved against
            (default cwd).

        Raises
        ------
        TerrainError
            Any malformed field (the message names ``source`` and the field).

        """
        return cls(spec, source=source, base_dir=base_dir)

    def __repr__(self) -> str:
        return f"Terrain(name={self.name!r}, kind={self.kind!r}, bounds={self.bounds})"

    def fingerprint(self) -> str:
        """A digest of everything that defines z_T: the spec and each part's numeric data.

        Two terrains with the same fingerprint give the same heights everywhere (a height
        field's grid is hashed, not its file name), so the problems built on one serve the
        other (:mod:`planner.problems.cache`).
        """
        digest = hashlib.sha256(json.dumps(self.spec, sort_keys=True, default=str).encode())
        for off, k in self._segments:
            digest.update(repr(float(off)).encode())
            for name, value in sorted(vars(k).items()):
                if isinstance(value, np.ndarray):
                    digest.update(name.encode() + np.ascontiguousarray(value).tobytes())
        return digest.hexdigest()

    # -- numpy ---------------------------------------------------------------------------

    def _apply(
        self, fn: Callable[[np.ndarray, np.ndarray], Any], x: Any, y: Any, n_out: int
    ) -> list[np.ndarray]:
        """Evaluate ``fn`` on broadcast (x, y) in chunks; returns ``n_out`` arrays."""
        xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        shape = xa.shape
        xf, yf = xa.reshape(-1), ya.reshape(-1)
        if 0 < xf.size <= _CHUNK:  # one chunk
            part = fn(xf, yf)
            return [
                o.reshape(shape)  # fn's own new array: no copy
                if isinstance(o, np.ndarray) and o.shape == xf.shape and o.dtype == float
                else np.array(np.broadcast_to(o, xf.shape), dtype=float).reshape(shape)
                for o in (part if n_out > 1 else (part,))
            ]
        outs = [np.empty(xf.size) for _ in range(n_out)]
        for i in range(0, xf.size, _CHUNK):
            part = fn(xf[i : i + _CHUNK], yf[i : i + _CHUNK])
            part = part if n_out > 1 else (part,)
            for o, p in zip(outs, part, strict=True):
                o[i : i + _CHUNK] = p
        return [o.reshape(shape) for o in outs]

    @staticmethod
    def _out(a: np.ndarray) -> float | np.ndarray:
        return float(a) if a.ndim == 0 else a

    def height(self, x: Any, y: Any) -> float | np.ndarray:
        """Smooth z_T(x, y) in metres (what the solver sees), vectorised over any shapes."""

        def fn(xf: np.ndarray, yf: np.ndarray) -> np.ndarray:
            return sum((k.value_np(xf - off, yf) for off, k in self._segments), np.zeros(xf.shape))

        return self._out(self._apply(fn, x, y, 1)[0])

    def height_sharp(self, x: Any, y: Any) -> float | np.ndarray:
        """True sharp-edged z_T(x, y) in metres (what the validator judges against)."""

        def fn(xf: np.ndarray, yf: np.ndarray) -> np.ndarray:
            return sum((k.sharp(xf - off, yf) for off, k in self._segments), np.zeros(xf.shape))

        return self._out(self._apply(fn, x, y, 1)[0])

    def height_sharp_offsets(self, x: Any, y: Any, dx: Any, dy: Any) -> np.ndarray:
        """(N, M) sharp heights [m] at the N points (x, y) each moved by the M offsets (dx, dy).

        The same as ``height_sharp(x[:, None] + dx, y[:, None] + dy)`` (to rounding); a
        relief sums its cosines as a matrix product (a disc or a grid around each point).
        """
        xs, ys = (np.asarray(v, dtype=float).reshape(-1) for v in np.broadcast_arrays(x, y))
        ox, oy = (np.asarray(v, dtype=float).reshape(-1) for v in np.broadcast_arrays(dx, dy))
        out = np.zeros((len(xs), len(ox)))
        rows = max(1, _CHUNK // max(len(ox), 1))
        for i in range(0, len(xs), rows):
            part = slice(i, i + rows)
            for off, k in self._segments:
                out[part] += k.sharp_offsets(xs[part] - off, ys[part], ox, oy)
        return out

    def height_sharp_grid(self, xs: Any, ys: Any) -> np.ndarray:
        """(len(ys), len(xs)) sharp heights [m] on the grid of the node coordinates xs, ys.

        The same as ``height_sharp(xs[None, :], ys[:, None])`` to rounding; a relief's
        cosines separate in x and y, so a grid costs it a matrix product.
        """
        xs = np.asarray(xs, dtype=float).reshape(-1)
        ys = np.asarray(ys, dtype=float).reshape(-1)
        out = np.zeros((len(ys), len(xs)))
        gx, gy = None, None
        for off, k in self._segments:
            if k.sharp_grid is not None:
                out += k.sharp_grid(xs - off, ys)
                continue
            if gx is None:
                gx, gy = np.meshgrid(xs, ys)
            out += self._apply(lambda xf, yf, k=k, off=off: k.sharp(xf - off, yf), gx, gy, 1)[0]
        return out

    def height_gradient(self, x: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
        """Exact (dz_T/dx, dz_T/dy) of the smooth height, numpy."""

        def fn(xf: np.ndarray, yf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            gx, gy = np.zeros(xf.shape), np.zeros(xf.shape)
            for off, k in self._segments:
                a, b = k.grad_np(xf - off, yf)
                gx, gy = gx + a, gy + b
            return gx, gy

        gx, gy = self._apply(fn, x, y, 2)
        return gx, gy

    def f_T_and_normal(self, p_W: Any) -> tuple[np.ndarray, np.ndarray]:
        """(:meth:`f_T`, :meth:`normal`) at points (..., 3) in one pass over the segments.

        The same numbers as the two calls; a sphere put to rest on the terrain
        (:mod:`planner.body.rolling`) asks both at the same points thousands of times a walk.
        """
        p = np.asarray(p_W, dtype=float)

        def fn(xf: np.ndarray, yf: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            z, gx, gy = np.zeros(xf.shape), np.zeros(xf.shape), np.zeros(xf.shape)
            for off, k in self._segments:
                h, a, b = k.value_and_grad_np(xf - off, yf)
                z, gx, gy = z + h, gx + a, gy + b
            return z, gx, gy

        z, gx, gy = self._apply(fn, p[..., 0], p[..., 1], 3)
        g = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
        return p[..., 2] - z, g / np.linalg.norm(g, axis=-1, keepdims=True)

    def f_T(self, p_W: Any) -> float | np.ndarray:
        """Implicit terrain function p_z - z_T(p_x, p_y) at points (..., 3), world frame, metres."""
        p = np.asarray(p_W, dtype=float)
        return self._out(np.asarray(p[..., 2] - self.height(p[..., 0], p[..., 1])))

    def gradient(self, p_W: Any) -> np.ndarray:
        """Gradient of f_T, (-dz/dx, -dz/dy, 1), at points (..., 3)."""
        p = np.asarray(p_W, dtype=float)
        gx, gy = self.height_gradient(p[..., 0], p[..., 1])
        return np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)

    def normal(self, p_W: Any) -> np.ndarray:
        """Pseudo-normal grad f_T / |grad f_T| at points (..., 3) (section 4.5)."""
        g = self.gradient(p_W)
        return g / np.linalg.norm(g, axis=-1, keepdims=True)

    def smoothed_normal(self, p_W: Any, radius: float) -> np.ndarray:
        """Smoothed pseudo-normal (section 4.5) at points (..., 3).

        The pseudo-normals at 25 points of a horizontal disc of ``radius`` metres around
        each point (centre plus 3 rings of 8) are averaged with Gaussian weights
        exp(-rho^2 / (2 sigma^2)), sigma = radius / 2, and the mean is renormalised. f_T's
        normal does not depend on p_z. ``radius = 0`` gives :meth:`normal`.
        """
        if not (radius >= 0.0 and math.isfinite(radius)):
            raise ValueError(f"smoothed_normal: radius must be >= 0 metres, got {radius}")
        p = np.asarray(p_W, dtype=float)
        if radius == 0.0:
            return self.normal(p)
        x = p[..., 0, None] + radius * _PATTERN_OFFSETS[:, 0]
        y = p[..., 1, None] + radius * _PATTERN_OFFSETS[:, 1]
        gx, gy = self.height_gradient(x, y)
        g = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
        n = g / np.linalg.norm(g, axis=-1, keepdims=True)
        m = np.einsum("...kc,k->...c", n, _PATTERN_WEIGHTS)
        return m / np.linalg.norm(m, axis=-1, keepdims=True)

    def height_grid(
        self, x0: float, x1: float, y0: float, y1: float, resolution: float = 0.005
    ) -> tuple[list[float], float, np.ndarray]:
        """Sharp heights on a grid, for the plan file's ``terrain_grid`` (resolution <= 5 mm).

        Returns
        -------
        origin, resolution, heights
            ``origin = [x0, y0]``; ``heights[iy][ix]`` is the sharp height at
            ``(x0 + ix * resolution, y0 + iy * resolution)``, covering [x0, x1] x [y0, y1]
            (the last node is the last one not beyond x1, y1).

        """
        if not (resolution > 0.0 and math.isfinite(resolution)):
            raise ValueError(f"height_grid: resolution must be > 0 metres, got {resolution}")
        if not (x1 >= x0 and y1 >= y0):
            raise ValueError(f"height_grid: need x1 >= x0 and y1 >= y0, got {(x0, x1, y0, y1)}")
        nx = int(math.floor((x1 - x0) / resolution + 1e-9)) + 1
        ny = int(math.floor((y1 - y0) / resolution + 1e-9)) + 1
        gx = x0 + resolution * np.arange(nx)
        gy = y0 + resolution * np.arange(ny)
        heights = np.asarray(self.height_sharp(gx[None, :], gy[:, None]))
        return [float(x0), float(y0)], float(resolution), heights

    # -- CasADi --------------------------------------------------------------------------

    def height_ca(self, x: Any, y: Any) -> Any:
        """Smooth z_T(x, y) for CasADi scalars (SX/MX/DM); exact derivatives."""
        return self._z_fun(x, y)

    def f_T_ca(self, p_W: Any) -> Any:
        """f_T for a CasADi 3-vector in the world frame."""
        return p_W[2] - self._z_fun(p_W[0], p_W[1])

    def gradient_ca(self, p_W: Any) -> Any:
        """Gradient of f_T, (-dz/dx, -dz/dy, 1), for a CasADi 3-vector."""
        zx, zy = self._zgrad_fun(p_W[0], p_W[1])
        return ca.vertcat(-zx, -zy, 1.0)

    def normal_ca(self, p_W: Any) -> Any:
        """Pseudo-normal grad f_T / |grad f_T| for a CasADi 3-vector (section 4.5)."""
        g = self.gradient_ca(p_W)
        return g / ca.norm_2(g)


# ----------------------------------------------------------------------------------------
# Loading.


def terrains_dir() -> Path:
    """The folder of named terrains: $STRATAWALK_TERRAINS, else the repo's ``terrains/``."""
    env = os.environ.get("STRATAWALK_TERRAINS")
    if env:
        return Path(env).expanduser()
    return Path(planner.__file__).resolve().parents[1] / "terrains"


def list_terrains() -> list[str]:
    """Names of the terrains in :func:`terrains_dir` (``NAME.yaml`` files), sorted."""
    folder = terrains_dir()
    if not folder.is_dir():
        return []
    return sorted(p.stem for p in folder.glob("*.yaml"))


def _display(path: Path) -> str:
    """A path relative to the cwd when possible, for messages."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def load_terrain(name_or_path: str | Path) -> Terrain:
    """Load a terrain by name (``terrains/NAME.yaml``), generated name, YAML or mesh path.

    A generated course's name ``gen:SEED[:DIFFICULTY[:LENGTH[:KINDS]]]`` or a feature
    ladder's ``feat:KIND:SIZE`` (:mod:`planner.world.course_gen`) is drawn anew: the same name
    gives the same terrain. A ``.stl``, ``.obj`` or ``.ply`` path is a ``mesh`` terrain with
    every default (metres, z up, the mesh's xy bounds, 1 cm); a YAML of kind ``mesh`` sets them.

    Raises
    ------
    TerrainError
        Unknown name, unreadable file, bad YAML, or any malformed field.
    InputError
        A ``gen:`` name whose numbers are malformed or out of range.

    """
    text = str(name_or_path)
    if not isinstance(name_or_path, Path) and text.startswith(("gen:", "feat:")):
        from planner.world.course_gen import course_spec

        return Terrain.from_spec(course_spec(text), source=text)
    is_path = (
        isinstance(name_or_path, Path)
        or text.endswith((".yaml", ".yml"))
        or is_mesh_path(text)
        or "/" in text
        or os.sep in text
    )
    if is_path:
        path = Path(text).expanduser()
        if not path.is_file():
            raise _error(_display(path), "(file)", "no such terrain file; check the path")
        if is_mesh_path(path):
            spec = {"name": path.stem, "kind": "mesh", "file": str(path)}
            return Terrain(spec, source=_display(path))
    else:
        path = terrains_dir() / f"{text}.yaml"
        if not path.is_file():
            known = ", ".join(list_terrains()) or "none"
            raise _error(
                _display(path),
                "name",
                f"no terrain named {text!r}; use one of: {known}, or give a path to a .yaml file",
            )
    source = _display(path)
    try:
        data = yaml.load(path.read_text(), Loader=_YamlLoader)  # a SafeLoader
    except OSError as exc:
        raise _error(
            source, "(file)", f"cannot read it ({exc.strerror or exc}); check permissions"
        ) from exc
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise _error(source, "(file)", f"not valid YAML ({exc}); fix the syntax") from exc
    if not isinstance(data, Mapping):
        raise _error(source, "(top level)", f"expected a mapping of fields, got {_show(data)}")
    data = dict(data)
    data.setdefault("name", path.stem)
    return Terrain(data, source=source, base_dir=path.parent)
