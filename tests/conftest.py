import os

import numpy as np
import pytest

# make test runs a planning process per core (pytest -n auto): each plans without the
# overlap worker (planner.planning.prefetch), which would only add a process per core (825 s
# against 763 s for the suite, 2 cores); the worker's own tests turn it on
if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) >= (os.cpu_count() or 1):
    os.environ.setdefault("STRATAWALK_OVERLAP_WORKER", "0")

from planner.body.robot import load_robot


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
    from planner.planfile.plan import Plan
    from planner.planning.local import LocalSettings
    from planner.planning.walk import plan_walk
    from planner.replay.plots import plan_series

    plan, report = plan_walk("littledog", "flat", (0.3, 0.0), (0.2, 0.0), "soft", LocalSettings())
    assert report.ok, report.summary()
    path = plan.save(tmp_path_factory.mktemp("walk") / "plan.json")
    plan = Plan.load(path)
    return path, plan, plan_series(plan)


# test files whose module fixtures plan long walks (500 s and 230 s on this 2-core
# machine): started first, so that with pytest-xdist (make test: a file per worker at a
# time, in this order: --no-loadscope-reorder) the other files share the other worker
# meanwhile instead of waiting behind them
LONG_FILES = ("test_climb.py", "test_dead_ends.py")


def pytest_collection_modifyitems(config, items):
    items.sort(key=lambda item: item.path.name not in LONG_FILES)  # stable: else as collected
