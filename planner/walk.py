"""Plan a walk end to end: robot + terrain + goal -> a validated :class:`~planner.plan.Plan`.

This is the main job (DESIGN.md section 2, steps 1-5): initial placement by Theta4, the
local planner of section 8.2, the plan assembled in the ``stratawalk.plan/1`` format, then
the independent validator. A plan is reported as reaching the goal only when the
validator finds nothing wrong with it.
"""

from __future__ import annotations

import numpy as np

from planner.local.base import LocalPlan, LocalSettings
from planner.local.hard import HardPlanner
from planner.local.recursive import RecursivePlanner
from planner.local.soft import SoftPlanner
from planner.plan import Plan
from planner.robot import load_robot
from planner.terrain import load_terrain
from planner.validate import check_plan

PLANNERS = {"soft": SoftPlanner, "hard": HardPlanner, "recursive": RecursivePlanner}


def plan_walk(
    robot="littledog",
    terrain="flat",
    goal_xy=(2.2, 0.0),
    start_xy=(0.2, 0.0),
    planner: str = "soft",
    settings: LocalSettings | None = None,
    progress=None,
) -> tuple[Plan, object]:
    """Plan, assemble and validate a walk; returns (plan, validation report).

    ``robot`` and ``terrain`` may be names/paths or loaded objects. Ctrl-C or the time
    budget of ``settings`` stops planning; the plan so far is still returned.
    """
    if planner not in PLANNERS:
        from planner.errors import InputError

        raise InputError(f"planner: unknown '{planner}'; available: {', '.join(PLANNERS)}")
    robot = load_robot(robot) if isinstance(robot, str) else robot
    terrain = load_terrain(terrain) if isinstance(terrain, str) else terrain
    local = PLANNERS[planner](robot, terrain, settings=settings)
    result = local.plan(start_xy, goal_xy, progress=progress)
    return assemble_plan(robot, terrain, local.mu, start_xy, goal_xy, result, {"planner": planner})


def assemble_plan(robot, terrain, mu, start_xy, goal_xy, result: LocalPlan, stats: dict):
    """The ``stratawalk.plan/1`` plan of a local plan, validated; returns (plan, report).

    ``stats`` are added to the local plan's. A plan the validator rejects is not reported
    as reaching the goal, whatever the local planner said.
    """

    def lift(xy):
        x, y = float(xy[0]), float(xy[1])
        return np.array([x, y, float(terrain.height(np.array(x), np.array(y)))])

    outcome = {
        "reached_goal": bool(result.reached_goal),
        "distance_to_goal": float(result.distance_to_goal_m),
        "message": result.message,
    }
    plan = Plan.build(
        robot,
        terrain,
        mu,
        lift(start_xy),
        lift(goal_xy),
        result.keyframes,
        result.samples,
        result.times,
        outcome,
        dict(result.stats, **stats),
    )
    report = check_plan(plan)
    plan.stats["validation"] = {"ok": report.ok, "violations": report.by_kind()}
    if not report.ok and plan.outcome["reached_goal"]:
        plan.outcome["reached_goal"] = False
        plan.outcome["message"] += (
            f"; NOT reported as reached: the validator found {len(report.violations)} "
            f"violations ({', '.join(report.by_kind())})"
        )
    return plan, report
