"""``stratawalk bench robots``: every robot of the list on courses scaled to its legs.

For each robot (:func:`planner.body.robot.robot_names`) and each course kind, a course is built
from the robot's mean leg reach L (hip centre to foot centre, stretched):

- ``flat``: level ground;
- ``rough``: band-limited relief of peak ``RELIEF_FRACTION`` x L, wavelengths from 0.83 L to
  3.3 L (rough2cm's 15-60 cm for LittleDog's 18 cm legs);
- ``step``: a step up of ``STEP_FRACTION`` x L, 1 m ahead of the start.

The walk starts at (0, 0) and its goal is ``WALK_M`` ahead. Each plan is checked
(:func:`planner.planfile.validate.check_plan`, inside :func:`planner.planning.walk.plan_walk`) and,
when it
reached and passed, executed with feedback (8.3) in MuJoCo at the plan's own timing
(:mod:`planner.sim.simulate`: servos scaled from LittleDog's, :mod:`planner.body.servo_model`).
The table (markdown and JSON in ``bench/results/robots.{md,json}``) gives per robot and
course: reached, check, steps, planning time, walk time and speed, and the MuJoCo result.
Jobs are those of :mod:`planner.bench.physics` (one JSONL record each, ``--resume``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from planner.core.errors import InputError

__all__ = ["KINDS", "robot_course", "robot_jobs", "robot_rows", "run_robots_bench"]

KINDS = ("flat", "rough", "step")
WALK_M = 2.0  # the goal this far ahead of the start [m]
RELIEF_FRACTION = 0.1  # peak of the rough relief / leg reach
STEP_FRACTION = 0.3  # height of the step / leg reach
STEP_X_M = 1.0  # the step's edge this far ahead of the start [m]
TIME_BUDGET_S = 180.0
MODES = ("feedback",)
RESULTS_NAME = "robots.jsonl"


def robot_course(name: str, kind: str) -> dict[str, Any]:
    """The terrain spec of ``kind`` scaled to robot ``name``'s legs (module doc)."""
    from planner.body.robot import load_robot

    if kind not in KINDS:
        raise InputError(f"--courses: unknown kind '{kind}'; use any of {','.join(KINDS)}")
    robot = load_robot(name)
    reach = float(np.mean(robot.reach_m))
    margin = round(0.5 + 1.5 * reach, 2)  # the body and its legs stay on the course
    side = round(0.3 + reach, 2)  # half its width (the relief's peak is taken over it)
    spec: dict[str, Any] = {
        "name": f"{name}_{kind}",
        "description": f"{kind} for {name} (leg reach {100 * reach:.1f} cm)",
        "friction": 0.7,
        "x_min": -margin,
        "length": WALK_M + 2 * margin,
        "y_min": -side,
        "y_max": side,
        "kind": kind,
    }
    if kind == "rough":
        spec |= {
            "amplitude": round(RELIEF_FRACTION * reach, 5),
            "wavelength": round(0.83 * reach, 4),
            "wavelength_max": round(3.3 * reach, 4),
            "terms": 40,
            "seed": 2,
            "x_start": round(0.5 * reach, 4),
            "x_end": WALK_M + margin,
            "taper": round(0.83 * reach, 4),
        }
    elif kind == "step":
        spec |= {"x": STEP_X_M, "height": round(STEP_FRACTION * reach, 5)}
    return spec


def robot_jobs(
    robots: Sequence[str],
    kinds: Sequence[str] = KINDS,
    time_budget_s: float = TIME_BUDGET_S,
    out_dir: str | Path = "bench/results",
    plans_dir: str | Path | None = None,
) -> list[dict]:
    """One :func:`planner.bench.physics.run_physics_job` job per robot and course kind."""
    from planner.world.course_gen import write_course

    jobs = []
    for robot in robots:
        for kind in kinds:
            spec = robot_course(robot, kind)
            path = write_course(spec, Path(out_dir) / "robot_courses" / f"{robot}_{kind}.yaml")
            jobs.append(
                {
                    "robot": robot,
                    "course": f"{robot}/{kind}",
                    "group": "robots",
                    "terrain": str(Path(path).resolve()),
                    "planner": "soft",
                    "start": [0.0, 0.0],
                    "goal": [WALK_M, 0.0],
                    "modes": list(MODES),
                    "time_budget_s": float(time_budget_s),
                    "time_scale": 1.0,
                    "plans_dir": None if plans_dir is None else str(plans_dir),
                    "planned_only": True,
                }
            )
    return jobs


def robot_rows(jobs: Sequence[dict], records: dict[str, dict]) -> list[dict]:
    """One row per robot and course: planning, and the feedback run in MuJoCo."""
    from planner.bench.physics import job_id

    rows = []
    for job in jobs:
        robot, kind = job["robot"], job["course"].split("/", 1)[1]
        rec = records.get(job_id(job))
        row: dict[str, Any] = {"robot": robot, "course": kind}
        if rec is None:
            rows.append(row | {"status": "missing"})
            continue
        p = rec.get("planning", {})
        if "error" in p:
            rows.append(row | {"status": "error", "message": p["error"]})
            continue
        walk = p.get("walk_time_s")
        speed = WALK_M / walk if p.get("plan_reached") and walk else None
        sim = next((r for r in rec.get("rows", []) if r.get("mode") == "feedback"), {})
        row |= {
            "status": "ok",
            "reached": bool(p.get("plan_reached")),
            "check_ok": bool(p.get("check_ok")),
            "steps": p.get("steps"),
            "planning_time_s": p.get("planning_time_s"),
            "walk_time_s": walk,
            "walk_speed_cm_s": None if speed is None else 100.0 * speed,
            "feedback": sim.get("status"),
            "feedback_reached": bool(sim.get("reached")) if sim.get("status") == "ok" else None,
            "feedback_fell": bool(sim.get("fell")) if sim.get("status") == "ok" else None,
            "message": p.get("message", ""),
            "feedback_message": sim.get("message") or sim.get("error", ""),
        }
        rows.append(row)
    return rows


def _cell(v: Any, fmt: str = "{}", bad: bool = False) -> str:
    """A table cell; a boolean in bold when it is the bad outcome (``bad``)."""
    if v is None:
        return "-"
    if isinstance(v, bool):
        return ("**yes**" if bad else "yes") if v else ("no" if bad else "**no**")
    return fmt.format(v)


def render_markdown(result: dict[str, Any]) -> str:
    """The robots table as markdown."""
    c = result["config"]
    lines = [
        "# Every robot on courses scaled to its legs (issue 14)",
        "",
        f"Soft planner, goal {c['walk_m']:g} m ahead, {c['time_budget_s']:g} s planning budget;"
        f" rough: peak {c['relief_fraction']:g} x leg reach; step: {c['step_fraction']:g} x leg"
        " reach up. Feedback (8.3) in MuJoCo at the plan's timing, servos scaled from "
        "LittleDog's (planner.body.servo_model), for plans that reached and pass the check.",
        "",
        "| robot | course | reached | check | steps | planning [s] | walk [s] | speed [cm/s] "
        "| MuJoCo feedback | fell |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        if r.get("status") != "ok":
            lines.append(
                f"| {r['robot']} | {r['course']} | {r.get('status')} | | | | | | "
                f"{r.get('message', '')[:80]} | |"
            )
            continue
        fb = r["feedback"]
        fb_cell = _cell(r["feedback_reached"]) if fb == "ok" else (fb or "-")
        lines.append(
            f"| {r['robot']} | {r['course']} | {_cell(r['reached'])} | {_cell(r['check_ok'])} "
            f"| {_cell(r['steps'])} | {_cell(r['planning_time_s'], '{:.1f}')} "
            f"| {_cell(r['walk_time_s'], '{:.0f}')} | {_cell(r['walk_speed_cm_s'], '{:.1f}')} "
            f"| {fb_cell} | {_cell(r['feedback_fell'], bad=True)} |"
        )
    s = result["summary"]
    lines += [
        "",
        f"Planned (reached and check ok): {s['planned']} of {s['jobs']}; feedback reached with "
        f"no fall: {s['feedback_ok']} of {s['simulated']} simulated.",
        "",
        "Not reached or failed in MuJoCo:",
        "",
    ]
    for r in result["rows"]:
        if r.get("status") != "ok" or not r["reached"] or r["feedback_reached"] is False:
            why = r.get("message", "") if not r.get("reached") else r.get("feedback_message", "")
            lines.append(f"- {r['robot']} {r['course']}: {why}")
    m = result["machine"]
    lines += ["", f"Machine: {m.get('cpu', '?')}, {m.get('nproc', '?')} cores, commit "
              f"{m.get('git_commit', '?')}; total {result['total_time_s']:.0f} s.", ""]  # fmt: skip
    return "\n".join(lines)


def summarize(rows: Sequence[dict]) -> dict[str, int]:
    """Counts: jobs, planned, simulated, feedback reached without a fall."""
    ok = [r for r in rows if r.get("status") == "ok"]
    planned = [r for r in ok if r["reached"] and r["check_ok"]]
    sims = [r for r in planned if r["feedback"] == "ok"]
    good = [r for r in sims if r["feedback_reached"] and not r["feedback_fell"]]
    return {"jobs": len(rows), "planned": len(planned), "simulated": len(sims),
            "feedback_ok": len(good)}  # fmt: skip


def run_robots_bench(
    robots: Sequence[str] | None = None,
    kinds: Sequence[str] = KINDS,
    time_budget_s: float = TIME_BUDGET_S,
    out_dir: str | Path = "bench/results",
    workers: int = 2,
    resume: bool = False,
    save_plans: bool = False,
    progress: bool = True,
) -> dict[str, Any]:
    """Run the jobs and write ``robots.{jsonl,json,md}`` to ``out_dir``; the JSON's content."""
    from planner.bench.batch import _clean, read_results
    from planner.bench.physics import run_jobs
    from planner.body.robot import robot_names
    from planner.core.machine import machine_info
    from planner.core.outputs import write_atomic

    robots = list(robots or robot_names())
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / RESULTS_NAME
    if not resume and path.exists():
        path.unlink()
    plans_dir = (out / "robot_plans").resolve() if save_plans else None
    jobs = robot_jobs(robots, kinds, time_budget_s, out, plans_dir)
    t0 = time.perf_counter()
    interrupted = run_jobs(jobs, path, workers, progress)
    rows = robot_rows(jobs, read_results(path))
    result = _clean(
        {
            "format": "stratawalk.bench.robots/1",
            "config": {
                "robots": robots,
                "kinds": list(kinds),
                "walk_m": WALK_M,
                "relief_fraction": RELIEF_FRACTION,
                "step_fraction": STEP_FRACTION,
                "time_budget_s": time_budget_s,
                "workers": workers,
            },
            "machine": machine_info()
            | {"load_average_1_5_15_at_end": [round(v, 2) for v in os.getloadavg()]},
            "total_time_s": time.perf_counter() - t0,
            "interrupted": interrupted,
            "summary": summarize(rows),
            "rows": rows,
        }
    )
    text = json.dumps(result, indent=1, allow_nan=False) + "\n"
    write_atomic(out / "robots.json", lambda p: p.write_text(text))
    write_atomic(out / "robots.md", lambda p: p.write_text(render_markdown(result)))
    return result


# ------------------------------------------------------------------------------ command line
def add_robots_parser(bench_sub) -> argparse.ArgumentParser:
    """Add ``bench robots`` to the ``bench`` subcommands."""
    p = bench_sub.add_parser(
        "robots", help="every robot on flat, rough and step courses scaled to its legs, in MuJoCo"
    )
    p.add_argument("--robots", default="all", help="comma-separated robot names, or 'all'")
    p.add_argument("--courses", default=",".join(KINDS), help="course kinds: flat,rough,step")
    p.add_argument("--time-budget", type=float, default=TIME_BUDGET_S, help="[s] per plan")
    p.add_argument("--out", default="bench/results", help="output folder")
    p.add_argument("--workers", type=int, default=2, help="processes at once")
    p.add_argument("--resume", action="store_true", help="keep finished jobs of robots.jsonl")
    p.add_argument("--save-plans", action="store_true", help="write OUT/robot_plans/*.json")
    p.set_defaults(func=cmd_robots)
    return p


def cmd_robots(args) -> int:
    """Run ``stratawalk bench robots`` and print the markdown table."""
    from planner.body.robot import robot_names
    from planner.core.outputs import check_folder

    check_folder(args.out, "--out")
    known = robot_names()
    robots = known if args.robots == "all" else [s.strip() for s in args.robots.split(",") if s]
    for r in robots:
        if r not in known:
            raise InputError(f"--robots: unknown robot '{r}'; known: {', '.join(known)}")
    if not robots:
        raise InputError("--robots: give at least one robot name, or 'all'")
    kinds = [s.strip() for s in args.courses.split(",") if s.strip()]
    for k in kinds:
        if k not in KINDS:
            raise InputError(f"--courses: unknown kind '{k}'; use any of {','.join(KINDS)}")
    if not kinds:
        raise InputError(f"--courses: give at least one of {','.join(KINDS)}")
    if not args.time_budget > 0:
        raise InputError(f"--time-budget: must be > 0 s, got {args.time_budget}")
    if args.workers < 1:
        raise InputError(f"--workers: must be >= 1, got {args.workers}")
    from planner.core.interrupts import Interrupts

    with Interrupts() as stop:  # Ctrl-C / SIGTERM: the workers stopped, finished jobs kept
        result = run_robots_bench(robots, kinds, args.time_budget, args.out, args.workers,
                                  args.resume, args.save_plans)  # fmt: skip
    print(render_markdown(result))
    print(f"wrote {Path(args.out) / 'robots.md'} and robots.json, robots.jsonl", file=sys.stderr)
    return stop.exit_code or 0
