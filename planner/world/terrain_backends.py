"""Terrain backends: each kind's one height expression, evaluated with numpy or CasADi.

The same generic expression gives z_T for numpy (vectorised over arrays of any shape, real
or complex step for exact gradients) and for CasADi (SX/MX, exact derivatives for IPOPT);
the smoothed steps and ramps that round a kind's edges (paper, section 4.4) are written once
for both.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

_COMPLEX_STEP = 1e-30
_CHUNK = 20000


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
