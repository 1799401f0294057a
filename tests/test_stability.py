"""The three-leg stability margin: numpy against the statics polygon distance, CasADi
against numpy, and Theta2 keeping it (planner.body.stability)."""

import casadi as ca
import numpy as np
import pytest

from planner.body import statics
from planner.body.robot import load_robot
from planner.body.stability import (
    BALANCE_MARGIN_M,
    support_margin_m,
    support_margins_ca,
    triangle_inradius_m,
)
from planner.problems import Theta2, Theta4
from planner.problems.base import FEASIBILITY_TOL
from planner.world.terrain import load_terrain


def _placed(dog, name, x):
    """The robot placed by Theta4 at x on a named course, and tau's directions there."""
    terrain = load_terrain(name)
    p = np.array([x, 0.0, float(terrain.height(np.array(x), np.array(0.0)))])
    u_n = terrain.smoothed_normal(p, 0.1)
    u_f = np.array([1.0, 0.0, 0.0]) - u_n[0] * u_n
    u_f /= np.linalg.norm(u_f)
    sol = Theta4(dog, terrain).solve(p + [0.0, 0.0, 0.15], u_f, u_n)
    return terrain, sol, u_f, u_n


def _ccw(tri_xy):
    c = tri_xy.mean(axis=0)
    ang = np.arctan2(tri_xy[:, 1] - c[1], tri_xy[:, 0] - c[0])
    return tri_xy[np.argsort(ang)]


def test_margin_matches_the_polygon_distance_and_casadi():
    rng = np.random.default_rng(3)
    feet = ca.MX.sym("feet", 9)
    com = ca.MX.sym("com", 3)
    cols = [feet[3 * i : 3 * i + 3] for i in range(3)]
    f = ca.Function("m", [feet, com], [ca.mmin(support_margins_ca(cols, com))])
    for _ in range(200):
        tri = rng.uniform(-0.2, 0.2, (3, 3))
        p = rng.uniform(-0.25, 0.25, 3)
        u, v = tri[1, :2] - tri[0, :2], tri[2, :2] - tri[0, :2]
        area = abs(u[0] * v[1] - u[1] * v[0])
        if area < 1e-3:
            continue
        got = support_margin_m(tri, p)
        want = statics.polygon_signed_distance(p[:2], _ccw(tri[:, :2]))
        if want > 0:  # inside: the distance to the nearest edge line
            assert got == pytest.approx(want, abs=1e-12)
        else:  # outside: negative (the edge-line distance is at most the true distance)
            assert got < 0 and got >= want - 1e-12
        # order of the feet does not matter, CasADi agrees
        assert support_margin_m(tri[::-1], p) == pytest.approx(got, abs=1e-12)
        assert float(f(tri.ravel(), p)) == pytest.approx(got, abs=1e-9)


@pytest.fixture(scope="module")
def dog():
    return load_robot("littledog")


@pytest.mark.parametrize("name,x", [("flat", 0.3), ("slope10", 0.6), ("rough2cm", 0.7)])
def test_theta2_keeps_the_com_inside_the_triangle(dog, name, x):
    terrain, placed, u_f, u_n = _placed(dog, name, x)
    start = placed.state
    support = (0, 2, 3)  # FR about to swing
    tri = start.feet_W[list(support)]
    # a COM target on the FL-HR edge: soft persuasion alone would go most of the way there
    rc = 0.5 * (tri[0] + tri[2]) + 0.15 * u_n
    problem = Theta2(dog, terrain, support=support)
    sol = problem.solve(start, rc, u_f, u_n)
    assert sol.feasible, sol.diagnosis
    assert sol.max_violation() < FEASIBILITY_TOL
    have = support_margin_m(tri, problem.check.com_W(sol.state))
    assert have >= BALANCE_MARGIN_M - 1e-6
    assert have < BALANCE_MARGIN_M + 0.01  # it is the margin that holds the COM back


def test_a_narrow_triangle_is_reported():
    terrain = load_terrain("flat")
    robot = load_robot("littledog")
    _, placed, u_f, u_n = _placed(robot, "flat", 0.3)
    start = placed.state.copy()
    start.feet_W[3, :2] = start.feet_W[2, :2] - [0.0, 0.03]  # HR 3 cm beside HL: a sliver
    sol = Theta2(robot, terrain, support=(0, 2, 3)).solve(
        start, start.feet_W[[0, 2, 3]].mean(axis=0) + 0.15 * u_n, u_f, u_n
    )
    assert not sol.feasible and "balance_margin" in sol.diagnosis


def test_inradius_is_the_largest_margin_in_the_triangle():
    rng = np.random.default_rng(5)
    tri = np.array([[0.0, 0.0, 0.0], [0.04, 0.0, 0.01], [0.0, 0.03, -0.02]])  # 3-4-5 x 1 cm
    assert triangle_inradius_m(tri) == pytest.approx(0.01, abs=1e-12)
    for _ in range(100):
        tri = rng.uniform(-0.2, 0.2, (3, 3))
        r = triangle_inradius_m(tri)
        sides = [np.linalg.norm(tri[(k + 2) % 3, :2] - tri[(k + 1) % 3, :2]) for k in range(3)]
        incentre = sum(s * p for s, p in zip(sides, tri, strict=True)) / sum(sides)
        assert support_margin_m(tri, incentre) == pytest.approx(r, abs=1e-9)
        w = rng.dirichlet(np.ones(3), 50)  # points inside never have a larger margin
        assert max(support_margin_m(tri, q) for q in w @ tri) <= r + 1e-12
    assert triangle_inradius_m(np.array([[0, 0, 0], [1, 1, 0], [2, 2, 0]])) == 0.0


def test_a_triangle_narrower_than_the_margin_holds_no_com(dog):
    """The look-ahead of LocalPlanner.leaves_no_support against Theta2 itself."""
    from planner.planning.soft import SoftPlanner

    terrain, placed, u_f, u_n = _placed(dog, "flat", 0.3)
    start = placed.state.copy()
    planner = SoftPlanner(dog, terrain)
    ahead = start.feet_W[0] + [0.06, 0.0, 0.0]  # FL's usual step: HR (next) keeps a stance
    assert not planner.leaves_no_support(start, 0, ahead)
    narrow = start.feet_W[1] + [0.08, 0.0, 0.0]  # FL in front of FR: FL, FR, HL a sliver
    assert planner.leaves_no_support(start, 0, narrow)
    start.feet_W[0] = narrow
    assert triangle_inradius_m(start.feet_W[[0, 1, 2]]) < BALANCE_MARGIN_M
    sol = Theta2(dog, terrain, support=(0, 1, 2)).solve(
        start, start.feet_W[[0, 1, 2]].mean(axis=0) + 0.15 * u_n, u_f, u_n
    )
    assert not sol.feasible and "balance_margin" in sol.diagnosis


def test_polygon_margin_is_the_triangle_margin_and_the_hull_margin(rng):
    """Three feet: :func:`support_margin_m`, inside and out; four: the hull's edges."""
    from planner.body.stability import polygon_margin_m

    for _ in range(200):
        tri = rng.uniform(-0.2, 0.2, size=(3, 3))
        p = rng.uniform(-0.3, 0.3, size=2)
        assert polygon_margin_m(tri, p) == pytest.approx(support_margin_m(tri, p), abs=1e-9)
    # a 0.4 x 0.2 rectangle of feet given in a crossing order
    feet = np.array([[0.2, 0.1, 0], [-0.2, -0.1, 0], [0.2, -0.1, 0], [-0.2, 0.1, 0.05]])
    assert polygon_margin_m(feet, [0.0, 0.0]) == pytest.approx(0.1)
    assert polygon_margin_m(feet, [0.15, 0.02]) == pytest.approx(0.05)
    assert polygon_margin_m(feet, [0.3, 0.0]) == pytest.approx(-0.1)


def test_nearest_inside_point_against_a_dense_grid(rng):
    """The point nearest a target among those ``margin`` inside the feet's hull: compared
    with the best of a dense grid filtered by :func:`polygon_margin_m` (an independent
    reference), inside (the target itself), outside, and for an empty inset."""
    from planner.body.stability import nearest_inside_point_W, polygon_margin_m

    gx, gy = np.meshgrid(np.linspace(-0.3, 0.3, 121), np.linspace(-0.3, 0.3, 121))
    grid = np.c_[gx.ravel(), gy.ravel()]

    def inside(points):
        # (points outside the feet's bounding box are outside their hull: not judged)
        lo, hi = feet[:, :2].min(axis=0), feet[:, :2].max(axis=0)
        points = points[np.all((points >= lo) & (points <= hi), axis=1)]
        return points[[polygon_margin_m(feet, g) >= margin for g in points]]

    for _ in range(12):
        feet = np.c_[rng.uniform(-0.2, 0.2, size=(4, 2)), rng.uniform(-0.05, 0.05, 4)]
        margin = rng.uniform(0.0, 0.03)
        target = rng.uniform(-0.3, 0.3, size=2)
        got = nearest_inside_point_W(feet, target, margin)
        if got is None:  # then no grid point is inside the inset
            assert len(inside(grid)) == 0
            continue
        assert polygon_margin_m(feet, got) >= margin - 1e-9  # inside the inset polygon
        # and no feasible grid point nearer: optimal to the grid's resolution (only the grid
        # points nearer than the answer are judged: any of them inside would beat it)
        dist = np.linalg.norm(grid - target, axis=1)
        nearer = grid[dist < np.linalg.norm(got - target) - 1e-9]
        assert len(inside(nearer)) == 0
    square = np.array([[0, 0, 0], [0.2, 0, 0], [0.2, 0.2, 0], [0, 0.2, 0.0]])
    assert np.allclose(nearest_inside_point_W(square, [0.1, 0.05], 0.025), [0.1, 0.05])
    assert np.allclose(nearest_inside_point_W(square, [0.3, 0.1], 0.025), [0.175, 0.1])
    assert nearest_inside_point_W(square, [0.1, 0.1], 0.11) is None
