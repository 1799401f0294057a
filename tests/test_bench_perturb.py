"""``bench courses --start-offsets`` (issue 65): every walk also from slightly moved starts,
a start-offset column and a robustness summary per planner (planner.bench.courses)."""

import json

import pytest

from planner.bench.batch import job_id, run_job
from planner.bench.courses import (
    START_XY,
    _row,
    course_jobs,
    parse_start_offsets,
    render_markdown,
    robustness,
    run_course_bench,
    start_label,
)
from planner.cli.main import main

OFFSETS = (1e-6, 1e-3)
DIRECTIONS = {"+x": (1.0, 0.0), "-x": (-1.0, 0.0), "+y": (0.0, 1.0), "-y": (0.0, -1.0)}
MACHINE = {"nproc": 2, "cpu": "", "load_average_1_5_15_at_start": [0, 0, 0],
           "git_commit": "", "date": ""}  # fmt: skip
OLD_HEADER = (
    "| robot | course | planner | reached | validated | steps | planning [s] | job [s] "
    "| walk [s] | ratio | left [m] | backtracks / retraces | note |"
)


def _config(offsets=()):
    config = {"start": list(START_XY), "goal": [2.2, 0.0], "courses": ["flat"],
              "time_budget_s": 60.0, "workers": 1, "scheduler": None}  # fmt: skip
    if offsets:
        config["start_offsets"] = list(offsets)
    return config


def test_a_course_with_two_offsets_is_nine_jobs_at_the_four_directions():
    plain = course_jobs(courses=("flat",), planners=("soft",))
    jobs = course_jobs(courses=("flat",), planners=("soft",), start_offsets=OFFSETS)
    assert len(plain) == 1 and "start_offset" not in plain[0]  # today's job, unchanged
    assert len(jobs) == 1 + 4 * len(OFFSETS)
    assert len({job_id(j) for j in jobs}) == len(jobs)
    # the unmoved job keeps its id, so a run without the option resumes into one with it
    assert jobs[0]["start"] == list(START_XY) and jobs[0]["start_offset"] == [0.0, 0.0]
    assert job_id(jobs[0]) == job_id(plain[0])
    x0, y0 = START_XY
    want = {
        (d, name): [x0 + d * ux, y0 + d * uy]
        for d in OFFSETS
        for name, (ux, uy) in DIRECTIONS.items()
    }
    got = {}
    for j in jobs[1:]:
        dx, dy = j["start_offset"]
        d, name = abs(dx) + abs(dy), start_label(j["start_offset"]).split()[0]
        assert [dx, dy] == [d * u for u in DIRECTIONS[name]]
        got[(d, name)] = j["start"]
        assert j["goal"] == plain[0]["goal"] and j["terrain"] == "flat"
    assert got == want
    assert got[(1e-6, "+x")] == [0.200001, 0.0] and got[(1e-3, "-y")] == [0.2, -0.001]
    # robot, course, planner, then the starts
    two = course_jobs(courses=("flat", "step10cm"), planners=("soft", "recursive"),
                      start_offsets=OFFSETS)  # fmt: skip
    assert len(two) == 2 * 2 * 9
    assert [(j["terrain"], j["planner"]) for j in two[:10:9]] == [
        ("flat", "soft"),
        ("flat", "recursive"),
    ]


def test_the_offsets_parse_in_metres_without_duplicates():
    assert parse_start_offsets("1e-6, 1e-3,1e-6") == (1e-6, 1e-3)
    assert parse_start_offsets("0.01") == (0.01,)


def _rows(course, planner, planned_at, offsets=OFFSETS, status="ok"):
    """Hand-made rows of a course: planned at the starts labelled in ``planned_at``."""
    out = []
    for j in course_jobs(courses=(course,), planners=(planner,), start_offsets=offsets):
        row = _row(j, None) | {"status": status}
        label = start_label(j.get("start_offset", [0.0, 0.0]))
        ok = planned_at == "all" or label in planned_at
        row |= {"reached": ok, "validated": True, "steps": 9, "message": "" if ok else "stuck"}
        out.append(row)
    return out


def test_the_robustness_summary_counts_starts_and_names_the_fragile_courses():
    rows = (
        _rows("flat", "soft", "all")
        + _rows("step10cm", "soft", {"0", "-x 1e-06", "+y 0.001"})
        + _rows("barrier9cm", "soft", set())  # fails from every start: not fragile
        + _rows("flat", "recursive", "all")
        + _rows("step10cm", "recursive", "all")
    )
    # reached but not passing the check is no success
    bad = next(r for r in rows if r["planner"] == "recursive" and r["terrain"] == "step10cm"
               and r["start_offset"] == [0.0, -1e-3])  # fmt: skip
    bad["validated"] = False
    rob = robustness(rows)
    soft, rec = rob["soft"], rob["recursive"]
    assert (soft["robust"], soft["of"], soft["fragile"]) == (1, 3, ["step10cm"])
    by = {e["course"]: e for e in soft["courses"]}
    assert [by[c]["planned"] for c in ("flat", "step10cm", "barrier9cm")] == [9, 3, 0]
    assert all(e["starts"] == 9 and e["missing"] == 0 for e in soft["courses"])
    assert by["flat"]["robust"] and not by["flat"]["fragile"]
    assert not by["barrier9cm"]["robust"] and not by["barrier9cm"]["fragile"]
    assert by["step10cm"]["not_from"] == [
        "+x 1e-06", "+y 1e-06", "-y 1e-06", "+x 0.001", "-x 0.001", "-y 0.001",
    ]  # fmt: skip
    assert (rec["robust"], rec["of"], rec["fragile"]) == (1, 2, ["step10cm"])
    md = render_markdown({"rows": rows, "config": _config(OFFSETS), "machine": MACHINE,
                          "total_time_s": 1.0, "interrupted": False})  # fmt: skip
    assert "moved by 1e-06, 0.001 m in +x, -x, +y, -y (9 starts per course and planner)" in md
    assert "## Robustness to the start (--start-offsets 1e-06,0.001)" in md
    assert "soft: 1 of 3 courses plan from every start; outcome differs between starts: " in md
    assert "step10cm." in md and "recursive: 1 of 2 courses plan from every start" in md
    assert "| step10cm | 3 of 9 | no | yes | +x 1e-06, +y 1e-06" in md
    assert "| flat | 9 of 9 | yes | no | - |" in md
    table = [ln for ln in md.splitlines() if ln.startswith("| littledog | step10cm | soft |")]
    assert [ln.split("|")[4].strip() for ln in table[:3]] == ["0", "+x 1e-06", "-x 1e-06"]
    assert "Reached: " in md  # the summary lines as before


def test_a_start_without_a_result_is_counted_apart():
    rows = _rows("flat", "soft", "all")
    rows[3] = {k: rows[3][k] for k in ("robot", "terrain", "planner", "start_offset")} | {
        "status": "missing"
    }
    rows[4] |= {"status": "error", "error": "RuntimeError: boom"}
    (e,) = robustness(rows)["soft"]["courses"]
    assert (e["planned"], e["missing"], e["robust"], e["fragile"]) == (7, 1, False, True)
    assert e["not_from"] == [start_label(rows[4]["start_offset"])]


def test_without_the_option_the_table_is_as_before():
    rows = _rows("flat", "soft", "all", offsets=())
    assert "start_offset" not in rows[0]
    md = render_markdown({"rows": rows, "config": _config(), "machine": MACHINE,
                          "total_time_s": 1.0, "interrupted": False})  # fmt: skip
    assert OLD_HEADER in md.splitlines()
    assert "Robustness" not in md and "moved by" not in md


@pytest.mark.parametrize(
    "value",
    ["abc", "0", "-0.001", "nan", "inf", "1e-3,abc", "", ",", "1e-3,0", "1e-20"],
)
def test_bad_offsets_are_one_line_errors(value, tmp_path, capsys):
    out = tmp_path / "out"
    # '=' so that argparse takes a negative number as the option's value
    assert main(["bench", "courses", "--out", str(out), f"--start-offsets={value}"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--start-offsets" in err, err
    assert not (out / "courses.jsonl").exists()  # stopped before any job


def _fake_record(job, planned):
    return {"id": job_id(job), "job": job, "status": "ok", "reached": planned,
            "validated": True, "violations": {}, "steps": 7, "distance_to_goal_m": 0.01,
            "planning_time_s": 1.0, "walk_time_s": 5.0, "time_ratio": 0.2,
            "message": "" if planned else "stuck", "wall_time_s": 1.5}  # fmt: skip


def test_resume_finds_the_perturbed_jobs_and_the_json_has_their_rows(tmp_path):
    """A run without the option, then with it: the unmoved job's record is reused; the
    others finished (records written here), so nothing is planned."""
    plain = course_jobs(courses=("step10cm",), planners=("soft",), time_budget_s=60.0)
    jobs = course_jobs(courses=("step10cm",), planners=("soft",), time_budget_s=60.0,
                       start_offsets=OFFSETS)  # fmt: skip
    recs = [_fake_record(plain[0], True)]
    recs += [_fake_record(j, j["start_offset"][0] >= 0) for j in jobs[1:]]
    (tmp_path / "courses.jsonl").write_text("".join(json.dumps(r) + "\n" for r in recs))
    result = run_course_bench(courses=("step10cm",), planners=("soft",), time_budget_s=60.0,
                              out_dir=tmp_path, resume=True, progress=False,
                              start_offsets=OFFSETS)  # fmt: skip
    saved = json.loads((tmp_path / "courses.json").read_text())
    assert saved["config"]["start_offsets"] == list(OFFSETS)
    assert [r["start_offset"] for r in saved["rows"]] == [j["start_offset"] for j in jobs]
    assert all(r["status"] == "ok" for r in saved["rows"])
    assert [r["reached"] for r in saved["rows"]] == [True] + [True, False, True, True] * 2
    assert saved["robustness"]["soft"]["fragile"] == ["step10cm"]
    assert saved["robustness"] == result["robustness"]
    md = (tmp_path / "courses.md").read_text()
    assert "| step10cm | 7 of 9 | no | yes | -x 1e-06, -x 0.001 |" in md
    assert len((tmp_path / "courses.jsonl").read_text().splitlines()) == 9  # none ran again


def test_a_moved_start_plans_from_its_own_start():
    """The job of a moved start runs as any (its extra field is no planner input) and is
    recorded with its start; a few steps on flat ground."""
    job = course_jobs(courses=("flat",), planners=("soft",), time_budget_s=60.0,
                      start_offsets=(1e-3,))[1]  # fmt: skip
    job["goal"] = [0.45, 0.0]
    rec = run_job(job)
    assert rec["status"] == "ok" and rec["reached"] and rec["validated"], rec
    assert rec["job"]["start"] == [0.201, 0.0] and rec["job"]["start_offset"] == [1e-3, 0.0]
    assert _row(job, rec)["start_offset"] == [1e-3, 0.0]
