"""The terrain kinds: features and reliefs, each a smooth height and its sharp original.

Flat, slope, step, stairs, gap, barrier, stepping stones, rough relief, rocks, logs,
height fields and meshes rasterised to height fields (fields in
:mod:`planner.world.terrain`'s docstring). ``expr`` is the smooth z (paper, section 4.4),
generic over the backends of :mod:`planner.world.terrain_backends` (local x = u); ``sharp``
the real, sharp-edged one the validator judges against.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from planner.world import heightfield as hf
from planner.world import mesh_terrain as mt
from planner.world.terrain_backends import (
    _CHUNK,
    _COMPLEX_STEP,
    CA,
    NP,
    _box,
    _box_sharp,
    _ramp,
    _sigmoid,
    _softplus,
)
from planner.world.terrain_spec import _REQUIRED, _Context, _Fields, _show

MAX_STONES = 5_000  # stepping stones in one field (each a term of the CasADi expression)
MAX_ROUGH_CELLS = 2e7  # the grid a rough relief's amplitude is scaled on (a tenth wavelength)
OFFSET_SETS_KEPT = 8  # offset sets whose e^{i k.d} a relief keeps (Rough.sharp_offsets)
_TANH_ONE = 25.0  # |x| beyond which tanh(x) is +-1 to the last bit (from 19.1 in float64)
_LOG_SQRT_EPS_M = 1e-6  # keeps sqrt differentiable where a log's height underflows to 0


class _Kind:
    """Base of the terrain kinds: smooth generic height, sharp height, numpy gradient."""

    kind = ""
    sharp_edges = False

    def __init__(self, f: _Fields, ctx: _Context):
        self.w = ctx.w
        self.spec: dict[str, Any] = {}

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """Smooth height at local (u, y) with backend ``ops``."""
        raise NotImplementedError

    def sharp(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Real (sharp-edged) height; equals the smooth one for kinds without edges."""
        return np.asarray(self.expr(u, y, NP), dtype=float) + 0.0 * u

    def value_np(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Smooth height, numpy."""
        return np.asarray(self.expr(u, y, NP), dtype=float) + 0.0 * u

    def sharp_offsets(
        self, u: np.ndarray, y: np.ndarray, du: np.ndarray, dy: np.ndarray
    ) -> np.ndarray:
        """(N, M) sharp heights at the N points (u, y) each moved by the M offsets (du, dy)."""
        return self.sharp(u[:, None] + du[None, :], y[:, None] + dy[None, :])

    sharp_grid = None  # (len(y), len(u)) heights on a grid, where a kind has a faster way

    def grad_np(self, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dz/dx, dz/dy) of the smooth height by complex-step differentiation (exact)."""
        return self.value_and_grad_np(u, y)[1:]

    def value_and_grad_np(self, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
        """(z, dz/dx, dz/dy) in two complex-step passes instead of three.

        The real part of the x pass is the height: z(u + ih) = z(u) - h^2 z''/2 + i h z',
        and h^2 = 1e-60 vanishes below rounding.
        """
        zx = self.expr(u + 1j * _COMPLEX_STEP, y + 0j, NP)
        hy = np.imag(self.expr(u + 0j, y + 1j * _COMPLEX_STEP, NP)) / _COMPLEX_STEP
        return np.real(zx) + 0.0 * u, np.imag(zx) / _COMPLEX_STEP + 0.0 * u, hy + 0.0 * u


class _Flat(_Kind):
    kind = "flat"

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """Zero."""
        return 0.0 * u


class _Slope(_Kind):
    kind = "slope"

    def __init__(self, f: _Fields, ctx: _Context):
        super().__init__(f, ctx)
        self.angle_deg = f.number("angle_deg", lo=-60.0, hi=60.0, hint="degrees, uphill > 0")
        self.direction_deg = f.number("direction_deg", 0.0)
        self.start = f.number("start", ctx.u0)
        self.ramp_length = f.number("ramp_length", None, lo=0.0, lo_open=True)
        self.spec = {
            "angle_deg": self.angle_deg,
            "direction_deg": self.direction_deg,
            "start": self.start,
            "ramp_length": self.ramp_length,
        }
        self.grade = math.tan(math.radians(self.angle_deg))
        self.c = math.cos(math.radians(self.direction_deg))
        self.s = math.sin(math.radians(self.direction_deg))
        self.sharp_edges = True

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """Grade times a smoothed clipped ramp along the direction."""
        d = u * self.c + y * self.s - self.start
        z = _ramp(d, self.w, ops)
        if self.ramp_length is not None:
            z = z - _ramp(d - self.ramp_length, self.w, ops)
        return self.grade * z

    def sharp(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Grade times the clipped ramp."""
        d = u * self.c + y * self.s - self.start
        hi = np.inf if self.ramp_length is None else self.ramp_length
        return self.grade * np.clip(d, 0.0, hi)


class _Step(_Kind):
    kind = "step"
    sharp_edges = True

    def __init__(self, f: _Fields, ctx: _Context):
        super().__init__(f, ctx)
        self.x = f.number("x", ctx.u0)
        self.height = f.number("height", lo=-1.0, hi=1.0, nonzero=True, hint="metres, up > 0")
        self.spec = {"x": self.x, "height": self.height}

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """The height times the smoothed Heaviside H_w(u - x)."""
        return self.height * _sigmoid(u - self.x, self.w, ops)

    def sharp(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The height for u >= x, else 0."""
        return np.where(u >= self.x, self.height, 0.0) + 0.0 * y


class _Stairs(_Kind):
    kind = "stairs"
    sharp_edges = True

    def __init__(self, f: _Fields, ctx: _Context):
        super().__init__(f, ctx)
        self.x_start = f.number("x_start", ctx.u0)
        self.rise = f.number("rise", lo=-0.5, hi=0.5, nonzero=True, hint="metres per step")
        self.run = f.number("run", lo=0.0, lo_open=True, hint="metres per step")
        self.count = f.integer("count", lo=1, hi=100)
        self.spec = {
            "x_start": self.x_start,
            "rise": self.rise,
            "run": self.run,
            "count": self.count,
        }
        self.edges = self.x_start + self.run * np.arange(self.count)

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """The rise times sum_k H_w(u - x_k)."""
        return self.rise * ops.vsum(_sigmoid(ops.bx(u) - ops.vec(self.edges), self.w, ops))

    def sharp(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The rise times the number of edges at or behind u."""
        n = np.searchsorted(self.edges, u, side="right")
        return self.rise * n + 0.0 * y


class _Gap(_Kind):
    kind = "gap"
    sharp_edges = True

    def __init__(self, f: _Fields, ctx: _Context):
        super().__init__(f, ctx)
        self.x_start = f.number("x_start", ctx.u0)
        self.width = f.number("width", lo=0.0, lo_open=True, hi=5.0, hint="metres along x")
        self.depth = f.number("depth", 0.2, lo=0.0, lo_open=True, hi=5.0)
        self.spec = {"x_start": self.x_start, "width": self.width, "depth": self.depth}

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """-depth on the smoothed [x_start, x_start + width)."""
        return -self.depth * _box(u, self.x_start, self.x_start + self.width, self.w, ops)

    def sharp(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """-depth on [x_start, x_start + width)."""
        return -self.depth * _box_sharp(u, self.x_start, self.x_start + self.width) + 0.0 * y


class _Barrier(_Kind):
    kind = "barrier"
    sharp_edges = True

    def __init__(self, f: _Fields, ctx: _Context):
        super().__init__(f, ctx)
        self.x = f.number("x", ctx.u0)
        self.height = f.number("height", lo=0.0, lo_open=True, hi=1.0)
        self.thickness = f.number("thickness", lo=0.0, lo_open=True, hi=5.0)
        self.spec = {"x": self.x, "height": self.height, "thickness": self.thickness}
        self.opening = f.pair("opening", None)
        if self.opening is not None:
            if self.opening[1] <= self.opening[0]:
                raise f.fail("opening", f"need [y0, y1] with y1 > y0, got {self.opening}")
            self.spec["opening"] = self.opening

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """The height on the smoothed [x, x + thickness), less the smoothed opening."""
        z = self.height * _box(u, self.x, self.x + self.thickness, self.w, ops)
        if self.opening is not None:
            z = z * (1.0 - _box(y, self.opening[0], self.opening[1], self.w, ops))
        return z

    def sharp(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The height on [x, x + thickness), zero in the opening."""
        z = self.height * _box_sharp(u, self.x, self.x + self.thickness) + 0.0 * y
        if self.opening is not None:
            z = z * (1.0 - _box_sharp(y, self.opening[0], self.opening[1]))
        return z


def _region(f: _Fields, ctx: _Context) -> tuple[float, float, float, float]:
    """Read ``x_start, x_end, y_start, y_end`` (defaults: the segment and course spans)."""
    x0 = f.number("x_start", ctx.u0)
    x1 = f.number("x_end", ctx.u1)
    y0 = f.number("y_start", ctx.y0)
    y1 = f.number("y_end", ctx.y1)
    if x1 <= x0:
        raise f.fail("x_end", f"must be > x_start ({x0}), got {x1}; change it")
    if y1 <= y0:
        raise f.fail("y_end", f"must be > y_start ({y0}), got {y1}; change it")
    return x0, x1, y0, y1


class _SteppingStones(_Kind):
    kind = "stepping_stones"
    sharp_edges = True

    def __init__(self, f: _Fields, ctx: _Context):
        super().__init__(f, ctx)
        x0, x1, y0, y1 = _region(f, ctx)
        self.size = f.number("size", lo=0.0, lo_open=True, hi=2.0, hint="stone side, metres")
        placed = f.has("stones")
        if placed and f.has("gap"):
            raise f.fail("gap", "give either 'gap' (a grid of stones) or 'stones', not both")
        self.gap = None if placed else f.number(
            "gap", lo=0.0, lo_open=True, hi=2.0, hint="metres between stones, or 'stones'"
        )  # fmt: skip
        self.height = f.number("height", 0.0, lo=-1.0, hi=1.0)
        self.height_jitter = f.number("height_jitter", 0.0, lo=0.0, hi=0.5)
        self.depth = f.number("depth", 0.1, lo=0.0, lo_open=True, hi=5.0)
        self.seed = f.integer("seed", 0, lo=0)
        self.spec = {
            "x_start": x0,
            "x_end": x1,
            "y_start": y0,
            "y_end": y1,
            "size": self.size,
            "gap": self.gap,
            "height": self.height,
            "height_jitter": self.height_jitter,
            "depth": self.depth,
            "seed": self.seed,
        }
        self.region = (x0, x1, y0, y1)
        if placed:
            self._place(f, ctx)
            return
        pitch = self.size + self.gap
        starts = []
        for key, lo, hi in (("x_end", x0, x1), ("y_max", y0, y1)):
            n = int(math.floor((hi - lo - self.gap) / pitch + 1e-9))
            if n < 1:
                raise f.fail(
                    key,
                    f"region {hi - lo:.3g} m holds no stone of size {self.size} "
                    f"plus gap {self.gap}; enlarge the region or shrink the stones",
                )
            span = n * self.size + (n - 1) * self.gap
            starts.append(lo + 0.5 * (hi - lo - span) + pitch * np.arange(n))
        self.xa, self.ya = starts
        nx, ny = self.xa.size, self.ya.size
        if nx * ny > MAX_STONES:
            raise f.fail(
                "size",
                f"{nx} x {ny} = {nx * ny} stones; at most {MAX_STONES} (each is a term of the "
                "terrain's expression): larger stones or gaps, or a smaller region",
            )
        rng = np.random.default_rng(self.seed)
        tops = self.height + self.height_jitter * rng.uniform(-1.0, 1.0, (ny, nx))
        self.iy, self.ix = (
            a.ravel() for a in np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
        )
        self.tops = tops.ravel()
        self.rise = self.tops + self.depth
        self.placed = False

    def _place(self, f: _Fields, ctx: _Context) -> None:
        """Hand-placed stones from ``stones``: [x, y] centres or [x, y, top].

        Tops at ``height`` + jitter unless given; x relative to a course segment's start,
        as ``x_start``. Stones must lie inside the pit and not overlap.
        """
        rows = f.raw("stones")
        hint = "a list of [x, y] or [x, y, top] stone centres in metres"
        if not isinstance(rows, (list, tuple)) or not rows:
            raise f.fail("stones", f"expected {hint}, got {_show(rows)}")
        if len(rows) > MAX_STONES:
            raise f.fail("stones", f"{len(rows)} stones; at most {MAX_STONES}")
        x0, x1, y0, y1 = self.region
        rng = np.random.default_rng(self.seed)
        jitter = self.height_jitter * rng.uniform(-1.0, 1.0, len(rows))
        centres, tops = [], []
        for i, row in enumerate(rows):
            ok = isinstance(row, (list, tuple)) and len(row) in (2, 3)
            if ok:
                ok = all(
                    not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
                    for v in row
                )
            if not ok:
                raise f.fail(f"stones[{i}]", f"expected [x, y] or [x, y, top], got {_show(row)}")
            cx, cy = float(row[0]), float(row[1])
            h = self.size / 2
            if not (x0 <= cx - h and cx + h <= x1 and y0 <= cy - h and cy + h <= y1):
                raise f.fail(
                    f"stones[{i}]",
                    f"stone at [{cx}, {cy}] (side {self.size}) is not inside the pit "
                    f"x {x0}..{x1}, y {y0}..{y1}; move it or widen x_start..x_end, y_start..y_end",
                )
            centres.append((cx, cy))
            tops.append(float(row[2]) if len(row) == 3 else self.height + float(jitter[i]))
        c = np.array(centres)
        order = np.argsort(c[:, 0], kind="stable")  # a sweep along x, not an S x S table
        xs = c[order, 0]
        ends = np.searchsorted(xs, xs + self.size, side="left")
        for a, (i, end) in enumerate(zip(order, ends, strict=True)):
            later = order[a + 1 : end]
            hit = later[np.abs(c[later, 1] - c[i, 1]) < self.size]
            if hit.size:
                j, k = sorted((int(i), int(hit[0])))
                raise f.fail(
                    f"stones[{k}]",
                    f"overlaps stones[{j}] (stones of side {self.size} must not overlap); move it",
                )
        del self.spec["gap"]
        self.spec["stones"] = [list(map(float, r)) for r in rows]
        self.xa, self.ya = c[:, 0] - self.size / 2, c[:, 1] - self.size / 2
        self.ix = self.iy = np.arange(len(c))
        self.tops = np.array(tops)
        self.rise = self.tops + self.depth
        self.placed = True

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """Smoothed pit plus separable smoothed stone boxes."""
        x0, x1, y0, y1 = self.region
        w = self.w
        pit = _box(u, x0, x1, w, ops) * _box(y, y0, y1, w, ops)
        bxu, byv = ops.bx(u), ops.bx(y)
        wx = _box(bxu, ops.vec(self.xa), ops.vec(self.xa + self.size), w, ops)
        wy = _box(byv, ops.vec(self.ya), ops.vec(self.ya + self.size), w, ops)
        stones = ops.vsum(ops.take(wx, self.ix) * ops.take(wy, self.iy) * ops.vec(self.rise))
        return stones - self.depth * pit

    def sharp(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """-depth in the pit, the stone's top on a stone, 0 outside."""
        x0, x1, y0, y1 = self.region
        z = -self.depth * _box_sharp(u, x0, x1) * _box_sharp(y, y0, y1)
        if self.placed:  # the highest stone under each point, points by the chunk
            uf, yf = (a.reshape(-1) for a in np.broadcast_arrays(np.asarray(u, float), y))
            top = np.full(uf.shape, -np.inf)
            rows = max(1, _CHUNK // self.tops.size)
            for i in range(0, uf.size, rows):
                uu, yy = uf[i : i + rows, None], yf[i : i + rows, None]
                on = (uu >= self.xa) & (uu < self.xa + self.size)
                on &= (yy >= self.ya) & (yy < self.ya + self.size)
                top[i : i + rows] = np.where(on, self.tops, -np.inf).max(axis=-1)
            top = top.reshape(np.shape(z))
            return np.where(np.isfinite(top), top, z)
        i = np.searchsorted(self.xa, u, side="right") - 1
        j = np.searchsorted(self.ya, y, side="right") - 1
        ic, jc = np.clip(i, 0, None), np.clip(j, 0, None)
        on = (i >= 0) & (j >= 0) & (u < self.xa[ic] + self.size) & (y < self.ya[jc] + self.size)
        top = self.tops.reshape(self.ya.size, self.xa.size)[jc, ic]
        return np.where(on, top, z)


class _Rough(_Kind):
    kind = "rough"

    def __init__(self, f: _Fields, ctx: _Context):
        super().__init__(f, ctx)
        self.amplitude = f.number("amplitude", lo=0.0, lo_open=True, hi=1.0, hint="metres")
        self.wavelength = f.number("wavelength", lo=0.01, hi=10.0, hint="shortest, metres")
        self.wavelength_max = f.number(
            "wavelength_max", 4.0 * self.wavelength, lo=self.wavelength, hi=100.0
        )
        self.terms = f.integer("terms", 40, lo=1, hi=60)
        self.seed = f.integer("seed", 0, lo=0)
        self.x_start = f.number("x_start", ctx.u0)
        self.x_end = f.number("x_end", ctx.u1)
        self.taper = f.number("taper", 0.1, lo=0.0, lo_open=True)
        if self.x_end - self.x_start < self.taper:
            raise f.fail(
                "x_end",
                f"must be >= x_start + taper ({self.x_start + self.taper}), "
                f"got {self.x_end}; change it",
            )
        self.spec = {
            "amplitude": self.amplitude,
            "wavelength": self.wavelength,
            "wavelength_max": self.wavelength_max,
            "terms": self.terms,
            "seed": self.seed,
            "x_start": self.x_start,
            "x_end": self.x_end,
            "taper": self.taper,
        }
        rng = np.random.default_rng(self.seed)
        freq = rng.uniform(1.0 / self.wavelength_max, 1.0 / self.wavelength, self.terms)
        theta = rng.uniform(0.0, math.pi, self.terms)
        self.phase = rng.uniform(0.0, 2.0 * math.pi, self.terms)
        self.kx = 2.0 * math.pi * freq * np.cos(theta)
        self.ky = 2.0 * math.pi * freq * np.sin(theta)
        self.a = 1.0 / freq
        step = self.wavelength / 10.0
        cells = ((self.x_end - self.x_start) / step + 1) * ((ctx.y1 - ctx.y0) / step + 1)
        if cells > MAX_ROUGH_CELLS:
            raise f.fail(
                "wavelength",
                f"{self.wavelength} m over a {self.x_end - self.x_start:.3g} x "
                f"{ctx.y1 - ctx.y0:.3g} m region is {cells:.3g} cells of a tenth wavelength "
                f"to scale the relief on; at most {MAX_ROUGH_CELLS:.0e}: a longer wavelength "
                "or a smaller region",
            )
        gx = np.arange(self.x_start, self.x_end + 0.5 * step, step)
        gy = np.arange(ctx.y0, ctx.y1 + 0.5 * step, step)
        peak = max(float(np.max(np.abs(self._relief(gx[:, None], row, NP)))) for row in gy)
        self.a = self.a * (self.amplitude / peak)

    def _relief(self, u: Any, y: Any, ops: Any) -> Any:
        arg = ops.bx(u) * ops.vec(self.kx) + ops.bx(y) * ops.vec(self.ky) + ops.vec(self.phase)
        return ops.vsum(ops.vec(self.a) * ops.cos(arg))

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """Tapered sum of cosines."""
        return self._window(u, ops) * self._relief(u, y, ops)

    def sharp(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The relief has no edges: :meth:`expr` in numpy, the same numbers, in place."""
        u, y = np.broadcast_arrays(np.asarray(u, float), np.asarray(y, float))
        arg = u[..., None] * self.kx
        arg += y[..., None] * self.ky
        arg += self.phase
        np.cos(arg, out=arg)
        arg *= self.a
        relief = np.sum(arg, axis=-1)
        if self._inside_taper(u):
            return relief + 0.0 * u
        return self._window(u, NP) * relief + 0.0 * u

    value_np = sharp

    def _window(self, u: Any, ops: Any) -> Any:
        s = self.taper / 6.0
        h = 0.5 * self.taper
        if ops is NP and self._inside_taper(u):
            return np.ones(np.shape(u))
        return _sigmoid(u - (self.x_start + h), s, ops) - _sigmoid(u - (self.x_end - h), s, ops)

    def _inside_taper(self, u: Any) -> bool:
        """Whether every real u is where the window is exactly 1 (tanh rounds to +-1 there)."""
        u = np.asarray(u)
        if u.size == 0 or np.iscomplexobj(u):
            return False
        s = self.taper / 6.0
        h = 0.5 * self.taper
        return bool(
            (float(u.min()) - (self.x_start + h)) / s > _TANH_ONE
            and (float(u.max()) - (self.x_end - h)) / s < -_TANH_ONE
        )

    def grad_np(self, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dz/dx, dz/dy), analytic.

        One complex exponential per term instead of the complex step's two complex cosines.
        """
        return self.value_and_grad_np(u, y)[1:]

    def value_and_grad_np(self, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
        """(z, dz/dx, dz/dy) from one complex exponential per term."""
        u, y = np.broadcast_arrays(np.asarray(u, float), np.asarray(y, float))
        e = np.exp(1j * (u[..., None] * self.kx + y[..., None] * self.ky + self.phase))
        relief = e.real @ self.a
        d_x = -(e.imag @ (self.a * self.kx))
        d_y = -(e.imag @ (self.a * self.ky))
        s = self.taper / 6.0
        h = 0.5 * self.taper
        t0, t1 = np.tanh((u - (self.x_start + h)) / s), np.tanh((u - (self.x_end - h)) / s)
        window = 0.5 * (t0 - t1)
        d_window = 0.5 * ((1.0 - t0 * t0) - (1.0 - t1 * t1)) / s
        return window * relief, d_window * relief + window * d_x, window * d_y

    def sharp_offsets(
        self, u: np.ndarray, y: np.ndarray, du: np.ndarray, dy: np.ndarray
    ) -> np.ndarray:
        """(N, M) heights at (u + du, y + dy).

        cos(a + b) = Re(e^{ia} e^{ib}): a product of an (N, terms) and a (terms, M) matrix
        instead of N M terms cosines.
        """
        arg = u[:, None] * self.kx + y[:, None] * self.ky + self.phase
        at = np.empty(arg.shape, complex)  # e^{i arg}: cos and sin, cheaper than exp(1j arg)
        np.cos(arg, out=at.real)
        np.sin(arg, out=at.imag)
        at *= self.a
        relief = (at @ self._offset_factors(du, dy).T).real
        return self._window(u[:, None] + du[None, :], NP) * relief

    def sharp_grid(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(len(y), len(u)) heights on a grid: cos(a + b) = Re(e^{ia} e^{ib}) again.

        The x and y factors are one complex exponential per node and term, their product
        a matrix product (equal to :meth:`sharp` to rounding, ~1e-16 of the amplitude).
        """
        ex = np.exp(1j * (u[:, None] * self.kx))
        ey = np.exp(1j * (y[:, None] * self.ky + self.phase)) * self.a
        return self._window(u, NP)[None, :] * (ey @ ex.T).real

    def _offset_factors(self, du: np.ndarray, dy: np.ndarray) -> np.ndarray:
        """(M, terms) e^{i k.d} of the offsets, kept for the offset sets asked last.

        The callers ask again and again with the same few sets (a disc, a grid).
        """
        key = (np.ascontiguousarray(du).tobytes(), np.ascontiguousarray(dy).tobytes())
        kept = self.__dict__.setdefault("_offsets_kept", {})
        by = kept.get(key)
        if by is None:
            by = np.exp(1j * (du[:, None] * self.kx + dy[:, None] * self.ky))
            if len(kept) >= OFFSET_SETS_KEPT:
                kept.clear()
            kept[key] = by
        return by


class _Rocks(_Kind):
    kind = "rocks"

    def __init__(self, f: _Fields, ctx: _Context):
        super().__init__(f, ctx)
        x0, x1, y0, y1 = _region(f, ctx)
        self.count = f.integer("count", 30, lo=1, hi=200)
        hmin = f.number("height_min", 0.01, lo=0.0, lo_open=True, hi=0.5)
        hmax = f.number("height_max", 0.04, lo=hmin, hi=0.5)
        rmin = f.number("radius_min", 0.03, lo=0.005, hi=1.0, hint="Gaussian std dev, metres")
        rmax = f.number("radius_max", 0.07, lo=rmin, hi=1.0)
        self.seed = f.integer("seed", 0, lo=0)
        self.spec = {
            "x_start": x0,
            "x_end": x1,
            "y_start": y0,
            "y_end": y1,
            "count": self.count,
            "height_min": hmin,
            "height_max": hmax,
            "radius_min": rmin,
            "radius_max": rmax,
            "seed": self.seed,
        }
        margin = 3.0 * rmax
        if x1 - x0 <= 2 * margin or y1 - y0 <= 2 * margin:
            raise f.fail(
                "radius_max",
                f"region {x1 - x0:.3g} x {y1 - y0:.3g} m is too small for "
                f"rocks of radius {rmax} (needs > 6 radii); shrink them",
            )
        rng = np.random.default_rng(self.seed)
        rocks: list[tuple[float, ...]] = []
        tries = 0
        while len(rocks) < self.count:
            tries += 1
            if tries > 500 * self.count:
                raise f.fail(
                    "count",
                    f"only {len(rocks)} rocks fit apart in the region; lower count or radius_max",
                )
            ra, rb = rng.uniform(rmin, rmax, 2)
            cx = rng.uniform(x0 + margin, x1 - margin)
            cy = rng.uniform(y0 + margin, y1 - margin)
            r = max(ra, rb)
            if all(math.hypot(cx - o[0], cy - o[1]) >= r + o[5] for o in rocks):
                rocks.append(
                    (cx, cy, rng.uniform(hmin, hmax), ra, rb, r, rng.uniform(0.0, math.pi))
                )
        arr = np.array(rocks)
        self.cx, self.cy, self.h = arr[:, 0], arr[:, 1], arr[:, 2]
        self.inv_a2, self.inv_b2 = 1.0 / arr[:, 3] ** 2, 1.0 / arr[:, 4] ** 2
        self.cos, self.sin = np.cos(arr[:, 6]), np.sin(arr[:, 6])

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """Sum of rotated elliptic Gaussians."""
        dx = ops.bx(u) - ops.vec(self.cx)
        dy = ops.bx(y) - ops.vec(self.cy)
        p = dx * ops.vec(self.cos) + dy * ops.vec(self.sin)
        q = dy * ops.vec(self.cos) - dx * ops.vec(self.sin)
        e = p * p * ops.vec(self.inv_a2) + q * q * ops.vec(self.inv_b2)
        return ops.vsum(ops.vec(self.h) * ops.exp(-0.5 * e))


class _Logs(_Kind):
    kind = "logs"
    sharp_edges = True

    def __init__(self, f: _Fields, ctx: _Context):
        super().__init__(f, ctx)
        self.x_start = f.number("x_start", ctx.u0, hint="x of the first log's axis")
        self.spacing = f.number("spacing", lo=0.0, lo_open=True, hint="metres between axes")
        self.count = f.integer("count", lo=1, hi=100)
        self.radius = f.number("radius", lo=0.0, lo_open=True, hi=1.0)
        self.radius_jitter = f.number("radius_jitter", 0.0, lo=0.0)
        self.yaw_jitter_deg = f.number("yaw_jitter_deg", 0.0, lo=0.0, hi=45.0)
        self.seed = f.integer("seed", 0, lo=0)
        if self.radius_jitter >= self.radius:
            raise f.fail("radius_jitter", f"must be < radius ({self.radius}); lower it")
        if self.spacing <= 2.0 * (self.radius + self.radius_jitter):
            raise f.fail(
                "spacing",
                f"must exceed 2 * (radius + radius_jitter) = "
                f"{2 * (self.radius + self.radius_jitter):.4g} so logs do not overlap",
            )
        self.spec = {
            "x_start": self.x_start,
            "spacing": self.spacing,
            "count": self.count,
            "radius": self.radius,
            "radius_jitter": self.radius_jitter,
            "yaw_jitter_deg": self.yaw_jitter_deg,
            "seed": self.seed,
        }
        rng = np.random.default_rng(self.seed)
        self.r = self.radius + self.radius_jitter * rng.uniform(-1.0, 1.0, self.count)
        yaw = np.radians(self.yaw_jitter_deg * rng.uniform(-1.0, 1.0, self.count))
        self.c = self.x_start + self.spacing * np.arange(self.count)
        self.cos, self.sin = np.cos(yaw), np.sin(yaw)
        self.eps = 0.5 * self.r * self.w  # far field decays like exp(-2 d / w), as a step

    def _d(self, u: Any, y: Any, ops: Any) -> Any:
        return (ops.bx(u) - ops.vec(self.c)) * ops.vec(self.cos) + ops.bx(y) * ops.vec(self.sin)

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """Sum of sqrt(softplus(R^2 - d^2)) half-cylinder profiles."""
        d = self._d(u, y, ops)
        v = _softplus(ops.vec(self.r**2) - d * d, ops.vec(self.eps), ops)
        return ops.vsum(ops.sqrt(v + _LOG_SQRT_EPS_M**2) - _LOG_SQRT_EPS_M)

    def sharp(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Sum of sqrt(max(R^2 - d^2, 0))."""
        d = self._d(u, y, NP)
        return np.sum(np.sqrt(np.maximum(self.r**2 - d * d, 0.0)), axis=-1)


class _Heightfield(_Kind):
    kind = "heightfield"

    def __init__(self, f: _Fields, ctx: _Context):
        super().__init__(f, ctx)
        source = f.source
        if f.has("file") == f.has("heights"):
            raise f.fail(
                "file",
                "give exactly one of 'file' (a .npy/.csv/.png path) and "
                "'heights' (an inline list of rows)",
            )
        file_origin = file_res = None
        spec: dict[str, Any] = {}
        if f.has("file"):
            name = f.string("file")
            path = Path(name).expanduser()
            if not path.is_absolute():
                path = (ctx.base_dir or Path.cwd()) / path
            raw, file_origin, file_res = hf.read_height_file(path, source, f.path("file"))
            spec["file"] = str(path.resolve())
        else:
            rows = f.raw("heights")
            try:
                raw = np.array(rows, dtype=float)
            except (TypeError, ValueError) as exc:
                raise f.fail(
                    "heights", f"expected a list of equal-length rows of numbers ({exc})"
                ) from exc
            raw = hf.as_grid(raw, source, f.path("heights"), "inline heights")
            spec["heights"] = raw.tolist()
        is_png = "file" in spec and spec["file"].lower().endswith(".png")
        mpu = f.number(
            "metres_per_unit",
            _REQUIRED if is_png else 1.0,
            lo=0.0,
            lo_open=True,
            hint="metres per raw unit, e.g. 0.0001",
        )
        offset = f.number("offset", 0.0)
        res = f.number(
            "resolution",
            file_res if file_res is not None else _REQUIRED,
            lo=0.0,
            lo_open=True,
            hint="metres between nodes",
        )
        origin = f.pair("origin", list(file_origin) if file_origin is not None else _REQUIRED)
        if file_res is not None:
            if abs(res - file_res) > 1e-9 * max(file_res, 1.0):
                raise f.fail(
                    "resolution",
                    f"inconsistent resolution: {res} given, but the "
                    f"file's coordinates are {file_res:.9g} apart; remove or fix it",
                )
            if max(abs(origin[0] - file_origin[0]), abs(origin[1] - file_origin[1])) > 1e-9:
                raise f.fail(
                    "origin",
                    f"{origin} given, but the file's first node is at "
                    f"{list(file_origin)}; remove or fix it",
                )
        heights = raw * mpu + offset
        hf.check_finite(heights, source, f.path("file" if "file" in spec else "heights"))
        spec.update({"origin": origin, "resolution": res, "metres_per_unit": mpu, "offset": offset})
        self.spec = spec
        self._fit(heights, origin, res)

    def _fit(self, heights: np.ndarray, origin: list[float], res: float) -> None:
        """Fit the B-spline through ``heights[iy][ix]`` [m] at ``origin + (ix, iy) * res``."""
        self.heights = heights
        self.origin, self.resolution = origin, res
        ny, nx = heights.shape
        self.extent = (origin[0], origin[0] + (nx - 1) * res, origin[1], origin[1] + (ny - 1) * res)
        self.fun, self.clamp = hf.build_interpolant(heights, origin, res)
        xs, ys = ca.SX.sym("x"), ca.SX.sym("y")
        z = self.expr(xs, ys, CA)
        self._eval = ca.Function(
            "heightfield_z", [xs, ys], [z, ca.gradient(z, xs), ca.gradient(z, ys)]
        )

    def expr(self, u: Any, y: Any, ops: Any) -> Any:
        """The B-spline at the point clamped to the padded grid."""
        if ops is NP:
            return self.value_np(np.real(u), np.real(y))
        x0, x1, y0, y1 = self.clamp
        return self.fun(ca.vertcat(ca.fmin(ca.fmax(u, x0), x1), ca.fmin(ca.fmax(y, y0), y1)))

    def _call(self, u: np.ndarray, y: np.ndarray) -> list[np.ndarray]:
        u, y = np.broadcast_arrays(np.asarray(u, float), np.asarray(y, float))
        if u.size == 0:
            return [np.zeros(u.shape)] * 3
        out = self._eval(u.reshape(1, -1), y.reshape(1, -1))
        return [np.asarray(o).reshape(u.shape) for o in out]

    def value_np(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The same CasADi B-spline, evaluated numerically (on 2 x N points: 10x faster)."""
        u, y = np.broadcast_arrays(np.asarray(u, float), np.asarray(y, float))
        if u.size == 0:
            return np.zeros(u.shape)
        x0, x1, y0, y1 = self.clamp  # fmin/fmax: NaN handled as ca.fmin/ca.fmax do
        xy = np.vstack([u.reshape(-1), y.reshape(-1)])
        xy = np.fmin(np.fmax(xy, [[x0], [y0]]), [[x1], [y1]])
        return np.asarray(self.fun(xy)).reshape(u.shape)

    def sharp(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The B-spline through the samples is the terrain itself."""
        return self.value_np(u, y)

    def grad_np(self, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """CasADi's exact derivatives of the B-spline."""
        _, zx, zy = self._call(u, y)
        return zx, zy

    def value_and_grad_np(self, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
        """Height and derivatives of the B-spline in one CasADi call."""
        z, zx, zy = self._call(u, y)
        return z, zx, zy


class _Mesh(_Heightfield):
    """An STL, OBJ or PLY surface rasterised to a height field (:mod:`~planner.world.mesh_terrain`).

    The normalised spec holds the rasterised grid (``heights``), so that it rebuilds the
    terrain (a plan file is checked) without the mesh; given, ``heights`` is used as it is
    and ``file`` only names where it came from.
    """

    kind = "mesh"

    def __init__(self, f: _Fields, ctx: _Context):
        _Kind.__init__(self, f, ctx)
        if not f.has("file") and not f.has("heights"):
            raise f.fail("file", "missing; give the mesh file (.stl, .obj or .ply)")
        mpu = f.number(
            "metres_per_unit", 1.0, lo=0.0, lo_open=True, hint="e.g. 0.001 for a mesh in mm"
        )
        up = f.string("up", "z")
        if up not in ("z", "y"):
            raise f.fail("up", f"expected 'z' or 'y' (the file's up axis), got {_show(up)}")
        offset = f.numbers("offset", 3, [0.0, 0.0, 0.0], "[dx, dy, dz] in metres")
        region = f.numbers("region", 4, None, "[x0, x1, y0, y1] in metres")
        if region is not None and not (region[1] > region[0] and region[3] > region[2]):
            raise f.fail("region", f"need x0 < x1 and y0 < y1, got {region}; fix the order")
        res = f.number("resolution", None, lo=1e-4, hi=1.0, hint="metres between nodes")
        spec: dict[str, Any] = {}
        path = None
        if f.has("file"):
            path = Path(f.string("file")).expanduser()
            if not path.is_absolute():
                path = (ctx.base_dir or Path.cwd()) / path
            spec["file"] = str(path.resolve())
        if f.has("heights"):
            if region is None or res is None:
                raise f.fail("heights", "needs 'region' and 'resolution' (the grid's placement)")
            heights = self._inline(f, region, res)
        else:
            grid = mt.mesh_heights(
                path,
                f.source,
                f.prefix,
                metres_per_unit=mpu,
                up=up,
                offset=offset,
                region=region,
                resolution=res,
            )
            heights, region, res = grid.heights, list(grid.region), grid.resolution
        spec.update(
            {
                "metres_per_unit": mpu,
                "up": up,
                "offset": offset,
                "region": [float(r) for r in region],
                "resolution": float(res),
                "heights": heights.tolist(),
            }
        )
        self.spec = spec
        self._fit(heights, [float(region[0]), float(region[2])], float(res))

    @staticmethod
    def _inline(f: _Fields, region: list[float], res: float) -> np.ndarray:
        """The ``heights`` of a normalised spec, checked against its region and resolution."""
        try:
            raw = np.array(f.raw("heights"), dtype=float)
        except (TypeError, ValueError) as exc:
            raise f.fail("heights", f"expected a list of equal-length rows ({exc})") from exc
        heights = hf.as_grid(raw, f.source, f.path("heights"), "inline heights")
        want = mt.grid_shape(region, res)
        if heights.shape != want:
            raise f.fail(
                "heights",
                f"has {heights.shape[0]} x {heights.shape[1]} rows x columns, but region "
                f"{region} at {res:g} m needs {want[0]} x {want[1]}; rasterise the mesh again",
            )
        hf.check_finite(heights, f.source, f.path("heights"))
        return heights


KINDS: dict[str, type[_Kind]] = {
    k.kind: k
    for k in (
        _Flat,
        _Slope,
        _Step,
        _Stairs,
        _Gap,
        _Barrier,
        _SteppingStones,
        _Rough,
        _Rocks,
        _Logs,
        _Heightfield,
        _Mesh,
    )
}
