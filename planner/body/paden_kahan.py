"""Paden-Kahan subproblems 1-3 for revolute twists (pure numpy geometry).

Reference: R. M. Murray, Z. Li, S. S. Sastry, *A Mathematical Introduction to
Robotic Manipulation*, CRC 1994, section 3.2.2.  The leg inverse kinematics of
the paper (section 5.1.2) uses subproblem 3 for the knee angle and then
subproblem 2 for hip roll and pitch.

A revolute twist is given by a unit axis ``omega`` and a point ``r`` on the axis;
``exp(xi theta) p = r + Rot(omega, theta) (p - r)``.  All solutions are returned,
angles wrapped to ``[-pi, pi)``.  ``tol`` is a *distance* tolerance (same unit as
the points): a problem that is infeasible by at most ``tol`` is treated as
tangent and clamped to its single closest solution; beyond ``tol`` no solution
(``None`` / ``[]``) is returned, never NaN.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["subproblem1", "subproblem2", "subproblem3"]

_PARALLEL_SIN = 1e-9  # |omega1 x omega2| below this: axes treated as parallel


def _vec(x: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(x, dtype=float).reshape(3)


def _unit(w: ArrayLike, name: str) -> NDArray[np.float64]:
    w = _vec(w)
    n = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if n == 0.0 or not math.isfinite(n):
        raise ValueError(f"{name} must be a finite non-zero axis vector, got {w}")
    return w / n


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def _dot(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    return float(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])


def _wrap(a: float) -> float:
    """Wrap an angle to ``[-pi, pi)``."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _planar_angle(w: NDArray[np.float64], u: NDArray[np.float64], v: NDArray[np.float64]) -> float:
    """Angle rotating ``u`` onto ``v`` about unit ``w`` (projections taken here)."""
    up = u - _dot(w, u) * w
    vp = v - _dot(w, v) * w
    return math.atan2(_dot(w, _cross(up, vp)), _dot(up, vp))


def subproblem1(
    omega: ArrayLike, r: ArrayLike, p: ArrayLike, q: ArrayLike, tol: float = 1e-9
) -> float | None:
    """Paden-Kahan subproblem 1: ``exp(xi theta) p = q`` (MLS section 3.2.2).

    Parameters
    ----------
    omega : array_like, shape (3,)
        Axis direction (normalised here).
    r : array_like, shape (3,)
        A point on the axis.
    p, q : array_like, shape (3,)
        Start and target points.
    tol : float
        Distance tolerance on ``omega.(p - q)`` and on the difference of the
        distances of ``p`` and ``q`` to the axis.

    Returns
    -------
    float or None
        ``theta`` in ``[-pi, pi)``; ``None`` when no rotation maps ``p`` to ``q``
        (beyond ``tol``).  If ``p`` lies on the axis (within ``tol``) every angle
        works and ``0.0`` is returned.

    """
    w = _unit(omega, "omega")
    r = _vec(r)
    u = _vec(p) - r
    v = _vec(q) - r
    wu, wv = _dot(w, u), _dot(w, v)
    up, vp = u - wu * w, v - wv * w
    nu, nv = math.sqrt(_dot(up, up)), math.sqrt(_dot(vp, vp))
    if abs(wu - wv) > tol or abs(nu - nv) > tol:
        return None
    if nu <= tol:
        return 0.0
    return _wrap(math.atan2(_dot(w, _cross(up, vp)), _dot(up, vp)))


def subproblem2(
    omega1: ArrayLike,
    omega2: ArrayLike,
    r: ArrayLike,
    p: ArrayLike,
    q: ArrayLike,
    tol: float = 1e-9,
) -> list[tuple[float, float]]:
    """Paden-Kahan subproblem 2: ``exp(xi1 theta1) exp(xi2 theta2) p = q`` (MLS 3.2.2).

    The two axes intersect at ``r``.  With ``u = p - r``, ``v = q - r`` the
    intermediate point ``c = exp(xi2 theta2) p = exp(-xi1 theta1) q`` is
    ``r + alpha omega1 + beta omega2 + gamma (omega1 x omega2)``, ``gamma`` from
    ``|c - r| = |u|``; then ``theta2`` and ``theta1`` follow from subproblem 1.

    Parameters
    ----------
    omega1, omega2 : array_like, shape (3,)
        Axis directions (normalised here); applied as ``exp(xi1 .) exp(xi2 .)``.
    r : array_like, shape (3,)
        Intersection point of the two axes.
    p, q : array_like, shape (3,)
        Start and target points.
    tol : float
        Distance tolerance: ``||q - r| - |p - r|| > tol`` gives ``[]``; a circle
        intersection missed by at most ``tol`` is clamped to the tangent solution.

    Returns
    -------
    list of (float, float)
        ``(theta1, theta2)`` pairs: 0, 1 (tangent) or 2 (generic) solutions.

    Raises
    ------
    ValueError
        If the axes are parallel (``|omega1 x omega2| < 1e-9``): the subproblem
        then has no isolated solutions; use two subproblem-1 / planar solves.

    """
    w1 = _unit(omega1, "omega1")
    w2 = _unit(omega2, "omega2")
    w12 = _cross(w1, w2)
    s2 = _dot(w12, w12)
    if s2 < _PARALLEL_SIN**2:
        raise ValueError(
            "subproblem2: omega1 and omega2 are parallel (|omega1 x omega2| = "
            f"{math.sqrt(s2):.3g}); the axes must intersect at a single point r"
        )
    r = _vec(r)
    u = _vec(p) - r
    v = _vec(q) - r
    nu2 = _dot(u, u)
    nu, nv = math.sqrt(nu2), math.sqrt(_dot(v, v))
    if abs(nu - nv) > tol:
        return []
    c12 = _dot(w1, w2)
    w2u, w1v = _dot(w2, u), _dot(w1, v)
    den = c12 * c12 - 1.0  # = -s2
    alpha = (c12 * w2u - w1v) / den
    beta = (c12 * w1v - w2u) / den
    z0 = alpha * w1 + beta * w2
    nz02 = _dot(z0, z0)
    g2s2 = nu2 - nz02  # = gamma^2 |w1 x w2|^2
    if g2s2 < 0.0:
        if math.sqrt(nz02) - nu > tol:
            return []
        zs = [z0]
    elif g2s2 == 0.0:
        zs = [z0]
    else:
        g = math.sqrt(g2s2 / s2)
        zs = [z0 + g * w12, z0 - g * w12]
    sols = []
    for z in zs:
        th2 = _planar_angle(w2, u, z)
        th1 = _planar_angle(w1, z, v)
        sols.append((_wrap(th1), _wrap(th2)))
    return sols


def subproblem3(
    omega: ArrayLike,
    r: ArrayLike,
    p: ArrayLike,
    q: ArrayLike,
    delta: float,
    tol: float = 1e-9,
) -> list[float]:
    """Paden-Kahan subproblem 3: ``|exp(xi theta) p - q| = delta`` (MLS 3.2.2).

    With ``u'``, ``v'`` the projections of ``p - r``, ``q - r`` on the plane normal
    to ``omega`` and ``delta'^2 = delta^2 - (omega.(p - q))^2``:
    ``theta = theta0 +- phi``, ``theta0`` the angle from ``u'`` to ``v'`` and
    ``cos(phi) = (|u'|^2 + |v'|^2 - delta'^2) / (2 |u'| |v'|)``; ``phi`` is taken
    with ``atan2`` and a factored (Heron-like) sine for accuracy near tangency.

    Parameters
    ----------
    omega : array_like, shape (3,)
        Axis direction (normalised here).
    r : array_like, shape (3,)
        A point on the axis.
    p, q : array_like, shape (3,)
        Rotated point and fixed point.
    delta : float
        Required distance, ``>= 0``.
    tol : float
        Distance tolerance: ``delta`` outside the reachable range
        ``[d_min, d_max]`` by at most ``tol`` is clamped to the single tangent
        solution; further out gives ``[]``.

    Returns
    -------
    list of float
        0, 1 (tangent) or 2 (generic) angles in ``[-pi, pi)``.  If the distance does
        not depend on ``theta`` (``p`` or ``q`` on the axis) and equals ``delta``
        within ``tol``, ``[0.0]`` is returned (every angle is a solution).

    """
    w = _unit(omega, "omega")
    r = _vec(r)
    u = _vec(p) - r
    v = _vec(q) - r
    d_ax = _dot(w, u) - _dot(w, v)
    up = u - _dot(w, u) * w
    vp = v - _dot(w, v) * w
    a, b = math.sqrt(_dot(up, up)), math.sqrt(_dot(vp, vp))
    d_ax2 = d_ax * d_ax
    dmin = math.sqrt((a - b) ** 2 + d_ax2)
    dmax = math.sqrt((a + b) ** 2 + d_ax2)
    if delta < dmin - tol or delta > dmax + tol:
        return []
    if a <= tol or b <= tol:
        return [0.0]
    theta0 = math.atan2(_dot(w, _cross(up, vp)), _dot(up, vp))
    dp2 = max(delta * delta - d_ax2, 0.0)  # delta'^2
    disc = (dp2 - (a - b) ** 2) * ((a + b) ** 2 - dp2)  # = (2ab sin(phi))^2
    if delta <= dmin or delta >= dmax or disc <= 0.0:
        phi = 0.0 if a * a + b * b - dp2 >= 0.0 else math.pi
        return [_wrap(theta0 - phi)]
    phi = math.atan2(math.sqrt(disc), a * a + b * b - dp2)
    return [_wrap(theta0 - phi), _wrap(theta0 + phi)]
