"""Convex polygons in the horizontal plane: a hull and a point's signed distance.

The exact static-feasibility test (:mod:`planner.body.statics`, beyond the paper's
eq. 5) gives a stance's feasible COM region as the convex hull of its support points
(:func:`~planner.body.statics.feasible_com_region`), and a COM's margin
(:attr:`~planner.body.statics.StaticFeasibility.com_margin_m`) as its signed distance to
that polygon's boundary.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["convex_hull", "polygon_signed_distance"]

_Array = NDArray[np.float64]


def convex_hull(points: _Array, tol: float) -> _Array:
    """Counter-clockwise convex hull (monotone chain), dropping collinear points."""
    pts = np.unique(np.round(points / tol) * tol, axis=0)
    if len(pts) <= 2:
        return pts

    def cross(o: _Array, a: _Array, b: _Array) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[_Array] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= tol * tol:
            lower.pop()
        lower.append(p)
    upper: list[_Array] = []
    for p in pts[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= tol * tol:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def polygon_signed_distance(point_xy: ArrayLike, polygon_xy: ArrayLike) -> float:
    """Signed distance [m] from a point to a convex polygon's boundary, positive inside.

    ``polygon_xy`` (K, 2) is counter-clockwise; with fewer than 3 vertices (a segment or
    a point) nothing is inside and the result is minus the distance to it.
    """
    p = np.asarray(point_xy, dtype=float).reshape(2)
    poly = np.asarray(polygon_xy, dtype=float).reshape(-1, 2)
    if len(poly) == 0:
        return -math.inf
    if len(poly) == 1:
        return -float(np.linalg.norm(p - poly[0]))
    dists, inside = [], len(poly) >= 3
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        e = b - a
        t = np.clip(np.dot(p - a, e) / max(np.dot(e, e), 1e-300), 0.0, 1.0)
        dists.append(float(np.linalg.norm(p - (a + t * e))))
        if e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0]) < 0.0:
            inside = False
    d = min(dists)
    return d if inside or d == 0.0 else -d
