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


# the longest test files, longest first (make test on this 2-core machine: the recursive
# climb of the 10 cm step ~60 s, test_replay ~60 s with its 4 m walk, test_fuzz, test_local,
# test_simulate 50-60 s, the rest 20-45 s; test_dead_ends, 150 s, runs in make test-long):
# with pytest-xdist (make test: a file per worker at a time, in this order:
# --no-loadscope-reorder; a worker takes the next file once two of its tests are left) the
# long files start first and the many short ones fill in around them, instead of a long
# file starting last on a worker
LONG_FILES = (
    "test_dead_ends.py",
    "test_climb.py",
    "test_replay.py",
    "test_fuzz.py",
    "test_local.py",
    "test_simulate.py",
    "test_mesh_terrain.py",
    "test_bad_input.py",
    "test_batch.py",
    "test_global_plan.py",
    "test_notebooks.py",
    "test_two_beat.py",
    "test_bench_speed.py",
    "test_guide_path.py",
    "test_overlap.py",
)


def pytest_collection_modifyitems(config, items):
    order = {name: k for k, name in enumerate(LONG_FILES)}
    # stable: the long files in the order above, the rest as collected
    items.sort(key=lambda item: order.get(item.path.name, len(LONG_FILES)))
