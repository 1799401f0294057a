import signal
import time

import numpy as np
import pytest

from planner.body.state import State
from planner.core.errors import InputError
from planner.motion.trajectory import Trajectory
from planner.planning.global_plan import (
    CostWeights,
    GlobalSettings,
    candidate_trajectory,
    lateral_coefficients,
    plan_global_walk,
    stability_margin_m,
    trajectory_cost,
)
from planner.planning.local import LocalSettings
from planner.world.terrain import load_terrain

COURSE = "barrier15cm_opening"


@pytest.fixture(scope="module")
def course():
    return load_terrain(COURSE)


def test_course_wall_blocks_the_straight_line_and_opens_to_the_left(course):
    x = np.full(5, 1.22)
    y = np.array([-0.3, 0.0, 0.08, 0.3, 0.52])  # 4 smoothing widths from the sides
    assert np.allclose(course.height_sharp(x, y), [0.15, 0.15, 0.15, 0.0, 0.15])
    smooth = course.height(x, y)
    assert np.allclose(smooth, course.height_sharp(x, y), atol=1e-3)
    # CasADi and numpy agree on the opening's smoothed sides
    for yi in (0.1, 0.102, 0.5):
        assert float(course.height_ca(1.22, yi)) == pytest.approx(
            float(course.height(np.array(1.22), np.array(yi))), abs=1e-12
        )


def test_barrier_opening_must_be_ordered():
    from planner.world.terrain import Terrain

    spec = {"kind": "barrier", "length": 3.0, "x": 1.0, "height": 0.1, "thickness": 0.05}
    with pytest.raises(InputError, match="opening"):
        Terrain.from_spec(spec | {"opening": [0.5, 0.1]})
    assert "opening" not in Terrain.from_spec(spec).spec  # old specs unchanged


def test_sine_series_candidates_bend_sideways_and_keep_the_ends(course):
    tau0 = Trajectory.straight((0.2, 0.0), (2.2, 0.0), course, 0.15)
    assert candidate_trajectory(tau0, [0.0, 0.0], (0.2, 0), (2.2, 0)) is tau0
    A = lateral_coefficients([0.3, 0.0, -0.1], (0.2, 0), (2.2, 0))
    assert np.allclose(A[:, :2], [[0, 0.3], [0, 0], [0, -0.1]]) and np.all(A[:, 2] == 0)
    tau = candidate_trajectory(tau0, [0.3], (0.2, 0), (2.2, 0))
    assert np.allclose(tau.start_W[:2], [0.2, 0.0]) and np.allclose(tau.end_W[:2], [2.2, 0.0])
    _, pts = tau.sample(0.01)
    assert pts[:, 1].max() == pytest.approx(0.3, abs=1e-3)  # sin peaks at the middle
    assert pts[np.argmax(pts[:, 1]), 0] == pytest.approx(1.2, abs=0.01)


def test_cost_ranks_every_reaching_walk_before_any_other():
    w = CostWeights()
    common = dict(walk_time_s=130.0, planning_time_s=30.0, stability_margin_m=0.035)
    reached, _ = trajectory_cost(
        w, reached=True, distance_to_goal_m=0.049, steps=200, path_length_m=3.0, **common
    )
    near, terms = trajectory_cost(
        w, reached=False, distance_to_goal_m=0.051, steps=10, path_length_m=2.0, **common
    )
    far, _ = trajectory_cost(
        w, reached=False, distance_to_goal_m=1.0, steps=10, path_length_m=2.0, **common
    )
    assert reached < near < far
    assert terms["not_reached"] == w.not_reached and terms["stability"] == 0.0
    shaky, t2 = trajectory_cost(
        w,
        reached=True,
        distance_to_goal_m=0.0,
        steps=60,
        path_length_m=2.0,
        **common | {"stability_margin_m": 0.01},
    )
    assert t2["stability"] == pytest.approx(w.margin_per_m * 0.02)


def test_stability_margin_is_the_distance_to_the_nearest_support_edge():
    class _Check:
        def com_W(self, s):
            return np.array([0.0, 0.0, 0.1])

    feet = np.array([[1.0, 1.0, 0], [1.0, -1.0, 0], [-1.0, 0.0, 0], [9.0, 9.0, 0]])
    s = State(np.zeros(3), np.eye(3), feet, np.zeros((4, 3)), stratum=4, support=(0, 1, 2))
    four = State(np.zeros(3), np.eye(3), feet, np.zeros((4, 3)))
    # edges: x = 1 (distance 1) and the two slanted ones (distance 1/sqrt(5))
    assert stability_margin_m(None, _Check(), [s, four]) == pytest.approx(1 / np.sqrt(5))
    s.support = (1, 0, 2)  # orientation does not matter
    assert stability_margin_m(None, _Check(), [s]) == pytest.approx(1 / np.sqrt(5))
    assert np.isnan(stability_margin_m(None, _Check(), [four]))


def test_settings_errors_name_the_field():
    with pytest.raises(InputError, match="GlobalSettings.seed"):
        plan_global_walk(global_settings=GlobalSettings(seed=0))
    with pytest.raises(InputError, match="same x, y"):
        plan_global_walk(goal_xy=(0.2, 0.0), start_xy=(0.2, 0.0))


def test_cli_has_the_global_flag():
    from planner.cli.main import build_parser

    args = build_parser().parse_args(
        ["plan", "--terrain", COURSE, "--goal", "2.2,0", "--global", "--terms", "2"]
    )
    assert args.global_plan and args.terms == 2


@pytest.mark.slow
def test_global_planner_walks_through_the_opening_where_the_local_planner_is_stuck():
    """A shortened course: 1 m, 0.7 -> 1.7 with the wall in the middle (one sine term).

    The paper's straight tau0 (the guide path off: with it tau0 goes through the opening,
    tests/test_guide_path.py), walked into the wall until 12 cycles bring it no nearer (a
    rule of the planner's own, the same on every machine; a time budget, which it burned
    whole before, made the test 2.3x longer and its outcome the machine's); then
    generations of 2 candidates on a pool of 2. With seed 713 the first generation's
    candidates (0.35 and 0.30 m) both go through the opening: the search takes one walk's
    time, where a candidate into the wall would take the time of tau0 again.
    """
    plan, report = plan_global_walk(
        "littledog",
        COURSE,
        goal_xy=(1.7, 0.0),
        start_xy=(0.7, 0.0),
        planner="soft",
        # a time budget never reached: tau0 stops by no progress (11 steps, ~10 s here)
        settings=LocalSettings(time_budget_s=300.0, max_fails_in_row=4, no_progress_cycles=12),
        global_settings=GlobalSettings(
            terms=1, popsize=2, workers=2, patience=0, max_generations=3, seed=713, guide=False
        ),
    )
    g = plan.stats["global"]
    # tau0 = the local planner alone: blocked by the wall
    assert not g["tau0"]["reached"] and g["tau0"]["distance_to_goal_m"] > 0.3
    # the global planner's tau goes through the opening, and the plan is valid
    assert g["best"]["reached"] and report.ok and plan.outcome["reached_goal"]
    assert 0.15 < g["best"]["coefficients_m"][0] < 0.45
    assert g["best"]["cost"] < g["tau0"]["cost"] - 40
    ys = [k.base_position[1] for k in plan.keyframes]
    assert max(ys) > 0.15  # it went round


def test_a_candidate_the_planner_cannot_start_costs_as_much_as_no_progress(monkeypatch):
    from planner.core.errors import NoSolutionFound
    from planner.planning import global_plan as gp
    from planner.planning.soft import SoftPlanner

    problem = gp._Problem(
        "littledog",
        load_terrain("flat").spec,
        None,
        "soft",
        LocalSettings(),
        (0.2, 0.0),
        (1.2, 0.0),
        CostWeights(),
    )
    old = signal.getsignal(signal.SIGINT)
    try:
        gp._init_worker(problem)  # what a worker process does first (it ignores Ctrl-C)
    finally:
        signal.signal(signal.SIGINT, old)

    def no_stance(self, *args, **kwargs):
        raise NoSolutionFound("initial placement at (0.200, 0.000) failed")

    monkeypatch.setattr(SoftPlanner, "plan", no_stance)
    ev, plan = gp._evaluate([0.1])
    assert plan is None and not ev.reached and ev.validated is None
    assert ev.cost >= 100 * 1.0 + 50 and "initial placement" in ev.message


def test_a_candidate_already_costlier_than_the_best_stops_early():
    """Early rejection: once the length, steps and planning time of a partial walk add up to
    the best candidate's C, planning stops; below that bound the same candidate walks on."""
    from planner.planning import global_plan as gp

    problem = gp._Problem(
        "littledog", load_terrain("flat").spec, None, "soft", LocalSettings(),
        (0.2, 0.0), (0.5, 0.0), CostWeights(),
    )  # fmt: skip
    old = signal.getsignal(signal.SIGINT)
    try:
        gp._init_worker(problem)
    finally:
        signal.signal(signal.SIGINT, old)
    ev, plan = gp._evaluate([0.0], 1, 0.3)  # the 0.3 m path alone costs 0.3
    assert plan is None and not ev.reached and "rejected after 1 steps" in ev.message
    assert ev.cost >= 0.3 and ev.steps == 1
    ev, plan = gp._evaluate([0.0], 1, 100.0)
    assert plan is not None and ev.reached and ev.steps > 1
    # the search's time budget spent: the candidate is not planned and costs not-reached
    ev, plan = gp._evaluate([0.0], 1, 100.0, deadline=time.time() - 1.0)
    assert plan is None and not ev.reached and ev.steps == 0 and "budget is spent" in ev.message
    assert ev.cost >= CostWeights().not_reached + CostWeights().goal_per_m * 0.3 - 1e-9
