"""The process-wide store of Theta problems (planner.problems.cache): a second plan in the
same process builds nothing again, and only equal robots, terrains and options share."""

import json
from dataclasses import replace

import numpy as np
import pytest

from planner.body.robot import load_robot
from planner.planning.local import LocalSettings
from planner.planning.soft import SoftPlanner
from planner.planning.walk import plan_walk
from planner.problems import Theta2
from planner.problems import cache as problem_cache
from planner.problems.options import ThetaOptions
from planner.world.terrain import Terrain, load_terrain


@pytest.fixture(autouse=True)
def empty_store():
    problem_cache.clear_problems()
    yield
    problem_cache.clear_problems()


def test_fingerprints_follow_content_not_identity(tmp_path):
    assert load_robot("littledog").fingerprint() == load_robot("littledog").fingerprint()
    assert (
        load_robot("littledog").fingerprint()
        != load_robot("littledog", foot_radius_m=0.015).fingerprint()
    )
    assert load_robot("littledog").fingerprint() != load_robot("solo12").fingerprint()
    assert load_terrain("rough2cm").fingerprint() == load_terrain("rough2cm").fingerprint()
    spec = dict(load_terrain("rough2cm").spec)
    assert Terrain(dict(spec, seed=spec["seed"] + 1)).fingerprint() != (Terrain(spec).fingerprint())
    # a height field: the same file name with other heights is another terrain
    grid = tmp_path / "grid.npy"
    np.save(grid, np.zeros((5, 6)))
    hf = {"kind": "heightfield", "file": str(grid), "resolution": 0.1, "origin": [0.0, -0.2]}
    first = Terrain(hf).fingerprint()
    np.save(grid, np.full((5, 6), 0.01))
    assert Terrain(hf).fingerprint() != first


def test_shared_problem_is_built_once_per_content(littledog):
    terrain = load_terrain("flat")
    opts = ThetaOptions()
    a = problem_cache.shared_problem(Theta2, littledog, terrain, opts, 0.7, support=(0, 1, 2))
    b = problem_cache.shared_problem(
        Theta2, load_robot("littledog"), load_terrain("flat"), ThetaOptions(), 0.7,
        support=(0, 1, 2),
    )  # fmt: skip
    assert a is b and problem_cache.stored_problems() == 1
    others = [
        problem_cache.shared_problem(Theta2, littledog, terrain, opts, 0.7, support=(1, 2, 3)),
        problem_cache.shared_problem(Theta2, littledog, terrain, opts, 0.5, support=(0, 1, 2)),
        problem_cache.shared_problem(
            Theta2,
            littledog,
            terrain,
            replace(opts, balance_margin_m=0.03),
            0.7,
            support=(0, 1, 2),
        ),  # fmt: skip
        problem_cache.shared_problem(
            Theta2, littledog, load_terrain("rough2cm"), opts, 0.7, support=(0, 1, 2)
        ),
    ]
    assert all(o is not a for o in others) and len({id(o) for o in others}) == 4
    assert others[1].mu == 0.5 and others[2].options.balance_margin_m == 0.03


def test_the_store_keeps_the_problems_used_last(littledog, monkeypatch):
    monkeypatch.setattr(problem_cache, "MAX_PROBLEMS", 2)
    terrain = load_terrain("flat")
    built = [
        problem_cache.shared_problem(Theta2, littledog, terrain, ThetaOptions(), 0.7, support=s)
        for s in [(0, 1, 2), (1, 2, 3)]
    ]
    problem_cache.shared_problem(Theta2, littledog, terrain, ThetaOptions(), 0.7, support=(0, 1, 2))
    problem_cache.shared_problem(Theta2, littledog, terrain, ThetaOptions(), 0.7, support=(0, 2, 3))
    assert problem_cache.stored_problems() == 2
    again = problem_cache.shared_problem(
        Theta2, littledog, terrain, ThetaOptions(), 0.7, support=(0, 1, 2)
    )
    assert again is built[0]  # used last but one: kept; (1, 2, 3) was dropped


def test_a_second_plan_in_the_process_builds_nothing_and_is_the_same():
    plans = []
    for _ in range(2):
        plan, report = plan_walk(
            "littledog", "flat", (0.3, 0.0), (0.2, 0.0), "soft", LocalSettings()
        )
        assert report.ok
        plans.append(json.dumps(plan.to_dict()["samples"], sort_keys=True))
        if len(plans) == 1:
            stored = problem_cache.stored_problems()
            assert stored > 0
    assert problem_cache.stored_problems() == stored  # the second plan built no problem
    assert plans[0] == plans[1]
    # two planners on robots and terrains loaded again share their problems
    p1 = SoftPlanner(load_robot("littledog"), load_terrain("flat"))
    p2 = SoftPlanner(load_robot("littledog"), load_terrain("flat"))
    assert p1.theta2((0, 1, 2)) is p2.theta2((0, 1, 2))
