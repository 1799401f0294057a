"""The course benchmark: robots x courses x local planners, run by the batch machinery.

``stratawalk bench courses`` (part of ``make bench``) plans every (robot, course, planner)
walk from (0.2, 0) to (2.2, 0) with a time budget, through :func:`planner.bench.batch.run_batch`
(a local process pool, or a Dask cluster with ``--scheduler``), and tabulates per walk:
reached (and validated by :func:`planner.planfile.validate.check_plan`), steps, planning time,
the time the walk takes to execute (``plan.samples.time[-1]``) and their ratio (planning
time / execution time; below 1 the planner is faster than the robot). Results stream to
``courses.jsonl`` (``--resume`` continues an interrupted run) and are summarised in
``courses.md`` and ``courses.json`` in the output folder.

``--start-offsets 1e-6,1e-3`` (issue 65: success must not hinge on rounding) repeats every
walk from the start moved by each distance in +x, -x, +y, -y (the planner's own start
argument; it finds the initial stance there): 1 + 4 x N jobs per course and planner, the
unmoved one with the id it has without the option. The table gets a start-offset column and
the summary a robustness section per planner (:func:`robustness`): at how many starts each
course reached the goal and passed the check, how many courses plan from every start, and
the courses whose outcome differs between starts (the rounding-fragile ones).

Planning times are wall-clock times of the local planner inside its job, measured with
``--workers`` jobs at once on the machine (the JSON records the machine and its load).
"""

from __future__ import annotations

import argparse
import json
import math
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
    "START_DIRECTIONS",
    "expand_courses",
    "parse_start_offsets",
    "robustness",
    "start_label",
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
# --start-offsets: the start moved by each distance along these unit vectors
START_DIRECTIONS = (
    ("+x", (1.0, 0.0)),
    ("-x", (-1.0, 0.0)),
    ("+y", (0.0, 1.0)),
    ("-y", (0.0, -1.0)),
)
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


def parse_start_offsets(text: str, start_xy=START_XY) -> tuple[float, ...]:
    """The distances of ``--start-offsets`` ("1e-6,1e-3"), in metres, duplicates dropped.

    Raises
    ------
    InputError
        One line naming ``--start-offsets``: a word that is no number, a distance that is
        not finite and > 0, or one too small to move ``start_xy`` in float64.

    """
    from planner.core.errors import InputError

    words = [w.strip() for w in str(text).split(",") if w.strip()]
    if not words:
        raise InputError("--start-offsets: give distances in metres, comma-separated (1e-6,1e-3)")
    out = []
    for w in words:
        try:
            v = float(w)
        except ValueError:
            raise InputError(
                f"--start-offsets: '{w}' is not a number; give distances in metres, "
                "comma-separated (1e-6,1e-3)"
            ) from None
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"--start-offsets: each distance must be finite and > 0 m, got {w}")
        moved = [(start_xy[0] + v * ux, start_xy[1] + v * uy) for _, (ux, uy) in START_DIRECTIONS]
        if any(tuple(m) == (float(start_xy[0]), float(start_xy[1])) for m in moved):
            raise InputError(
                f"--start-offsets: {w} m does not move the start {tuple(start_xy)} in float64 "
                "arithmetic; give a larger distance"
            )
        out.append(v)
    return tuple(dict.fromkeys(out))


def _starts(start_xy, start_offsets) -> list[tuple[list[float], list[float]]]:
    """(start, offset) pairs: the unmoved start, then each distance in each direction."""
    x0, y0 = float(start_xy[0]), float(start_xy[1])
    out = [([x0, y0], [0.0, 0.0])]
    for d in start_offsets:
        for _, (ux, uy) in START_DIRECTIONS:
            dx, dy = float(d) * ux, float(d) * uy
            out.append(([x0 + dx, y0 + dy], [dx, dy]))
    return out


def start_label(offset) -> str:
    """A start offset [dx, dy] as the table writes it: '0', '+x 1e-06', '-y 0.001'."""
    if offset is None:
        return "-"
    dx, dy = float(offset[0]), float(offset[1])
    if dx == 0 and dy == 0:
        return "0"
    if dy == 0:
        return f"{'+' if dx > 0 else '-'}x {abs(dx):g}"
    if dx == 0:
        return f"{'+' if dy > 0 else '-'}y {abs(dy):g}"
    return f"({dx:g}, {dy:g})"


def course_jobs(
    robots=ROBOTS,
    courses=COURSES,
    planners=PLANNERS,
    start_xy=START_XY,
    goal_xy=GOAL_XY,
    time_budget_s: float = TIME_BUDGET_S,
    seed: int = 0,
    start_offsets=(),
) -> list[dict]:
    """The batch jobs of the table, robot-major then course then planner.

    With ``start_offsets`` (metres) each (robot, course, planner) is followed by its walks
    from the start moved by each distance in +x, -x, +y, -y (:data:`START_DIRECTIONS`), and
    every job carries its ``start_offset`` [dx, dy] ([0, 0] for the unmoved one, whose job
    id is the one without offsets: the id hashes the start, not the offset).
    """
    starts = _starts(start_xy, start_offsets)
    jobs = []
    for r in robots:
        for c in courses:
            goal = list(goal_for(c, goal_xy))
            for p in planners:
                for start, offset in starts:
                    job = DEFAULTS | {
                        "robot": r,
                        "terrain": c,
                        "planner": p,
                        "start": list(start),
                        "goal": list(goal),
                        "seed": int(seed),
                        "time_budget_s": float(time_budget_s),
                    }
                    if start_offsets:
                        job["start_offset"] = list(offset)
                    jobs.append(job)
    return jobs


def _row(job: dict, rec: dict | None) -> dict[str, Any]:
    row = {k: job[k] for k in ("robot", "terrain", "planner")}
    if "start_offset" in job:
        row["start_offset"] = list(job["start_offset"])
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
        "longest_stall_cycles",
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
    start_offsets=(),
    goal_xy=GOAL_XY,
) -> dict[str, Any]:
    """Run the table's jobs and write ``courses.{jsonl,json,md}`` to ``out_dir``.

    Without ``resume`` an old ``courses.jsonl`` is replaced; with it, finished jobs are
    kept and only the others run. ``start_offsets`` (metres): each walk also from the start
    moved by each in +x, -x, +y, -y (:func:`course_jobs`); the result then has them in its
    config and a ``robustness`` (:func:`robustness`). ``goal_xy``: the goal of the courses
    without their own. Returns the content of ``courses.json``.
    """
    from planner.core.machine import machine_info

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results = out / "courses.jsonl"
    if not resume and results.exists():
        results.unlink()
    start_offsets = tuple(float(d) for d in start_offsets)
    jobs = course_jobs(
        robots,
        courses,
        planners,
        goal_xy=goal_xy,
        time_budget_s=time_budget_s,
        start_offsets=start_offsets,
    )
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
            "goal": [float(goal_xy[0]), float(goal_xy[1])],
            "time_budget_s": time_budget_s,
            "scheduler": scheduler,
            "workers": workers or os.cpu_count(),
        },
        "machine": machine | {"load_average_1_5_15_at_end": [round(v, 2) for v in os.getloadavg()]},
        "total_time_s": time.perf_counter() - t0,
        "interrupted": summary.interrupted,
        "rows": rows,
    }
    if start_offsets:
        result["config"]["start_offsets"] = list(start_offsets)
        result["robustness"] = robustness(rows)
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


def _planned(row: dict) -> bool:
    """The row's walk reached the goal and its plan passed the check."""
    return row.get("status") == "ok" and bool(row.get("reached")) and bool(row.get("validated"))


def robustness(rows) -> dict[str, dict[str, Any]]:
    """Per planner, per course: at how many of its starts the walk was planned.

    Planned = reached the goal and passed the check (:func:`_planned`). For each planner:
    ``courses``, one entry per (robot, course) in row order with ``starts`` (its rows),
    ``planned``, ``missing`` (no result: an interrupted run), ``not_from`` (the labels of
    the starts with a result that did not plan), ``robust`` (planned from every start) and
    ``fragile`` (the outcome differs between the starts with a result); ``robust`` and
    ``of``: the count of robust courses and of courses; ``fragile``: those courses' names
    ("course" with one robot, "course (robot)" with more).
    """
    robots = {r["robot"] for r in rows}
    out: dict[str, dict[str, Any]] = {}
    for r in rows:
        per = out.setdefault(r["planner"], {"courses": {}})["courses"]
        name = r["terrain"] if len(robots) == 1 else f"{r['terrain']} ({r['robot']})"
        e = per.setdefault(
            name,
            {"robot": r["robot"], "course": r["terrain"], "starts": 0, "planned": 0,
             "missing": 0, "not_from": [], "outcomes": set()},
        )  # fmt: skip
        e["starts"] += 1
        if r.get("status") in (None, "missing"):
            e["missing"] += 1
            continue
        ok = _planned(r)
        e["planned"] += ok
        e["outcomes"].add(ok)
        if not ok:
            e["not_from"].append(start_label(r.get("start_offset", [0.0, 0.0])))
    for planner, s in out.items():
        courses = []
        for name, e in s["courses"].items():
            outcomes = e.pop("outcomes")
            e["name"] = name
            e["robust"] = e["planned"] == e["starts"]
            e["fragile"] = len(outcomes) > 1
            courses.append(e)
        out[planner] = {
            "courses": courses,
            "robust": sum(e["robust"] for e in courses),
            "of": len(courses),
            "fragile": [e["name"] for e in courses if e["fragile"]],
        }
    return out


def _robustness_lines(result: dict[str, Any]) -> list[str]:
    """The robustness section of ``courses.md`` (with ``--start-offsets``)."""
    offsets = result["config"].get("start_offsets") or []
    rob = result.get("robustness") or robustness(result["rows"])
    lines = [
        f"## Robustness to the start (--start-offsets {','.join(f'{d:g}' for d in offsets)})",
        "",
        f"Each walk also from the start moved by {', '.join(f'{d:g}' for d in offsets)} m in "
        "+x, -x, +y, -y. planned = reached the goal and passed `stratawalk check`; robust = "
        "planned from every start; fragile = the outcome differs between starts (success "
        "hinges on rounding).",
    ]
    for planner, s in rob.items():
        lines += [
            "",
            f"### {planner}",
            "",
            "| course | planned from | robust | fragile | not planned from |",
            "|---|---:|---|---|---|",
        ]
        for e in s["courses"]:
            left = f" ({e['missing']} without a result)" if e["missing"] else ""
            lines.append(
                f"| {e['name']} | {e['planned']} of {e['starts']}{left} | "
                f"{'yes' if e['robust'] else 'no'} | {'yes' if e['fragile'] else 'no'} | "
                f"{', '.join(e['not_from']) or '-'} |"
            )
        lines += [
            "",
            f"{planner}: {s['robust']} of {s['of']} courses plan from every start; "
            "outcome differs between starts: " + (", ".join(s["fragile"]) or "none") + ".",
        ]
    return [*lines, ""]


def render_markdown(result: dict[str, Any]) -> str:
    """The table of ``courses.md``."""
    c, m = result["config"], result["machine"]
    offsets = c.get("start_offsets") or []
    # with --start-offsets: a start-offset column after the planner's
    so_head, so_rule = (" start offset [m] |", "---|") if offsets else ("", "")
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
        + "."
        + (
            f" Each walk also from the start moved by {', '.join(f'{d:g}' for d in offsets)} m "
            f"in +x, -x, +y, -y ({1 + 4 * len(offsets)} starts per course and planner)."
            if offsets
            else ""
        ),
        "",
        "reached = the COM within 5 cm of the goal *and* the plan passes `stratawalk check`; "
        "ratio = planning time / time the walk takes to execute; job = wall time of the whole "
        "job (loading, planning, `check`): compare planners by it, since `global` plans "
        "check their candidates inside their planning time. backtracks / retraces: steps the "
        "recursive planner (8.5) undid inside a window / committed windows it planned again; "
        "for soft, its retraces (dead ends traced back a crawl cycle or more, 8.5's "
        "tracing back inside 8.2); greedy is 8.2 as the paper has it, without them.",
        "",
        f"| robot | course | planner |{so_head} reached | validated | steps | planning [s] "
        "| job [s] | walk [s] | ratio | left [m] | backtracks / retraces | note |",
        f"|---|---|---|{so_rule}---|---|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in result["rows"]:
        so = f" {start_label(r.get('start_offset'))} |" if offsets else ""
        if r["status"] != "ok":
            note = r.get("error") or r["status"]
            lines.append(
                f"| {r['robot']} | {r['terrain']} | {r['planner']} |{so} - | - | - | - | - | - | "
                f"- | - | - | {note[:80]} |"
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
            f"| {r['robot']} | {r['terrain']} | {r['planner']} |{so} "
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
    if offsets:
        lines += _robustness_lines(result)
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
    p.add_argument(
        "--start-offsets",
        default=None,
        metavar="D1,D2",
        help="comma-separated distances [m] (e.g. 1e-6,1e-3): each walk also from the start "
        "moved by each in +x, -x, +y, -y (1 + 4 x N walks per course and planner), a "
        "start-offset column and a robustness summary per planner (issue 65); default: "
        "the start alone",
    )
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
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers: must be >= 1, got {args.workers}")
    start_offsets = () if args.start_offsets is None else parse_start_offsets(args.start_offsets)
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
            start_offsets=start_offsets,
        )
    print(render_markdown(result))
    print(f"wrote {Path(args.out) / 'courses.md'} and courses.json, courses.jsonl", file=sys.stderr)
    return stop.exit_code or 0
