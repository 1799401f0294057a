"""The search Omega along the trajectory (section 7.6) by bisection over Theta1."""

import numpy as np
import pytest

from planner.body.robot import load_robot
from planner.motion.heuristics import reference_directions
from planner.motion.trajectory import Trajectory
from planner.planning.omega import omega
from planner.problems import Theta1, Theta4
from planner.world.terrain import load_terrain


@pytest.fixture(scope="module")
def setup():
    dog = load_robot("littledog")
    terrain = load_terrain("flat")
    placed = Theta4(dog, terrain).solve([0.3, 0.0, 0.15], [1, 0, 0], [0, 0, 1])
    assert placed.feasible
    start = placed.state
    problem = Theta1(dog, terrain, support=(0, 1, 2, 3))
    com = problem.check.com_W(start)
    tau = Trajectory.straight(
        com[:2], com[:2] + [0.5, 0.0], terrain, float(com[2]), footprint_radius_m=0.0
    )
    return dog, terrain, start, problem, tau


def test_omega_finds_the_end_of_the_feasible_interval(setup):
    dog, terrain, start, problem, tau = setup
    res = omega(problem, start, tau, 0.0, 0.2, tol_m=0.004, max_solves=12)
    assert res.best is not None
    state, lam = res.best
    assert lam > 0.02  # the COM can move forward on four fixed feet
    assert lam < 0.2  # but not 20 cm: the legs run out of reach
    np.testing.assert_array_equal(state.feet_W, start.feet_W)  # stays on the leaf
    # the bracket is tight: a little farther along is infeasible
    fails = [lam_ for lam_, ok in res.probes if not ok]
    assert fails and min(fails) - lam <= 0.004 + 1e-12
    rc = tau.point(min(fails))
    u_f, u_n = reference_directions(tau, terrain, rc, lam=min(fails))
    assert not problem.solve(state, rc, u_f, u_n).feasible
    # every element of Xi is feasible with its COM on tau
    for s, lam_ in res.xi:
        assert np.linalg.norm(problem.check.com_W(s) - tau.point(lam_)) < 1e-6


def test_omega_returns_at_once_when_the_far_end_is_feasible(setup):
    dog, terrain, start, problem, tau = setup
    res = omega(problem, start, tau, 0.0, 0.005)
    assert res.solves == 1 and res.best[1] == pytest.approx(0.005)


@pytest.mark.parametrize("edge", [0, 3, 8, 16, 31])
def test_farthest_feasible_bisects_the_screened_lambdas(edge):
    """Feasible up to the ``edge``-th nearest of 32 lambdas: the farthest is tried first,
    then bisection finds the edge in 1 + log2(31) solves, never solving a lambda twice."""
    from planner.planning.omega import farthest_feasible

    lams = [0.01 * k for k in range(31, -1, -1)]  # farthest first
    edge_lam = 0.01 * edge
    asked = []

    def solve(lam):
        asked.append(lam)
        return ("pose", lam) if lam <= edge_lam + 1e-12 else None

    got, lam = farthest_feasible(lams, solve, max_solves=6)
    assert lam == pytest.approx(edge_lam) and got == ("pose", lam)
    assert len(asked) <= 6 and len(set(asked)) == len(asked)
    none, at = farthest_feasible(lams, lambda lam: None, max_solves=6)
    assert (none, at) == (None, None)
    short = farthest_feasible(lams, solve, max_solves=2)  # the budget bounds the solves
    assert short[1] is None or short[1] <= edge_lam
