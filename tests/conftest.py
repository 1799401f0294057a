import numpy as np
import pytest

from planner.robot import load_robot


@pytest.fixture(scope="session")
def littledog():
    return load_robot("littledog")


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)


@pytest.fixture(scope="session")
def short_flat_walk(tmp_path_factory):
    """A short validated walk on flat ground (two crawl steps), saved; its path, the plan
    loaded back from the file, and its series (shared by the replay and plot tests)."""
    from planner.local.base import LocalSettings
    from planner.plan import Plan
    from planner.plots import plan_series
    from planner.walk import plan_walk

    plan, report = plan_walk("littledog", "flat", (0.3, 0.0), (0.2, 0.0), "soft", LocalSettings())
    assert report.ok, report.summary()
    path = plan.save(tmp_path_factory.mktemp("walk") / "plan.json")
    plan = Plan.load(path)
    return path, plan, plan_series(plan)
