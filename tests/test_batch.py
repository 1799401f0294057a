import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from planner.bench.batch import job_id, load_scenarios, read_results, run_batch
from planner.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
DETERMINISTIC = ("status", "reached", "validated", "steps", "distance_to_goal_m", "message")

# tiny walks (15 cm on flat, a few steps each) and one job that fails (unknown robot)
TINY = """\
defaults:
  terrain: flat
  start: [0.2, 0.0]
  goal: [0.35, 0.0]
  time_budget_s: 30
jobs:
  - {planner: soft}
  - {planner: recursive}
  - {planner: soft, goal: [0.33, 0.04]}
  - {robot: no_such_robot}
"""


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The tiny batch run once through the command line with a local pool of 2."""
    d = tmp_path_factory.mktemp("tiny")
    scen = d / "scenarios.yaml"
    scen.write_text(TINY)
    out = d / "local"
    rc = main(["batch", str(scen), "--out", str(out), "--workers", "2", "--quiet"])
    jobs = load_scenarios(scen)
    return jobs, out / "results.jsonl", rc


def _lines(path: Path) -> list[dict]:
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()]


def _same(a: dict, b: dict) -> bool:
    return all(a.get(k) == b.get(k) for k in DETERMINISTIC)


def test_scenarios_defaults_matrix_dedup_and_relative_paths(tmp_path):
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "mine.yaml").write_text("kind: flat\nlength: 3\n")
    scen = tmp_path / "s.yaml"
    scen.write_text(
        "defaults: {planner: recursive, seed: 3}\n"
        "jobs:\n  - {terrain: t/mine.yaml}\n  - {terrain: flat, planner: soft}\n"
        "matrix:\n  terrain: [flat, rough2cm]\n  planner: [soft, recursive]\n"
    )
    jobs = load_scenarios(scen)
    assert len(jobs) == 5  # (flat, soft) appears twice
    assert jobs[0]["terrain"] == str((tmp_path / "t" / "mine.yaml").resolve())
    assert all(j["seed"] == 3 and j["robot"] == "littledog" for j in jobs)
    assert jobs[1] == jobs[1] | {"start": [0.2, 0.0], "goal": [2.2, 0.0], "time_budget_s": 60.0}


def test_job_id_is_a_hash_of_the_fields():
    a = {
        "robot": "littledog",
        "terrain": "flat",
        "start": [0.2, 0.0],
        "goal": [0.45, 0.0],
        "planner": "soft",
        "seed": 0,
        "time_budget_s": 30.0,
    }
    assert job_id(a) == job_id(dict(reversed(list(a.items()))))
    assert len(job_id(a)) == 16 and job_id(a) != job_id(a | {"seed": 1})


@pytest.mark.parametrize(
    "text, where",
    [
        ("jobs: [{terrain: flat}\n", "not valid YAML at line"),
        ("- a\n- b\n", "expected a mapping"),
        ("jobz: []\n", "jobz: unknown top-level field"),
        ("jobs:\n  - {terrain: flat, goal: [1]}\n", "jobs[0].goal: expected [x, y]"),
        ("jobs:\n  - {terrain: flat, planner: fast}\n", "jobs[0].planner: expected one of"),
        ("jobs:\n  - {planner: soft}\n", "jobs[0].terrain: missing"),
        ("matrix: {terrain: flat}\n", "matrix.terrain: expected a non-empty list"),
        ("defaults: {speed: 2}\njobs: [{terrain: flat}]\n", "defaults.speed: unknown field"),
        ("defaults: {seed: -1}\njobs: [{terrain: flat}]\n", "jobs[0].seed: expected an integer"),
        ("{}\n", "no jobs"),
    ],
)
def test_malformed_scenarios_give_a_one_line_error(tmp_path, capsys, text, where):
    scen = tmp_path / "bad.yaml"
    scen.write_text(text)
    assert main(["batch", str(scen), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "bad.yaml" in err and where in err, err


def test_missing_scenarios_file(tmp_path, capsys):
    assert main(["batch", str(tmp_path / "nope.yaml"), "--out", str(tmp_path)]) == 2
    assert "no such scenarios file" in capsys.readouterr().err


def test_local_pool_runs_every_job_and_records_the_failing_one(tiny):
    jobs, results, rc = tiny
    assert rc == 1  # one job failed
    lines = _lines(results)
    assert sorted(r["id"] for r in lines) == sorted(job_id(j) for j in jobs)
    by_id = {r["id"]: r for r in lines}
    bad = by_id[job_id(jobs[3])]
    assert bad["status"] == "error" and "no_such_robot" in bad["error"]
    for j in jobs[:3]:
        r = by_id[job_id(j)]
        assert r["status"] == "ok" and r["reached"] and r["validated"], r
        assert r["steps"] > 0 and r["walk_time_s"] > 0
        assert r["time_ratio"] == pytest.approx(r["planning_time_s"] / r["walk_time_s"])


def test_interrupted_batch_resumes_without_losing_or_repeating_results(tiny, tmp_path):
    jobs, results, _ = tiny
    local = read_results(results)
    out = tmp_path / "resume"
    out.mkdir()
    # a first run that finished one job and was killed while writing the next line
    first = results.read_text().splitlines()[0]
    (out / "results.jsonl").write_text(first + "\n" + first[: len(first) // 2])
    stop_after_one = []

    def interrupt(rec):
        stop_after_one.append(rec["id"])
        raise KeyboardInterrupt  # Ctrl-C right after the first new result is written

    s1 = run_batch(jobs, out, workers=1, progress=False, on_record=interrupt)
    assert s1.interrupted and s1.skipped == 1 and s1.ran == 1
    assert len(s1.records) == 2  # the jobs not yet run are not recorded
    s2 = run_batch(jobs, out, workers=1, progress=False)
    assert not s2.interrupted and s2.skipped == 2 and s2.ran == 2
    lines = _lines_tolerant(out / "results.jsonl")
    ids = [r["id"] for r in lines]
    assert len(ids) == len(set(ids)) == len(jobs)  # none lost, none repeated
    assert (out / "results.jsonl").read_text().startswith(first + "\n")  # old line untouched
    for r in lines:
        assert _same(r, local[r["id"]])
    s3 = run_batch(jobs, out, progress=False)  # nothing left to do
    assert s3.ran == 0 and s3.skipped == len(jobs)


def _lines_tolerant(path: Path) -> list[dict]:
    out = []
    for x in path.read_text().splitlines():
        try:
            out.append(json.loads(x))
        except json.JSONDecodeError:
            pass
    return out


def _start(cmd: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen(
        cmd, cwd=ROOT, stdout=log.open("w"), stderr=subprocess.STDOUT, start_new_session=True
    )


@pytest.mark.slow
def test_dask_cluster_gives_the_same_results_as_the_local_pool(tiny, tmp_path):
    jobs, results, _ = tiny
    dask = str(Path(sys.executable).parent / "dask")
    sched_file = tmp_path / "scheduler.json"
    procs = [
        _start(
            [dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard"]
            + ["--scheduler-file", str(sched_file)],
            tmp_path / "scheduler.log",
        )
    ]
    try:
        t0 = time.monotonic()
        while not sched_file.exists() and time.monotonic() - t0 < 60:
            time.sleep(0.2)
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        procs.append(
            _start(
                [dask, "worker", "--scheduler-file", str(sched_file), "--nworkers", "1"]
                + ["--nthreads", "1", "--no-dashboard"],
                tmp_path / "worker.log",
            )
        )
        out = tmp_path / "dask"
        rc = main(
            ["batch", str(results.parent.parent / "scenarios.yaml"), "--out", str(out)]
            + ["--scheduler", address, "--quiet"]
        )
        assert rc == 1  # the same failing job
        local, remote = read_results(results), read_results(out / "results.jsonl")
        assert set(remote) == set(local)
        for k in local:
            assert _same(remote[k], local[k]), (remote[k], local[k])
        assert {r["pid"] for r in remote.values()}.isdisjoint({os.getpid()})
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def test_unreachable_scheduler_is_a_one_line_error(tiny, tmp_path):
    from planner.core.errors import InputError

    jobs, _, _ = tiny
    with pytest.raises(InputError, match="--scheduler tcp://127.0.0.1:9: cannot connect") as e:
        run_batch(jobs, tmp_path, scheduler="tcp://127.0.0.1:9", connect_timeout_s=1.0)
    assert "\n" not in str(e.value) and not (tmp_path / "results.jsonl").exists()


def test_example_scenarios_file_loads():
    jobs = load_scenarios(ROOT / "examples" / "scenarios.yaml")
    assert len(jobs) == 9 and {j["planner"] for j in jobs} == {"soft", "recursive"}
