"""Contact forces of a quasi-static stance and its static feasibility.

Two answers to "can this stance stand?":

1. **The paper's particular solution** (section 5.2).  The weight-carrying feet get
   *equilibrating* forces with zero *interaction* components, ``F_i = u x r_i + w``
   (eq. 3), where ``(u, w)`` solve the 6x6 force and moment balance (eqs. 4-5).  The
   stance is then accepted if these forces satisfy the inequalities (d) ``F_i.n_i > 0``
   and (e) ``|F_i - (F_i.n_i) n_i| < mu F_i.n_i`` of section 7.3 (how far inside the
   cones they are, the paper's sigma5, is an objective term of the Theta problems,
   :mod:`planner.problems.base`).  Provided in numpy (:func:`equilibrating_forces`) and
   CasADi (:func:`equilibrating_forces_ca`, exact derivatives for IPOPT).

2. **The exact test** (beyond the paper; eq. 5 is only one of infinitely many force
   systems).  :func:`static_feasibility` decides whether *any* contact forces inside
   the friction cones balance gravity and moments at the given centre of mass, as a
   second-order-cone program (SOCP), and :func:`feasible_com_region` gives the set of
   horizontal COM positions for which such forces exist.

Why Clarabel for the SOCP: the friction cones ``||F_t|| <= mu F_n`` are exact Lorentz
(second-order) cones, so an interior-point conic solver decides feasibility exactly
(to solver tolerance ~1e-8) with no linearised pyramid and its inner/outer
approximation error; ``scipy.optimize.linprog`` is LP-only and would need such a
pyramid.  Clarabel (Oxford control group, Apache-2.0) is a native Rust interior-point
solver with a pip wheel and a Python API (no compilation); on these 10-14 variable
problems one solve takes well under a millisecond, and a built solver can be re-solved
with a new objective (used for the 32 support directions of the COM region).

Conventions: world frame ``_W``, SI units (m, kg, N); legs are 0-based indices
``0..3`` (FL, FR, HL, HR); a ``support`` is a sequence of 3 or 4 distinct leg indices or
a boolean mask of length 4.  Positions are expressed relative to the centroid of the
support feet and scaled by their RMS radius inside the solvers (the forces do not
depend on the origin; only ``w`` of eq. 3 does), which keeps every system well
conditioned.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import clarabel
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from planner.body.polygon import convex_hull, polygon_signed_distance
from planner.core.errors import InputError, PlannerError
from planner.core.units import GRAVITY_M_S2

__all__ = [
    "GRAVITY_W",
    "COND_MAX",
    "DegenerateStanceError",
    "EquilibriumForces",
    "StaticFeasibility",
    "support_indices",
    "equilibrating_forces",
    "equilibrating_forces_ca",
    "friction_cone_residuals",
    "forces_in_friction_cones",
    "friction_cone_residuals_ca",
    "static_feasibility",
    "feasible_com_region",
    "polygon_signed_distance",
]

GRAVITY_W: tuple[float, float, float] = (0.0, 0.0, -GRAVITY_M_S2)
"""Default gravity vector in the world frame [m/s^2]."""

COND_MAX: float = 1e8
"""Above this condition number of the scaled eq.-5 system a stance is degenerate."""

N_LEGS = 4
# contacts within this of one horizontal plane (in RMS support radii), normals and gravity
# within this of vertical: the feasible COM region in closed form (the support polygon)
LEVEL_TOL = 1e-9
_Array = NDArray[np.float64]
_SOLVED = ("Solved", "AlmostSolved")


class DegenerateStanceError(PlannerError):
    """The support feet cannot determine eq.-5 forces (collinear or coincident feet)."""


@dataclass(frozen=True)
class EquilibriumForces:
    """Result of :func:`equilibrating_forces` (paper eqs. 3-5).

    Attributes
    ----------
    forces : ndarray (4, 3)
        ``F_i`` [N] in the world frame; zero rows for feet not in ``support`` (and all
        zeros when ``degenerate``).
    u : ndarray (3,)
        ``u`` of eq. 3 [N/m].
    w : ndarray (3,)
        ``w`` of eq. 3 [N], for positions measured from the world origin.
    condition_number : float
        2-norm condition number of the eq.-5 matrix in centroid-relative, RMS-radius
        scaled coordinates (a geometric quantity; ``inf`` if singular).
    degenerate : bool
        True when the system is singular or ill conditioned (``> cond_max``).
    reason : str
        Empty, or why the stance is degenerate.
    support : tuple of int
        The weight-carrying legs, sorted.

    """

    forces: _Array
    u: _Array
    w: _Array
    condition_number: float
    degenerate: bool
    reason: str
    support: tuple[int, ...]


@dataclass(frozen=True)
class StaticFeasibility:
    """Result of :func:`static_feasibility` (exact SOCP test).

    Attributes
    ----------
    feasible : bool
        True iff contact forces strictly inside every support foot's friction cone
        balance gravity and moments, i.e. ``margin_N > tol_N``.
    margin_N : float
        Force margin [N]: the largest ``s`` such that balancing forces exist whose
        every support force is at Euclidean distance ``>= s`` from the boundary of its
        friction cone, ``mu F_i.n_i - ||F_t,i|| >= s sqrt(1 + mu^2)``, capped at the
        weight ``m|g|`` (reached only when squeezing internal forces could raise it
        without bound, e.g. feet on facing slopes).  Negative: how far the best forces
        are from the cones; ``-inf`` when no forces balance at all (collinear feet with
        the COM off their line); ``nan`` if the solver failed (see ``status``).
    forces : ndarray (4, 3)
        The forces [N] at the optimum of that margin problem (zeros off support).
    status : str
        Clarabel status (``"Solved"``, ``"PrimalInfeasible"``, ...).
    solve_time_s : float
        Wall time of building and solving the margin SOCP [s].
    com_margin_m : float or None
        Signed distance [m] of the COM's horizontal projection to the boundary of
        the feasible COM region (:func:`feasible_com_region`), positive inside,
        ``-inf`` if the region is empty; None when not computed.  A knife-edge stance
        (collinear feet, COM on their line) can be ``feasible`` with ``com_margin_m``
        zero: check both margins.
    com_region_xy : ndarray (K, 2) or None
        That region's polygon (counter-clockwise), or None when not computed.
    support : tuple of int
        The weight-carrying legs, sorted.

    """

    feasible: bool
    margin_N: float
    forces: _Array
    status: str
    solve_time_s: float
    com_margin_m: float | None
    com_region_xy: _Array | None
    support: tuple[int, ...]


# ----------------------------------------------------------------------------- inputs


def _array(x: ArrayLike, name: str, shape: tuple[int, ...], what: str) -> _Array:
    """Return ``x`` as a finite float array of ``shape`` or raise InputError."""
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: expected {what} as numbers, got {x!r} ({exc})") from None
    if a.shape != shape:
        raise InputError(f"{name}: expected {what} of shape {shape}, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name}: contains NaN or inf; pass finite {what}")
    return a


def _positive(x: float, name: str, what: str, allow_zero: bool = False) -> float:
    """Return ``x`` as a finite float > 0 (or >= 0) or raise InputError."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected {what} as a number, got {x!r}") from None
    if not math.isfinite(v) or v < 0.0 or (v == 0.0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise InputError(f"{name}: expected a finite {what} {bound}, got {x!r}")
    return v


def support_indices(support: Sequence[int] | Sequence[bool] | ArrayLike) -> tuple[int, ...]:
    """Return the sorted 0-based leg indices of a support (3 or 4 weight-carrying feet).

    Parameters
    ----------
    support : sequence of int, or boolean mask of length 4
        Leg indices in ``0..3`` (FL, FR, HL, HR), distinct; or a mask.

    Raises
    ------
    InputError
        Malformed indices, or fewer than 3 feet (point contacts on fewer than three
        feet cannot hold a quasi-static stance, and eqs. 3-5 need three).

    """
    arr = np.asarray(support)
    if arr.dtype == bool:
        if arr.shape != (N_LEGS,):
            raise InputError(f"support: a boolean mask needs 4 entries, got shape {arr.shape}")
        idx = tuple(int(i) for i in np.flatnonzero(arr))
    else:
        integral = arr.size == 0 or np.issubdtype(arr.dtype, np.integer)
        if arr.ndim != 1 or not integral:
            raise InputError(
                f"support: expected leg indices 0..3 (a sequence of int) or a mask of 4 bools,"
                f" got {support!r}"
            )
        idx = tuple(int(i) for i in arr)
        if any(i < 0 or i >= N_LEGS for i in idx) or len(set(idx)) != len(idx):
            raise InputError(f"support: leg indices must be distinct and in 0..3, got {idx}")
    if len(idx) < 3:
        raise InputError(
            f"support: needs 3 or 4 weight-carrying feet, got {len(idx)} {list(idx)};"
            " a stance on fewer point contacts cannot be statically balanced"
        )
    return tuple(sorted(idx))


def _normals(normals_W: ArrayLike | None) -> _Array:
    """Return unit terrain normals (4, 3); default +z for every foot."""
    if normals_W is None:
        return np.tile([0.0, 0.0, 1.0], (N_LEGS, 1))
    n = _array(normals_W, "normals_W", (N_LEGS, 3), "a (4, 3) array of terrain normals")
    norms = np.linalg.norm(n, axis=1)
    if np.any(norms < 1e-9):
        raise InputError("normals_W: a normal has zero length; pass one unit normal per foot")
    return n / norms[:, None]


def _gravity(gravity_W: ArrayLike) -> _Array:
    g = _array(gravity_W, "gravity_W", (3,), "a gravity 3-vector [m/s^2]")
    if np.linalg.norm(g) == 0.0:
        raise InputError("gravity_W: is zero; pass the gravity vector, e.g. (0, 0, -9.81)")
    return g


def _hat(v: _Array) -> _Array:
    """Skew-symmetric matrix, ``_hat(v) @ x == cross(v, x)``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _hat_ca(v: ca.SX | ca.MX | ca.DM) -> ca.SX | ca.MX | ca.DM:
    z = 0 * v[0]
    return ca.vertcat(
        ca.horzcat(z, -v[2], v[1]), ca.horzcat(v[2], z, -v[0]), ca.horzcat(-v[1], v[0], z)
    )


def _cross(a: _Array, b: _Array) -> _Array:
    """Cross product of 3-vectors or rows of (k, 3) arrays (faster than np.cross)."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _tangent_bases(n: _Array) -> tuple[_Array, _Array]:
    """Rows ``t1, t2`` completing unit normals ``n`` (k, 3) to right-handed frames."""
    a = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = _cross(n, a)
    t1 /= np.sqrt(np.einsum("ij,ij->i", t1, t1))[:, None]
    return t1, _cross(n, t1)


@functools.lru_cache(maxsize=16)
def _zero_csc(n: int) -> sp.csc_matrix:
    """The (n, n) zero matrix in CSC, built once per size: a linear cost's P.

    It has no entries, so no solve can change it: one instance serves them all.
    """
    return sp.csc_matrix((n, n))


def _csc(a: _Array) -> _CscView:
    """Dense -> CSC for Clarabel, without scipy's per-matrix construction and checks.

    The statics and torque SOCPs come in a few sparsity patterns, asked thousands of times
    a walk (scipy's checks cost more than the solve): a pattern's index arrays are built
    once (:func:`_csc_pattern`) and each matrix is a :class:`_CscView` of them with its
    own values, in scipy's canonical CSC form (the same arrays scipy would build).
    """
    mask = a.T != 0.0
    rows, indptr = _csc_pattern(a.shape, mask.tobytes())
    return _CscView(a.shape, indptr, rows, a.T[mask])


class _CscView:
    """The attributes of a canonical ``scipy.sparse.csc_matrix`` that Clarabel reads."""

    format = "csc"
    has_canonical_format = True

    def __init__(self, shape: tuple[int, int], indptr, indices, data):
        self.shape, self.indptr, self.indices, self.data = shape, indptr, indices, data
        self.nnz = len(data)

    def toarray(self) -> _Array:
        """The dense matrix (for tests and debugging)."""
        return sp.csc_matrix((self.data, self.indices, self.indptr), shape=self.shape).toarray()


@functools.lru_cache(maxsize=256)
def _csc_pattern(shape: tuple[int, int], mask_bytes: bytes) -> tuple[_Array, _Array]:
    """(row indices, column pointers) of the CSC pattern ``mask_bytes`` (of ``a.T != 0``)."""
    mask = np.frombuffer(mask_bytes, dtype=bool).reshape(shape[1], shape[0])
    _, rows = np.nonzero(mask)
    indptr = np.concatenate([[0], np.cumsum(mask.sum(axis=1))])
    return rows.astype(np.int32), indptr.astype(np.int32)


# ------------------------------------------------------------------------ eqs. 3-5


def _eq5_system(rho: _Array, rho_c: _Array, weight: _Array) -> tuple[_Array, _Array]:
    """Eq. 5 at the support centroid, lengths scaled: ``A [u L; w] = b``.

    With the origin at the centroid ``R^ = sum_i r^_i = 0`` identically, so eq. 5
    reads ``[[0, n I], [-sum r^_i^2, -n r^_c]] [u; w] = [-m g; 0]`` (moments taken as
    ``sum (r_i - r_c) x F_i``; lengths in units of the RMS radius ``L``).
    """
    n = rho.shape[0]
    s2 = rho.T @ rho - np.sum(rho * rho) * np.eye(3)  # sum_i r^_i r^_i
    a = np.zeros((6, 6))
    a[:3, 3:] = n * np.eye(3)
    a[3:, :3] = -s2
    a[3:, 3:] = -n * _hat(rho_c)
    return a, np.concatenate([weight, np.zeros(3)])


def equilibrating_forces(
    feet_W: ArrayLike,
    com_W: ArrayLike,
    mass_kg: float,
    support: Sequence[int] | Sequence[bool],
    gravity_W: ArrayLike = GRAVITY_W,
    *,
    strict: bool = False,
    cond_max: float = COND_MAX,
) -> EquilibriumForces:
    """Equilibrating contact forces with zero interaction components (paper 5.2).

    Solves eq. 5 for ``(u, w)`` and returns ``F_i = u x r_i + w`` (eq. 3) for the
    support feet, which balance gravity and moments about the COM (eq. 4) and have
    ``(F_i - F_j).(r_i - r_j) = 0``.  This is one particular solution, not the only
    one; see :func:`static_feasibility` for the exact question.

    Parameters
    ----------
    feet_W : array (4, 3)
        Foot contact points ``r_i`` [m]; rows of legs not in ``support`` are ignored.
    com_W : array (3,)
        Centre of mass ``r_c`` [m].
    mass_kg : float
        Total mass ``m`` [kg].
    support : sequence of int or mask of 4 bool
        The 3 or 4 weight-carrying legs (0-based).
    gravity_W : array (3,)
        Gravity ``g`` [m/s^2].
    strict : bool
        Raise :class:`DegenerateStanceError` instead of returning a degenerate result.
    cond_max : float
        Condition-number threshold of the scaled 6x6 system.

    Returns
    -------
    EquilibriumForces
        With ``degenerate=True``, zero forces and a ``reason`` when the support feet are
        collinear or coincident (singular eq. 5), or the system is ill conditioned.

    """
    feet = _array(feet_W, "feet_W", (N_LEGS, 3), "a (4, 3) array of foot positions [m]")
    com = _array(com_W, "com_W", (3,), "a centre-of-mass 3-vector [m]")
    m = _positive(mass_kg, "mass_kg", "mass [kg]")
    g = _gravity(gravity_W)
    sup = support_indices(support)
    r = feet[list(sup)]
    centroid = r.mean(axis=0)
    rel = r - centroid
    length = math.sqrt(float(np.mean(np.sum(rel * rel, axis=1))))
    zeros4, zeros3 = np.zeros((N_LEGS, 3)), np.zeros(3)
    if length <= 1e-12 * max(1.0, float(np.abs(feet).max())):
        cond = math.inf
    else:
        a, b = _eq5_system(rel / length, (com - centroid) / length, -m * g)
        cond = float(np.linalg.cond(a))
    if not math.isfinite(cond) or cond > cond_max:
        reason = (
            f"support feet {list(sup)} are (nearly) collinear or coincident: eq. 5 is singular"
            f" (condition number {cond:.3g} > {cond_max:.3g}); no unique equilibrating forces"
        )
        if strict:
            raise DegenerateStanceError(f"feet_W/support: {reason}; choose non-collinear feet")
        return EquilibriumForces(zeros4, zeros3, zeros3.copy(), cond, True, reason, sup)
    x = np.linalg.solve(a, b)
    u_scaled, w_c = x[:3], x[3:]
    forces = zeros4.copy()
    forces[list(sup)] = _cross(u_scaled, rel / length) + w_c
    u = u_scaled / length
    w = w_c - _cross(u, centroid)  # eq. 3 about the world origin
    return EquilibriumForces(forces, u, w, cond, False, "", sup)


def _vectors_ca(feet: object, name: str = "feet_W") -> list:
    """Four 3x1 CasADi vectors from a 3x4 matrix or a list of four 3-vectors."""
    if isinstance(feet, (list, tuple)):
        if len(feet) != N_LEGS:
            raise InputError(f"{name}: expected four 3-vectors, got {len(feet)}")
        out = [f if isinstance(f, (ca.SX, ca.MX, ca.DM)) else ca.DM(f) for f in feet]
        out = [ca.reshape(f, 3, 1) if f.numel() == 3 else f for f in out]
    else:
        if isinstance(feet, np.ndarray) and feet.shape == (N_LEGS, 3):
            feet = feet.T
        if not isinstance(feet, (ca.SX, ca.MX, ca.DM)):
            feet = ca.DM(np.asarray(feet, dtype=float))
        if feet.shape != (3, N_LEGS):
            raise InputError(
                f"{name}: expected a 3x4 matrix (one column per leg), got {feet.shape}"
            )
        out = [feet[:, i] for i in range(N_LEGS)]
    for i, f in enumerate(out):
        if f.shape != (3, 1):
            raise InputError(f"{name}[{i}]: expected a 3-vector, got shape {f.shape}")
    return out


def _vec3_ca(v: object, name: str) -> ca.SX | ca.MX | ca.DM:
    if not isinstance(v, (ca.SX, ca.MX, ca.DM)):
        v = ca.DM(np.asarray(v, dtype=float).reshape(-1))
    if v.numel() != 3:
        raise InputError(f"{name}: expected a 3-vector, got shape {v.shape}")
    return ca.reshape(v, 3, 1)


def equilibrating_forces_ca(
    feet_W: object,
    com_W: object,
    mass_kg: object,
    support: Sequence[int] | Sequence[bool],
    gravity_W: object = GRAVITY_W,
) -> list:
    """CasADi version of :func:`equilibrating_forces` (eqs. 3-5) with exact derivatives.

    Builds the same centroid-relative, RMS-scaled 6x6 system and solves it with
    ``casadi.solve``, so the result equals the numpy one to rounding.  No degeneracy
    check can be made symbolically: for collinear support feet the system is singular
    and the forces are inf/NaN; guard the stance (e.g. with :func:`equilibrating_forces`
    or a geometric constraint) where that can happen.

    Parameters
    ----------
    feet_W : SX/MX/DM 3x4, or list of four 3-vectors
        Foot contact points ``r_i`` [m] (columns); non-support feet are ignored.
    com_W : SX/MX/DM 3-vector
        Centre of mass [m].
    mass_kg : float or scalar SX/MX
        Total mass [kg].
    support : tuple of int or mask of 4 bool
        Fixed weight-carrying legs (a Python constant of the built problem).
    gravity_W : 3-vector
        Gravity [m/s^2].

    Returns
    -------
    list
        Four 3x1 force vectors [N] (same CasADi type), zeros for non-support legs.

    """
    sup = support_indices(support)
    feet = _vectors_ca(feet_W, "feet_W")
    com = _vec3_ca(com_W, "com_W")
    g = _vec3_ca(gravity_W, "gravity_W")
    r = [feet[i] for i in sup]
    n = len(sup)
    centroid = sum(r[1:], r[0]) / n
    rel = [ri - centroid for ri in r]
    length = ca.sqrt(sum(ca.dot(q, q) for q in rel) / n)
    rho = [q / length for q in rel]
    rho_c = (com - centroid) / length
    s2 = sum(q @ q.T for q in rho) - sum(ca.dot(q, q) for q in rho) * ca.DM.eye(3)
    zero3 = ca.DM.zeros(3, 3)
    a = ca.vertcat(
        ca.horzcat(zero3, n * ca.DM.eye(3)),
        ca.horzcat(-s2, -n * _hat_ca(rho_c)),
    )
    b = ca.vertcat(-mass_kg * g, ca.DM.zeros(3, 1))
    x = ca.solve(a, b)
    u_scaled, w_c = x[:3], x[3:]
    forces_sup = {i: ca.cross(u_scaled, q) + w_c for i, q in zip(sup, rho, strict=True)}
    zero = type(forces_sup[sup[0]]).zeros(3, 1)
    return [forces_sup.get(i, zero) for i in range(N_LEGS)]


# ------------------------------------------------------------------- section 7.3 (d), (e)


def _forces(forces_W: ArrayLike) -> _Array:
    return _array(forces_W, "forces_W", (N_LEGS, 3), "a (4, 3) array of contact forces [N]")


def friction_cone_residuals(
    forces_W: ArrayLike,
    mu: float,
    support: Sequence[int] | Sequence[bool],
    normals_W: ArrayLike | None = None,
) -> _Array:
    """Exact residuals of the force inequalities (d) and (e) of paper section 7.3.

    Returns
    -------
    ndarray (k, 2)
        Per support foot (sorted legs): ``[F_i.n_i, mu F_i.n_i - |F_i - (F_i.n_i) n_i|]``
        [N]; (d) and (e) hold iff both columns are ``> 0``.

    """
    f = _forces(forces_W)
    mu = _positive(mu, "mu", "friction coefficient", allow_zero=True)
    n = _normals(normals_W)
    sup = list(support_indices(support))
    fn = np.einsum("ij,ij->i", f[sup], n[sup])
    ft = f[sup] - fn[:, None] * n[sup]
    return np.column_stack([fn, mu * fn - np.linalg.norm(ft, axis=1)])


def forces_in_friction_cones(
    forces_W: ArrayLike,
    mu: float,
    support: Sequence[int] | Sequence[bool],
    normals_W: ArrayLike | None = None,
    tol_N: float = 0.0,
) -> bool:
    """Whether inequalities (d) and (e) of section 7.3 hold: all residuals ``> tol_N``."""
    return bool(np.all(friction_cone_residuals(forces_W, mu, support, normals_W) > tol_N))


def _normals_ca(normals_W: object) -> list:
    """Four unit normals (CasADi) from None (+z), a (4, 3) array or four 3-vectors."""
    symbolic = isinstance(normals_W, (ca.SX, ca.MX)) or (
        isinstance(normals_W, (list, tuple))
        and any(isinstance(v, (ca.SX, ca.MX)) for v in normals_W)
    )
    if not symbolic:
        if isinstance(normals_W, (list, tuple)):
            normals_W = [np.asarray(v, dtype=float).reshape(-1) for v in normals_W]
        elif isinstance(normals_W, ca.DM):
            normals_W = np.asarray(normals_W).T  # 3x4 -> (4, 3)
        return [ca.DM(v) for v in _normals(normals_W)]
    return [v / ca.norm_2(v) for v in _vectors_ca(normals_W, "normals_W")]


def friction_cone_residuals_ca(
    forces: Sequence,
    mu: object,
    support: Sequence[int] | Sequence[bool],
    normals_W: object = None,
    *,
    form: str = "smooth",
    eps_N: float = 1e-3,
) -> ca.SX | ca.MX:
    """Smooth CasADi residuals of inequalities (d), (e) of section 7.3, all ``>= 0``.

    Per support foot (sorted legs) two entries, stacked into one column:

    - (d) ``F_i.n_i``;
    - (e) ``form="smooth"``: ``mu F_i.n_i - sqrt(|F_t,i|^2 + eps_N^2)``, differentiable
      everywhere and conservative (it implies the exact cone, tightened by at most
      ``eps_N`` newtons); ``form="squared"``: ``mu^2 (F_i.n_i)^2 - |F_t,i|^2``, which
      together with (d) is equivalent to the closed cone (polynomial, but its gradient
      vanishes at ``F = 0``).

    The independent validator uses the exact :func:`friction_cone_residuals`.

    Parameters
    ----------
    forces : list of four 3-vectors, or 3x4 (SX/MX)
        ``F_i`` [N], e.g. from :func:`equilibrating_forces_ca`.
    mu : float or scalar SX/MX
        Friction coefficient.
    support : tuple of int or mask of 4 bool
        Weight-carrying legs.
    normals_W : None (+z), (4, 3) array, or list of four CasADi 3-vectors
        Terrain normals (normalised here).
    form : {"smooth", "squared"}
        Which form of (e), see above.
    eps_N : float
        Smoothing of ``|F_t|`` [N] for ``form="smooth"``.

    """
    if form not in ("smooth", "squared"):
        raise InputError(f"form: expected 'smooth' or 'squared', got {form!r}")
    sup = support_indices(support)
    forces = _vectors_ca(forces, "forces")
    ns = _normals_ca(normals_W)
    out = []
    for i in sup:
        f, n = forces[i], ns[i]
        fn = ca.dot(f, n)
        ft = f - fn * n
        ft2 = ca.dot(ft, ft)
        cone = mu * fn - ca.sqrt(ft2 + eps_N**2) if form == "smooth" else mu**2 * fn**2 - ft2
        out += [fn, cone]
    return ca.vertcat(*out)


# --------------------------------------------------------------------- exact SOCP test


@dataclass(frozen=True)
class _Scaled:
    """Support geometry in centroid-relative, RMS-radius units, forces in units m|g|."""

    sup: tuple[int, ...]
    centroid: _Array
    length: float
    rho: _Array  # (k, 3)
    normals: _Array  # (k, 3)
    tangents1: _Array  # (k, 3)
    tangents2: _Array  # (k, 3)
    gamma: _Array  # -g/|g|: the sum of scaled forces
    weight_N: float


def _scaled(
    feet_W: ArrayLike,
    mass_kg: float,
    support: Sequence[int] | Sequence[bool],
    normals_W: ArrayLike | None,
    gravity_W: ArrayLike,
) -> _Scaled:
    feet = _array(feet_W, "feet_W", (N_LEGS, 3), "a (4, 3) array of foot positions [m]")
    m = _positive(mass_kg, "mass_kg", "mass [kg]")
    g = _gravity(gravity_W)
    n = _normals(normals_W)
    sup = support_indices(support)
    r = feet[list(sup)]
    centroid = r.mean(axis=0)
    length = math.sqrt(float(np.mean(np.sum((r - centroid) ** 2, axis=1))))
    if length <= 1e-9:
        length = 1.0  # coincident feet: any unit works
    gnorm = float(np.linalg.norm(g))
    nrm = n[list(sup)]
    t1, t2 = _tangent_bases(nrm)
    return _Scaled(
        sup, centroid, length, (r - centroid) / length, nrm, t1, t2, -g / gnorm, m * gnorm
    )


# Clarabel settings tried in turn when a solve ends neither solved nor infeasible
# (InsufficientProgress / NumericalError were seen on ordinary four-foot stances with
# equilibration on; off, or with more regularisation, the same problems solve).
_RETRIES = (
    {},
    {"equilibrate_enable": False},
    {"static_regularization_constant": 1e-7},
)


def _settings() -> clarabel.DefaultSettings:
    s = clarabel.DefaultSettings()
    s.verbose = False
    return s


def _cone_rows(sc: _Scaled, mu: float, n_var: int, margin_col: int | None) -> _Array:
    """Rows ``-A`` of the friction Lorentz cones ``(mu n.f - c s, t1.f, t2.f) in SOC(3)``."""
    k = len(sc.sup)
    a = np.zeros((3 * k, n_var))
    for j in range(k):
        a[3 * j, 3 * j : 3 * j + 3] = -mu * sc.normals[j]
        a[3 * j + 1, 3 * j : 3 * j + 3] = -sc.tangents1[j]
        a[3 * j + 2, 3 * j : 3 * j + 3] = -sc.tangents2[j]
        if margin_col is not None:
            a[3 * j, margin_col] = math.sqrt(1.0 + mu * mu)
    return a


def _balance_rows(sc: _Scaled, n_var: int) -> _Array:
    """Force and moment balance on the scaled forces: ``[I ... I; rho^_1 ... rho^_k]``."""
    k = len(sc.sup)
    a = np.zeros((6, n_var))
    for j in range(k):
        a[:3, 3 * j : 3 * j + 3] = np.eye(3)
        a[3:, 3 * j : 3 * j + 3] = _hat(sc.rho[j])
    return a


def _margin_socp(sc: _Scaled, com_W: _Array, mu: float) -> tuple[float, _Array, str]:
    """Maximise the scaled cone margin; return (margin / m|g|, scaled forces (k,3), status)."""
    k = len(sc.sup)
    nv = 3 * k + 1
    rho_c = (com_W - sc.centroid) / sc.length
    a_eq = _balance_rows(sc, nv)
    b_eq = np.concatenate([sc.gamma, _cross(rho_c, sc.gamma)])
    a_cap = np.zeros((1, nv))
    a_cap[0, -1] = 1.0
    a = np.vstack([a_eq, a_cap, _cone_rows(sc, mu, nv, nv - 1)])
    b = np.concatenate([b_eq, [1.0], np.zeros(3 * k)])
    q = np.zeros(nv)
    q[-1] = -1.0
    cones = [clarabel.ZeroConeT(6), clarabel.NonnegativeConeT(1)]
    cones += [clarabel.SecondOrderConeT(3) for _ in range(k)]
    status = "not solved"
    for retry in _RETRIES:  # Clarabel now and then stalls on an ordinary stance: retry
        settings = _settings()
        for key, value in retry.items():
            setattr(settings, key, value)
        solver = clarabel.DefaultSolver(_zero_csc(nv), q, _csc(a), b, cones, settings)
        res = solver.solve()
        status = str(res.status)
        x = np.asarray(res.x)
        if status in _SOLVED:
            return float(x[-1]), x[:-1].reshape(k, 3), status
        if status in ("PrimalInfeasible", "AlmostPrimalInfeasible"):
            return -math.inf, np.zeros((k, 3)), status
    return math.nan, np.zeros((k, 3)), status


def static_feasibility(
    feet_W: ArrayLike,
    com_W: ArrayLike,
    mass_kg: float,
    support: Sequence[int] | Sequence[bool],
    mu: float,
    normals_W: ArrayLike | None = None,
    gravity_W: ArrayLike = GRAVITY_W,
    *,
    with_com_margin: bool = True,
    n_dirs: int = 32,
    tol_N: float | None = None,
) -> StaticFeasibility:
    """Decide exactly whether any friction-cone forces hold the stance (SOCP).

    Beyond the paper: eq. 5 gives one particular force system; this asks whether
    *any* forces ``F_i`` on the support feet with ``||F_i - (F_i.n_i) n_i|| <= mu F_i.n_i``
    (exact Lorentz cones, inequalities (d), (e) of section 7.3) satisfy the balance of
    eq. 4.  Solved with Clarabel as ``max s`` over ``(F, s)``: eq. 4, ``s <= m|g|`` and
    ``mu F_i.n_i - ||F_t,i|| >= s sqrt(1 + mu^2)``; see :class:`StaticFeasibility` for
    ``margin_N`` and ``com_margin_m``.

    Parameters
    ----------
    feet_W : array (4, 3)
        Foot contact points [m].
    com_W : array (3,)
        Centre of mass [m].
    mass_kg : float
        Total mass [kg].
    support : sequence of int or mask of 4 bool
        The 3 or 4 weight-carrying legs.
    mu : float
        Friction coefficient (>= 0).
    normals_W : array (4, 3), optional
        Terrain normal at each foot (normalised here); default +z.
    gravity_W : array (3,)
        Gravity [m/s^2].
    with_com_margin : bool
        Also compute the feasible COM region and ``com_margin_m`` (``n_dirs`` more
        solves).
    n_dirs : int
        Support directions of the COM region polygon.
    tol_N : float, optional
        ``feasible`` iff ``margin_N > tol_N``; default ``1e-7 m|g|`` (solver accuracy).

    """
    com = _array(com_W, "com_W", (3,), "a centre-of-mass 3-vector [m]")
    mu = _positive(mu, "mu", "friction coefficient", allow_zero=True)
    sc = _scaled(feet_W, mass_kg, support, normals_W, gravity_W)
    t0 = time.perf_counter()
    margin, f_scaled, status = _margin_socp(sc, com, mu)
    solve_time = time.perf_counter() - t0
    margin_n = margin * sc.weight_N
    tol = 1e-7 * sc.weight_N if tol_N is None else float(tol_N)
    forces = np.zeros((N_LEGS, 3))
    forces[list(sc.sup)] = f_scaled * sc.weight_N
    region = com_margin = None
    if with_com_margin:
        region = _com_region(sc, float(com[2]), mu, n_dirs)
        com_margin = polygon_signed_distance(com[:2], region) if len(region) else -math.inf
    return StaticFeasibility(
        feasible=bool(margin_n > tol),
        margin_N=float(margin_n),
        forces=forces,
        status=status,
        solve_time_s=solve_time,
        com_margin_m=com_margin,
        com_region_xy=region,
        support=sc.sup,
    )


def _level(sc: _Scaled) -> bool:
    """Whether the contacts are coplanar and horizontal, their normals and gravity vertical."""
    vertical = np.array([0.0, 0.0, 1.0])
    return (
        float(np.ptp(sc.rho[:, 2])) <= LEVEL_TOL
        and float(np.max(np.abs(sc.normals - vertical))) <= LEVEL_TOL
        and float(np.max(np.abs(sc.gamma - vertical))) <= LEVEL_TOL
    )


def _com_region(sc: _Scaled, com_z_m: float, mu: float, n_dirs: int, clip: float = 20.0) -> _Array:
    """Support-function polygon of the feasible COM xy set (see feasible_com_region).

    Level contacts (:func:`_level`) in closed form: vertical forces suffice and the
    horizontal ones cancel in the moments about a horizontal axis (they act at one height),
    so the set is the support polygon, the convex hull of the feet (7.3), for any mu.
    """
    if _level(sc):
        return sc.centroid[:2] + sc.length * convex_hull(sc.rho[:, :2], tol=1e-7)
    k = len(sc.sup)
    nv = 3 * k + 2  # scaled forces, then COM x, y (centroid-relative, units of L)
    rho_cz = (com_z_m - sc.centroid[2]) / sc.length
    gam_hat = _hat(sc.gamma)
    # moments about the COM: sum rho_i x f_i - rho_c x gamma = sum rho_i x f_i + gamma^ rho_c
    a_eq = _balance_rows(sc, nv)
    a_eq[3:, 3 * k : 3 * k + 2] = gam_hat[:, :2]
    b_eq = np.concatenate([sc.gamma, -gam_hat[:, 2] * rho_cz])
    a_box = np.zeros((4, nv))
    a_box[0, 3 * k], a_box[1, 3 * k], a_box[2, 3 * k + 1], a_box[3, 3 * k + 1] = 1, -1, 1, -1
    a = np.vstack([a_eq, a_box, _cone_rows(sc, mu, nv, None)])
    b = np.concatenate([b_eq, np.full(4, clip), np.zeros(3 * k)])
    cones = [clarabel.ZeroConeT(6), clarabel.NonnegativeConeT(4)]
    cones += [clarabel.SecondOrderConeT(3) for _ in range(k)]
    solver = None
    points = []
    for ang in np.linspace(0.0, 2.0 * math.pi, n_dirs, endpoint=False):
        q = np.zeros(nv)
        q[3 * k :] = -np.array([math.cos(ang), math.sin(ang)])
        if solver is None:
            solver = clarabel.DefaultSolver(_zero_csc(nv), q, _csc(a), b, cones, _settings())
        else:
            solver.update(q=q)
        res = solver.solve()
        status = str(res.status)
        if status in ("PrimalInfeasible", "AlmostPrimalInfeasible"):
            return np.zeros((0, 2))
        if status in _SOLVED:
            points.append(np.asarray(res.x)[3 * k :])
    if not points:
        raise PlannerError(
            f"feasible_com_region: Clarabel failed on every direction (last status {status});"
            " check that feet_W, normals_W and gravity_W are physically sensible"
        )
    hull = convex_hull(np.array(points), tol=1e-7)
    return sc.centroid[:2] + sc.length * hull


def feasible_com_region(
    feet_W: ArrayLike,
    com_z_m: float,
    mass_kg: float,
    support: Sequence[int] | Sequence[bool],
    mu: float,
    normals_W: ArrayLike | None = None,
    gravity_W: ArrayLike = GRAVITY_W,
    *,
    n_dirs: int = 32,
) -> _Array:
    """Polygon of COM horizontal positions at height ``com_z_m`` that can be held.

    The set ``{c_xy : forces in the (closed) friction cones balance gravity and
    moments with the COM at (c_xy, com_z_m)}`` is convex: since ``sum F_i = -m g`` is
    fixed, the moment balance ``sum r_i x F_i + c x m g = 0`` is linear in ``(F, c)``
    jointly, so the set is the projection of a convex cone-constrained set.  Its
    support points are found by maximising ``d_k . c_xy`` over ``(F, c_xy)`` (one SOCP
    per direction ``d_k``, ``n_dirs`` evenly spaced), and their convex hull is returned:
    an inner approximation, exact at polygon vertices (e.g. the support polygon on flat
    ground under vertical gravity).  Unbounded directions (squeezing on facing slopes)
    are clipped at 20 RMS support radii from the support centroid.

    Parameters
    ----------
    feet_W, mass_kg, support, mu, normals_W, gravity_W
        As for :func:`static_feasibility` (the region does not depend on the mass).
    com_z_m : float
        COM height [m] (matters only when gravity is not vertical).
    n_dirs : int
        Number of support directions (>= 3).

    Returns
    -------
    ndarray (K, 2)
        Counter-clockwise vertices [m]; ``(0, 2)`` if no COM position can be held.

    """
    mu = _positive(mu, "mu", "friction coefficient", allow_zero=True)
    z = _array(com_z_m, "com_z_m", (), "a COM height [m]")
    if int(n_dirs) != n_dirs or n_dirs < 3:
        raise InputError(f"n_dirs: expected an integer >= 3, got {n_dirs!r}")
    sc = _scaled(feet_W, mass_kg, support, normals_W, gravity_W)
    return _com_region(sc, float(z), mu, int(n_dirs))
