"""The physics benchmark: plan each course, then execute the plan in MuJoCo (section 10).

``stratawalk bench physics`` plans, for every course (the nine named courses of
:data:`planner.bench.courses.COURSES` and ``--generated N`` courses of
:mod:`planner.world.course_gen`, seeds 0..N-1), a walk with a local planner (``--planner``: the
soft one of 8.2 by default, the recursive one of 8.5 or the hard one of 8.1) from
(0.2, 0) to (2.2, 0) on a named course, or to (3.0, 0) = the end of a generated course
minus 0.4 m, validates it (:func:`planner.planfile.validate.check_plan`, run by
:func:`planner.planning.walk.plan_walk`), then executes it with
:func:`planner.sim.execution.simulate_plan`
in each mode, as ``stratawalk simulate`` does:

- ``open``: open loop, the plan's joint set-points (:func:`planner.sim.simulate.run_open_loop`);
- ``feedback``: re-planning every step from the measured state (8.3,
  :func:`planner.sim.execution.run_feedback`);
- ``correct``: precompute then correct (8.4, :func:`planner.sim.execution.run_corrected`);

at ``--time-scale`` (default 1: the plan's own speed). One job per course (plan once, run
the modes) goes to a process pool (``--workers``, default 2); each finished job is one
line of ``physics.jsonl`` (``--resume`` keeps finished jobs and reruns failed ones); a job
that raises becomes error rows, the others go on. ``physics.json`` (rows, configuration,
machine) and ``physics.md`` (a table per course group and the summary of
:func:`summarize`) are written at the end. Generated courses are written as YAML to
``OUT/courses/`` (the jobs' terrains), ``--save-plans`` writes the plans to ``OUT/plans/``.

``--courses generated-set`` adds the generated set of
:func:`planner.world.course_gen.generated_set_names` (60 courses: seeds 0..19 at difficulty
0.6, 1 and 1.3, all seven kinds); its rows have the group ``generated-set`` and a
``family`` per difficulty (``generated d=0.6``), and the summary a line per family
(:func:`family_summary`).

A row's ``success`` is: the run reached (:attr:`planner.sim.simulate.Metrics.reached`: open loop
and correction, the final base within 5 cm of the plan's final base; feedback, the COM
within 5 cm of the goal) without a fall, and, executing a plan, the plan reached the goal.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import socket
import sys
import time
import traceback
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from planner.bench.courses import (
    COURSE_GROUPS_HELP,
    COURSES,
    GOAL_XY,
    START_XY,
    expand_courses,
    goal_for,
    own_goals_text,
)
from planner.core.errors import InputError
from planner.core.outputs import write_atomic

__all__ = [
    "MODES",
    "add_physics_parser",
    "cmd_physics",
    "expand_physics_courses",
    "family_summary",
    "physics_jobs",
    "physics_rows",
    "render_markdown",
    "run_physics_bench",
    "run_physics_job",
    "summarize",
    "write_results",
]

MODES = ("open", "feedback", "correct")
MODE_NAMES = {"open": "open loop", "feedback": "feedback (8.3)", "correct": "correct (8.4)"}
GENERATED = 20
# [s] per plan: the rolling feet and per-sample torque checks make planning ~5x slower
# than without them
TIME_BUDGET_S = 240.0
TIME_SCALE = 1.0
WORKERS = 2
RESULTS_NAME = "physics.jsonl"
_ID_FIELDS = ("robot", "course", "planner", "start", "goal", "modes", "time_budget_s", "time_scale")
GENERATED_SET = "generated-set"  # the --courses group of course_gen.generated_set_names
COURSES_HELP = (
    COURSE_GROUPS_HELP + ", 'generated-set' = 60 generated courses, seeds 0..19 at "
    "difficulty 0.6, 1 and 1.3, all seven kinds (course_gen.generated_set_names), a summary "
    "line per difficulty"
)


def expand_physics_courses(names: Iterable[str]) -> tuple[tuple[str, ...], dict[str, str]]:
    """The course names with the groups spelled out, and the family of each generated-set course.

    ``generated-set`` becomes :func:`planner.world.course_gen.generated_set_names` (each
    course's family :func:`planner.world.course_gen.generated_set_family`, e.g.
    "generated d=0.6"); the other groups are those of
    :func:`planner.bench.courses.expand_courses`, in the order given.
    """
    from planner.world.course_gen import generated_set_family, generated_set_names

    courses: list[str] = []
    families: dict[str, str] = {}
    for name in names:
        if name == GENERATED_SET:
            for course in generated_set_names():
                families[course] = generated_set_family(course)
                courses.append(course)
        else:
            courses += expand_courses([name])
    return tuple(dict.fromkeys(courses)), families


# ------------------------------------------------------------------------------ jobs
def job_id(job: dict) -> str:
    """16 hex digits of the SHA-256 of the job's fields (not its terrain path or plans_dir).

    ``planned_only`` counts only when set (a run that skipped simulations must not stand in
    for one that simulates every plan on ``--resume``; older records keep their ids).
    """
    fields = {k: job[k] for k in _ID_FIELDS}
    if job.get("planned_only"):
        fields["planned_only"] = True
    if job.get("preset", "default") != "default":
        fields["preset"] = job["preset"]
    text = json.dumps(fields, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def physics_jobs(
    courses: Sequence[str] = COURSES,
    generated: int = GENERATED,
    difficulty: float = 1.0,
    modes: Sequence[str] = MODES,
    time_budget_s: float = TIME_BUDGET_S,
    time_scale: float = TIME_SCALE,
    out_dir: str | Path = "bench/results",
    named_goal_xy: Sequence[float] = GOAL_XY,
    plans_dir: str | Path | None = None,
    first_seed: int = 0,
    planned_only: bool = False,
    planner: str = "soft",
    preset: str = "default",
    families: dict[str, str] | None = None,
) -> list[dict]:
    """The jobs: ``courses`` (names, paths or ``gen:...`` names), then ``generated`` seeds.

    Generated courses (seeds ``first_seed``, ``first_seed + 1``, ...) are written to
    ``out_dir/courses/`` and their YAML path is the job's terrain; their goal is
    :func:`planner.world.course_gen.course_goal_xy`, a named course's ``named_goal_xy``.
    ``planned_only``: simulate a plan only when it reached the goal and passes the check.
    ``planner``: the local planner of every plan (soft, recursive or hard); ``preset``:
    its settings (``stratawalk plan --preset``), "default" the defaults. ``families``: the
    generated set's courses and their families (:func:`expand_physics_courses`): their
    jobs get the group "generated-set" and a ``family`` (not part of the job's id).
    """
    from planner.world.course_gen import (
        course_goal_xy,
        course_spec,
        generated_course_names,
        write_course,
    )

    gen = generated_course_names(generated, first_seed, difficulty)
    names = list(dict.fromkeys([*courses, *gen]))
    families = families or {}
    jobs = []
    for name in names:
        spec = course_spec(name)
        if spec is None:
            terrain, goal, group = name, goal_for(name, named_goal_xy), "named"
        else:
            terrain = str(write_course(spec, Path(out_dir) / "courses").resolve())
            goal = course_goal_xy(spec)
            group = "ladder" if name.startswith("feat:") else "generated"
            if name in families:
                group = GENERATED_SET
        family = {"family": families[name]} if group == GENERATED_SET else {}
        jobs.append(
            {
                "robot": "littledog",
                "course": name,
                "group": group,
                **family,
                "terrain": terrain,
                "planner": planner,
                "preset": preset,
                "start": [float(START_XY[0]), float(START_XY[1])],
                "goal": [float(goal[0]), float(goal[1])],
                "modes": list(modes),
                "time_budget_s": float(time_budget_s),
                "time_scale": float(time_scale),
                "plans_dir": None if plans_dir is None else str(plans_dir),
                "planned_only": bool(planned_only),
            }
        )
    return jobs


# ------------------------------------------------------------------------------ one job
def _job_settings(job: dict):
    """The local planner's settings of a job: its preset's, with its time budget."""
    from dataclasses import replace

    from planner.planning.settings import preset_settings

    local = preset_settings(job.get("preset", "default"), job["robot"])
    return replace(local, time_budget_s=float(job["time_budget_s"]))


def _sim_fields(metrics: dict) -> dict[str, Any]:
    """The row's columns from :meth:`planner.sim.simulate.Metrics.to_dict` (cm, mm, %)."""

    def scaled(key: str, factor: float) -> float | None:
        v = metrics.get(key)
        return None if v is None else float(v) * factor

    return {
        "reached": bool(metrics.get("reached")),
        "fell": bool(metrics.get("fell")),
        "final_error_cm": scaled("final_error_m", 100.0),
        "com_to_goal_cm": scaled("com_to_goal_m", 100.0),
        "body_contact": bool(metrics.get("body_contact")),
        "leg_contact_s": scaled("leg_contact_s", 1.0),
        "max_slip_mm": scaled("max_slip_m", 1000.0),
        "max_sliding_mm": scaled("max_sliding_m", 1000.0),
        "saturation_pct": scaled("saturation_frac", 100.0),
        "three_leg_load_pct": scaled("max_three_leg_load", 100.0),
        "load_over_plan_pct": scaled("max_load_over_plan", 100.0),
        "sim_time_s": scaled("sim_time_s", 1.0),
        "message": str(metrics.get("message", "")),
    }


def _error(exc: BaseException) -> dict[str, str]:
    return {
        "status": "error",
        "error": f"{type(exc).__name__}: {' '.join(str(exc).split())}",
        "traceback": traceback.format_exc(limit=-4),
    }


def run_physics_job(job: dict) -> dict:
    """Plan one course, then execute the plan in each mode; never raises.

    Returns the record of the JSONL: ``id``, ``job``, ``status`` ("ok", or "error" when the
    planning or any mode raised), ``planning`` (planned, plan_reached, check_ok, steps,
    planning_time_s, walk_time_s, distance_to_goal_m, message), ``rows`` (one per mode, see
    :func:`physics_rows`), ``wall_time_s``, ``host``, ``pid``.
    """
    t0 = time.perf_counter()
    rec: dict[str, Any] = {"id": job_id(job), "job": dict(job), "status": "ok"}
    head = _head(job)
    plan, planning = None, {}
    try:
        from planner.planning.walk import plan_walk

        plan, report = plan_walk(  # runs planner.planfile.validate.check_plan on the plan
            job["robot"],
            job["terrain"],
            tuple(job["goal"]),
            tuple(job["start"]),
            job["planner"],
            _job_settings(job),
        )
        reached = bool(plan.outcome["reached_goal"])
        planning = {
            "planned": reached and bool(report.ok),
            "plan_reached": reached,
            "check_ok": bool(report.ok),
            "violations": report.by_kind(),
            "steps": int(plan.stats.get("steps", 0)),
            "planning_time_s": float(plan.stats.get("planning_time_s", float("nan"))),
            "walk_time_s": float(plan.samples.time[-1]),
            "distance_to_goal_m": float(plan.outcome["distance_to_goal"]),
            "message": plan.outcome["message"],
        }
        if job.get("plans_dir"):
            name = job["course"].replace(":", "_").replace("/", "_")
            Path(job["plans_dir"]).mkdir(parents=True, exist_ok=True)
            planning["plan_file"] = str(plan.save(Path(job["plans_dir"]) / f"{name}.json"))
    except Exception as exc:  # the planner failed: every mode is an error row
        planning = _error(exc)
        rec["status"] = "error"
    rec["planning"] = planning
    rows = []
    for mode in job["modes"]:
        row = head | {"mode": mode}
        w0 = time.perf_counter()
        if plan is None:
            row |= {"status": "error", "error": f"planning failed: {planning['error']}"}
        elif job.get("planned_only") and not planning["planned"]:
            row |= {"status": "skipped", "message": "not simulated: the plan did not reach"}
        else:
            try:
                from planner.sim.execution import simulate_plan
                from planner.sim.simulate import SimSettings

                res = simulate_plan(plan, mode, SimSettings(time_scale=float(job["time_scale"])))
                row |= {"status": "ok"} | _sim_fields(res.metrics.to_dict())
            except Exception as exc:  # one failing mode must not stop the others
                row |= _error(exc)
                rec["status"] = "error"
        row["wall_time_s"] = time.perf_counter() - w0
        rows.append(row)
    rec["rows"] = rows
    rec.update(wall_time_s=time.perf_counter() - t0, host=socket.gethostname(), pid=os.getpid())
    return rec


def _head(job: dict) -> dict[str, Any]:
    """The first columns of a job's rows: course, group and (the generated set's) family."""
    head = {"course": job["course"], "group": job["group"]}
    if job.get("family"):
        head["family"] = job["family"]
    return head


def _failed_record(job: dict, exc: BaseException) -> dict:
    """The record of a job whose worker died: an error row per mode."""
    err = _error(exc)
    head = _head(job)
    rows = [head | {"mode": m, "status": "error", "error": err["error"]} for m in job["modes"]]
    return {"id": job_id(job), "job": dict(job), "planning": err, "rows": rows} | err


# ------------------------------------------------------------------------------ rows, summary
_PLAN_COLUMNS = ("planned", "plan_reached", "check_ok", "steps", "planning_time_s", "walk_time_s")


def physics_rows(jobs: Sequence[dict], records: dict[str, dict]) -> list[dict]:
    """One row per (course, mode) in job order: the run's columns and the plan's.

    A job without a record gives rows with ``status`` "missing". ``success``: reached
    without a fall, and the plan reached the goal (feedback walks to the goal itself).
    """
    rows = []
    for job in jobs:
        rec = records.get(job_id(job))
        planning = (rec or {}).get("planning", {})
        by_mode = {r["mode"]: r for r in (rec or {}).get("rows", [])}
        for mode in job["modes"]:
            row = by_mode.get(mode) or _head(job) | {"mode": mode, "status": "missing"}
            row = {k: v for k, v in row.items() if k != "traceback"} | _head(job)
            row.update({k: planning[k] for k in _PLAN_COLUMNS if k in planning})
            if mode == "feedback" and row.get("com_to_goal_cm") is not None:
                # the COM at the goal (records of older versions counted the end of a partial plan)
                row["reached"] = bool(row["com_to_goal_cm"] <= 5.0 and not row.get("fell"))
            row["success"] = bool(
                row.get("status") == "ok"
                and row.get("reached")
                and not row.get("fell")
                and (mode == "feedback" or row.get("planned"))
            )
            rows.append(row)
    return rows


def summarize(rows: Sequence[dict]) -> dict[str, Any]:
    """The summary of ``physics.md``.

    ``named``: per mode, how many named courses succeeded (reached without a fall) of how
    many; ``generated``: how many generated courses the planner reached, and per mode how
    many of those succeeded and the fraction; ``ladder``: :func:`ladder_limits`;
    ``families``: :func:`family_summary` (the generated set's, per difficulty).
    """
    modes = list(dict.fromkeys(r["mode"] for r in rows))
    named = [r for r in rows if r.get("group") == "named"]
    gen = [r for r in rows if r.get("group") == "generated"]
    out: dict[str, Any] = {"named": {}, "generated": {}, "ladder": ladder_limits(rows)}
    out["families"] = family_summary(rows)
    for mode in modes:
        rs = [r for r in named if r["mode"] == mode]
        if rs:
            out["named"][mode] = {"success": sum(r["success"] for r in rs), "of": len(rs)}
    gen_courses = list(dict.fromkeys(r["course"] for r in gen))
    planned = list(dict.fromkeys(r["course"] for r in gen if r.get("planned")))
    out["generated"] = {"courses": len(gen_courses), "planned": len(planned), "modes": {}}
    for mode in modes:
        rs = [r for r in gen if r["mode"] == mode and r.get("planned")]
        if gen_courses:
            k = sum(r["success"] for r in rs)
            out["generated"]["modes"][mode] = {
                "success": k,
                "of": len(rs),
                "fraction": k / len(rs) if rs else None,
            }
    return out


def family_summary(rows: Sequence[dict]) -> dict[str, Any]:
    """Per family of the generated set (rows with a ``family``), in the rows' order.

    ``courses``: how many; ``planned``: how many the planner planned within the time budget
    (the plan reached the goal and passes the check); ``errors``: courses with an error
    row. Per mode, over the planned courses' rows: ``runs`` (simulated, without error),
    ``reached`` (reached without a fall: a row's ``success``), ``fell``; open loop also
    ``within_5cm`` (the final base within 5 cm of the plan's final base, fall or not).
    """
    out: dict[str, Any] = {}
    for family in dict.fromkeys(r["family"] for r in rows if r.get("family")):
        rs = [r for r in rows if r.get("family") == family]
        courses = list(dict.fromkeys(r["course"] for r in rs))
        planned = list(dict.fromkeys(r["course"] for r in rs if r.get("planned")))
        errors = list(dict.fromkeys(r["course"] for r in rs if r.get("status") == "error"))
        entry: dict[str, Any] = {
            "courses": len(courses),
            "planned": len(planned),
            "errors": len(errors),
            "modes": {},
        }
        for mode in dict.fromkeys(r["mode"] for r in rs):
            ran = [
                r for r in rs if r["mode"] == mode and r.get("planned") and r.get("status") == "ok"
            ]
            m = {
                "runs": len(ran),
                "reached": sum(bool(r.get("success")) for r in ran),
                "fell": sum(bool(r.get("fell")) for r in ran),
            }
            if mode == "open":
                m["within_5cm"] = sum(
                    r.get("final_error_cm") is not None and r["final_error_cm"] <= 5.0 for r in ran
                )
            entry["modes"][mode] = m
        out[family] = entry
    return out


def ladder_limits(rows: Sequence[dict]) -> dict[str, Any]:
    """Where the planner's limits are, from the feature ladder's rows.

    Per ladder family: each size's results, and the largest size planned (the plan reached
    and passes the check) and reached in each mode. Families are the kinds of
    :data:`planner.world.course_gen.LADDER`, steps and stairs split into up and down; sizes are
    magnitudes in the ladder's units.
    """
    from planner.world.course_gen import LADDER_UNITS, parse_feature_name

    out: dict[str, Any] = {}
    for r in rows:
        if r.get("group") != "ladder":
            continue
        kind, size = parse_feature_name(r["course"])
        family = f"{kind} {'up' if size > 0 else 'down'}" if kind in ("step", "stairs") else kind
        entry = out.setdefault(family, {"unit": LADDER_UNITS.get(kind, ""), "sizes": {}})
        cell = entry["sizes"].setdefault(abs(size), {"planned": bool(r.get("planned"))})
        cell[r["mode"]] = bool(r.get("success"))
    for entry in out.values():
        sizes = sorted(entry["sizes"])
        modes = {m for c in entry["sizes"].values() for m in c if m != "planned"}
        entry["largest"] = {
            what: max((v for v in sizes if entry["sizes"][v].get(what)), default=None)
            for what in ["planned", *sorted(modes)]
        }
        # the planner's limit is where it first fails: a larger size reached beyond it is luck
        entry["smallest_not_planned"] = min(
            (v for v in sizes if not entry["sizes"][v]["planned"]), default=None
        )
        entry["sizes"] = {f"{v:g}": entry["sizes"][v] for v in sizes}
    return out


def _ladder_lines(limits: dict[str, Any], modes: Sequence[str]) -> list[str]:
    names = ["planned", *modes]
    lines = [
        "| feature | unit | sizes: planned / "
        + " / ".join(MODE_NAMES.get(m, m) for m in modes)
        + " | smallest not planned | largest planned | "
        + " | ".join(f"largest, {MODE_NAMES.get(m, m)}" for m in modes)
        + " |",
        "|---|---|---|---:|---:|" + "---:|" * len(modes),
    ]
    for family, e in limits.items():
        cells = ", ".join(
            f"{v}: " + "/".join(_yn(c.get(n)) for n in names) for v, c in e["sizes"].items()
        )
        big = [_f(e["smallest_not_planned"], "g")] + [_f(e["largest"].get(n), "g") for n in names]
        lines.append(f"| {family} | {e['unit']} | {cells} | " + " | ".join(big) + " |")
    return lines


def _f(v: Any, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


def _yn(v: Any) -> str:
    return "-" if v is None else ("yes" if v else "no")


def _table(rows: Sequence[dict]) -> list[str]:
    lines = [
        "| course | mode | planned | planning [s] | reached | fell | final error [cm] "
        "| COM to goal [cm] | body contact | leg contact [s] | max slip [mm] "
        "| max sliding [mm] | saturation [%] | wall [s] | note |",
        "|---|---|---|---:|---|---|---:|---:|---|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        head = (
            f"| {r['course']} | {MODE_NAMES.get(r['mode'], r['mode'])} | {_yn(r.get('planned'))} "
            f"| {_f(r.get('planning_time_s'), '.1f')} "
        )
        if r.get("status") != "ok":
            note = (r.get("error") or r.get("message") or r.get("status") or "")[:80]
            note = note.replace("|", "/")
            lines.append(head + "| - " * 10 + f"| {note} |")
            continue
        note = "" if r.get("success") else r.get("message", "")[:60].replace("|", "/")
        lines.append(
            head + f"| {_yn(r.get('reached'))} | {_yn(r.get('fell'))} "
            f"| {_f(r.get('final_error_cm'), '.1f')} | {_f(r.get('com_to_goal_cm'), '.1f')} "
            f"| {_yn(r.get('body_contact'))} | {_f(r.get('leg_contact_s'), '.2f')} "
            f"| {_f(r.get('max_slip_mm'), '.1f')} | {_f(r.get('max_sliding_mm'), '.1f')} "
            f"| {_f(r.get('saturation_pct'), '.1f')} | {_f(r.get('wall_time_s'), '.0f')} "
            f"| {note} |"
        )
    return lines


def _summary_lines(s: dict[str, Any]) -> list[str]:
    lines = []
    for mode, v in s["named"].items():
        lines.append(
            f"- named courses, {MODE_NAMES.get(mode, mode)}: {v['success']} of {v['of']} "
            "reached without a fall"
        )
    g = s["generated"]
    if g["courses"]:
        lines.append(
            f"- generated courses: the planner reached the goal on {g['planned']} of "
            f"{g['courses']}; of those, reached without a fall:"
        )
        for mode, v in g["modes"].items():
            frac = "-" if v["fraction"] is None else f"{100 * v['fraction']:.0f} %"
            lines.append(f"  - {MODE_NAMES.get(mode, mode)}: {v['success']} of {v['of']} ({frac})")
    for family, e in (s.get("families") or {}).items():
        lines.append(_family_line(family, e))
    ladder = s.get("ladder") or {}
    if ladder:
        sizes = [c for e in ladder.values() for c in e["sizes"].values()]
        lines.append(
            f"- feature ladder: {sum(c['planned'] for c in sizes)} of {len(sizes)} sizes planned "
            "(each feature's limits in the table above)"
        )
    return lines


def _family_line(family: str, e: dict[str, Any]) -> str:
    """One summary line of a generated-set family."""
    parts = []
    for mode, m in e["modes"].items():
        text = f"{MODE_NAMES.get(mode, mode)} {m['reached']} reached, {m['fell']} fell"
        if "within_5cm" in m:
            text += f", {m['within_5cm']} within 5 cm"
        parts.append(text + f" (of {m['runs']} runs)")
    errors = f", {e['errors']} with errors" if e.get("errors") else ""
    return (
        f"- {family}: {e['courses']} courses, {e['planned']} planned within the budget"
        f"{errors}; " + "; ".join(parts)
    )


_PLANNER_NAMES = {
    "soft": "Soft local planner (8.2)",
    "recursive": "Recursive local planner (8.5)",
    "hard": "Hard-persuasion local planner (8.1)",
}


def _difficulties(result: dict[str, Any]) -> str:
    """The generated courses' difficulty: the configuration's, and the generated set's."""
    text = f"{result['config']['difficulty']:g}"
    families = list((result.get("summary") or {}).get("families") or {})
    if families:
        text += "; the generated set: " + ", ".join(families)
    return text


def render_markdown(result: dict[str, Any]) -> str:
    """``physics.md``: the setting, a table per course group, the summary."""
    c, m = result["config"], result["machine"]
    lines = [
        "# Physics benchmark (`stratawalk bench physics`)",
        "",
        f"{_PLANNER_NAMES.get(c.get('planner', 'soft'), c.get('planner'))}"
        f"{'' if c.get('preset', 'default') == 'default' else ' (--preset ' + c['preset'] + ')'}"
        " from "
        f"{tuple(c['start'])} to {tuple(c['goal_named'])} m on the "
        f"named courses"
        + own_goals_text(c.get("courses", ()))
        + f", to the end of the course minus 0.4 m on the generated ones "
        f"(`planner/world/course_gen.py`, difficulty {_difficulties(result)}), time budget "
        f"{c['time_budget_s']:g} s; each plan executed in MuJoCo at time scale "
        f"{c['time_scale']:g}: {', '.join(MODE_NAMES.get(x, x) for x in c['modes'])}. "
        f"{c['workers']} jobs at once; {m.get('nproc')} cores ({m.get('cpu') or 'cpu unknown'}), "
        f"load at start {m.get('load_average_1_5_15_at_start')}, commit "
        f"{m.get('git_commit') or '?'}, {m.get('date')}. Total {result['total_time_s']:.0f} s"
        + (" (interrupted: rows marked missing)" if result.get("interrupted") else "")
        + ".",
        "",
        "planned = the plan reached the goal and passes `stratawalk check`; reached = open loop "
        "and correct: the final base within 5 cm of the plan's final base, feedback: the COM "
        "within 5 cm of the goal; slip = a stance foot centre's travel (the sphere rolls), "
        "sliding = its contact point's; saturation = control ticks with a servo at its limit; "
        "wall = simulation wall time.",
        "",
    ]
    groups = {
        "named": "Named courses",
        "generated": "Generated courses",
        "ladder": "Feature ladder",
    }
    for group, title in groups.items():
        rows = [r for r in result["rows"] if r.get("group") == group]
        if rows:
            lines += [f"## {title}", "", *_table(rows), ""]
    set_rows = [r for r in result["rows"] if r.get("group") == GENERATED_SET]
    for family in dict.fromkeys(r.get("family", "generated set") for r in set_rows):
        rows = [r for r in set_rows if r.get("family", "generated set") == family]
        lines += [f"## Generated set: {family}", "", *_table(rows), ""]
    limits = result["summary"].get("ladder")
    if limits:
        lines += [
            "## Limits (feature ladder)",
            "",
            "One feature per course (`feat:KIND:SIZE`, `planner/world/course_gen.py`): each size's "
            "results (yes/no: planned, then each mode reached without a fall) and the largest "
            "size of each.",
            "",
            *_ladder_lines(limits, c["modes"]),
            "",
        ]
    lines += ["## Summary", "", *_summary_lines(result["summary"]), ""]
    return "\n".join(lines)


def write_results(
    jobs: Sequence[dict],
    records: dict[str, dict],
    out_dir: str | Path,
    config: dict[str, Any],
    machine: dict[str, Any],
    total_time_s: float,
    interrupted: bool = False,
) -> dict[str, Any]:
    """Write ``physics.json`` and ``physics.md`` to ``out_dir``; returns the JSON's content."""
    from planner.bench.batch import _clean

    rows = physics_rows(jobs, records)
    result = {
        "format": "stratawalk.bench.physics/1",
        "config": config,
        "machine": machine | {"load_average_1_5_15_at_end": [round(v, 2) for v in os.getloadavg()]},
        "total_time_s": total_time_s,
        "interrupted": interrupted,
        "summary": summarize(rows),
        "rows": rows,
    }
    result = _clean(result)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    text = json.dumps(result, indent=1, allow_nan=False) + "\n"
    write_atomic(out / "physics.json", lambda p: p.write_text(text))
    write_atomic(out / "physics.md", lambda p: p.write_text(render_markdown(result)))
    return result


# ------------------------------------------------------------------------------ running
def _run_pool(jobs: list[dict], workers: int) -> Iterable[dict]:
    """Records of the jobs as they finish, from a pool of fresh (spawned) processes."""
    from planner.bench.batch import run_pool

    return run_pool(run_physics_job, jobs, workers, _failed_record)


def run_jobs(jobs: list[dict], path: Path, workers: int, progress: bool = True) -> bool:
    """Run the jobs not yet finished without error in the JSONL ``path``; True if Ctrl-C.

    Records are appended to ``path`` as they finish (a pool of spawned processes).
    """
    from planner.bench.batch import _Progress, _Writer, read_results

    done = {k: v for k, v in read_results(path).items() if v.get("status") == "ok"}
    todo = [j for j in jobs if job_id(j) not in done]
    writer = _Writer(path, None)
    bar = _Progress(len(todo), len(jobs) - len(todo), enabled=progress)
    try:
        if todo:
            stream = _run_pool(todo, max(1, min(workers, len(todo))))
            try:
                for rec in stream:
                    writer.write(rec)
                    bar.update(rec)
            finally:
                stream.close()
    except KeyboardInterrupt:
        return True
    finally:
        bar.close()
        writer.close()
    return False


def run_physics_bench(
    courses: Sequence[str] = COURSES,
    generated: int = GENERATED,
    difficulty: float = 1.0,
    modes: Sequence[str] = MODES,
    time_budget_s: float = TIME_BUDGET_S,
    time_scale: float = TIME_SCALE,
    out_dir: str | Path = "bench/results",
    workers: int = WORKERS,
    resume: bool = False,
    save_plans: bool = False,
    named_goal_xy: Sequence[float] = GOAL_XY,
    progress: bool = True,
    first_seed: int = 0,
    planned_only: bool = False,
    planner: str = "soft",
    preset: str = "default",
    families: dict[str, str] | None = None,
) -> dict[str, Any]:
    """Run the benchmark's jobs and write ``physics.{jsonl,json,md}`` to ``out_dir``.

    Without ``resume`` an old ``physics.jsonl`` is replaced; with it, jobs finished without
    error are kept and only the others run. Returns the content of ``physics.json``.
    """
    from planner.bench.batch import read_results
    from planner.core.machine import machine_info

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / RESULTS_NAME
    if not resume and path.exists():
        path.unlink()
    plans_dir = (out / "plans").resolve() if save_plans else None
    jobs = physics_jobs(
        courses,
        generated,
        difficulty,
        modes,
        time_budget_s,
        time_scale,
        out,
        named_goal_xy,
        plans_dir=plans_dir,
        first_seed=first_seed,
        planned_only=planned_only,
        planner=planner,
        preset=preset,
        families=families,
    )
    machine = machine_info()
    t0 = time.perf_counter()
    interrupted = run_jobs(jobs, path, workers, progress)
    config = {
        "robot": "littledog",
        "planner": planner,
        "preset": preset,
        "courses": [j["course"] for j in jobs],
        "generated": generated,
        "first_seed": first_seed,
        "planned_only": planned_only,
        "difficulty": difficulty,
        "modes": list(modes),
        "start": list(START_XY),
        "goal_named": list(named_goal_xy),
        "time_budget_s": time_budget_s,
        "time_scale": time_scale,
        "workers": workers,
    }
    return write_results(
        jobs, read_results(path), out, config, machine, time.perf_counter() - t0, interrupted
    )


# ------------------------------------------------------------------------------ command line
def add_physics_parser(bench_sub) -> argparse.ArgumentParser:
    """Add ``bench physics`` to the ``bench`` subcommands."""
    p = bench_sub.add_parser(
        "physics", help="plan each course, execute in MuJoCo: open loop, feedback, correction"
    )
    p.add_argument(
        "--courses",
        default="named",
        help=COURSES_HELP,
    )
    p.add_argument("--generated", type=int, default=GENERATED, help="generated courses")
    p.add_argument("--first-seed", type=int, default=0, help="seed of the first generated course")
    p.add_argument(
        "--planned-only",
        action="store_true",
        help="simulate only plans that reached the goal and pass the check",
    )
    p.add_argument(
        "--difficulty",
        type=float,
        default=1.0,
        help="of the --generated courses, 0..1.5 (above 1: sizes past the maxima)",
    )
    p.add_argument("--modes", default=",".join(MODES), help="open,feedback,correct")
    p.add_argument(
        "--planner", default="soft", choices=["soft", "recursive", "hard"], help="local planner"
    )
    p.add_argument(
        "--preset", default="default", help="settings of every plan: default, or plan --preset's"
    )
    p.add_argument("--time-budget", type=float, default=TIME_BUDGET_S, help="[s] per plan")
    p.add_argument("--time-scale", type=float, default=TIME_SCALE, help="simulated s per plan s")
    p.add_argument("--out", default="bench/results", help="output folder")
    p.add_argument("--workers", type=int, default=WORKERS, help="processes at once")
    p.add_argument("--resume", action="store_true", help="keep finished jobs of physics.jsonl")
    p.add_argument("--save-plans", action="store_true", help="write OUT/plans/COURSE.json")
    p.set_defaults(func=cmd_physics)
    return p


def _names(text: str) -> tuple[str, ...]:
    return tuple(s.strip() for s in text.split(",") if s.strip())


def cmd_physics(args) -> int:
    """Run ``stratawalk bench physics`` and print the markdown tables."""
    from planner.core.outputs import check_folder

    check_folder(args.out, "--out")
    from planner.world.course_gen import course_spec

    courses, families = expand_physics_courses(_names(args.courses))
    modes = _names(args.modes)
    bad = [m for m in modes if m not in MODES]
    if bad:
        raise InputError(f"--modes: unknown '{bad[0]}'; use any of {','.join(MODES)}")
    if not modes:
        raise InputError(f"--modes: give at least one of {','.join(MODES)}, comma-separated")
    if args.generated < 0:
        raise InputError(f"--generated: must be >= 0, got {args.generated}")
    if args.first_seed < 0:
        raise InputError(f"--first-seed: must be >= 0, got {args.first_seed}")
    if not courses and args.generated == 0:
        raise InputError("--courses: give at least one course, or --generated N")
    for name in courses:
        course_spec(name)  # a malformed gen:/feat: name fails here, not in a job
    from planner.world.course_gen import MAX_DIFFICULTY

    if not 0.0 <= args.difficulty <= MAX_DIFFICULTY:
        raise InputError(f"--difficulty: must be in [0, {MAX_DIFFICULTY:g}], got {args.difficulty}")
    if not args.time_budget > 0:
        raise InputError(f"--time-budget: must be > 0 s, got {args.time_budget}")
    if not args.time_scale > 0:
        raise InputError(f"--time-scale: must be > 0, got {args.time_scale}")
    if args.workers < 1:
        raise InputError(f"--workers: must be >= 1, got {args.workers}")
    if args.preset != "default":
        from planner.planning.settings import preset

        preset(args.preset)  # an unknown name fails here, not in every job
    from planner.core.interrupts import Interrupts

    # Ctrl-C / SIGTERM: the running jobs are dropped and their workers stopped (a killed
    # bench left its pool's workers planning on for an hour), the finished ones written
    with Interrupts() as stop:
        result = run_physics_bench(
            courses=courses,
            generated=args.generated,
            difficulty=args.difficulty,
            modes=modes,
            time_budget_s=args.time_budget,
            time_scale=args.time_scale,
            out_dir=args.out,
            workers=args.workers,
            resume=args.resume,
            save_plans=args.save_plans,
            first_seed=args.first_seed,
            planned_only=args.planned_only,
            planner=args.planner,
            preset=args.preset,
            families=families,
        )
    print(render_markdown(result))
    print(f"wrote {Path(args.out) / 'physics.md'} and physics.json, physics.jsonl", file=sys.stderr)
    return stop.exit_code or 0
