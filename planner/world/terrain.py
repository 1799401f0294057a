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
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import yaml

import planner
from planner.core.errors import TerrainError
from planner.world import heightfield as hf

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
MAX_STONES = 5_000  # stepping stones in one field (each a term of the CasADi expression)
MAX_ROUGH_CELLS = 2e7  # the grid a rough relief's amplitude is scaled on (a tenth wavelength)
DEFAULT_Y_MAX = 0.6
_COMPLEX_STEP = 1e-30
_CHUNK = 20000
_LOG_SQRT_EPS_M = 1e-6  # keeps sqrt differentiable where a log's height underflows to 0

# ----------------------------------------------------------------------------------------
# Backends: one expression per kind, evaluated with numpy (real or complex step) or CasADi.


class _NumpyOps:
    """Numpy operations, safe for complex-step differentiation (no abs/max on complex)."""

    tanh = staticmethod(np.tanh)
    exp = staticmethod(np.exp)
    sin = staticmethod(np.sin)
    cos = staticmethod(np.cos)
    sqrt = staticmethod(np.sqrt)
    log1p = staticmethod(np.log1p)

    @staticmethod
    def fabs(a: Any) -> Any:
        """|a| by the sign of the real part (keeps the complex-step derivative)."""
        return np.where(np.real(a) >= 0.0, a, -a)

    @staticmethod
    def pos(a: Any) -> Any:
        """max(a, 0) by the sign of the real part."""
        return np.where(np.real(a) >= 0.0, a, 0.0 * a)

    @staticmethod
    def bx(a: Any) -> Any:
        """Make a point array broadcast against a vector of terms (new last axis)."""
        return np.asarray(a)[..., None]

    @staticmethod
    def vec(v: Any) -> np.ndarray:
        """A constant vector of terms."""
        return np.asarray(v, dtype=float)

    @staticmethod
    def vsum(a: Any) -> Any:
        """Sum over the terms axis."""
        return np.sum(a, axis=-1)

    @staticmethod
    def take(a: Any, idx: np.ndarray) -> Any:
        """Select terms."""
        return a[..., idx]


class _CasadiOps:
    """CasADi operations on scalar SX/MX points; vectors of terms are columns."""

    tanh = staticmethod(ca.tanh)
    exp = staticmethod(ca.exp)
    sin = staticmethod(ca.sin)
    cos = staticmethod(ca.cos)
    sqrt = staticmethod(ca.sqrt)
    log1p = staticmethod(ca.log1p)
    fabs = staticmethod(ca.fabs)

    @staticmethod
    def pos(a: Any) -> Any:
        """max(a, 0)."""
        return ca.fmax(a, 0.0)

    @staticmethod
    def bx(a: Any) -> Any:
        """A scalar already broadcasts against a column."""
        return a

    @staticmethod
    def vec(v: Any) -> ca.DM:
        """A constant column of terms."""
        return ca.DM(np.asarray(v, dtype=float).reshape(-1))

    @staticmethod
    def vsum(a: Any) -> Any:
        """Sum of a column."""
        return ca.sum1(a)

    @staticmethod
    def take(a: Any, idx: np.ndarray) -> Any:
        """Select entries of a column."""
        return a[[int(i) for i in idx]]


NP = _NumpyOps()
CA = _CasadiOps()


def _sigmoid(u: Any, w: float, ops: Any) -> Any:
    """Smooth unit step (1 + tanh(u / w)) / 2, the smoothed Heaviside H(u)."""
    return 0.5 * (1.0 + ops.tanh(u / w))


def _ramp(u: Any, w: float, ops: Any) -> Any:
    """Integral of :func:`_sigmoid`: (w/2) log(1 + exp(2u/w)), written without overflow."""
    return ops.pos(u) + 0.5 * w * ops.log1p(ops.exp(-2.0 * ops.fabs(u) / w))


def _softplus(v: Any, eps: Any, ops: Any) -> Any:
    """Softplus eps * log(1 + exp(v / eps)), written without overflow."""
    return ops.pos(v) + eps * ops.log1p(ops.exp(-ops.fabs(v) / eps))


def _box(u: Any, a: Any, b: Any, w: float, ops: Any) -> Any:
    """Smoothed indicator of [a, b)."""
    return _sigmoid(u - a, w, ops) - _sigmoid(u - b, w, ops)


def _box_sharp(u: np.ndarray, a: Any, b: Any) -> np.ndarray:
    """Indicator of [a, b)."""
    return ((u >= a) & (u < b)).astype(float)


# ----------------------------------------------------------------------------------------
# Spec validation.

_REQUIRED = object()


def _one_line(text: str) -> str:
    """Collapse whitespace (including newlines) to single spaces."""
    return " ".join(str(text).split())


def _error(source: str, field: str, message: str) -> TerrainError:
    """A one-line error naming the file and the field."""
    return TerrainError(_one_line(f"{source}: field '{field}': {message}"))


class _YamlLoader(yaml.SafeLoader):
    """PyYAML's safe loader (YAML 1.1), reading YAML 1.2's floats too.

    ``1e9`` and ``1.0e9`` are numbers (YAML 1.1 wants a dot and a signed exponent,
    ``1.0e+9``, and reads them as strings).
    """


_YamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def _show(value: Any) -> str:
    """Short repr of a bad value for an error message."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


class _Fields:
    """Typed, range-checked access to one mapping of a spec; records which keys were used."""

    def __init__(self, data: Any, source: str, prefix: str, what: str = "a mapping"):
        if not isinstance(data, Mapping):
            raise _error(
                source, prefix.rstrip(".") or "(top level)", f"expected {what}, got {_show(data)}"
            )
        self.data = dict(data)
        self.source = source
        self.prefix = prefix
        self.used: set[str] = set()

    def path(self, key: str) -> str:
        """Dotted field path for messages."""
        return f"{self.prefix}{key}"

    def fail(self, key: str, message: str) -> TerrainError:
        """Error about ``key``."""
        return _error(self.source, self.path(key), message)

    def has(self, key: str) -> bool:
        """Whether ``key`` was given (and not null)."""
        return self.data.get(key) is not None

    def raw(self, key: str, default: Any = _REQUIRED, hint: str = "") -> Any:
        """The value of ``key``, or ``default``; missing required keys raise."""
        self.used.add(key)
        value = self.data.get(key)
        if value is None:
            if default is _REQUIRED:
                raise self.fail(key, f"missing; add it{(' (' + hint + ')') if hint else ''}")
            return default
        return value

    def number(
        self,
        key: str,
        default: Any = _REQUIRED,
        *,
        lo: float | None = None,
        hi: float | None = None,
        lo_open: bool = False,
        nonzero: bool = False,
        hint: str = "a number",
    ) -> float:
        """A finite float in [lo, hi] (or (lo, hi] with ``lo_open``)."""
        value = self.raw(key, default, hint)
        if value is None:
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            numeric = isinstance(value, str) and any(c.isdigit() for c in value)
            hint = "; write it as a plain number, e.g. 0.25 or 1e3" * numeric
            raise self.fail(key, f"expected a number, got {_show(value)}{hint}")
        value = float(value)
        if not math.isfinite(value):
            raise self.fail(key, f"expected a finite number, got {value}")
        if lo is not None and (value < lo or (lo_open and value == lo)):
            bound = f"> {lo}" if lo_open else f">= {lo}"
            raise self.fail(key, f"must be {bound}, got {value}; change it")
        if hi is not None and value > hi:
            raise self.fail(key, f"must be <= {hi}, got {value}; change it")
        if nonzero and value == 0.0:
            raise self.fail(key, "must not be 0; give a non-zero value")
        return value

    def integer(
        self, key: str, default: Any = _REQUIRED, *, lo: int | None = None, hi: int | None = None
    ) -> int:
        """An integer in [lo, hi]."""
        value = self.raw(key, default, "an integer")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value != int(value):
            raise self.fail(key, f"expected an integer, got {_show(value)}")
        value = int(value)
        if lo is not None and value < lo:
            raise self.fail(key, f"must be >= {lo}, got {value}; change it")
        if hi is not None and value > hi:
            raise self.fail(key, f"must be <= {hi}, got {value}; change it")
        return value

    def string(self, key: str, default: Any = _REQUIRED) -> str:
        """A string."""
        value = self.raw(key, default, "a string")
        if not isinstance(value, str):
            raise self.fail(key, f"expected a string, got {_show(value)}")
        return value

    def pair(self, key: str, default: Any = _REQUIRED) -> list[float] | None:
        """Two finite numbers ``[a, b]``."""
        value = self.raw(key, default, "[x, y] in metres")
        if value is None:
            return None
        if (
            not isinstance(value, (list, tuple))
            or len(value) != 2
            or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in value
            )
        ):
            raise self.fail(key, f"expected [x, y] (two finite numbers), got {_show(value)}")
        return [float(value[0]), float(value[1])]

    def finish(self, known: Sequence[str] | None = None) -> None:
        """Reject any key that was not read."""
        extra = sorted(set(self.data) - self.used)
        if extra:
            names = ", ".join(sorted(known if known is not None else self.used))
            raise self.fail(extra[0], f"unknown field; remove it or use one of: {names}")


@dataclass(frozen=True)
class _Context:
    """Where a kind lives: its x span (local coordinates), the course's y span, smoothing."""

    u0: float
    u1: float
    y0: float
    y1: float
    w: float
    base_dir: Path | None


# ----------------------------------------------------------------------------------------
# Kinds. ``expr`` is the smooth z (generic over backends, local x = u); ``sharp`` the real one.


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

    def _window(self, u: Any, ops: Any) -> Any:
        s = self.taper / 6.0
        h = 0.5 * self.taper
        return _sigmoid(u - (self.x_start + h), s, ops) - _sigmoid(u - (self.x_end - h), s, ops)

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
        at = np.exp(1j * (u[:, None] * self.kx + y[:, None] * self.ky + self.phase)) * self.a
        by = np.exp(1j * (du[:, None] * self.kx + dy[:, None] * self.ky))
        relief = (at @ by.T).real
        return self._window(u[:, None] + du[None, :], NP) * relief


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
        """The same CasADi B-spline, evaluated numerically."""
        return self._call(u, y)[0]

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
    )
}
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
        else:
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
            Directory that relative height-field paths are resolved against (default cwd).

        Raises
        ------
        TerrainError
            Any malformed field (the message names ``source`` and the field).

        """
        return cls(spec, source=source, base_dir=base_dir)

    def __repr__(self) -> str:
        return f"Terrain(name={self.name!r}, kind={self.kind!r}, bounds={self.bounds})"

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
                np.array(np.broadcast_to(o, xf.shape), dtype=float).reshape(shape)
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
    """Load a terrain by name (``terrains/NAME.yaml``), generated name or YAML path.

    A generated course's name ``gen:SEED[:DIFFICULTY[:LENGTH[:KINDS]]]`` or a feature
    ladder's ``feat:KIND:SIZE`` (:mod:`planner.world.course_gen`) is drawn anew: the same name
    gives the same terrain.

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
        or "/" in text
        or os.sep in text
    )
    if is_path:
        path = Path(text).expanduser()
        if not path.is_file():
            raise _error(_display(path), "(file)", "no such terrain file; check the path")
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
