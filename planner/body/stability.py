"""Static stability margin of a three-leg stance (beyond the paper, sections 7.3 and 10).

The margin is the horizontal distance of the centre of mass inside the nearest edge of the
support triangle (the feet's contact points projected along gravity): how far the COM can
be pushed before the robot tips over that edge. Eq. 5's forces inside the friction cones
only ask it to be positive; the robot that executes the plan needs more.

Why ``BALANCE_MARGIN_M``: open-loop MuJoCo runs at the plan's timing (bench physics,
12 generated and 9 named courses, 1,300 swings) fell only at swings whose planned margin
was 1-18 mm (15 falls; each within a second of such a swing); no course whose swings all
kept at least 21 mm fell. Executed feet land 5-10 mm from their planned points, the body
tilts 1-4 degrees on compliant servos (0.5-1 cm of COM at LittleDog's 15 cm height), and
the leg that lifts unloads before its planned lift-off. Keyframes ask 25 mm, path
samples (the swing leg's own mass moves the COM) 20 mm. Both are lengths of LittleDog's
size; a larger robot's errors scale with its COM height.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.body.margins import BALANCE_MARGIN_M, PATH_BALANCE_MARGIN_M

__all__ = [
    "BALANCE_MARGIN_M",
    "PATH_BALANCE_MARGIN_M",
    "nearest_inside_point_W",
    "polygon_margin_m",
    "support_margin_m",
    "support_margins_ca",
    "tip_margin_m",
    "triangle_inradius_m",
]


def support_margin_m(feet_W: ArrayLike, com_W: ArrayLike) -> float:
    """Signed horizontal distance [m] of ``com_W`` inside the triangle of three feet.

    ``feet_W`` (3, 3) are the support contact points in any order; positive inside,
    negative outside. A degenerate (collinear) triangle gives minus the distance to it.
    """
    tri = np.asarray(feet_W, dtype=float).reshape(3, 3)[:, :2]
    p = np.asarray(com_W, dtype=float).reshape(-1)[:2]
    area2 = _cross(tri[1] - tri[0], tri[2] - tri[0])
    if abs(area2) < 1e-12:
        return -float(min(np.linalg.norm(tri - p, axis=1)))
    sign = 1.0 if area2 > 0 else -1.0
    out = np.inf
    for a, b in ((0, 1), (1, 2), (2, 0)):
        e = tri[b] - tri[a]
        out = min(out, sign * _cross(e, p - tri[a]) / float(np.linalg.norm(e)))
    return float(out)


def polygon_margin_m(feet_W: ArrayLike, com_W: ArrayLike) -> float:
    """Signed horizontal distance [m] of ``com_W`` inside the convex hull of the feet.

    Any number of feet (four: the four-leg support polygon); positive inside, negative
    outside (then minus the distance to the nearest hull edge's line, a lower bound).
    """
    pts = np.asarray(feet_W, dtype=float).reshape(-1, 3)[:, :2]
    p = np.asarray(com_W, dtype=float).reshape(-1)[:2]
    hull = _convex_hull(pts)
    if len(hull) < 3:
        return -float(min(np.linalg.norm(pts - p, axis=1)))
    out = np.inf
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        e = b - a
        out = min(out, _cross(e, p - a) / float(np.linalg.norm(e)))
    return float(out)


def tip_margin_m(feet_W: ArrayLike, com_W: ArrayLike, gravity_W: ArrayLike) -> float:
    """:func:`polygon_margin_m` of the COM projected along ``gravity_W`` onto the feet's height.

    With the gravito-inertial vector g - a (d'Alembert) in place of g, the projected point
    is the zero-moment point of a body accelerating by ``a`` (its angular momentum
    neglected): its margin says how far the motion is from tipping the robot over an edge
    of its support, as the COM's own margin does at rest.
    """
    feet = np.asarray(feet_W, dtype=float).reshape(-1, 3)
    c = np.asarray(com_W, dtype=float).reshape(3)
    g = np.asarray(gravity_W, dtype=float).reshape(3)
    if g[2] >= 0.0:
        return -np.inf  # no downward load: nothing holds the feet on the ground
    t = (float(feet[:, 2].mean()) - c[2]) / g[2]
    return polygon_margin_m(feet, c + t * g)


def nearest_inside_point_W(feet_W: ArrayLike, p_W: ArrayLike, margin_m: float):
    """The horizontal point nearest ``p_W`` that lies ``margin_m`` inside the feet's hull.

    The hull of the feet (any number, projected along gravity) is shrunk by ``margin_m``
    (each edge's half-plane moved inwards, the polygon clipped by them); returns the
    (2,) point of that inset polygon nearest to ``p_W`` (``p_W`` itself when inside), or
    None when the inset polygon is empty.
    """
    pts = np.asarray(feet_W, dtype=float).reshape(-1, 3)[:, :2]
    p = np.asarray(p_W, dtype=float).reshape(-1)[:2]
    if polygon_margin_m(feet_W, p) >= margin_m:
        return p.copy()
    hull = _convex_hull(pts)
    if len(hull) < 3:
        return None
    poly = [np.asarray(v, float) for v in hull]
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        e = b - a
        n_in = np.array([-e[1], e[0]]) / float(np.linalg.norm(e))  # counter-clockwise hull
        side = [float(n_in @ (v - a)) - margin_m for v in poly]
        clipped = []
        for k, v in enumerate(poly):  # Sutherland-Hodgman against one half-plane
            w, sv, sw = poly[(k + 1) % len(poly)], side[k], side[(k + 1) % len(poly)]
            if sv >= 0.0:
                clipped.append(v)
            if sv * sw < 0.0:
                clipped.append(v + (w - v) * sv / (sv - sw))
        poly = clipped
        if len(poly) < 3:
            return None
    inset = np.array(poly)
    best, best_d = None, np.inf
    for a, b in zip(inset, np.roll(inset, -1, axis=0), strict=True):
        e = b - a
        t = float(np.clip((p - a) @ e / max(float(e @ e), 1e-18), 0.0, 1.0))
        q = a + t * e
        d = float(np.linalg.norm(p - q))
        if d < best_d:
            best, best_d = q, d
    return best


def _convex_hull(pts: NDArray) -> NDArray:
    """Counter-clockwise hull vertices of 2-D points (Andrew's monotone chain)."""
    order = sorted(map(tuple, np.round(pts, 12)))
    if len(order) < 3:
        return np.array(order)

    def half(seq):
        out: list = []
        for q in seq:
            while len(out) >= 2:
                if _cross(np.subtract(out[-1], out[-2]), np.subtract(q, out[-2])) > 0:
                    break
                out.pop()
            out.append(q)
        return out[:-1]

    return np.array(half(order) + half(order[::-1]))


def triangle_inradius_m(feet_W: ArrayLike) -> float:
    """Inradius [m] of the horizontal triangle of three feet: the largest margin of any COM.

    No point of the triangle is farther than this from its nearest edge, so a three-leg
    stance on these feet can keep a COM at most this far inside (0 when collinear).
    """
    tri = np.asarray(feet_W, dtype=float).reshape(3, 3)[:, :2]
    area = 0.5 * abs(_cross(tri[1] - tri[0], tri[2] - tri[0]))
    semi = 0.5 * sum(float(np.linalg.norm(tri[b] - tri[a])) for a, b in ((0, 1), (1, 2), (2, 0)))
    return area / semi if semi > 0.0 else 0.0


def support_margins_ca(feet_W: list, com_W) -> ca.MX:
    """The three edge distances [m] of the COM inside a triangle of feet (CasADi).

    ``feet_W``: three 3-vectors (parameters: the feet are fixed on a leaf, so the sign of
    the orientation is constant); ``com_W``: the COM expression. Each entry is positive
    when the COM is on the inner side of that edge; the margin is their minimum.
    """
    xy = [f[:2] for f in feet_W]
    c = com_W[:2]
    area2 = _cross_ca(xy[1] - xy[0], xy[2] - xy[0])
    sign = ca.sign(area2)
    rows = []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        e = xy[b] - xy[a]
        rows.append(sign * _cross_ca(e, c - xy[a]) / ca.sqrt(ca.dot(e, e) + 1e-12))
    return ca.vertcat(*rows)


def _cross(u, v) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


def _cross_ca(u, v):
    return u[0] * v[1] - u[1] * v[0]
