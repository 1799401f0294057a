"""The course table's jobs (planner.bench_courses): named and hard courses, their goals."""

import pytest

from planner.bench_courses import (
    COURSES,
    GOAL_XY,
    HARD_COURSES,
    START_XY,
    course_jobs,
    expand_courses,
    goal_for,
)
from planner.terrain import load_terrain


def test_groups_expand_in_order_without_duplicates():
    got = expand_courses(["named", "flat", "hard", "my.yaml"])
    assert got == (*COURSES, *HARD_COURSES, "my.yaml")
    assert expand_courses(["gap6cm"]) == ("gap6cm",)


@pytest.mark.parametrize("course", [*COURSES, *HARD_COURSES])
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
