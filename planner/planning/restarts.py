"""Restarts: a walk that stalls is planned again with another model of the stance.

Beyond the paper. The local planners (8.2, 8.5) choose footholds a step or a window
ahead, and on tall edges where a walk ends hangs on millimetres: the same course with the
stance spheres rolling (``ThetaOptions.rolling_feet``) instead of holding their contact
points, or with the swing leg kept able to lift off (``lift_ready``), reaches where the
other stalls, and which one does changes from course to course and with the start
(bench/notes/2026-12-04-restarts.md). Search times with such heavy tails are cut by
restarting a stalled search with a different choice (Gomes, Selman and Kautz, "Boosting
combinatorial search through randomization", AAAI 1998).

:func:`plan_with_restarts` plans with the settings given; a walk that stops short of the
goal (stuck, or at ``max_cycles``) with at least ``MIN_RESTART_FRACTION`` of the time
budget left is planned again from the start with the next of :data:`VARIANTS`, in the
time that remains. The plan is the first walk that reaches the goal, else the one that
came nearest; every attempt is recorded in its stats (``restarts``). Each variant is a
model of the same leaf, and every plan meets the same independent check.
"""

from __future__ import annotations

from dataclasses import replace
from time import perf_counter

from planner.planning.local import LocalPlan, LocalSettings

__all__ = ["MIN_RESTART_FRACTION", "VARIANTS", "plan_with_restarts", "variant_settings"]

# (name, ThetaOptions fields flipped from the settings given), tried in this order
VARIANTS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("rolling_feet flipped", ("rolling_feet",)),
    ("rolling_feet and lift_ready flipped", ("rolling_feet", "lift_ready")),
)
MIN_RESTART_FRACTION = 0.1  # a restart needs at least this share of the time budget left


def variant_settings(settings: LocalSettings, flipped: tuple[str, ...], budget_s: float):
    """``settings`` with the Theta options ``flipped`` and the time budget ``budget_s``."""
    theta = replace(settings.theta, **{k: not getattr(settings.theta, k) for k in flipped})
    return replace(settings, theta=theta, time_budget_s=budget_s)


def _better(a: LocalPlan, b: LocalPlan) -> bool:
    """Whether walk ``a`` is better than ``b``: it reaches and ``b`` not, or comes nearer."""
    if a.reached_goal != b.reached_goal:
        return a.reached_goal
    return a.distance_to_goal_m < b.distance_to_goal_m


def plan_with_restarts(make_planner, settings: LocalSettings, start_xy, goal_xy, progress=None):
    """(local planner, its walk): ``make_planner(settings)`` planned, restarted if it stalls.

    ``settings.restarts`` bounds the restarts (0: none). The walk's ``stats`` get
    ``restarts`` (per attempt: variant, message, planning time, distance to the goal) and
    ``planning_time_s`` of all attempts together.
    """
    t0 = perf_counter()
    budget = float(settings.time_budget_s)
    local = make_planner(settings)
    best = (local, local.plan(start_xy, goal_xy, progress=progress), 0)
    attempts = [_attempt("as set", best[1])]
    for name, flipped in VARIANTS[: max(0, int(settings.restarts))]:
        result = best[1]
        left = budget - (perf_counter() - t0)
        if result.reached_goal or result.interrupted or left < MIN_RESTART_FRACTION * budget:
            break
        local = make_planner(variant_settings(settings, flipped, left))
        walk = local.plan(start_xy, goal_xy, progress=progress)
        attempts.append(_attempt(name, walk))
        if _better(walk, result):
            best = (local, walk, len(attempts) - 1)
        if walk.interrupted:
            break
    local, result, k = best
    if len(attempts) > 1:
        result.message += f" (attempt {k + 1} of {len(attempts)}: {attempts[k]['variant']})"
    result.stats["planning_time_s"] = perf_counter() - t0
    result.stats["restarts"] = attempts
    return local, result


def _attempt(name: str, walk: LocalPlan) -> dict:
    return {
        "variant": name,
        "reached": bool(walk.reached_goal),
        "distance_to_goal_m": float(walk.distance_to_goal_m),
        "planning_time_s": float(walk.stats.get("planning_time_s", 0.0)),
        "message": walk.message,
    }
