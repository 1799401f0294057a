"""The soft planner (8.2) out of a dead end: traced back and planned again with the
foothold look-ahead (issue 13 item 5, :mod:`planner.local.soft`).

On the generated course gen:2:0.6 (a gap, 12 cm stepping stones 3 cm apart, two steps
down) the greedy steps put three feet where the fourth finds no body move on the stones
(stuck at x = 1.9 m, "8 failed step attempts in a row", measured at 90b37a8); traced back
one crawl cycle before its best point and planned with the look-ahead, the walk reaches
the course's end (3.0 m). Walked to 2.4 m, since Theta2 keeps three-leg stances within
the servos' torque (the body moves differ), it stays stuck 52 cm short after one retrace.
With the sway-stiffness floor (planner.stiffness, 0.8 m g / L) the walk stays stuck at
x = 1.9 m after its retrace: the plan without it passes there on two three-leg stances of
114-116 N/m (below the floor's 131), and walks open loop in MuJoCo as planned. The test is
about retracing: it walks without the floor.
"""

import pytest

from planner.local.base import LocalSettings
from planner.validate import check_plan
from planner.walk import plan_walk


@pytest.fixture(scope="module")
def stones():
    from dataclasses import replace

    settings = LocalSettings(time_budget_s=600.0)  # never reached: the test is about the plan
    settings = replace(settings, theta=replace(settings.theta, sway_stiffness=None))
    return plan_walk("littledog", "gen:2:0.6", (3.0, 0.0), (0.2, 0.0), "soft", settings=settings)


def test_soft_traces_back_out_of_a_dead_end(stones):
    plan, report = stones
    assert plan.outcome["reached_goal"], plan.outcome["message"]
    assert plan.stats["retraces"] >= 1  # without it: stuck at x = 1.9 m (measured)
    assert report.ok, report
    again = check_plan(plan)  # the independent check of the whole plan
    assert again.ok and not again.violations
