import json

import pytest

from planner.bench.courses import expand_courses
from planner.bench.physics import (
    job_id,
    ladder_limits,
    physics_jobs,
    physics_rows,
    render_markdown,
    run_physics_bench,
    run_physics_job,
    summarize,
)
from planner.cli.main import main
from planner.world.course_gen import ladder_course_names
from planner.world.terrain import load_terrain


def _job(course, group, modes=("open", "feedback")):
    return {
        "robot": "littledog",
        "course": course,
        "group": group,
        "terrain": course,
        "planner": "soft",
        "start": [0.2, 0.0],
        "goal": [2.2, 0.0],
        "modes": list(modes),
        "time_budget_s": 60.0,
        "time_scale": 1.0,
        "plans_dir": None,
    }


def _sim(reached, fell=False, **kw):
    return {
        "status": "ok",
        "reached": reached,
        "fell": fell,
        "final_error_cm": 3.2,
        "com_to_goal_cm": 4.1 if reached else 30.0,
        "body_contact": False,
        "leg_contact_s": 0.0,
        "max_slip_mm": 2.5,
        "max_sliding_mm": 0.4,
        "saturation_pct": 1.5,
        "sim_time_s": 130.0,
        "message": "executed as planned" if reached else "fell at 3.0 s (roll)",
        "wall_time_s": 20.0,
    } | kw


def _record(job, planned, open_row, feedback_row):
    rows = [
        {"course": job["course"], "group": job["group"], "mode": m} | r
        for m, r in (("open", open_row), ("feedback", feedback_row))
    ]
    planning = {"planned": planned, "plan_reached": planned, "check_ok": True, "steps": 60}
    planning |= {"planning_time_s": 8.0, "walk_time_s": 130.0}
    return {"id": job_id(job), "job": job, "status": "ok", "planning": planning, "rows": rows}


@pytest.fixture
def hand_made():
    jobs = [
        _job("flat", "named"),
        _job("step5cm", "named"),
        _job("gen:0", "generated"),
        _job("gen:1", "generated"),
        _job("gen:2", "generated"),
        _job("gen:3", "generated"),
    ]
    recs = [
        _record(jobs[0], True, _sim(True), _sim(True)),
        _record(jobs[1], True, _sim(False, fell=True), _sim(True)),
        _record(jobs[2], True, _sim(True), _sim(True)),
        _record(jobs[3], True, _sim(True, fell=True), _sim(False)),
        # the planner did not reach: open loop "reaches" the plan's end, no success
        _record(jobs[4], False, _sim(True), _sim(True)),
    ]
    err = {"status": "error", "error": "RuntimeError: boom"}
    recs[4]["rows"][1] = {"course": "gen:2", "group": "generated", "mode": "feedback"} | err
    return jobs, {r["id"]: r for r in recs}


def test_rows_and_summary_from_hand_made_records(hand_made):
    jobs, records = hand_made
    rows = physics_rows(jobs, records)
    assert [(r["course"], r["mode"]) for r in rows[:2]] == [("flat", "open"), ("flat", "feedback")]
    assert len(rows) == 12
    by = {(r["course"], r["mode"]): r for r in rows}
    assert by[("flat", "open")]["success"] and by[("flat", "open")]["planning_time_s"] == 8.0
    assert not by[("step5cm", "open")]["success"]  # fell
    assert not by[("gen:1", "open")]["success"]  # reached, but fell
    assert not by[("gen:2", "open")]["success"]  # the plan did not reach the goal
    assert by[("gen:2", "feedback")]["status"] == "error"
    # feedback reaches when the COM is at the goal, not at the end of a partial plan
    stale = dict(records[job_id(jobs[0])])
    stale["rows"] = [dict(r) for r in stale["rows"]]
    stale["rows"][1] |= {"reached": True, "com_to_goal_cm": 140.0}
    rows_stale = physics_rows(jobs[:1], {job_id(jobs[0]): stale})
    assert not rows_stale[1]["reached"] and not rows_stale[1]["success"]
    assert by[("gen:3", "open")]["status"] == "missing"  # no record
    s = summarize(rows)
    assert s["named"] == {"open": {"success": 1, "of": 2}, "feedback": {"success": 2, "of": 2}}
    g = s["generated"]
    assert (g["courses"], g["planned"]) == (4, 2)
    assert g["modes"]["open"] == {"success": 1, "of": 2, "fraction": 0.5}
    assert g["modes"]["feedback"] == {"success": 1, "of": 2, "fraction": 0.5}


def test_markdown_has_a_table_per_group_and_the_summary(hand_made):
    jobs, records = hand_made
    rows = physics_rows(jobs, records)
    result = {
        "config": {
            "start": [0.2, 0.0],
            "goal_named": [2.2, 0.0],
            "difficulty": 1.0,
            "time_budget_s": 60.0,
            "time_scale": 1.0,
            "modes": ["open", "feedback"],
            "workers": 2,
        },
        "machine": {"nproc": 2, "cpu": "x", "git_commit": "abc", "date": "today"},
        "total_time_s": 100.0,
        "interrupted": False,
        "summary": summarize(rows),
        "rows": rows,
    }
    md = render_markdown(result)
    named = md.index("## Named courses")
    gen = md.index("## Generated courses")
    summary = md.index("## Summary")
    assert named < md.index("| step5cm | open loop |") < gen < md.index("| gen:1 |") < summary
    flat = "| flat | open loop | yes | 8.0 | yes | no | 3.2 | 4.1 | no | 0.00 | 2.5 | 0.4 | 1.5"
    assert flat in md
    assert "RuntimeError: boom" in md and "| gen:3 | open loop | - | - | - |" in md
    assert md.count("Soft local planner (8.2)") == 1  # a result without "planner": soft's
    result["config"]["planner"] = "recursive"
    assert "Recursive local planner (8.5) from (0.2, 0.0)" in render_markdown(result)
    assert "named courses, open loop: 1 of 2 reached without a fall" in md
    assert "named courses, feedback (8.3): 2 of 2" in md
    assert "the planner reached the goal on 2 of 4" in md
    assert "open loop: 1 of 2 (50 %)" in md


def test_ladder_limits_are_the_largest_sizes_reached():
    """The limits table: per family (steps split up and down), each size's results and the
    largest size planned and reached in each mode; a gap in the ladder does not hide a
    larger size that was reached."""
    jobs = [_job(c, "ladder") for c in ("feat:step:0.06", "feat:step:0.1", "feat:step:0.08",
                                         "feat:step:-0.06", "feat:gap:0.04")]  # fmt: skip
    recs = [
        _record(jobs[0], True, _sim(True), _sim(True)),
        _record(jobs[1], True, _sim(True), _sim(False, fell=True)),
        _record(jobs[2], False, _sim(True), _sim(True)),  # not planned
        _record(jobs[3], True, _sim(False, fell=True), _sim(True)),
        _record(jobs[4], False, _sim(False), _sim(False)),
    ]
    rows = physics_rows(jobs, {r["id"]: r for r in recs})
    limits = ladder_limits(rows)
    assert set(limits) == {"step up", "step down", "gap"}
    up = limits["step up"]
    assert list(up["sizes"]) == ["0.06", "0.08", "0.1"] and up["unit"] == "m"
    assert up["sizes"]["0.08"] == {"planned": False, "open": False, "feedback": True}
    assert up["largest"] == {"planned": 0.1, "open": 0.1, "feedback": 0.08}
    assert limits["step down"]["largest"] == {"planned": 0.06, "open": None, "feedback": 0.06}
    assert limits["gap"]["largest"] == {"planned": None, "open": None, "feedback": None}
    assert (
        up["smallest_not_planned"] == 0.08 and limits["step down"]["smallest_not_planned"] is None
    )
    assert summarize(rows)["ladder"] == limits
    md = render_markdown(
        {
            "config": {"start": [0.2, 0.0], "goal_named": [2.2, 0.0], "difficulty": 1.0,
                       "time_budget_s": 60.0, "time_scale": 1.0, "modes": ["open", "feedback"],
                       "workers": 2},
            "machine": {}, "total_time_s": 1.0, "summary": summarize(rows), "rows": rows,
        }
    )  # fmt: skip
    assert md.index("## Feature ladder") < md.index("## Limits (feature ladder)")
    row = "| step up | m | 0.06: yes/yes/yes, 0.08: no/no/yes, 0.1: yes/yes/no | 0.08 | 0.1 | 0.1 |"
    row += " 0.08 |"
    assert row in md


def test_job_list(tmp_path):
    jobs = physics_jobs(generated=3, out_dir=tmp_path)
    assert [j["course"] for j in jobs][-4:] == ["barrier75mm", "gen:0", "gen:1", "gen:2"]
    assert len(jobs) == 12 and len({job_id(j) for j in jobs}) == 12
    named, gen = jobs[0], jobs[-1]
    assert (named["terrain"], named["goal"], named["group"]) == ("flat", [2.2, 0.0], "named")
    assert named["modes"] == ["open", "feedback", "correct"] and named["time_scale"] == 1.0
    assert gen["group"] == "generated" and gen["goal"] == [3.0, 0.0]
    assert load_terrain(gen["terrain"]).name == "gen:2"
    # the id does not depend on where the course file was written
    again = physics_jobs(courses=(), generated=3, out_dir=tmp_path / "other")
    assert job_id(again[-1]) == job_id(gen)
    custom = physics_jobs(
        courses=("flat", "gen:5:0.5"), generated=0, modes=("open",), out_dir=tmp_path
    )
    assert [j["course"] for j in custom] == ["flat", "gen:5:0.5"]
    ladder = physics_jobs(courses=expand_courses(["ladder"]), generated=0, out_dir=tmp_path)
    assert len(ladder) == len(ladder_course_names()) and ladder[0]["course"] == "feat:step:0.06"
    assert {j["group"] for j in ladder} == {"ladder"} and ladder[0]["goal"] == [1.1, 0.0]
    assert load_terrain(ladder[0]["terrain"]).name == "feat:step:0.06"
    later = physics_jobs(courses=(), generated=2, first_seed=7, out_dir=tmp_path)
    assert [j["course"] for j in later] == ["gen:7", "gen:8"]
    assert not later[0]["planned_only"]
    # a run that skips unplanned simulations is another job (--resume must not mix them)
    skipping = physics_jobs(courses=(), generated=1, first_seed=7, out_dir=tmp_path,
                            planned_only=True)  # fmt: skip
    assert job_id(skipping[0]) != job_id(later[0])
    # --planner: the local planner of every job, part of its id
    recursive = physics_jobs(courses=(), generated=1, first_seed=7, out_dir=tmp_path,
                             planner="recursive")  # fmt: skip
    assert later[0]["planner"] == "soft" and recursive[0]["planner"] == "recursive"
    assert job_id(recursive[0]) != job_id(later[0])
    # --preset: the settings of every job, part of its id only when not the defaults
    fast = physics_jobs(courses=(), generated=1, first_seed=7, out_dir=tmp_path,
                        preset="fast")  # fmt: skip
    assert later[0]["preset"] == "default" and job_id(fast[0]) != job_id(later[0])
    old = dict(later[0])
    del old["preset"]  # a record written before presets keeps its id
    assert job_id(old) == job_id(later[0])


def test_planned_only_skips_a_plan_that_did_not_reach(tmp_path):
    """A plan cut off by its time budget is not simulated (a skipped row, no success)."""
    (job,) = physics_jobs(
        courses=("flat",),
        generated=0,
        modes=("open",),
        time_budget_s=0.5,
        out_dir=tmp_path,
        planned_only=True,
    )
    rec = run_physics_job(job)
    assert rec["planning"]["planned"] is False
    (row,) = rec["rows"]
    assert row["status"] == "skipped" and "reached" not in row
    (out,) = physics_rows([job], {job_id(job): rec})
    assert out["success"] is False


@pytest.mark.parametrize(
    "args, option",
    [
        (["--modes", "open,fly"], "--modes"),
        (["--generated", "-1"], "--generated"),
        (["--courses", "gen:x"], "gen:SEED"),
        (["--time-budget", "0"], "--time-budget"),
        (["--workers", "0"], "--workers"),
        (["--preset", "quick"], "--preset"),
    ],
)
def test_cli_bad_options_are_one_line_errors(args, option, tmp_path, capsys):
    assert main(["bench", "physics", "--out", str(tmp_path), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and option in err


def test_tiny_end_to_end_run(tmp_path):
    """Plan 0.25 m on flat, open loop at the plan's speed, in one worker process."""
    result = run_physics_bench(
        courses=("flat",),
        generated=0,
        modes=("open",),
        time_budget_s=30.0,
        named_goal_xy=(0.45, 0.0),
        out_dir=tmp_path,
        workers=1,
        progress=False,
    )
    (row,) = result["rows"]
    assert row["status"] == "ok", row
    assert (row["course"], row["group"], row["mode"]) == ("flat", "named", "open")
    for key in ("planned", "reached", "fell", "body_contact", "success"):
        assert isinstance(row[key], bool), key
    for key in ("final_error_cm", "com_to_goal_cm", "leg_contact_s", "max_slip_mm"):
        assert isinstance(row[key], float) and row[key] >= 0.0, key
    for key in ("max_sliding_mm", "saturation_pct", "planning_time_s", "wall_time_s"):
        assert isinstance(row[key], float) and row[key] >= 0.0, key
    assert not row["fell"]
    saved = json.loads((tmp_path / "physics.json").read_text())
    assert saved["rows"] == result["rows"] and saved["machine"]["nproc"]
    assert saved["summary"]["named"]["open"]["of"] == 1
    md = (tmp_path / "physics.md").read_text()
    assert "## Named courses" in md and "| flat | open loop |" in md
    (line,) = (tmp_path / "physics.jsonl").read_text().splitlines()
    assert json.loads(line)["rows"][0]["mode"] == "open"
