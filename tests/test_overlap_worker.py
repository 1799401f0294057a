"""The swing overlaps searched in a forked worker (planner.planning.prefetch): the same plan to
the bit as the planner computing them itself, through rewinds, and without a worker."""

import copy
import multiprocessing
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from planner.motion.trajectory import Trajectory
from planner.planning.local import LocalSettings, Walk
from planner.planning.prefetch import ENV_OFF, OverlapWorker
from planner.planning.soft import SoftPlanner
from planner.planning.walk import plan_walk
from planner.world.terrain import load_terrain


@pytest.fixture(autouse=True)
def worker_on(monkeypatch):
    """The worker even where the suite runs a planning process per core (conftest)."""
    monkeypatch.setenv(ENV_OFF, "1")


def _same_walk(a, b) -> None:
    assert len(a.samples) == len(b.samples) and len(a.keyframes) == len(b.keyframes)
    np.testing.assert_array_equal(a.times, b.times)
    for x, y in zip(a.samples + a.keyframes, b.samples + b.keyframes, strict=True):
        np.testing.assert_array_equal(x.joints_rad, y.joints_rad)
        np.testing.assert_array_equal(x.base_position_W, y.base_position_W)
        np.testing.assert_array_equal(x.base_rotation_W, y.base_rotation_W)
        np.testing.assert_array_equal(x.feet_W, y.feet_W)
        np.testing.assert_array_equal(x.in_contact, y.in_contact)


def test_a_plan_is_the_same_to_the_bit_with_the_overlap_worker(littledog):
    """rough2cm's relief (some swings overlap their body move, some do not): the plan with
    the worker equals the plan without it, sample for sample, and the worker did the work."""
    plans = {}
    for worker in (True, False):
        plans[worker], report = plan_walk(
            littledog, "rough2cm", (0.75, 0.0), (0.55, 0.0), "soft",
            LocalSettings(overlap_worker=worker),
        )  # fmt: skip
        assert report.ok, report.summary()
    on, off = plans[True], plans[False]
    assert on.outcome["reached_goal"] and off.outcome["reached_goal"]
    np.testing.assert_array_equal(on.samples.q, off.samples.q)
    np.testing.assert_array_equal(on.samples.time, off.samples.time)
    np.testing.assert_array_equal(on.samples.contact, off.samples.contact)
    assert [k.to_dict() for k in on.keyframes] == [k.to_dict() for k in off.keyframes]
    assert off.stats["overlap_worker_steps"] == 0
    # the worker timed most steps (the walk's last ones may be timed by the planner itself)
    assert on.stats["overlap_worker_steps"] >= on.stats["steps"] // 2 > 0


@pytest.fixture(scope="module")
def three_steps(littledog):
    """Three consecutive crawl steps on flat ground and a shorter alternative third."""
    terrain = load_terrain("flat")
    planner = SoftPlanner(littledog, terrain)
    tau = Trajectory.straight((0.2, 0.0), (1.0, 0.0), terrain, planner.com_height_m())
    state = planner.initial_state((0.2, 0.0), tau)
    steps = []
    for leg in planner.settings.gait[:3]:
        step = planner.step(state, leg, tau, planner.stride_m())
        assert step.ok, step.diagnosis
        steps.append(step)
        state = step.end
    short = planner.step(steps[1].end, steps[2].leg, tau, 0.5 * planner.stride_m())
    assert short.ok, short.diagnosis
    return planner, steps[0].start, steps, short


def _fresh(steps):
    return copy.deepcopy(steps)


def _walk_through(planner, start, steps, short, worker):
    """Add, trace back, keep the nearest, restore: the recursive planner's moves."""
    s1, s2, s3 = steps
    walk = Walk(planner, start, worker)
    walk.add(s1)
    walk.add(s2)
    mark = walk.mark()
    walk.add(s3)
    kept = walk.copy()
    walk.rewind(mark)
    walk.add(short)
    assert walk.state is short.end and walk.steps == 3
    walk.restore(kept)
    assert walk.state is s3.end and walk.n_keyframes == 1 + 3 * 3
    return walk


def test_a_walk_traced_back_and_restored_is_timed_the_same_with_the_worker(three_steps):
    planner, start, steps, short = three_steps
    alone = _walk_through(planner, start, *_fresh([steps, short]), worker=None)
    worker = OverlapWorker.start(planner)
    assert worker is not None  # Linux: fork
    try:
        with_worker = _walk_through(planner, start, *_fresh([steps, short]), worker=worker)
        _same_walk(alone, with_worker)
        assert worker.used >= 1
        assert len(alone.keyframes) == alone.n_keyframes
        assert any(s.overlap is not None for s in alone.parts)  # swings that overlap
    finally:
        worker.close()


def test_a_dead_worker_leaves_the_planner_to_time_its_steps(three_steps):
    planner, start, steps, short = three_steps
    alone = _walk_through(planner, start, *_fresh([steps, short]), worker=None)
    worker = OverlapWorker.start(planner)
    worker._proc.kill()
    worker._proc.join()
    try:
        walk = _walk_through(planner, start, *_fresh([steps, short]), worker=worker)
        _same_walk(alone, walk)
        assert worker.used == 0
    finally:
        worker.close()


def test_without_fork_there_is_no_worker(three_steps, monkeypatch):
    planner = three_steps[0]
    monkeypatch.setattr(multiprocessing, "get_all_start_methods", lambda: ["spawn"])
    assert OverlapWorker.start(planner) is None


def _children(pid: int) -> list[str]:
    ps = subprocess.run(["ps", "-o", "pid=,stat=", "--ppid", str(pid)], capture_output=True)
    rows = [line.split() for line in ps.stdout.decode().splitlines() if line.strip()]
    return [row[0] for row in rows if not row[1].startswith("Z")]


def test_a_planner_killed_takes_its_worker_with_it(tmp_path):
    """``stratawalk plan`` killed outright (SIGKILL: no handler, no atexit) while its worker
    runs: the worker is gone within seconds, nothing of the session is left (a batch job
    stopped on Ctrl-C once left its worker blocked on the pipe, and the batch hung)."""
    env = dict(os.environ, **{ENV_OFF: "1"})
    proc = subprocess.Popen(
        [sys.executable, "-m", "planner.cli.main", "plan", "--terrain", "flat", "--goal", "2.2,0",
         "--out", str(tmp_path / "p.json")],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True, env=env,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 300
        while not _children(proc.pid):  # the worker is forked when planning starts
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.2)
        worker = _children(proc.pid)
        proc.kill()
        proc.wait()
        deadline = time.monotonic() + 10
        while any(os.path.exists(f"/proc/{pid}") and _alive(pid) for pid in worker):
            assert time.monotonic() < deadline, f"worker {worker} outlived its planner"
            time.sleep(0.2)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def _alive(pid: str) -> bool:
    try:
        state = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_a_pool_with_a_process_per_core_plans_without_the_worker():
    """batch and bench's pools (planner.bench.batch.run_pool): a job process per core turns the
    worker off in each (it would only add a process per core); fewer leave it on."""
    from planner.bench.batch import run_pool

    def error(job, exc):
        raise exc

    cores = os.cpu_count() or 1
    got = list(run_pool(os.getenv, [ENV_OFF], cores, error))
    assert got == ["0"]
    if cores > 1:
        assert list(run_pool(os.getenv, [ENV_OFF], 1, error)) == ["1"]  # the fixture's


def test_a_step_that_does_not_pickle_is_timed_by_the_planner(three_steps):
    planner, start, steps, short = three_steps
    alone = _walk_through(planner, start, *_fresh([steps, short]), worker=None)
    fresh, fresh_short = _fresh([steps, short])
    fresh[0].body_path[0].info["not_picklable"] = lambda: None
    worker = OverlapWorker.start(planner)
    try:
        walk = _walk_through(planner, start, fresh, fresh_short, worker=worker)
        _same_walk(alone, walk)
        assert fresh[0].timed and worker.used >= 1  # the others went to the worker
    finally:
        worker.close()
