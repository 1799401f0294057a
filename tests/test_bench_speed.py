"""``stratawalk bench speed``: the breakdown adds up, the files and tables are written."""

import json
from types import SimpleNamespace

import pytest

from planner.bench.speed import profile_groups, run_speed_bench
from planner.cli.main import main


def test_profile_groups_give_library_time_to_the_heaviest_caller():
    """Own time per module group; a builtin or library function counts for its heaviest
    caller's group (followed through library callers), and nothing is lost."""
    terrain = ("/x/planner/world/terrain.py", 1, "height")
    theta = ("/x/planner/problems/base.py", 2, "solve")
    wrapper = ("/lib/casadi/casadi.py", 3, "call")
    cos = ("~", 0, "<built-in method numpy.cos>")
    c_call = ("~", 0, "<built-in method _casadi.call>")
    orphan = ("/lib/other.py", 4, "f")
    stats = SimpleNamespace(
        stats={
            terrain: (1, 1, 0.5, 1.0, {}),
            theta: (1, 1, 0.1, 2.0, {}),
            wrapper: (1, 1, 0.2, 1.9, {theta: (1, 1, 0.2, 1.9)}),
            c_call: (1, 1, 1.7, 1.7, {wrapper: (1, 1, 1.7, 1.7)}),
            # called from both; terrain's edge is the heavier
            cos: (3, 3, 0.4, 0.4, {terrain: (2, 2, 0.3, 0.3), theta: (1, 1, 0.1, 0.1)}),
            orphan: (1, 1, 0.05, 0.05, {}),
        }
    )
    got = profile_groups(stats)
    assert got["terrain"] == pytest.approx(0.9)
    assert got["theta"] == pytest.approx(0.1 + 0.2 + 1.7)
    assert got["other"] == pytest.approx(0.05)
    assert sum(got.values()) == pytest.approx(sum(v[2] for v in stats.stats.values()))


def test_a_tiny_speed_bench_writes_its_tables(tmp_path, capsys, monkeypatch):
    """One course and one flat length, once each in a new process (the course's plan also in
    MuJoCo), plus the profiled run."""
    monkeypatch.setenv("STRATAWALK_OVERLAP_WORKER", "1")  # as a lone bench run has it
    res = run_speed_bench(("flat",), 0.45, (0.25,), 1, tmp_path, ("default", "fast-serial"))
    (row, fast), (flat,) = res["courses"], res["flat"]
    assert (row["preset"], fast["preset"]) == ("default", "fast-serial")
    # the overlap worker forks inside the bench's spawned process; -serial plans without it
    assert row["worker_steps"] > 0 and fast["worker_steps"] == 0
    assert fast["reached"] and fast["check_ok"] and fast["mujoco"]["open"]["reached"]
    assert row["reached"] and row["check_ok"] and row["steps"] >= 4
    assert row["planning_median_s"] > 0 and row["total_median_s"] >= row["planning_median_s"]
    assert row["walk_speed_cm_s"] == pytest.approx(100 * 0.25 / row["walk_s"])
    assert sum(row["breakdown_s"].values()) == pytest.approx(row["profile_total_s"])
    assert row["breakdown_s"]["theta"] > 0 and row["breakdown_s"]["ik"] > 0
    assert flat["course"] == "flat 0.25 m" and flat["reached"] and "breakdown_s" not in flat
    assert json.loads((tmp_path / "speed.json").read_text())["format"] == "stratawalk.bench.speed/1"
    md = (tmp_path / "speed.md").read_text()
    assert "| flat | default | yes, ok |" in md and "| flat | fast-serial | yes, ok |" in md
    assert "## Flat walks by length" in md
    # the first plan, executed in MuJoCo at its own timing: it holds up
    for mode in ("open", "feedback"):
        run = row["mujoco"][mode]
        assert run["reached"] and not run["fell"], (mode, run)
    assert "## The plans in MuJoCo" in md and "| reached |" in md
    assert main(["bench", "speed", "--repeats", "0", "--out", str(tmp_path)]) == 2
    assert "--repeats: must be >= 1" in capsys.readouterr().err
    assert main(["bench", "speed", "--presets", "slow", "--out", str(tmp_path)]) == 2
    assert "--presets: unknown 'slow'; known: default, fast" in capsys.readouterr().err
    assert main(["bench", "speed", "--presets", "slow-serial", "--out", str(tmp_path)]) == 2
    assert "--presets: unknown 'slow-serial'" in capsys.readouterr().err
