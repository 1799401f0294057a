"""Plan a walk end to end: robot + terrain + goal -> a validated plan.

This is the main job (DESIGN.md section 2, steps 1-5): initial placement by Theta4, the
local planner of section 8.2, the plan assembled in the ``stratawalk.plan/1`` format, then
the independent validator. A plan is reported as reaching the goal only when the
validator finds nothing wrong with it.
"""

from __future__ import annotations

import math

import numpy as np

from planner.body.robot import load_robot
from planner.core.interrupts import shielded
from planner.planfile.plan import Plan
from planner.planfile.validate import check_plan
from planner.planning.hard import HardPlanner
from planner.planning.local import LocalPlan, LocalSettings
from planner.planning.recursive import RecursivePlanner
from planner.planning.restarts import plan_with_restarts
from planner.planning.settings import effective
from planner.planning.soft import GreedyPlanner, SoftPlanner
from planner.world.terrain import load_terrain

PLANNERS = {
    "soft": SoftPlanner,
    "hard": HardPlanner,
    "recursive": RecursivePlanner,
    "greedy": GreedyPlanner,  # 8.2 without soft's tracing back: the baseline of 8.5
}


def plan_walk(
    robot="littledog",
    terrain="flat",
    goal_xy=(2.2, 0.0),
    start_xy=(0.2, 0.0),
    planner: str = "soft",
    settings: LocalSettings | None = None,
    progress=None,
    mu: float | None = None,
) -> tuple[Plan, object]:
    """Plan, assemble and validate a walk; returns (plan, validation report).

    ``robot`` and ``terrain`` may be names/paths or loaded objects; ``mu`` overrides the
    terrain's friction. Ctrl-C or the time budget of ``settings`` stops planning; the plan
    so far is still returned. A walk that stalls with time left is planned again with
    another model of the stance (:mod:`planner.planning.restarts`, ``settings.restarts``).
    The plan records the settings in force (``stats.settings``).
    """
    if planner not in PLANNERS:
        from planner.core.errors import InputError

        raise InputError(f"planner: unknown '{planner}'; available: {', '.join(PLANNERS)}")
    robot = load_robot(robot) if isinstance(robot, str) else robot
    terrain = load_terrain(terrain) if isinstance(terrain, str) else terrain
    check_endpoints(robot, terrain, start_xy, goal_xy)
    local, result = plan_with_restarts(
        lambda st: PLANNERS[planner](robot, terrain, mu=mu, settings=st),
        settings or LocalSettings(),
        start_xy,
        goal_xy,
        progress,
    )
    extra = {"planner": planner, "settings": effective(local)}
    with shielded():  # a Ctrl-C now would lose the plan computed: it waits for the plan
        return assemble_plan(robot, terrain, local.mu, start_xy, goal_xy, result, extra)


def check_endpoints(robot, terrain, start_xy, goal_xy, names=("start", "goal")) -> None:
    """InputError unless start and goal lie on the terrain's declared extent.

    The robot's hips and feet at zero angles must fit inside ``terrain.bounds`` (x_min ..
    x_min + length, y_min .. y_max) around each point.
    """
    from planner.core.errors import InputError

    x0, x1, y0, y1 = terrain.bounds
    hips = np.array([p for leg in robot.legs for p in (leg.points_B[0], leg.foot_B0)])
    mx, my = float(np.abs(hips[:, 0]).max()), float(np.abs(hips[:, 1]).max())
    extent = (
        f"x {x0:g}..{x1:g}, y {y0:g}..{y1:g} m (the robot needs {mx:.2f} m in x and "
        f"{my:.2f} m in y around it)"
    )
    if x1 - x0 <= 2 * mx or y1 - y0 <= 2 * my:
        raise InputError(f"terrain {terrain.name}: too small for the robot: {extent}")
    for name, xy in zip(names, (start_xy, goal_xy), strict=True):
        x, y = float(xy[0]), float(xy[1])
        if not (math.isfinite(x) and math.isfinite(y)):
            raise InputError(f"{name}: {x:g},{y:g} is not a finite point; give X,Y in metres")
        if not (x0 + mx <= x <= x1 - mx and y0 + my <= y <= y1 - my):
            raise InputError(
                f"{name}: {x:g},{y:g} is off terrain {terrain.name}: {extent}; choose a "
                "point inside"
            )


def plan_of(robot, terrain, mu, start_xy, goal_xy, result: LocalPlan, stats: dict) -> Plan:
    """The ``stratawalk.plan/1`` plan of a local plan, not validated; ``stats`` added."""

    def lift(xy):
        x, y = float(xy[0]), float(xy[1])
        return np.array([x, y, float(terrain.height(np.array(x), np.array(y)))])

    outcome = {
        "reached_goal": bool(result.reached_goal),
        "distance_to_goal": float(result.distance_to_goal_m),
        "message": result.message,
    }
    return Plan.build(
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


def assemble_plan(robot, terrain, mu, start_xy, goal_xy, result: LocalPlan, stats: dict):
    """The ``stratawalk.plan/1`` plan of a local plan, validated; returns (plan, report).

    ``stats`` are added to the local plan's. A plan the validator rejects is not reported
    as reaching the goal, whatever the local planner said.
    """
    plan = plan_of(robot, terrain, mu, start_xy, goal_xy, result, stats)
    report = check_plan(plan)
    plan.stats["validation"] = {"ok": report.ok, "violations": report.by_kind()}
    if not report.ok and plan.outcome["reached_goal"]:
        plan.outcome["reached_goal"] = False
        plan.outcome["message"] += (
            f"; NOT reported as reached: the validator found {len(report.violations)} "
            f"violations ({', '.join(report.by_kind())})"
        )
    return plan, report
