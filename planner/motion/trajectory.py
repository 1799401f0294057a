"""The trajectory tau to follow, R_tau(lambda) (paper sections 4.6, 7.2-7.3, 8.2 and 9).

Convention: every trajectory is parametrised by its **arc length**, lambda in
[lambda_a, lambda_b] = [0, L] metres (L = ``length_m``), so ``tangent(lambda)`` =
dR_tau/dlambda is a unit vector and "a stride of ds metres ahead" is ``lambda + ds``.

Kinds
-----
- ``polyline``: straight segments through waypoints; lambda is exact arc length and the
  tangent is piecewise constant (at a vertex it is the outgoing segment's, at lambda = L the
  last segment's).
- ``spline``: a C2 cubic spline through waypoints (scipy ``CubicSpline`` over the chord-length
  parameter), reparametrised by arc length numerically (Gauss-Legendre quadrature on a fine
  grid, then Newton steps; lambda accurate to ~1e-12 m).
- ``sine_series``: eq. 15 of section 9, R_tau(t) = R_tau0(t) + sum_p sin(p pi (t - t_a) /
  (t_b - t_a)) A_p, with t tau0's own arc length; the result is again reparametrised by its
  own arc length, so its endpoints are tau0's (the sines vanish there).

Points are world frame (x, y, z) in metres. The trajectory is where the body (COM) should
go, so its z is a height above the terrain (see :meth:`Trajectory.straight`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.core.errors import InputError

__all__ = ["Trajectory", "PolylineTrajectory", "CurveTrajectory"]

_Array = NDArray[np.float64]
_DUPLICATE_TOL_M = 1e-12
_GRID_STEP_M = 2e-3  # arc-length table spacing of smooth curves [m]
_GL_X, _GL_W = np.polynomial.legendre.leggauss(5)  # quadrature on [-1, 1]


class _HeightTerrain(Protocol):
    def height(self, x: ArrayLike, y: ArrayLike) -> _Array: ...


def _waypoints(points_W: ArrayLike, what: str) -> _Array:
    """Validate waypoints (N, 3): finite, at least two distinct; drop repeated points."""
    try:
        pts = np.asarray(points_W, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: waypoints must be numbers, got {points_W!r}") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"{what}: waypoints must have shape (N, 3) [m], got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise InputError(f"{what}: waypoints contain NaN or inf; give finite x, y, z [m]")
    keep = np.ones(len(pts), dtype=bool)
    if len(pts) > 1:
        keep[1:] = np.linalg.norm(np.diff(pts, axis=0), axis=1) > _DUPLICATE_TOL_M
    pts = pts[keep]
    if len(pts) < 2:
        raise InputError(f"{what}: need at least 2 distinct waypoints, got {len(pts)}")
    return pts


class Trajectory:
    """A trajectory R_tau(lambda), lambda in [0, L] its arc length [m] (section 4.6).

    Build one with :meth:`polyline`, :meth:`spline`, :meth:`straight` or
    :meth:`sine_series`. Subclasses implement :meth:`point` and :meth:`tangent`.
    """

    kind: str
    length_m: float
    waypoints_W: _Array

    # ---- construction -------------------------------------------------------------------
    @staticmethod
    def polyline(waypoints_W: ArrayLike) -> PolylineTrajectory:
        """Straight segments through ``waypoints_W`` (N, 3) [m]; lambda is arc length."""
        return PolylineTrajectory(_waypoints(waypoints_W, "Trajectory.polyline"))

    @staticmethod
    def spline(waypoints_W: ArrayLike, bc_type: str = "natural") -> CurveTrajectory:
        """C2 cubic spline through ``waypoints_W`` (N, 3) [m], reparametrised by arc length.

        ``bc_type`` is scipy's ``CubicSpline`` end condition ("natural", "not-a-knot",
        "clamped").
        """
        pts = _waypoints(waypoints_W, "Trajectory.spline")
        knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        from scipy.interpolate import CubicSpline  # imported here: ~0.5 s

        cs = CubicSpline(knots, pts, axis=0, bc_type=bc_type)
        dcs = cs.derivative()
        return CurveTrajectory("spline", cs, dcs, float(knots[-1]), breaks=knots, waypoints_W=pts)

    @staticmethod
    def straight(
        start_W: ArrayLike,
        goal_W: ArrayLike,
        terrain: _HeightTerrain,
        height_m: float,
        spacing_m: float = 0.02,
        footprint_radius_m: float = 0.1,
    ) -> PolylineTrajectory:
        """tau0: a straight line in xy from start to goal, ``height_m`` above the terrain.

        Samples every ``spacing_m`` along the xy segment. The ground level followed is the
        terrain's height (``height_sharp`` when the terrain has it) **max-filtered** over a
        disk of radius ``footprint_radius_m`` (the robot's footprint), so the path does not
        dip into gaps narrower than the footprint, then **averaged** over +-radius along the
        path so that a step becomes a ramp instead of a jump. The average of a max filter is
        still >= the terrain at the centre, so the path never gets closer than ``height_m``
        to the ground under it.

        Parameters
        ----------
        start_W, goal_W : array_like, shape (2,) or (3,)
            Start and goal [m]; only x, y are used (z comes from the terrain).
        terrain : Terrain
            Provides ``height(x, y)`` (and optionally ``height_sharp(x, y)``).
        height_m : float
            Height of the path above the filtered ground [m], e.g. the robot's nominal
            standing height (:func:`planner.motion.heuristics.nominal_height_m`).
        spacing_m : float
            Sample spacing along the path [m].
        footprint_radius_m : float
            Radius of the footprint the max filter runs over [m]; 0 follows the terrain.

        """
        a = np.asarray(start_W, dtype=float).ravel()
        b = np.asarray(goal_W, dtype=float).ravel()
        for name, v in (("start_W", a), ("goal_W", b)):
            if v.size not in (2, 3) or not np.all(np.isfinite(v)):
                raise InputError(f"Trajectory.straight: {name} must be 2 or 3 finite numbers [m]")
        if not (np.isfinite(height_m) and spacing_m > 0 and footprint_radius_m >= 0):
            raise InputError(
                "Trajectory.straight: need finite height_m, spacing_m > 0, footprint_radius_m >= 0"
            )
        d_xy = float(np.linalg.norm(b[:2] - a[:2]))
        if d_xy <= _DUPLICATE_TOL_M:
            raise InputError("Trajectory.straight: start and goal have the same x, y")
        n = max(2, int(np.ceil(d_xy / spacing_m)) + 1)
        u = np.linspace(0.0, 1.0, n)
        xy = a[:2] + u[:, None] * (b[:2] - a[:2])
        return Trajectory.over_terrain(xy, terrain, height_m, footprint_radius_m, "straight")

    @staticmethod
    def over_terrain(
        xy_W: ArrayLike,
        terrain: _HeightTerrain,
        height_m: float,
        footprint_radius_m: float = 0.1,
        kind: str = "polyline",
    ) -> PolylineTrajectory:
        """A polyline through the points ``xy_W`` (N, 2), ``height_m`` over the terrain.

        The height as in :meth:`straight` (which is this along a straight line): the
        terrain max-filtered over the footprint disk, averaged over +-radius of arc length.
        ``xy_W`` should be dense (a few cm apart): each point is a vertex.
        """
        xy = np.asarray(xy_W, dtype=float).reshape(-1, 2)
        ground = _ground_max(terrain, xy, footprint_radius_m)
        if footprint_radius_m > 0:
            s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
            ground = np.array(
                [ground[np.abs(s - si) <= footprint_radius_m + 1e-12].mean() for si in s]
            )
        pts = np.column_stack([xy, ground + float(height_m)])
        return PolylineTrajectory(_waypoints(pts, "Trajectory.over_terrain"), kind=kind)

    @staticmethod
    def sine_series(tau0: Trajectory, coefficients: ArrayLike) -> CurveTrajectory:
        """Eq. 15 of section 9: tau0 plus sum_p sin(p pi (t - t_a)/(t_b - t_a)) A_p.

        Parameters
        ----------
        tau0 : Trajectory
            The base trajectory, t in [0, L0] its arc length.
        coefficients : array_like, shape (P, 3)
            Row p-1 is A_p [m] (x, y, z amplitudes of the p-th sine).

        Returns
        -------
        CurveTrajectory
            The bent trajectory, reparametrised by its own arc length; same endpoints as tau0.

        """
        A = np.asarray(coefficients, dtype=float)
        if A.ndim == 1 and A.size == 3:
            A = A.reshape(1, 3)
        if A.ndim != 2 or A.shape[1] != 3:
            raise InputError(
                f"Trajectory.sine_series: coefficients must have shape (P, 3), got {A.shape}"
            )
        if not np.all(np.isfinite(A)):
            raise InputError("Trajectory.sine_series: coefficients contain NaN or inf")
        L0 = tau0.length_m
        p = np.arange(1, len(A) + 1, dtype=float)
        k = p * np.pi / L0

        def point(t: _Array) -> _Array:
            t = np.asarray(t, dtype=float)
            # sin(p pi u) with u in [0, 1]; at u = 1 exactly the bump is set to 0.
            sn = np.where((t[..., None] >= L0), 0.0, np.sin(k * t[..., None]))
            return tau0.point(t) + sn @ A

        def deriv(t: _Array) -> _Array:
            t = np.asarray(t, dtype=float)
            return tau0.tangent(t) + (k * np.cos(k * t[..., None])) @ A

        return CurveTrajectory(
            "sine_series",
            point,
            deriv,
            L0,
            breaks=tau0.breaks_lambda(),
            waypoints_W=tau0.waypoints_W,
            base=tau0,
            coefficients=A,
        )

    # ---- evaluation (subclasses) --------------------------------------------------------
    def point(self, lam: ArrayLike) -> _Array:
        """R_tau(lambda) [m], world frame; lambda (...) clipped to [0, L]; returns (..., 3)."""
        raise NotImplementedError

    def tangent(self, lam: ArrayLike) -> _Array:
        """Unit tangent dR_tau/dlambda at lambda (...); returns (..., 3)."""
        raise NotImplementedError

    def breaks_lambda(self) -> _Array:
        """Lambdas where the curve may be non-smooth (ends and polyline vertices)."""
        return np.array([0.0, self.length_m])

    def _dense(self) -> tuple[_Array, _Array]:
        """(lambdas, points) on a fine grid used to seed closest-point searches."""
        raise NotImplementedError

    # ---- derived ------------------------------------------------------------------------
    @property
    def lambda_a(self) -> float:
        """Start of the parameter range (0)."""
        return 0.0

    @property
    def start_W(self) -> _Array:
        """R_tau(lambda_a)."""
        return self.point(0.0)

    @property
    def end_W(self) -> _Array:
        """R_tau(lambda_b)."""
        return self.point(self.length_m)

    def __call__(self, lam: ArrayLike) -> _Array:
        """Same as :meth:`point`."""
        return self.point(lam)

    def clip(self, lam: ArrayLike) -> _Array:
        """Lambda clipped into [0, L]."""
        return np.clip(np.asarray(lam, dtype=float), 0.0, self.length_m)

    def sample(self, spacing_m: float = 0.01) -> tuple[_Array, _Array]:
        """(lambdas (M,), points (M, 3)) every ``spacing_m`` or less, both ends included."""
        m = max(2, int(np.ceil(self.length_m / spacing_m)) + 1)
        lam = np.linspace(0.0, self.length_m, m)
        return lam, self.point(lam)

    def closest_lambda(
        self, point_W: ArrayLike, within: tuple[float, float] | None = None
    ) -> float | _Array:
        """Lambda whose point is closest to ``point_W`` in the **xy** plane.

        Used for Lambda_t (section 8.2.2, the trajectory point near the body) and the
        reference direction u_f of section 7.3 (lambda near r_c*). Heights are ignored, so a
        body above the path projects onto it. Ties go to the smallest lambda.

        Parameters
        ----------
        point_W : array_like, shape (3,) or (..., 3) (only x, y used; (..., 2) accepted)
            Query points [m], world frame.
        within : (float, float), optional
            Restrict the search to lambda in this interval (e.g. near the last value, for a
            path that crosses itself).

        Returns
        -------
        float or ndarray (...)
            lambda [m] in [0, L].

        """
        q = np.asarray(point_W, dtype=float)
        if q.shape[-1] not in (2, 3) or not np.all(np.isfinite(q)):
            raise InputError(
                f"closest_lambda: point_W must be finite (..., 3) or (..., 2), got {q.shape}"
            )
        lo, hi = (0.0, self.length_m) if within is None else (float(within[0]), float(within[1]))
        lo, hi = max(0.0, lo), min(self.length_m, hi)
        if hi < lo:
            raise InputError(f"closest_lambda: empty interval within={within!r}")
        flat = q[..., :2].reshape(-1, 2)
        out = np.array([self._closest_xy(p, lo, hi) for p in flat])
        return float(out[0]) if q.ndim == 1 else out.reshape(q.shape[:-1])

    def _closest_xy(self, p_xy: _Array, lo: float, hi: float) -> float:
        lam, pts = self._dense()
        sel = (lam >= lo) & (lam <= hi)
        lam_s = np.concatenate([[lo], lam[sel], [hi]])
        pts_s = np.concatenate([self.point([lo]), pts[sel], self.point([hi])])
        d2 = np.sum((pts_s[:, :2] - p_xy) ** 2, axis=1)
        k = int(np.argmin(d2))
        a, b = lam_s[max(k - 1, 0)], lam_s[min(k + 1, len(lam_s) - 1)]
        if b - a <= 0:
            return float(lam_s[k])

        def f(x: float) -> float:
            return float(np.sum((self.point(x)[:2] - p_xy) ** 2))

        from scipy.optimize import minimize_scalar  # imported here: ~0.5 s, rarely needed

        res = minimize_scalar(f, bounds=(a, b), method="bounded", options={"xatol": 1e-12})
        best = float(res.x) if f(res.x) <= d2[k] else float(lam_s[k])
        return best


class PolylineTrajectory(Trajectory):
    """Straight segments through waypoints, lambda the exact arc length."""

    def __init__(self, waypoints_W: _Array, kind: str = "polyline"):
        self.kind = kind
        self.waypoints_W = np.asarray(waypoints_W, dtype=float)
        seg = np.diff(self.waypoints_W, axis=0)
        self._seg_len = np.linalg.norm(seg, axis=1)
        self._dir = seg / self._seg_len[:, None]
        self._s = np.concatenate([[0.0], np.cumsum(self._seg_len)])
        self.length_m = float(self._s[-1])

    def _segment(self, lam: _Array) -> _Array:
        k = np.searchsorted(self._s, lam, side="right") - 1
        return np.clip(k, 0, len(self._seg_len) - 1)

    def point(self, lam: ArrayLike) -> _Array:
        """R_tau(lambda) [m]; lambda (...) clipped to [0, L]; returns (..., 3)."""
        lam = self.clip(lam)
        k = self._segment(lam)
        return self.waypoints_W[k] + (lam - self._s[k])[..., None] * self._dir[k]

    def tangent(self, lam: ArrayLike) -> _Array:
        """Unit segment direction at lambda (outgoing one at a vertex); (..., 3)."""
        return self._dir[self._segment(self.clip(lam))].copy()

    def breaks_lambda(self) -> _Array:
        """The vertices' lambdas."""
        return self._s.copy()

    def _dense(self) -> tuple[_Array, _Array]:
        return self._s, self.waypoints_W

    def _closest_xy(self, p_xy: _Array, lo: float, hi: float) -> float:
        """Exact: projection onto every segment's xy shadow, arc length kept 3-D."""
        a = self.waypoints_W[:-1, :2]
        d = self.waypoints_W[1:, :2] - a
        dd = np.sum(d * d, axis=1)
        f = np.where(dd > 0, np.sum((p_xy - a) * d, axis=1) / np.where(dd > 0, dd, 1.0), 0.0)
        lam = self._s[:-1] + np.clip(f, 0.0, 1.0) * self._seg_len
        lam = np.clip(lam, np.maximum(lo, self._s[:-1]), np.minimum(hi, self._s[1:]))
        valid = (self._s[1:] >= lo) & (self._s[:-1] <= hi)
        pts = self.point(lam)
        d2 = np.where(valid, np.sum((pts[:, :2] - p_xy) ** 2, axis=1), np.inf)
        return float(lam[int(np.argmin(d2))])


class CurveTrajectory(Trajectory):
    """A smooth (piecewise smooth) curve c(t), t in [0, T], reparametrised by arc length.

    The arc length s(t) is tabulated with 5-point Gauss-Legendre quadrature of |c'(t)| on a
    grid of at most 2 mm that includes ``breaks`` (where c may have kinks); lambda -> t is
    inverted by interpolation of that table followed by Newton steps on s(t) - lambda.
    """

    def __init__(
        self,
        kind: str,
        curve: Callable[[_Array], _Array],
        curve_derivative: Callable[[_Array], _Array],
        t_end: float,
        breaks: ArrayLike | None = None,
        waypoints_W: ArrayLike | None = None,
        base: Trajectory | None = None,
        coefficients: _Array | None = None,
    ):
        self.kind = kind
        self._c, self._dc, self._T = curve, curve_derivative, float(t_end)
        self.base, self.coefficients = base, coefficients
        extra = np.zeros(0) if breaks is None else np.asarray(breaks, dtype=float).ravel()
        brk = np.unique(np.clip(np.r_[0.0, self._T, extra], 0.0, self._T))
        grid = [brk[:1]]
        for a, b in zip(brk[:-1], brk[1:], strict=True):
            m = max(1, int(np.ceil((b - a) / _GRID_STEP_M)))
            grid.append(np.linspace(a, b, m + 1)[1:])
        self._t = np.concatenate(grid)
        ds = self._arc(self._t[:-1], self._t[1:])
        self._s = np.concatenate([[0.0], np.cumsum(ds)])
        self.length_m = float(self._s[-1])
        if not (self.length_m > 0 and np.isfinite(self.length_m)):
            raise InputError(f"{kind} trajectory: zero or non-finite length")
        self.waypoints_W = (
            self._c(np.array([0.0, self._T])) if waypoints_W is None else np.asarray(waypoints_W)
        )
        self._dense_pts = self._c(self._t)

    def _speed(self, t: _Array) -> _Array:
        return np.linalg.norm(self._dc(t), axis=-1)

    def _arc(self, a: _Array, b: _Array) -> _Array:
        """Arc length from t=a to t=b (elementwise), Gauss-Legendre."""
        a, b = np.asarray(a, float), np.asarray(b, float)
        mid, half = 0.5 * (a + b), 0.5 * (b - a)
        nodes = mid[..., None] + half[..., None] * _GL_X
        return half * (self._speed(nodes) @ _GL_W)

    def t_of_lambda(self, lam: ArrayLike) -> _Array:
        """Curve parameter t for arc length lambda (clipped to [0, L])."""
        lam = self.clip(lam)
        t = np.interp(lam, self._s, self._t)
        for _ in range(4):
            k = np.clip(np.searchsorted(self._t, t, side="right") - 1, 0, len(self._t) - 2)
            s = self._s[k] + self._arc(self._t[k], t)
            v = np.maximum(self._speed(t), 1e-12)
            t = np.clip(t - (s - lam) / v, self._t[k], self._t[k + 1])
        return t

    def point(self, lam: ArrayLike) -> _Array:
        """R_tau(lambda) [m]; lambda (...) clipped to [0, L]; returns (..., 3)."""
        lam = np.asarray(lam, dtype=float)
        out = self._c(self.t_of_lambda(lam))
        return out.reshape(lam.shape + (3,))

    def tangent(self, lam: ArrayLike) -> _Array:
        """Unit tangent c'(t)/|c'(t)| at lambda; (..., 3)."""
        lam = np.asarray(lam, dtype=float)
        d = self._dc(self.t_of_lambda(lam)).reshape(lam.shape + (3,))
        n = np.linalg.norm(d, axis=-1, keepdims=True)
        if np.any(n < 1e-12):  # a cusp: use the chord direction around it
            h = 1e-6
            chord = self.point(lam + h) - self.point(lam - h)
            d = np.where(n < 1e-12, chord, d)
            n = np.linalg.norm(d, axis=-1, keepdims=True)
        return d / n

    def breaks_lambda(self) -> _Array:
        """Lambdas of the ends."""
        return np.array([0.0, self.length_m])

    def _dense(self) -> tuple[_Array, _Array]:
        return self._s, self._dense_pts


def _ground_max(terrain: _HeightTerrain, xy: _Array, radius_m: float) -> _Array:
    """Max terrain height over disks of ``radius_m`` around each xy (N, 2) (sharp heights)."""
    height = getattr(terrain, "height_sharp", None) or terrain.height
    offsets = [np.zeros(2)]
    if radius_m > 0:
        for ring in np.linspace(radius_m / 4, radius_m, 4):
            m = max(8, int(np.ceil(2 * np.pi * ring / 0.01)))
            ang = np.linspace(0, 2 * np.pi, m, endpoint=False)
            offsets.extend(ring * np.column_stack([np.cos(ang), np.sin(ang)]))
    off = np.array(offsets)
    pts = xy[:, None, :] + off[None, :, :]
    h = np.asarray(height(pts[..., 0], pts[..., 1]), dtype=float)
    return h.max(axis=1)
