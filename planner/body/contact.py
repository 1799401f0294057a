"""Foot contact points and foot sphere centres (paper sections 4.3 and 4.5).

A foot is a sphere of radius rho (``robot.foot_radius_m``). Kinematics (eq. 1-2) places
the sphere *centre*; a plan stores the *contact point* r_i on the terrain (section 4.3,
DESIGN.md section 3). The two differ by rho along the pseudo-normal n = grad f_T / |grad f_T|
(section 4.5):

    centre = r + rho n(r).

Both maps are exact for a locally planar terrain (the sphere touches the plane at the foot
of the perpendicular from its centre). On a curved terrain the true touching point moves by
O(rho^2 kappa) (kappa the surface curvature) from what these maps give; with LittleDog's
rho = 10.3 mm and curvatures below ~10 1/m that is about a millimetre at worst.

Swing-foot convention (used by :mod:`planner.motion.interpolate` and ``State.feet_W``): a foot in
the air is stored as the point one radius *below* its sphere centre, ``centre - rho e_z``
(the sphere's lowest point), see :func:`swing_centre_from_point`.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "TerrainLike",
    "foot_centre_from_contact",
    "contact_from_foot_centre",
    "swing_centre_from_point",
    "swing_point_from_centre",
    "foot_centres_W",
    "contact_points_from_centres",
    "unique_contact_points",
    "sphere_penetration_m",
]

_Array = NDArray[np.float64]
E_Z = np.array([0.0, 0.0, 1.0])


class TerrainLike(Protocol):
    """The part of ``planner.world.terrain.Terrain`` used here (section 4.4-4.5)."""

    def height(self, x: ArrayLike, y: ArrayLike) -> _Array:
        """Terrain height z_T(x, y) [m]."""

    def normal(self, p_W: ArrayLike) -> _Array:
        """Unit pseudo-normals grad f_T / |grad f_T| at points (..., 3)."""

    def f_T(self, p_W: ArrayLike) -> _Array:
        """Implicit terrain function z - z_T(x, y) at points (..., 3) [m]."""


def _points(p: ArrayLike, what: str) -> _Array:
    arr = np.asarray(p, dtype=float)
    if arr.shape[-1:] != (3,):
        raise ValueError(f"{what}: expected points of shape (..., 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: points must be finite, got {p!r}")
    return arr


def foot_centre_from_contact(terrain: TerrainLike, contact_W: ArrayLike, radius_m: float) -> _Array:
    """Sphere centre ``r + rho n(r)`` of a foot touching the terrain at ``contact_W``.

    Parameters
    ----------
    terrain : Terrain
        Provides ``normal(p_W)``, the unit pseudo-normal (section 4.5).
    contact_W : array_like, shape (..., 3)
        Contact points r_i on the terrain [m], world frame.
    radius_m : float
        Foot sphere radius rho [m].

    Returns
    -------
    ndarray, shape (..., 3)
        Sphere centres [m], world frame. Exact for a locally planar terrain.

    """
    r = _points(contact_W, "foot_centre_from_contact")
    return r + float(radius_m) * np.asarray(terrain.normal(r), dtype=float)


def contact_from_foot_centre(terrain: TerrainLike, centre_W: ArrayLike, radius_m: float) -> _Array:
    """Contact point ``c - rho n`` of a foot sphere centred at ``centre_W``.

    The normal is evaluated at the terrain point under the centre,
    ``(c_x, c_y, height(c_x, c_y))``. Exact for a locally planar terrain whose slope is
    small enough that the normal does not vary between that point and the touching point;
    off by O(rho^2 curvature) otherwise.

    Parameters
    ----------
    terrain : Terrain
        Provides ``height(x, y)`` and ``normal(p_W)``.
    centre_W : array_like, shape (..., 3)
        Foot sphere centres [m], world frame.
    radius_m : float
        Foot sphere radius rho [m].

    Returns
    -------
    ndarray, shape (..., 3)
        Contact points [m], world frame.

    """
    c = _points(centre_W, "contact_from_foot_centre")
    below = c.copy()
    below[..., 2] = np.asarray(terrain.height(c[..., 0], c[..., 1]), dtype=float)
    return c - float(radius_m) * np.asarray(terrain.normal(below), dtype=float)


def swing_centre_from_point(point_W: ArrayLike, radius_m: float) -> _Array:
    """Sphere centre of a swing foot stored as the point one radius below it: ``p + rho e_z``."""
    return _points(point_W, "swing_centre_from_point") + float(radius_m) * E_Z


def swing_point_from_centre(centre_W: ArrayLike, radius_m: float) -> _Array:
    """Stored point of a swing foot (its sphere's lowest point): ``c - rho e_z``."""
    return _points(centre_W, "swing_point_from_centre") - float(radius_m) * E_Z


def foot_centres_W(
    terrain: TerrainLike, feet_W: ArrayLike, in_contact: ArrayLike, radius_m: float
) -> _Array:
    """Sphere centres of four feet: contact feet by the normal, swing feet by ``+rho e_z``.

    Parameters
    ----------
    terrain : Terrain
        The terrain the contact feet stand on.
    feet_W : array_like, shape (4, 3)
        Stored foot points (``State.feet_W``) [m], world frame.
    in_contact : array_like, shape (4,)
        Booleans, True for a foot on the terrain (``State.in_contact``).
    radius_m : float
        Foot sphere radius rho [m].

    Returns
    -------
    ndarray, shape (4, 3)
        Sphere centres [m], world frame, what the leg kinematics (eq. 2) must reach.

    """
    feet = _points(feet_W, "foot_centres_W").reshape(4, 3)
    mask = np.asarray(in_contact, dtype=bool).reshape(4)
    out = swing_centre_from_point(feet, radius_m)
    if mask.any():
        out[mask] = foot_centre_from_contact(terrain, feet[mask], radius_m)
    return out


def contact_points_from_centres(
    terrain: TerrainLike, centres_W: _Array, radius_m: float, refine_above_m: float = 1e-6
) -> tuple[_Array, _Array]:
    """Contact points of foot spheres resting on the smooth terrain, and how well they rest.

    The contract (DESIGN.md section 3, :mod:`planner.body.contact`): ``c = r + rho n(r)`` with
    r on the surface. It is solved by Gauss-Newton on ``r_xy`` from the point
    ``c - rho n(c_xy)`` (the tangent plane under the centre, exact on planar ground); where
    the fit is worse than ``refine_above_m`` (where rho times the curvature
    exceeds 1 the map r -> r + rho n(r) folds and has several roots), from the best node
    of a 0.25 mm grid within 1.2 rho of the centre.

    Parameters
    ----------
    terrain : Terrain
        Smooth ``height``, ``normal`` and ``f_T``.
    centres_W : array (N, 3)
        Sphere centres [m], world frame.
    radius_m : float
        Sphere radius rho [m].
    refine_above_m : float
        Miss [m] above which the grid search is run.

    Returns
    -------
    contacts : ndarray (N, 3)
        Contact points [m]: ``c - rho n`` with the normal of the better convention (on the
        terrain when the foot rests on it).
    miss : ndarray (N,)
        How far the foot is from resting on the terrain [m]: ``|r + rho n(r) - c|`` with r
        on the surface.

    """
    c = np.asarray(centres_W, dtype=float).reshape(-1, 3)
    rho = float(radius_m)
    r2 = contact_from_foot_centre(terrain, c, rho)
    miss2 = np.abs(np.atleast_1d(terrain.f_T(r2))).astype(float)

    def residual(xy: _Array, cc: _Array) -> tuple[_Array, _Array]:
        """Surface point over xy, and its r + rho n(r) - c."""
        p = np.column_stack([xy, np.asarray(terrain.height(xy[:, 0], xy[:, 1])).reshape(-1)])
        return p, p + rho * np.asarray(terrain.normal(p)).reshape(-1, 3) - cc

    def gauss_newton(xy: _Array, cc: _Array, steps: int = 8) -> tuple[_Array, _Array]:
        h = 1e-7
        for _ in range(steps):
            f = residual(xy, cc)[1]
            jac = np.stack(
                [
                    (residual(xy + d, cc)[1] - residual(xy - d, cc)[1]) / (2 * h)
                    for d in (np.array([h, 0.0]), np.array([0.0, h]))
                ],
                axis=-1,
            )  # (N, 3, 2)
            jtj = np.einsum("nki,nkj->nij", jac, jac) + 1e-12 * np.eye(2)
            step = np.linalg.solve(jtj, np.einsum("nki,nk->ni", jac, f)[..., None])[..., 0]
            xy = xy - np.clip(step, -rho, rho)
            if float(np.max(np.abs(step), initial=0.0)) < 1e-12:  # converged (planar: 1 step)
                break
        p, f = residual(xy, cc)
        return p, np.linalg.norm(f, axis=1)

    r1, miss1 = gauss_newton(r2[:, :2].copy(), c)
    bad = np.flatnonzero(np.minimum(miss1, miss2) > refine_above_m)
    if len(bad):
        k = int(math.ceil(1.2 * rho / 2.5e-4))
        u = 2.5e-4 * np.arange(-k, k + 1)
        ux, uy = (g.ravel() for g in np.meshgrid(u, u))
        for j in bad:
            xy = np.column_stack([c[j, 0] + ux, c[j, 1] + uy])
            f = np.linalg.norm(residual(xy, c[j])[1], axis=1)
            p, m = gauss_newton(xy[[int(np.argmin(f))]], c[j][None])
            if m[0] < miss1[j]:
                r1[j], miss1[j] = p[0], m[0]
    # the sphere's point along the normal: r1 itself when the foot rests on the terrain
    r1 = c - rho * np.asarray(terrain.normal(r1)).reshape(-1, 3)
    del miss2  # r2 (tangent plane under the centre) only seeds the solve
    return r1, miss1


def unique_contact_points(
    terrain: TerrainLike, centres_W: _Array, radius_m: float
) -> tuple[_Array, _Array]:
    """:func:`contact_points_from_centres`, solved once per distinct centre.

    A stance foot keeps its sphere centre along a leaf, so a plan's thousands of stance
    samples hold a few hundred distinct centres.
    """
    centres_W = np.asarray(centres_W, dtype=float).reshape(-1, 3)
    keys = np.round(centres_W / 1e-10)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    pts, fit = contact_points_from_centres(terrain, centres_W[first], radius_m)
    return pts[inverse.ravel()], fit[inverse.ravel()]


# a sphere's underside sampled at these shares of its radius (horizontal), 8 directions each
_RING_FRACTIONS = (0.0, 0.5, 0.75, 0.9, 1.0)
_RING_DIRECTIONS = 8


def sphere_penetration_m(terrain, centres_W: ArrayLike, radius_m: float) -> _Array:
    """How far the sharp terrain rises into spheres [m], vertically (<= 0: not into them).

    At horizontal offsets of ``_RING_FRACTIONS`` x the radius in ``_RING_DIRECTIONS``
    directions, the sharp height minus the sphere's underside there (centre z minus
    sqrt(r^2 - offset^2)); the largest. A sphere resting on the ground gives 0; a stance
    foot that rolled against a riser gives how far the riser rises into it (beyond the
    paper: a rigid sphere foot rolls as its shank turns, by about its radius x the turn,
    2.7 cm over four body moves for ANYmal-B's 3.1 cm feet). Positive exactly where the
    terrain enters the sphere at a sample; the vertical overlap is at least the Euclidean
    depth there.
    """
    c = np.asarray(centres_W, float).reshape(-1, 3)
    rho = float(radius_m)
    angles = np.linspace(0.0, 2.0 * np.pi, _RING_DIRECTIONS, endpoint=False)
    offsets = [(0.0, 0.0, 0.0)] + [
        (f * rho * np.cos(a), f * rho * np.sin(a), np.sqrt(max(rho * rho * (1 - f * f), 0.0)))
        for f in _RING_FRACTIONS[1:]
        for a in angles
    ]
    off = np.array(offsets)
    off[0, 2] = rho
    under = c[:, 2:3] - off[None, :, 2]
    h = terrain.height_sharp_offsets(c[:, 0], c[:, 1], off[:, 0], off[:, 1])
    return (h - under).max(axis=1)
