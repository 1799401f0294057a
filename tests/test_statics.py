"""Tests of planner.body.statics: eq. 3-5 forces, section 7.3 (d), (e), exact SOCP."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import linprog

from planner.body.statics import (
    GRAVITY_W,
    DegenerateStanceError,
    equilibrating_forces,
    equilibrating_forces_ca,
    feasible_com_region,
    forces_in_friction_cones,
    friction_cone_residuals,
    friction_cone_residuals_ca,
    polygon_signed_distance,
    static_feasibility,
    support_indices,
)
from planner.core.errors import InputError, PlannerError

G = np.array(GRAVITY_W)
MASS = 2.5
RECT = np.array([[0.2, 0.15, 0.0], [0.2, -0.15, 0.0], [-0.2, 0.15, 0.0], [-0.2, -0.15, 0.0]])
SUPPORTS = [(0, 1, 2, 3), (0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]


def random_stance(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    feet = RECT + rng.normal(scale=[0.04, 0.04, 0.03], size=(4, 3))
    com = np.array([0.0, 0.0, 0.25]) + rng.normal(scale=[0.05, 0.05, 0.03])
    return feet, com


def slope_frame(theta: float) -> np.ndarray:
    """Rotation about x by theta: the plane z=0 tilted so it rises towards -y."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def tilted_stance(theta: float) -> tuple[np.ndarray, np.ndarray]:
    rot = slope_frame(theta)
    return RECT @ rot.T, np.tile(rot[:, 2], (4, 1))


def triangle_edge_distance(tri: np.ndarray, p: np.ndarray) -> float:
    """Signed distance of p to the boundary of triangle tri (3, 2), positive inside."""

    def cross2(a: np.ndarray, b: np.ndarray) -> float:
        return a[0] * b[1] - a[1] * b[0]

    if cross2(tri[1] - tri[0], tri[2] - tri[0]) < 0:
        tri = tri[::-1]
    dists, inside = [], True
    for a, b in zip(tri, np.roll(tri, -1, axis=0), strict=True):
        e = b - a
        side = cross2(e, p - a) / np.linalg.norm(e)  # signed distance to the edge's line
        inside &= side >= 0
        t = np.clip(np.dot(p - a, e) / np.dot(e, e), 0, 1)
        dists.append(np.linalg.norm(p - a - t * e))
    return min(dists) if inside else -min(dists)


# ------------------------------------------------------------------- eq. 3-5 forces


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("support", SUPPORTS)
def test_eq5_forces_balance_and_have_no_interaction(seed: int, support: tuple[int, ...]) -> None:
    rng = np.random.default_rng(seed)
    feet, com = random_stance(rng)
    gravity = G if seed % 2 == 0 else G + rng.normal(scale=1.0, size=3)  # tilted gravity too
    res = equilibrating_forces(feet, com, MASS, support, gravity)
    tol = 1e-9 * MASS * np.linalg.norm(gravity)
    f = res.forces
    assert not res.degenerate and res.reason == ""
    np.testing.assert_allclose(f.sum(axis=0) + MASS * gravity, 0.0, atol=tol)
    np.testing.assert_allclose(np.cross(feet - com, f).sum(axis=0), 0.0, atol=tol)
    off = [i for i in range(4) if i not in support]
    assert np.all(f[off] == 0.0)
    for i in support:
        for j in support:
            assert abs((f[i] - f[j]) @ (feet[i] - feet[j])) < tol
    # eq. 3 with the returned u, w about the world origin
    np.testing.assert_allclose(
        np.cross(res.u, feet[list(support)]) + res.w, f[list(support)], atol=tol
    )


@pytest.mark.parametrize("kind", ["SX", "MX"])
@pytest.mark.parametrize("support", [(0, 1, 2, 3), (0, 2, 3)])
def test_casadi_forces_match_numpy(kind: str, support: tuple[int, ...]) -> None:
    sym = getattr(ca, kind).sym
    feet_s, com_s, m_s = sym("feet", 3, 4), sym("com", 3), sym("m")
    forces = equilibrating_forces_ca(feet_s, com_s, m_s, support, GRAVITY_W)
    fun = ca.Function("f", [feet_s, com_s, m_s], [ca.horzcat(*forces)])
    rng = np.random.default_rng(3)
    for _ in range(5):
        feet, com = random_stance(rng)
        ref = equilibrating_forces(feet, com, MASS, support).forces
        got = np.array(fun(feet.T, com, MASS)).T
        np.testing.assert_allclose(got, ref, atol=1e-9, rtol=0)
    # list-of-vectors input and numeric (DM) evaluation give the same
    feet, com = random_stance(rng)
    as_list = equilibrating_forces_ca([ca.DM(r) for r in feet], com, MASS, support)
    got = np.array(ca.horzcat(*as_list)).T
    np.testing.assert_allclose(
        got, equilibrating_forces(feet, com, MASS, support).forces, atol=1e-9
    )


def test_casadi_jacobians_match_finite_differences() -> None:
    feet_s, com_s = ca.SX.sym("feet", 3, 4), ca.SX.sym("com", 3)
    support = (0, 1, 3)
    f = ca.vec(ca.horzcat(*equilibrating_forces_ca(feet_s, com_s, MASS, support)))
    jac = ca.Function("j", [feet_s, com_s], [ca.jacobian(f, com_s), ca.jacobian(f, feet_s)])
    feet, com = random_stance(np.random.default_rng(7))

    def forces(feet_: np.ndarray, com_: np.ndarray) -> np.ndarray:
        return equilibrating_forces(feet_, com_, MASS, support).forces.reshape(-1)  # = vec(3x4)

    j_com, j_feet = (np.array(j) for j in jac(feet.T, com))
    h = 1e-6
    fd_com = np.column_stack(
        [(forces(feet, com + h * e) - forces(feet, com - h * e)) / (2 * h) for e in np.eye(3)]
    )
    np.testing.assert_allclose(j_com, fd_com, atol=1e-6)
    assert np.abs(j_com).max() > 1.0  # the check is not vacuous
    cols = []
    for k in range(12):  # vec(3x4) order: column (leg) major
        d = np.zeros((4, 3))
        d[k // 3, k % 3] = h
        cols.append((forces(feet + d, com) - forces(feet - d, com)) / (2 * h))
    np.testing.assert_allclose(j_feet, np.column_stack(cols), atol=1e-5)


# --------------------------------------------------------------------- section 7.3 (d), (e)


def test_cone_residuals_numpy_and_casadi() -> None:
    mu = 0.6
    rng = np.random.default_rng(11)
    forces = rng.normal(size=(4, 3)) + [0.0, 0.0, 3.0]
    normals = np.tile([0.0, 0.0, 1.0], (4, 1)) + rng.normal(scale=0.2, size=(4, 3))
    unit = normals / np.linalg.norm(normals, axis=1)[:, None]
    support = (0, 1, 3)
    exact = friction_cone_residuals(forces, mu, support, normals)
    for k, i in enumerate(support):  # direct evaluation of (d), (e)
        fn = forces[i] @ unit[i]
        assert exact[k, 0] == pytest.approx(fn)
        assert exact[k, 1] == pytest.approx(mu * fn - np.linalg.norm(forces[i] - fn * unit[i]))
    eps = 1e-3
    smooth = np.array(friction_cone_residuals_ca(list(forces), mu, support, normals, eps_N=eps))
    smooth = smooth.reshape(-1, 2)
    np.testing.assert_allclose(smooth[:, 0], exact[:, 0], atol=1e-12)
    assert np.all(smooth[:, 1] <= exact[:, 1]) and np.all(smooth[:, 1] >= exact[:, 1] - eps)
    tangential = mu * exact[:, 0] - exact[:, 1]
    np.testing.assert_allclose(
        smooth[:, 1], mu * exact[:, 0] - np.sqrt(tangential**2 + eps**2), atol=1e-12
    )
    sq = np.array(friction_cone_residuals_ca(forces.T, mu, support, normals, form="squared"))
    assert np.array_equal(np.sign(sq.reshape(-1, 2)[:, 1]), np.sign(exact[:, 1]))
    # symbolic normals (normalised inside) give the same
    ns = ca.SX.sym("n", 3, 4)
    fun = ca.Function("r", [ns], [friction_cone_residuals_ca(list(forces), mu, support, ns)])
    np.testing.assert_allclose(np.array(fun(normals.T)).reshape(-1, 2), smooth, atol=1e-12)


def test_cone_boundary() -> None:
    mu = 0.5
    on_cone = np.array([mu, 0.0, 1.0]) * 10.0  # |F_t| = mu F_n exactly
    forces = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 10.0], on_cone, [0.0, 0.0, 10.0]])
    assert forces_in_friction_cones(forces, mu, (0, 1, 3))
    assert not forces_in_friction_cones(forces, mu, (0, 1, 2))  # (e) strict, as in the paper
    pulling = forces.copy()
    pulling[1] = [0.0, 0.0, -1.0]
    assert not forces_in_friction_cones(pulling, mu, (0, 1, 3))  # (d)


# --------------------------------------------------------------------- reference cases

TRI = (0, 1, 2)  # FL, FR, HL


def test_com_over_triangle_centroid_is_feasible_both_ways() -> None:
    mu = 0.6
    com = RECT[list(TRI)].mean(axis=0) + [0.0, 0.0, 0.25]
    eq5 = equilibrating_forces(RECT, com, MASS, TRI)
    np.testing.assert_allclose(eq5.forces[list(TRI), 2], MASS * 9.81 / 3, rtol=1e-12)
    assert forces_in_friction_cones(eq5.forces, mu, TRI)
    res = static_feasibility(RECT, com, MASS, TRI, mu)
    assert res.feasible and res.status == "Solved"
    # analytic margin: vertical loads m g / 3, distance to the cone mu F_n / sqrt(1 + mu^2)
    assert res.margin_N == pytest.approx(MASS * 9.81 / 3 * mu / math.sqrt(1 + mu**2), rel=1e-6)
    assert np.all(friction_cone_residuals(res.forces, mu, TRI)[:, 1] > 0)


def test_com_outside_triangle_is_infeasible_both_ways() -> None:
    mu = 0.6
    com = np.array([-0.1, -0.1, 0.25])  # beyond the FR-HL diagonal
    eq5 = equilibrating_forces(RECT, com, MASS, TRI)
    assert not forces_in_friction_cones(eq5.forces, mu, TRI)
    assert eq5.forces[list(TRI), 2].min() < 0
    res = static_feasibility(RECT, com, MASS, TRI, mu)
    assert not res.feasible and res.margin_N < 0
    assert res.com_margin_m < 0


@pytest.mark.parametrize("support", [(0, 1, 2, 3), (1, 2, 3)])
def test_slope_steeper_than_friction_angle_cannot_hold(support: tuple[int, ...]) -> None:
    mu = 0.5
    feet, normals = tilted_stance(math.atan(mu) + math.radians(5))
    com = feet[list(support)].mean(axis=0) + [0.0, 0.0, 0.1]
    res = static_feasibility(feet, com, MASS, support, mu, normals)
    assert not res.feasible and res.margin_N < 0
    assert res.com_region_xy.shape == (0, 2) and res.com_margin_m == -math.inf
    gentle_feet, gentle_normals = tilted_stance(math.atan(mu) - math.radians(5))
    com = gentle_feet[list(support)].mean(axis=0) + [0.0, 0.0, 0.1]
    res = static_feasibility(gentle_feet, com, MASS, support, mu, gentle_normals)
    assert res.feasible and res.margin_N > 0 and res.com_margin_m > 0


def test_exact_method_accepts_four_foot_stance_eq5_rejects() -> None:
    # Rectangle +-0.2 x +-0.15: eq. 5 loads are m g / 4 (1 + cx x_i / a^2 + cy y_i / b^2),
    # negative at the HR foot (-0.2, -0.15) for c = (0.12, 0.09), although the COM is
    # 0.06 m inside the support rectangle.
    com = np.array([0.12, 0.09, 0.25])
    eq5 = equilibrating_forces(RECT, com, MASS, (0, 1, 2, 3))
    assert eq5.forces[3, 2] == pytest.approx(MASS * 9.81 / 4 * (1 - 0.6 - 0.6))
    assert not forces_in_friction_cones(eq5.forces, 0.6, (0, 1, 2, 3))
    res = static_feasibility(RECT, com, MASS, (0, 1, 2, 3), 0.6, n_dirs=64)
    assert res.feasible and res.margin_N > 0
    assert res.com_margin_m == pytest.approx(0.06, abs=1e-6)
    assert forces_in_friction_cones(res.forces, 0.6, (0, 1, 2, 3))


def test_exact_method_accepts_three_foot_slope_stance_eq5_rejects() -> None:
    # 3 feet on a slope of atan(0.5) - 8 deg, COM 0.2 m above the triangle centroid along
    # the normal: eq. 5's particular solution leaves a friction cone (residual ~ -1.07 N),
    # but other forces hold the stance with margin ~0.91 N.
    mu, support = 0.5, (0, 1, 2)
    feet, normals = tilted_stance(math.atan(mu) - math.radians(8))
    com = feet[list(support)].mean(axis=0) + 0.2 * normals[0]
    eq5 = equilibrating_forces(feet, com, MASS, support)
    residuals = friction_cone_residuals(eq5.forces, mu, support, normals)
    assert residuals[:, 0].min() > 0 and residuals[:, 1].min() < -0.5
    res = static_feasibility(feet, com, MASS, support, mu, normals)
    assert res.feasible and res.margin_N > 0.5
    exact = friction_cone_residuals(res.forces, mu, support, normals)
    assert exact[:, 1].min() >= res.margin_N * math.sqrt(1 + mu**2) - 1e-6


@pytest.mark.parametrize("seed", range(6))
def test_socp_forces_balance_and_agree_with_pyramid_bounds(seed: int) -> None:
    """The SOCP verdict sits between an inscribed and a circumscribed friction pyramid (LP)."""
    rng = np.random.default_rng(100 + seed)
    feet, com = random_stance(rng)
    normals = np.tile([0.0, 0.0, 1.0], (4, 1)) + rng.normal(scale=0.25, size=(4, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    support, mu = SUPPORTS[seed % len(SUPPORTS)], 0.7
    res = static_feasibility(feet, com, MASS, support, mu, normals)
    if res.feasible:
        f = res.forces
        np.testing.assert_allclose(f.sum(axis=0) + MASS * G, 0.0, atol=1e-6 * MASS * 9.81)
        np.testing.assert_allclose(np.cross(feet - com, f).sum(axis=0), 0.0, atol=1e-6)
    sides = 16

    def pyramid_feasible(mu_eff: float) -> bool:
        k = len(support)
        a_eq = np.zeros((6, 3 * k))
        for j, i in enumerate(support):
            a_eq[:3, 3 * j : 3 * j + 3] = np.eye(3)
            r = feet[i] - com
            a_eq[3:, 3 * j : 3 * j + 3] = [[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]]
        rows = []
        for j, i in enumerate(support):
            n = normals[i]
            t1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
            t1 /= np.linalg.norm(t1)
            t2 = np.cross(n, t1)
            for ang in np.linspace(0, 2 * np.pi, sides, endpoint=False):
                row = np.zeros(3 * k)  # d.F_t - mu_eff F_n <= 0
                row[3 * j : 3 * j + 3] = math.cos(ang) * t1 + math.sin(ang) * t2 - mu_eff * n
                rows.append(row)
        b_eq = np.concatenate([-MASS * G, np.zeros(3)])
        lp = linprog(
            np.zeros(3 * k), A_ub=np.array(rows), b_ub=np.zeros(len(rows)), A_eq=a_eq, b_eq=b_eq,
            bounds=[(None, None)] * (3 * k), method="highs",
        )  # fmt: skip
        return lp.status == 0

    inner = pyramid_feasible(mu * math.cos(math.pi / sides))  # pyramid inside the cone
    outer = pyramid_feasible(mu)  # polygon of this mu circumscribes the cone's section
    if inner:
        assert res.feasible or res.margin_N > -1e-6
    if not outer:
        assert not res.feasible
    if abs(res.com_margin_m) > 1e-4:  # both margins tell the same story
        assert (res.com_margin_m > 0) == res.feasible


# --------------------------------------------------------------------- COM region


@pytest.mark.parametrize("mu", [50.0, 0.3])
@pytest.mark.parametrize(
    "com_xy", [(0.05, 0.03), (0.15, 0.1), (-0.1, -0.1), (0.0, 0.2), (0.195, 0.14)]
)
def test_com_margin_is_distance_to_support_triangle_on_flat_ground(
    mu: float, com_xy: tuple[float, float]
) -> None:
    com = np.array([*com_xy, 0.3])
    res = static_feasibility(RECT, com, MASS, TRI, mu, n_dirs=48)
    ref = triangle_edge_distance(RECT[list(TRI), :2], com[:2])
    assert res.com_margin_m == pytest.approx(ref, abs=1e-3)
    assert res.feasible == (ref > 0)
    assert len(res.com_region_xy) == 3  # the support triangle itself
    np.testing.assert_allclose(
        np.sort(res.com_region_xy, axis=0), np.sort(RECT[list(TRI), :2], axis=0), atol=1e-6
    )


@pytest.mark.parametrize("legs", [(0, 1, 2, 3), (0, 1, 3), (1, 2, 3)])
def test_level_com_region_in_closed_form_is_the_socps(legs, rng, monkeypatch) -> None:
    """Level contacts: the closed form (the support polygon) against the support-function
    SOCPs it replaces there, on random stances at one height and random friction."""
    import planner.body.statics as statics

    for _ in range(5):
        feet = RECT.copy()  # each foot up to 4 cm off the rectangle's corner: still convex
        feet[:, :2] += rng.uniform(-0.04, 0.04, (4, 2))
        feet[:, 2] = rng.uniform(-0.2, 0.2)  # one height for all four
        mu, z = rng.uniform(0.0, 1.5), rng.uniform(0.05, 0.4)
        closed = feasible_com_region(feet, z, MASS, legs, mu)
        with monkeypatch.context() as m:
            m.setattr(statics, "_level", lambda sc: False)
            socp = feasible_com_region(feet, z, MASS, legs, mu, n_dirs=256)
        # the same polygon: every vertex of one within 1e-6 m of one of the other (the
        # SOCPs' solutions repeat a vertex to within the solver's tolerance)
        d = np.linalg.norm(closed[:, None] - socp[None], axis=-1)
        assert len(closed) == len(legs) and d.min(axis=0).max() < 1e-6, (closed, socp)
        assert d.min(axis=1).max() < 1e-6, (closed, socp)
    # a foot 1 mm higher, or a normal tilted, is not level: the SOCPs there
    assert statics._level(statics._scaled(feet, MASS, legs, None, GRAVITY_W))
    raised = feet.copy()
    raised[legs[0], 2] += 1e-3
    assert not statics._level(statics._scaled(raised, MASS, legs, None, GRAVITY_W))
    tilted = np.tile([0.0, 0.0, 1.0], (4, 1))
    tilted[legs[0]] = [0.01, 0.0, 1.0]
    assert not statics._level(statics._scaled(feet, MASS, legs, tilted, GRAVITY_W))


def test_com_region_on_a_slope_shrinks_downhill_with_height() -> None:
    # Gravity tilted in the world frame = flat feet on a slope seen in the slope's frame:
    # the feasible region moves against the gravity tilt by z tan(theta), independent of mu
    # when mu is large, and is empty when tan(theta) > mu.
    theta = math.radians(10)
    g = 9.81 * np.array([0.0, math.sin(theta), -math.cos(theta)])
    low = feasible_com_region(RECT, 0.0, MASS, (0, 1, 2, 3), 5.0, gravity_W=g)
    high = feasible_com_region(RECT, 0.3, MASS, (0, 1, 2, 3), 5.0, gravity_W=g)
    np.testing.assert_allclose(np.sort(low, axis=0), np.sort(RECT[:, :2], axis=0), atol=1e-6)
    shift = high.mean(axis=0) - low.mean(axis=0)
    np.testing.assert_allclose(shift, [0.0, -0.3 * math.tan(theta)], atol=1e-6)
    assert feasible_com_region(RECT, 0.3, MASS, (0, 1, 2, 3), 0.15, gravity_W=g).shape == (0, 2)


def test_polygon_signed_distance() -> None:
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert polygon_signed_distance([0.5, 0.25], square) == pytest.approx(0.25)
    assert polygon_signed_distance([2.0, 0.5], square) == pytest.approx(-1.0)
    assert polygon_signed_distance([2.0, 2.0], square) == pytest.approx(-math.sqrt(2))
    assert polygon_signed_distance([0.5, 0.5], np.zeros((0, 2))) == -math.inf


# ---------------------------------------------------------------------- degenerate


def test_collinear_feet_are_degenerate_not_nan() -> None:
    feet = RECT.copy()
    feet[2] = [0.0, 0.15, 0.0]  # FL, HL and this on y = 0.15
    feet[1] = [-0.2, 0.15, 0.0]
    for offset in (0.0, 1e-10):
        feet[1, 1] = 0.15 + offset
        res = equilibrating_forces(feet, [0.0, 0.1, 0.25], MASS, (0, 1, 2))
        assert res.degenerate and "collinear" in res.reason
        assert np.all(np.isfinite(res.forces)) and np.all(res.forces == 0)
        with pytest.raises(DegenerateStanceError, match="collinear"):
            equilibrating_forces(feet, [0.0, 0.1, 0.25], MASS, (0, 1, 2), strict=True)
    assert issubclass(DegenerateStanceError, PlannerError)
    # the exact test: no forces balance a COM off the line ...
    feet[1, 1] = 0.15
    res = static_feasibility(feet, [0.0, 0.1, 0.25], MASS, (0, 1, 2), 0.6)
    assert not res.feasible and res.margin_N == -math.inf and res.status == "PrimalInfeasible"
    assert res.com_margin_m == pytest.approx(-0.05) and np.all(np.isfinite(res.forces))
    # ... a COM on the line balances (a knife edge): feasible, but zero COM margin
    res = static_feasibility(feet, [0.0, 0.15, 0.25], MASS, (0, 1, 2), 0.6)
    assert res.feasible and res.com_margin_m == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("support", [(0, 1), [True, False, False, True], (2,), ()])
def test_fewer_than_three_feet_is_a_clear_error(support: object) -> None:
    with pytest.raises(InputError, match="support: needs 3 or 4"):
        equilibrating_forces(RECT, [0, 0, 0.2], MASS, support)
    with pytest.raises(InputError, match="support"):
        static_feasibility(RECT, [0, 0, 0.2], MASS, support, 0.5)
    with pytest.raises(InputError, match="support"):
        equilibrating_forces_ca(ca.SX.sym("f", 3, 4), ca.SX.sym("c", 3), MASS, support)


def test_support_mask_and_indices_agree() -> None:
    assert support_indices([True, True, False, True]) == (0, 1, 3)
    assert support_indices(np.array([3, 0, 1])) == (0, 1, 3)
    a = equilibrating_forces(RECT, [0.05, 0, 0.2], MASS, [True, True, False, True]).forces
    b = equilibrating_forces(RECT, [0.05, 0, 0.2], MASS, (3, 1, 0)).forces
    np.testing.assert_array_equal(a, b)


# ---------------------------------------------------------------------- bad inputs

NAN_FEET = RECT.copy()
NAN_FEET[1, 2] = np.nan


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"feet_W": RECT.T}, "feet_W"),
        ({"feet_W": NAN_FEET}, "feet_W"),
        ({"com_W": [0.0, 0.0]}, "com_W"),
        ({"com_W": [0.0, np.inf, 0.2]}, "com_W"),
        ({"mass_kg": -1.0}, "mass_kg"),
        ({"mass_kg": np.nan}, "mass_kg"),
        ({"support": (0, 1, 4)}, "support"),
        ({"support": (0, 1, 1)}, "support"),
        ({"support": [True, True, True]}, "support"),
        ({"support": (0.5, 1, 2)}, "support"),
        ({"gravity_W": [0.0, 0.0, 0.0]}, "gravity_W"),
        ({"gravity_W": [0.0, np.nan, -9.8]}, "gravity_W"),
    ],
)
def test_bad_inputs_name_the_argument(kwargs: dict, field: str) -> None:
    args = {"feet_W": RECT, "com_W": [0.0, 0.0, 0.2], "mass_kg": MASS, "support": (0, 1, 2, 3)}
    args.update(kwargs)
    with pytest.raises(InputError, match=f"^{field}"):
        equilibrating_forces(**args)
    with pytest.raises(InputError, match=f"^{field}"):
        static_feasibility(mu=0.5, **args)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"mu": -0.1}, "mu"),
        ({"mu": np.nan}, "mu"),
        ({"normals_W": np.zeros((4, 3))}, "normals_W"),
        ({"normals_W": np.ones((3, 3))}, "normals_W"),
    ],
)
def test_bad_friction_inputs_name_the_argument(kwargs: dict, field: str) -> None:
    args = {"mu": 0.5, "normals_W": None}
    args.update(kwargs)
    with pytest.raises(InputError, match=f"^{field}"):
        static_feasibility(RECT, [0, 0, 0.2], MASS, (0, 1, 2), **args)
    with pytest.raises(InputError, match=f"^{field}"):
        friction_cone_residuals(np.ones((4, 3)), support=(0, 1, 2), **args)


def test_bad_casadi_and_region_inputs() -> None:
    with pytest.raises(InputError, match="^feet_W"):
        equilibrating_forces_ca(ca.SX.sym("f", 4, 3), ca.SX.sym("c", 3), MASS, (0, 1, 2))
    with pytest.raises(InputError, match="^com_W"):
        equilibrating_forces_ca(ca.SX.sym("f", 3, 4), ca.SX.sym("c", 2), MASS, (0, 1, 2))
    with pytest.raises(InputError, match="^forces_W"):
        friction_cone_residuals(np.ones((4, 2)), 0.5, (0, 1, 2))
    with pytest.raises(InputError, match="^form"):
        friction_cone_residuals_ca(list(np.ones((4, 3))), 0.5, (0, 1, 2), form="cubic")
    with pytest.raises(InputError, match="^n_dirs"):
        feasible_com_region(RECT, 0.2, MASS, (0, 1, 2), 0.5, n_dirs=2)
    with pytest.raises(InputError, match="^com_z_m"):
        feasible_com_region(RECT, np.nan, MASS, (0, 1, 2), 0.5)


def test_clarabel_stall_on_an_ordinary_stance_is_retried():
    # a four-foot stance from a stepping-stones plan on which Clarabel with its default
    # settings stopped with InsufficientProgress (margin nan; the 1e-98 normal components
    # upset its equilibration): retried, it solves
    feet = [
        [0.6371550368655762, 0.06551389006563385, 0.0042396384979301385],
        [0.7413165285800238, -0.0649841446363585, -0.011524354066020008],
        [0.46449929879574126, 0.06614357833307932, -6.806067470721544e-08],
        [0.46491167127749056, -0.06552523559921215, -8.026618739803704e-08],
    ]
    normals = [[8.209883690974056e-05, -5.027502468919441e-07, 0.9999999966297641],
               [-0.00012842327362273063, 5.326124765896361e-07, 0.9999999917535897],
               [2.7224251321989382e-05, -4.94990675022635e-98, 0.9999999996294202],
               [3.21064491235959e-05, 4.5584402522647566e-98, 0.9999999994845881]]  # fmt: skip
    com = [0.5839186753820351, -0.003836096673121596, 0.13858309047892428]
    res = static_feasibility(feet, com, 3.004, [0, 1, 2, 3], 0.7, normals, with_com_margin=False)
    assert res.feasible and res.status == "Solved" and res.margin_N > 1.0


def test_the_clarabel_matrices_are_scipy_s_csc_and_solve_the_same() -> None:
    """statics._csc (index arrays shared per sparsity pattern) is the canonical CSC scipy
    builds, and Clarabel solves the same problem with either to the bit."""
    import clarabel
    import scipy.sparse as sp

    from planner.body.statics import _csc

    rng = np.random.default_rng(3)
    for _ in range(20):
        a = rng.normal(size=(8, 5))
        a[rng.uniform(size=a.shape) < 0.4] = 0.0
        m, ref = _csc(a), sp.csc_matrix(a)
        np.testing.assert_array_equal(m.toarray(), a)
        for name in ("indptr", "indices", "data"):
            np.testing.assert_array_equal(getattr(m, name), getattr(ref, name))
        # min c.x over the box |x| <= 1 written as A x + s = b with s in the cone
        q = rng.normal(size=5)
        A = np.vstack([a, np.eye(5), -np.eye(5)])
        b = np.concatenate([np.full(8, 10.0), np.ones(10)])
        xs = []
        for mat in (_csc(A), sp.csc_matrix(A)):
            settings = clarabel.DefaultSettings()
            settings.verbose = False
            res = clarabel.DefaultSolver(
                sp.csc_matrix((5, 5)), q, mat, b, [clarabel.NonnegativeConeT(18)], settings
            ).solve()
            assert str(res.status) == "Solved"
            xs.append(np.asarray(res.x))
        np.testing.assert_array_equal(xs[0], xs[1])
