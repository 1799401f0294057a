"""The course table's jobs (planner.bench.courses): named and hard courses, their goals."""

import pytest

from planner.bench.courses import (
    BACKTRACK_COURSES,
    COURSES,
    GOAL_XY,
    HARD_COURSES,
    START_XY,
    course_jobs,
    expand_courses,
    goal_for,
)
from planner.world.terrain import load_terrain


def test_groups_expand_in_order_without_duplicates():
    got = expand_courses(["named", "flat", "hard", "backtrack", "my.yaml"])
    assert got == (*COURSES, *HARD_COURSES, *BACKTRACK_COURSES, "my.yaml")
    assert expand_courses(["gap6cm"]) == ("gap6cm",)


@pytest.mark.parametrize("course", [*COURSES, *HARD_COURSES, *BACKTRACK_COURSES])
def test_every_course_loads_and_its_walk_lies_on_it(course):
    """Start and goal at least a body length inside the terrain's bounds."""
    terrain = load_terrain(course)
    x0, x1, y0, y1 = terrain.bounds
    for x, y in (START_XY, goal_for(course)):
        assert x0 + 0.3 <= x <= x1 - 0.3 and y0 + 0.3 <= y <= y1 - 0.3


def test_jobs_carry_each_course_its_goal():
    jobs = course_jobs(courses=("flat", "mix4m"), planners=("soft",))
    goals = {j["terrain"]: tuple(j["goal"]) for j in jobs}
    assert goals == {"flat": tuple(GOAL_XY), "mix4m": (4.2, 0.0)}
    assert goal_for("flat", (1.0, 0.5)) == (1.0, 0.5)  # the caller's default otherwise


@pytest.mark.parametrize("course", ["feat:stones:0.07", "feat:step:0.1", "gen:3"])
def test_a_ladder_or_generated_course_walks_to_its_own_goal(course):
    """`bench courses --courses ladder` walked every feature course to (2.2, 0), off the
    shorter ones: each walks to the end of its feature segment, on the terrain."""
    from planner.world.course_gen import course_goal_xy, course_spec

    goal = goal_for(course)
    assert goal == course_goal_xy(course_spec(course))
    x0, x1, y0, y1 = load_terrain(course).bounds
    assert x0 + 0.3 <= goal[0] <= x1 - 0.3
    job = course_jobs(courses=(course,), planners=("soft",))[0]
    assert tuple(job["goal"]) == goal


def test_the_table_counts_the_recursive_planners_backtracks():
    """A recursive job's record carries its backtracks and window retraces (8.5), and the
    table shows them; soft's shows its retraces (none on flat ground)."""
    from planner.bench.batch import run_job
    from planner.bench.courses import _row, render_markdown

    jobs = course_jobs(courses=("flat",), planners=("soft", "recursive"), time_budget_s=60.0)
    for job in jobs:
        job["goal"] = [0.45, 0.0]  # a few steps
    recs = [run_job(job) for job in jobs]
    assert all(r["status"] == "ok" and r["reached"] for r in recs), recs
    soft, rec = recs
    assert "backtracks" not in soft and soft["retraces"] == 0
    assert rec["backtracks"] >= 0 and rec["retraces"] >= 0
    rows = [_row(j, r) for j, r in zip(jobs, recs, strict=True)]
    config = {"start": [0.2, 0.0], "goal": [0.45, 0.0], "courses": ["flat"],
              "time_budget_s": 60.0, "workers": 1, "scheduler": None}  # fmt: skip
    machine = {"nproc": 2, "cpu": "", "load_average_1_5_15_at_start": [0, 0, 0],
               "git_commit": "", "date": ""}  # fmt: skip
    md = render_markdown({"rows": rows, "config": config, "machine": machine,
                          "total_time_s": 1.0, "interrupted": False})  # fmt: skip
    lines = [ln for ln in md.splitlines() if ln.startswith("| littledog | flat")]
    assert lines[0].split("|")[12].strip() == "- / 0"
    assert lines[1].split("|")[12].strip() == f"{rec['backtracks']} / {rec['retraces']}"
