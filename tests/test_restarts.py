"""Restarts (planner.planning.restarts): a stalled walk planned again with another model."""

import pytest

from planner.planning.local import LocalPlan, LocalSettings
from planner.planning.restarts import VARIANTS, plan_with_restarts


class _Fake:
    """A planner whose walks are scripted: (reached, distance, seconds spent, interrupted)."""

    def __init__(self, settings, script, seen):
        self.settings, self.script, self.seen = settings, script, seen

    def plan(self, start_xy, goal_xy, progress=None):
        reached, dist, spent, interrupted = self.script[len(self.seen)]
        self.seen.append(self.settings)
        msg = "reached the goal" if reached else f"stuck {len(self.seen)}"
        stats = {"planning_time_s": spent}
        return LocalPlan([], [], [], reached, dist, msg, stats, interrupted=interrupted)


def _run(script, monkeypatch, **kw):
    import planner.planning.restarts as restarts

    clock = [0.0]
    seen = []

    def now():  # the time a walk spends is its script's
        return clock[0] + sum(s[2] for s in script[: len(seen)])

    monkeypatch.setattr(restarts, "perf_counter", now)
    settings = LocalSettings(time_budget_s=100.0, **kw)
    local, walk = plan_with_restarts(lambda st: _Fake(st, script, seen), settings, (0, 0), (1, 0))
    return local, walk, seen


def test_a_stalled_walk_is_planned_again_with_the_next_variant(monkeypatch):
    local, walk, seen = _run([(False, 1.2, 30.0, False), (True, 0.01, 20.0, False)], monkeypatch)
    assert len(seen) == 2 and walk.reached_goal and local.settings is seen[1]
    # the restart flips the first variant's options and gets the time left
    assert seen[1].theta.rolling_feet != seen[0].theta.rolling_feet
    assert seen[1].theta.lift_ready == seen[0].theta.lift_ready
    assert seen[1].time_budget_s == pytest.approx(70.0) and seen[0].time_budget_s == 100.0
    assert walk.stats["planning_time_s"] == pytest.approx(50.0)
    assert [a["variant"] for a in walk.stats["restarts"]] == ["as set", VARIANTS[0][0]]
    assert walk.message.endswith(f"(attempt 2 of 2: {VARIANTS[0][0]})")


def test_the_walk_nearest_the_goal_is_kept_when_none_reaches(monkeypatch):
    script = [(False, 0.9, 10.0, False), (False, 1.3, 10.0, False), (False, 1.0, 10.0, False)]
    local, walk, seen = _run(script, monkeypatch)
    assert len(seen) == 1 + len(VARIANTS) and walk.distance_to_goal_m == 0.9
    assert local.settings is seen[0] and walk.message.startswith("stuck 1 (attempt 1 of 3")
    assert seen[2].theta.lift_ready != seen[0].theta.lift_ready


@pytest.mark.parametrize(
    "first, kw",
    [
        ((True, 0.01, 10.0, False), {}),  # reached
        ((False, 1.0, 95.0, False), {}),  # less than MIN_RESTART_FRACTION of the budget left
        ((False, 1.0, 10.0, True), {}),  # interrupted (Ctrl-C): the user's plan so far
        ((False, 1.0, 10.0, False), {"restarts": 0}),  # asked for none
    ],
)
def test_no_restart_where_it_cannot_or_need_not_help(monkeypatch, first, kw):
    _, walk, seen = _run([first, (True, 0.0, 1.0, False)], monkeypatch, **kw)
    assert len(seen) == 1 and walk.distance_to_goal_m == first[1]
    assert len(walk.stats["restarts"]) == 1
