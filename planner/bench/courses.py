"""The course benchmark: robots x courses x local planners, run by the batch machinery.

``stratawalk bench courses`` (part of ``make bench``) plans every (robot, course, planner)
walk from (0.2, 0) to (2.2, 0) with a time budget, through :func:`planner.bench.batch.run_batch`
(a local process pool, or a Dask cluster with ``--scheduler``), and tabulates per walk:
reached (and validated by :func:`planner.planfile.validate.check_plan`), steps, planning time,
the time the walk takes to execute (``plan.samples.time[-1]``) and their ratio (planning
time / execution time; below 1 the planner is faster than the robot). Results stream to
``courses.jsonl`` (``--resume`` continues an interrupted run) and are summarised in
``courses.md`` and ``courses.json`` in the output folder.

Planning times are wall-clock times of the local planner inside its job, measured with
``--workers`` jobs at once on the machine (the JSON records the machine and its load).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

from planner.bench.batch import DEFAULTS, PLANNER_NAMES, job_id, run_batch
from planner.core.outputs import write_atomic

__all__ = [
    "COURSES",
    "GLOBAL_COURSES",
    "BACKTRACK_COURSES",
    "COURSE_GROUPS_HELP",
    "HARD_COURSES",
    "PLANNERS",
    "expand_courses",
    "own_goals_text",
    "goal_for",
    "add_courses_parser",
    "cmd_courses",
    "course_jobs",
    "render_markdown",
    "run_course_bench",
]

COURSES = (
    "flat",
    "slope10",
    "step5cm",
    "stairs",
    "rough2cm",
    "rough4cm",
    "gap6cm",
    "stepping_stones",
    "barrier75mm",
)
# the harder courses, at the limits of LittleDog's 18 cm legs
HARD_COURSES = (
    "trench12cm",
    "incline18",
    "barrier9cm",
    "step10cm",
    "stepdown8cm",
    "stairs_down",
    "sparse_stones",
    "mix4m",
)
# a 6 cm step up to a goal on its top: a hind leg left below the riser is a dead end for
# greedy stepping (8.2), which backtracking (8.5) gets out of
BACKTRACK_COURSES = ("step6cm",)
# walls and rocks the straight line runs into (planner "global", section 9)
GLOBAL_COURSES = ("barrier15cm_opening", "maze_two_walls", "tall_rocks")
# longer than 2 m; step6cm's on the step's top, 35 cm past its edge
COURSE_GOALS = {"mix4m": (4.2, 0.0), "maze_two_walls": (2.6, 0.0), "step6cm": (1.1, 0.0)}
PLANNERS = ("soft", "recursive")
ROBOTS = ("littledog",)
START_XY = (0.2, 0.0)
GOAL_XY = (2.2, 0.0)
# [s] per plan: the rolling feet and per-sample torque checks make planning ~5x slower
# than without them
TIME_BUDGET_S = 240.0


COURSE_GROUPS_HELP = (
    "comma-separated terrains; 'named' = the 9 first courses, 'hard' = issue 15's 8, "
    "'backtrack' = step6cm (soft dead-ends, recursive reaches), 'global' = issue 17's 3 "
    "(walls, rocks), 'ladder' = the feature ladder (feat:KIND:SIZE, "
    "planner.world.course_gen.LADDER)"
)  # the groups of expand_courses, for the --courses of bench courses and bench physics


def own_goals_text(courses) -> str:
    """' (COURSE: to (x, y))' for each of ``courses`` with its own goal (COURSE_GOALS)."""
    return "".join(f" ({k}: to {v})" for k, v in COURSE_GOALS.items() if k in courses)


def expand_courses(names) -> tuple[str, ...]:
    """Course names with the groups spelled out.

    'named' (:data:`COURSES`), 'hard', 'backtrack', 'global' and 'ladder'
    (:func:`planner.world.course_gen.ladder_course_names`).
    """
    from planner.world.course_gen import ladder_course_names

    groups = {"named": COURSES, "hard": HARD_COURSES, "global": GLOBAL_COURSES}
    groups["backtrack"] = BACKTRACK_COURSES
    groups["ladder"] = tuple(ladder_course_names())
    return tuple(dict.fromkeys(c for n in names for c in groups.get(n, (n,))))


def goal_for(course: str, default=GOAL_XY) -> tuple[float, float]:
    """The goal of a course's walk: ``COURSE_GOALS`` or ``default``.

    A generated or feature-ladder course's (gen:..., feat:...) is its own
    (:func:`planner.world.course_gen.course_goal_xy`, past its last edge).
    """
    from planner.world.course_gen import course_goal_xy, course_spec

    spec = None if course in COURSE_GOALS else course_spec(course)
    g = course_goal_xy(spec) if spec is not None else COURSE_GOALS.get(course, default)
    return float(g[0]), float(g[1])


def course_jobs(
    robots=ROBOTS,
    courses=COURSES,
    planners=PLANNERS,
    start_xy=START_XY,
    goal_xy=GOAL_XY,
    time_budget_s: float = TIME_BUDGET_S,
    seed: int = 0,
) -> list[dict]:
    """The batch jobs of the table, robot-major then course then planner."""
    return [
        DEFAULTS
        | {
            "robot": r,
            "terrain": c,
            "planner": p,
            "start": [float(start_xy[0]), float(start_xy[1])],
            "goal": list(goal_for(c, goal_xy)),
            "seed": int(seed),
            "time_budget_s": float(time_budget_s),
        }
        for r in robots
        for c in courses
        for p in planners
    ]


def _row(job: dict, rec: dict | None) -> dict[str, Any]:
    row = {k: job[k] for k in ("robot", "terrain", "planner")}
    if rec is None:
        return row | {"status": "missing"}
    row["status"] = rec.get("status")
    for k in (
        "reached",
        "validated",
        "violations",
        "steps",
        "distance_to_goal_m",
        "planning_time_s",
        "walk_time_s",
        "time_ratio",
        "backtracks",
        "retraces",
        "message",
        "error",
        "wall_time_s",
    ):
        if k in rec:
            row[k] = rec[k]
    return row


def run_course_bench(
    robots=ROBOTS,
    courses=COURSES,
    planners=PLANNERS,
    time_budget_s: float = TIME_BUDGET_S,
    out_dir: str | Path = "bench/results",
    scheduler: str | None = None,
    workers: int | None = None,
    resume: bool = False,
    progress: bool = True,
) -> dict[str, Any]:
    """Run the table's jobs and write ``courses.{jsonl,json,md}`` to ``out_dir``.

    Without ``resume`` an old ``courses.jsonl`` is replaced; with it, finished jobs are
    kept and only the others run. Returns the content of ``courses.json``.
    """
    from planner.core.machine import machine_info

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results = out / "courses.jsonl"
    if not resume and results.exists():
        results.unlink()
    jobs = course_jobs(robots, courses, planners, time_budget_s=time_budget_s)
    machine = machine_info()
    t0 = time.perf_counter()
    summary = run_batch(
        jobs,
        out,
        scheduler=scheduler,
        workers=workers,
        progress=progress,
        results_name="courses.jsonl",
    )
    rows = [_row(j, summary.records.get(job_id(j))) for j in jobs]
    result = {
        "format": "stratawalk.bench.courses/1",
        "config": {
            "robots": list(robots),
            "courses": list(courses),
            "planners": list(planners),
            "start": list(START_XY),
            "goal": list(GOAL_XY),
            "time_budget_s": time_budget_s,
            "scheduler": scheduler,
            "workers": workers or os.cpu_count(),
        },
        "machine": machine | {"load_average_1_5_15_at_end": [round(v, 2) for v in os.getloadavg()]},
        "total_time_s": time.perf_counter() - t0,
        "interrupted": summary.interrupted,
        "rows": rows,
    }
    text = json.dumps(result, indent=1, allow_nan=False) + "\n"
    write_atomic(out / "courses.json", lambda p: p.write_text(text))
    write_atomic(out / "courses.md", lambda p: p.write_text(render_markdown(result)))
    return result


def _f(v, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


def _backtracks(row: dict) -> str:
    """'backtracks / retraces' of a row: recursive's both, soft's retraces alone ('- / n')."""
    if row.get("backtracks") is None:
        return "-" if row.get("retraces") is None else f"- / {row['retraces']}"
    return f"{row['backtracks']} / {row.get('retraces', 0)}"


def render_markdown(result: dict[str, Any]) -> str:
    """The table of ``courses.md``."""
    c, m = result["config"], result["machine"]
    lines = [
        "# Course benchmark (`stratawalk bench courses`)",
        "",
        f"Walks from {tuple(c['start'])} to {tuple(c['goal'])} m"
        + own_goals_text(c["courses"])
        + (
            " (generated and feature courses: to their own goals, past their last edge)"
            if any(str(k).startswith(("gen:", "feat:")) for k in c["courses"])
            else ""
        )
        + ", time budget "
        f"{c['time_budget_s']:g} s each, {c['workers']} jobs at once"
        + (f" on the Dask cluster {c['scheduler']}" if c["scheduler"] else "")
        + f"; {m['nproc']} cores ({m['cpu'] or 'cpu unknown'}), load at start "
        f"{m['load_average_1_5_15_at_start']}, commit {m['git_commit'] or '?'}, {m['date']}. "
        f"Total {result['total_time_s']:.0f} s"
        + (" (interrupted: rows marked missing)" if result["interrupted"] else "")
        + ".",
        "",
        "reached = the COM within 5 cm of the goal *and* the plan passes `stratawalk check`; "
        "ratio = planning time / time the walk takes to execute; job = wall time of the whole "
        "job (loading, planning, `check`): compare planners by it, since `global` plans "
        "check their candidates inside their planning time. backtracks / retraces: steps the "
        "recursive planner (8.5) undid inside a window / committed windows it planned again; "
        "for soft, its retraces (dead ends traced back a crawl cycle or more, 8.5's "
        "tracing back inside 8.2); greedy is 8.2 as the paper has it, without them.",
        "",
        "| robot | course | planner | reached | validated | steps | planning [s] | job [s] "
        "| walk [s] | ratio | left [m] | backtracks / retraces | note |",
        "|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in result["rows"]:
        if r["status"] != "ok":
            note = r.get("error") or r["status"]
            lines.append(
                f"| {r['robot']} | {r['terrain']} | {r['planner']} | - | - | - | - | - | - | - | - "
                f"| - | {note[:80]} |"
            )
            continue
        note = "" if r["reached"] else r.get("message", "")[:80]
        if r.get("violations"):
            note = (
                (note + "; " if note else "")
                + "violations: "
                + ", ".join(f"{k} {v}" for k, v in r["violations"].items())
            )
        lines.append(
            f"| {r['robot']} | {r['terrain']} | {r['planner']} | "
            f"{'yes' if r['reached'] else 'no'} | {'yes' if r['validated'] else 'no'} | "
            f"{r['steps']} | {_f(r.get('planning_time_s'), '.1f')} | "
            f"{_f(r.get('wall_time_s'), '.1f')} | {_f(r.get('walk_time_s'), '.1f')} | "
            f"{_f(r.get('time_ratio'), '.3f')} | "
            f"{_f(r.get('distance_to_goal_m'), '.3f')} | {_backtracks(r)} | "
            f"{note.replace('|', '/')} |"
        )
    ok = [r for r in result["rows"] if r["status"] == "ok"]
    lines += [
        "",
        f"Reached: {sum(bool(r['reached']) for r in ok)} of {len(result['rows'])} walks.",
        "",
    ]
    return "\n".join(lines)


def add_courses_parser(bench_sub) -> argparse.ArgumentParser:
    """Add ``bench courses`` to the ``bench`` subcommands."""
    p = bench_sub.add_parser("courses", help="robots x courses x planners: reached, steps, times")
    p.add_argument("--robots", default=",".join(ROBOTS), help="comma-separated names")
    p.add_argument(
        "--courses",
        default="named,hard",
        help=COURSE_GROUPS_HELP,
    )
    p.add_argument(
        "--planners",
        default=",".join(PLANNERS),
        help="soft,hard,recursive,global (section 9 from the guide path)",
    )
    p.add_argument("--time-budget", type=float, default=TIME_BUDGET_S, help="[s] per walk")
    p.add_argument("--out", default="bench/results", help="output folder")
    p.add_argument("--scheduler", help="tcp://HOST:PORT of a running Dask scheduler")
    p.add_argument("--workers", type=int, default=None, help="local processes (default: cores)")
    p.add_argument("--resume", action="store_true", help="keep finished jobs of courses.jsonl")
    p.set_defaults(func=cmd_courses)
    return p


def cmd_courses(args) -> int:
    """Run ``stratawalk bench courses`` and print the markdown table."""
    from planner.core.outputs import check_folder

    check_folder(args.out, "--out")
    from planner.core.errors import InputError

    def names(text: str, what: str) -> tuple[str, ...]:
        out = tuple(s.strip() for s in text.split(",") if s.strip())
        if not out:
            raise InputError(f"--{what}: give at least one name, comma-separated")
        return out

    planners = names(args.planners, "planners")
    bad = [p for p in planners if p not in PLANNER_NAMES]
    if bad:
        raise InputError(f"--planners: unknown '{bad[0]}'; use {', '.join(PLANNER_NAMES)}")
    if not args.time_budget > 0:
        raise InputError(f"--time-budget: must be > 0 s, got {args.time_budget}")
    from planner.core.interrupts import Interrupts

    # Ctrl-C / SIGTERM: the workers stopped, finished jobs kept (as ``stratawalk batch``)
    with Interrupts(cooperative=args.scheduler is None) as stop:
        result = run_course_bench(
            robots=names(args.robots, "robots"),
            courses=expand_courses(names(args.courses, "courses")),
            planners=planners,
            time_budget_s=args.time_budget,
            out_dir=args.out,
            scheduler=args.scheduler,
            workers=args.workers,
            resume=args.resume,
        )
    print(render_markdown(result))
    print(f"wrote {Path(args.out) / 'courses.md'} and courses.json, courses.jsonl", file=sys.stderr)
    return stop.exit_code or 0
