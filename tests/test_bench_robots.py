"""``stratawalk bench robots`` (issue 14): courses scaled to each robot, rows, errors."""

import numpy as np
import pytest

from planner.bench.physics import job_id
from planner.bench.robots import (
    RELIEF_FRACTION,
    STEP_FRACTION,
    WALK_M,
    render_markdown,
    robot_course,
    robot_jobs,
    robot_rows,
    summarize,
)
from planner.body.robot import load_robot
from planner.cli.main import main
from planner.world.terrain import Terrain


@pytest.mark.parametrize("name", ["littledog", "anymal"])
def test_courses_scale_with_the_legs(name):
    reach = float(np.mean(load_robot(name).reach_m))
    spec = robot_course(name, "rough")
    rough = Terrain.from_spec(spec)
    xs = np.linspace(spec["x_start"], spec["x_end"], 400)
    ys = np.linspace(spec["y_min"], spec["y_max"], 120)
    h = rough.height(xs[None, :] + 0 * ys[:, None], ys[:, None] + 0 * xs[None, :])
    # the relief's peak over the course (its taper aside) is the scaled amplitude
    assert np.abs(h).max() == pytest.approx(RELIEF_FRACTION * reach, rel=0.05)
    step = Terrain.from_spec(robot_course(name, "step"))
    top = float(step.height_sharp(np.array(WALK_M), np.array(0.0)))
    assert top == pytest.approx(STEP_FRACTION * reach, rel=1e-3)
    flat = robot_course(name, "flat")
    assert flat["x_min"] + flat["length"] > WALK_M + reach  # the goal's stance is on it


def _record(job, reached, check, fb_reached=None, fell=None):
    rows = []
    if fb_reached is not None:
        rows = [{"mode": "feedback", "status": "ok", "reached": fb_reached, "fell": fell,
                 "message": "fell at 3 s" if fell else ""}]  # fmt: skip
    return {
        "id": job_id(job),
        "status": "ok",
        "planning": {
            "plan_reached": reached,
            "check_ok": check,
            "steps": 40,
            "planning_time_s": 12.0,
            "walk_time_s": 200.0,
            "message": "m",
        },  # fmt: skip
        "rows": rows,
    }


def test_rows_and_summary_from_records(tmp_path):
    jobs = robot_jobs(["littledog"], ("flat", "rough", "step"), 60.0, tmp_path)
    records = {
        job_id(jobs[0]): _record(jobs[0], True, True, True, False),
        job_id(jobs[1]): _record(jobs[1], True, True, False, True),
        job_id(jobs[2]): _record(jobs[2], False, True),
    }
    rows = robot_rows(jobs, records)
    assert [r["course"] for r in rows] == ["flat", "rough", "step"]
    assert rows[0]["walk_speed_cm_s"] == pytest.approx(100 * WALK_M / 200.0)
    assert rows[2]["walk_speed_cm_s"] is None and rows[2]["feedback_reached"] is None
    assert summarize(rows) == {"jobs": 3, "planned": 2, "simulated": 2, "feedback_ok": 1}
    md = render_markdown(
        {
            "config": {
                "walk_m": WALK_M,
                "time_budget_s": 60.0,
                "relief_fraction": 0.1,
                "step_fraction": 0.3,
            },
            "rows": rows,
            "summary": summarize(rows),
            "machine": {},
            "total_time_s": 1.0,
        }  # fmt: skip
    )
    assert "| littledog | flat | yes | yes | 40 |" in md and "fell at 3 s" in md


@pytest.mark.parametrize(
    "args, expect",
    [
        (["--robots", "nosuch"], "--robots: unknown robot 'nosuch'"),
        (["--courses", "flat,hill"], "--courses: unknown kind 'hill'"),
        (["--time-budget", "0"], "--time-budget"),
        (["--workers", "0"], "--workers"),
    ],
)
def test_bad_options_are_one_line_errors(args, expect, tmp_path, capsys):
    assert main(["bench", "robots", "--out", str(tmp_path), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and expect in err, err
