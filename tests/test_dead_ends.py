"""The soft planner (8.2) out of a dead end: traced back and planned again with the
foothold look-ahead (issue 13 item 5, :mod:`planner.local.soft`).

Up step10cm (a 10 cm step at x = 0.8 m, LittleDog's body 15 cm high) the greedy full
strides put the front feet up the step with the hind feet stretched below it, a stance
from which no hind leg finds a body move; traced back one crawl cycle before its best
point and planned again with the look-ahead (and, met again, with 0.6 of the stride), the
walk climbs and reaches (67 steps, 2 retraces, measured at the change that made this the
test's course). The generated gen:2:0.6 was the course here until its dead end went away:
since the joint-space swings enter a landing on a knee near its limit from above
(:func:`planner.leg_swing.joint_space_swing`), the greedy walk passes there.
"""

import pytest

from planner.validate import check_plan
from planner.walk import plan_walk


@pytest.fixture(scope="module")
def step_up():
    return plan_walk("littledog", "step10cm", (2.2, 0.0), (0.2, 0.0), "soft")


def test_soft_traces_back_out_of_a_dead_end(step_up):
    plan, report = step_up
    assert plan.outcome["reached_goal"], plan.outcome["message"]
    assert plan.stats["retraces"] >= 1  # without: stuck with the hind feet below the step
    assert report.ok, report
    again = check_plan(plan)  # the independent check of the whole plan
    assert again.ok and not again.violations
