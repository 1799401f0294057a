"""Planning speed: time per course and per metre, where it goes, how it grows.

``stratawalk bench speed`` plans each course ``repeats`` times, each in a new process as
``stratawalk plan`` would (soft persuasion, 8.2, the default settings), and reports the
median wall time of planning (the local planner: Theta solves, IK, statics, terrain
queries) and of everything ``stratawalk plan`` does (planning, assembly of the samples
and ``check``), with the walk's time and speed from the plan; the first plan of each
course is executed in MuJoCo at its own timing, open loop and with feedback (8.3). One
more run under :mod:`cProfile` splits that time by where it is spent: each function's
*own* time goes to the group of its module (:data:`GROUPS`); a function outside the
package (numpy, CasADi, Pinocchio, builtins) counts for the group of its heaviest caller,
so the parts add up to the profiled total. Each course is measured with every preset of
``presets`` side by side ("default": the settings' defaults; "fast": ``stratawalk plan
--preset fast``, :data:`planner.planning.settings.PRESETS`). Flat walks of 1, 2, 4 and 8 m
(``FLAT_LENGTHS_M``, the first preset) show how the cost grows with the length of the walk. Writes
``speed.json`` and ``speed.md``. Timings are measurements of this machine, never asserted
in tests.
"""

from __future__ import annotations

import cProfile
import json
import pstats
import statistics
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from planner.core.errors import InputError

__all__ = [
    "COURSES",
    "FLAT_LENGTHS_M",
    "GROUPS",
    "add_speed_parser",
    "profile_groups",
    "render_markdown",
    "run_speed_bench",
]

# (terrain, goal x [m]) from (0.2, 0): level, rough, a step and stairs, walks of 2 m
COURSES = ("rough2cm", "flat", "step5cm", "stairs")
PRESETS = ("default", "fast")  # the settings compared side by side
# a preset name ending so is planned without the overlap worker (planner.planning.prefetch):
# "default-serial" beside "default" measures the worker (runs one after the other, so
# that each has the machine's two cores)
SERIAL = "-serial"
FLAT_LENGTHS_M = (1.0, 2.0, 4.0, 8.0)
START_XY = (0.2, 0.0)
# where the time goes: the first group whose any path fragment is in a module's file name
GROUPS = (
    ("theta", "Theta solves (problems/, CasADi, IPOPT)", ("/planner/problems/", "/casadi/")),
    ("ik", "IK and FK (Paden-Kahan, Pinocchio)", ("/planner/body/kinematics.py",
                                                  "/planner/body/paden_kahan.py", "pinocchio")),
    ("statics", "statics and torques", ("/planner/body/statics.py", "/planner/body/torques.py",
                                         "/planner/body/stability.py")),
    ("terrain", "terrain queries", ("/planner/world/terrain", "/planner/world/heightfield.py")),
    ("links", "leg links and rolling feet", ("/planner/body/links.py", "/planner/body/rolling.py")),
    ("check", "check (validate)", ("/planner/planfile/validate",)),
    ("other", "other", ()),
)  # fmt: skip


def _group_of_file(filename: str) -> str | None:
    for key, _, parts in GROUPS:
        if any(p in filename for p in parts):
            return key
    return "other" if "/planner/" in filename else None


def profile_groups(stats: pstats.Stats) -> dict[str, float]:
    """Own time [s] per group of :data:`GROUPS` from a profile; the values sum to its total.

    A function outside the package counts for the group of its heaviest caller (by
    cumulative time along that call edge), followed up to 20 levels; else "other".
    """
    raw = stats.stats  # {func: (cc, nc, tt, ct, callers{func: (cc, nc, tt, ct)})}
    memo: dict[Any, str] = {}

    def group(func, depth: int = 0) -> str:
        if func in memo:
            return memo[func]
        own = _group_of_file(func[0])
        if own is None:
            callers = raw.get(func, (0, 0, 0.0, 0.0, {}))[4]
            if depth >= 20 or not callers:
                own = "other"
            else:
                heaviest = max(callers, key=lambda c: callers[c][3])
                own = group(heaviest, depth + 1)
        memo[func] = own
        return own

    out = {key: 0.0 for key, _, _ in GROUPS}
    for func, (_, _, tt, _, _) in raw.items():
        out[group(func)] += tt
    return out


def _flat(length_m: float):
    """A flat course long enough for a walk of ``length_m`` from x = 0.2 m."""
    from planner.world.terrain import Terrain

    spec = {
        "name": f"flat{length_m:g}m",
        "description": f"Level ground for a {length_m:g} m walk (bench speed).",
        "friction": 0.7,
        "x_min": -0.5,
        "length": round(length_m + 1.5, 6),
        "y_min": -0.6,
        "y_max": 0.6,
        "kind": "flat",
    }
    return Terrain.from_spec(spec, source="bench speed")


def _plan_once(
    terrain_name: str,
    length_m: float | None,
    goal_x: float,
    profile: bool,
    sim: bool = False,
    preset: str = "default",
):
    """One plan in this process: its figures, wall time and (``profile``) time per group.

    ``sim``: the plan is then executed in MuJoCo at time scale 1, open loop and with
    feedback (8.3), each summarised by :func:`_sim_summary`. ``preset``: the settings.
    """
    from planner.planning.walk import plan_walk
    from planner.world.terrain import load_terrain

    terrain = _flat(length_m) if length_m is not None else load_terrain(terrain_name)
    from planner.planning.settings import preset_settings

    base, serial = _preset_and_mode(preset)
    settings = preset_settings(base)
    if serial:  # the overlaps timed in the planning process (no worker, 1.5x on rough2cm)
        settings = replace(settings, overlap_worker=False)
    prof = cProfile.Profile() if profile else None
    t0 = time.perf_counter()
    if prof is not None:
        prof.enable()
    plan, report = plan_walk(
        "littledog", terrain, goal_xy=(goal_x, 0.0), start_xy=START_XY, settings=settings
    )
    if prof is not None:
        prof.disable()
    wall = time.perf_counter() - t0
    s = plan.samples
    mujoco = _simulate(plan) if sim and plan.outcome.get("reached_goal") and report.ok else None
    return {
        "mujoco": mujoco,
        "reached": bool(plan.outcome.get("reached_goal")),
        "check_ok": bool(report.ok),
        "steps": int(plan.stats.get("steps", 0)),
        "planning_s": float(plan.stats.get("planning_time_s", wall)),
        "worker_steps": int(plan.stats.get("overlap_worker_steps", 0)),
        "wall_s": wall,
        "walk_s": float(s.time[-1] - s.time[0]) if len(s) else 0.0,
        "groups": profile_groups(pstats.Stats(prof)) if prof is not None else None,
    }


def _preset_and_mode(preset: str) -> tuple[str, bool]:
    """("fast", True) of "fast-serial": a preset planned without the overlap worker."""
    if preset.endswith(SERIAL):
        return preset[: -len(SERIAL)], True
    return preset, False


def _simulate(plan) -> dict[str, dict]:
    """The plan in MuJoCo at its own timing: open loop and feedback (8.3)."""
    from planner.sim.execution import run_feedback
    from planner.sim.simulate import SimSettings, run_open_loop

    settings = SimSettings(time_scale=1.0)
    return {
        "open": _sim_summary(run_open_loop(plan, settings).metrics),
        "feedback": _sim_summary(run_feedback(plan, settings).metrics),
    }


def _sim_summary(m) -> dict:
    """reached, fell, the final error and the COM's distance to the goal [cm] of a run."""
    return {
        "reached": bool(m.reached),
        "fell": bool(m.fell),
        "final_error_cm": 100.0 * float(m.final_error_m),
        "com_to_goal_cm": 100.0 * float(m.com_to_goal_m),
    }


def _fresh(*args):
    """:func:`_plan_once` in a new process.

    Each run pays what ``stratawalk plan`` pays (building the Theta problems); none
    inherits another's caches.
    """
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as pool:
        return pool.submit(_plan_once, *args).result()


def _measure(
    name: str,
    length_m: float | None,
    goal_x: float,
    repeats: int,
    profile: bool,
    preset: str = "default",
):
    runs = [
        _fresh(name, length_m, goal_x, False, profile and i == 0, preset) for i in range(repeats)
    ]
    planning = [r["planning_s"] for r in runs]
    metres = goal_x - START_XY[0]
    last = runs[-1]
    row: dict[str, Any] = {
        "course": name,
        "preset": preset,
        "walk_m": metres,
        "repeats": repeats,
        "reached": all(r["reached"] for r in runs),
        "check_ok": all(r["check_ok"] for r in runs),
        "steps": last["steps"],
        "worker_steps": last["worker_steps"],  # steps whose overlap the worker searched
        "planning_s": planning,
        "planning_median_s": statistics.median(planning),
        "planning_per_m_s": statistics.median(planning) / metres,
        "total_median_s": statistics.median(r["wall_s"] for r in runs),
        "walk_s": last["walk_s"],
        "walk_speed_cm_s": 100.0 * metres / last["walk_s"] if last["walk_s"] > 0 else None,
        "mujoco": runs[0]["mujoco"],
    }
    row["planning_to_walk"] = row["planning_median_s"] / last["walk_s"] if last["walk_s"] else None
    if profile:
        groups = _fresh(name, length_m, goal_x, True, False, preset)["groups"]
        row["profile_total_s"] = sum(groups.values())
        row["breakdown_s"] = groups
    return row


def cli_start_s(repeats: int = 5, args=("--help",)) -> list[float]:
    """Wall times [s] of ``stratawalk --help`` (``args``), each in a new interpreter.

    What a user waits for before any work: Python and the command line's imports (the
    parser imports no CasADi, Pinocchio, MuJoCo or SciPy).
    """
    import subprocess
    import sys

    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "planner.cli.main", *args], check=True,
                       stdout=subprocess.DEVNULL)  # fmt: skip
        times.append(time.perf_counter() - t0)
    return times


def run_speed_bench(
    courses=COURSES,
    goal_x: float = 2.2,
    flat_lengths_m=FLAT_LENGTHS_M,
    repeats: int = 5,
    out_dir: str | Path = "bench/results",
    presets=PRESETS,
) -> dict[str, Any]:
    """Measure, write ``speed.json`` and ``speed.md`` to ``out_dir``; returns the JSON's content."""
    from planner.core.machine import machine_info
    from planner.core.outputs import write_atomic

    machine = machine_info()
    t0 = time.perf_counter()
    cli = cli_start_s(repeats)
    rows = [_measure(c, None, goal_x, repeats, True, p) for c in courses for p in presets]
    flats = [
        _measure(f"flat {m:g} m", m, START_XY[0] + m, repeats, False, presets[0])
        for m in flat_lengths_m
    ]
    result = {
        "format": "stratawalk.bench.speed/1",
        "config": {"courses": list(courses), "goal_x": goal_x, "repeats": repeats,
                   "flat_lengths_m": list(flat_lengths_m), "start": list(START_XY),
                   "presets": list(presets)},
        "machine": machine,
        "total_time_s": time.perf_counter() - t0,
        "cli_start_s": cli,
        "courses": rows,
        "flat": flats,
    }  # fmt: skip
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "speed.json", lambda p: p.write_text(json.dumps(result, indent=1)))
    md = render_markdown(result)
    write_atomic(out / "speed.md", lambda p: p.write_text(md))
    return result


def _f(v, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


def render_markdown(result: dict[str, Any]) -> str:
    """``speed.md``: per course, the times and where they go; the flat walks by length."""
    c, m = result["config"], result["machine"]
    keys = [k for k, _, _ in GROUPS]
    lines = [
        "# Planning speed (`stratawalk bench speed`)",
        "",
        f"Soft persuasion (8.2), LittleDog, from {tuple(c['start'])} to x = {c['goal_x']:g} m; "
        f"median of {c['repeats']} runs each; {m.get('nproc')} cores ({m.get('cpu') or '?'}), "
        f"load at start {m.get('load_average_1_5_15_at_start')}, commit "
        f"{m.get('git_commit') or '?'}, {m.get('date')}. Total {result['total_time_s']:.0f} s.",
        "",
        "planning = the local planner; total = all that `stratawalk plan` does (planning, "
        "assembly, `check`); walk = the plan's duration. Where the time goes: one more run "
        "under cProfile, own time per group of modules (a library function counts for its "
        "heaviest caller's group), in % of the profiled total (profiling slows it down; "
        "the planning process only: the swing overlaps searched by the overlap worker, "
        "planner.planning.prefetch, are not in it, but they are in a `-serial` preset's).",
        "",
        "Presets: default = the settings' defaults (the paper's Lambda_c, 0.5 m/s^2); fast = "
        "`stratawalk plan --preset fast` (two body moves per crawl cycle, long strides on "
        "level ground, 1.5 m/s^2, 2 cm swing height); NAME-serial = that preset without the "
        "overlap worker (each step's swing overlap searched in the planning process itself).",
        "",
    ]
    if result.get("cli_start_s"):
        lines += [
            f"`stratawalk --help` (the command line's start, a new interpreter each): median "
            f"{statistics.median(result['cli_start_s']):.2f} s of {len(result['cli_start_s'])}.",
            "",
        ]
    lines += [
        "| course | preset | reached, check | steps | planning [s] | per m [s] | total [s] "
        "| walk [s] "
        "| walk speed [cm/s] | planning / walk | "
        + " | ".join(f"{lbl} [%]" for _, lbl, _ in GROUPS)
        + " |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|" + "---:|" * len(keys),
    ]
    for r in result["courses"]:
        total = r.get("profile_total_s") or 0.0
        parts = [_f(100.0 * r["breakdown_s"][k] / total if total else None, ".0f") for k in keys]
        lines.append(
            f"| {r['course']} | {r.get('preset', 'default')} | {'yes' if r['reached'] else 'no'}, "
            f"{'ok' if r['check_ok'] else 'NOT ok'} | {r['steps']} "
            f"| {r['planning_median_s']:.2f} | {r['planning_per_m_s']:.2f} "
            f"| {r['total_median_s']:.2f} | {r['walk_s']:.1f} | {_f(r['walk_speed_cm_s'], '.2f')} "
            f"| {_f(r['planning_to_walk'], '.3f')} | " + " | ".join(parts) + " |"
        )
    lines += [
        "",
        "## The plans in MuJoCo",
        "",
        "The first plan of each course executed at its own timing (time scale 1): reached = "
        "open loop, the final base within 5 cm of the plan's; feedback (8.3), the COM within "
        "5 cm of the goal.",
        "",
        "| course | preset | walk speed [cm/s] | open loop | final error [cm] | feedback "
        "| COM to goal [cm] |",
        "|---|---|---:|---|---:|---|---:|",
    ]
    for r in result["courses"]:
        mj = r.get("mujoco") or {}
        op, fb = mj.get("open"), mj.get("feedback")
        lines.append(
            f"| {r['course']} | {r.get('preset', 'default')} "
            f"| {_f(r['walk_speed_cm_s'], '.2f')} | {_verdict(op)} "
            f"| {_f(op and op['final_error_cm'], '.1f')} | {_verdict(fb)} "
            f"| {_f(fb and fb['com_to_goal_cm'], '.1f')} |"
        )
    lines += [
        "",
        "## Flat walks by length",
        "",
        f"Preset {c.get('presets', ['default'])[0]}.",
        "",
        "| walk [m] | reached, check | steps | planning [s] | per m [s] | total [s] "
        "| x the 2 m walk |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    flats = result["flat"]
    two = next((f["planning_median_s"] for f in flats if abs(f["walk_m"] - 2.0) < 1e-9), None)
    for f in flats:
        ratio = f["planning_median_s"] / two if two else None
        lines.append(
            f"| {f['walk_m']:g} | {'yes' if f['reached'] else 'no'}, "
            f"{'ok' if f['check_ok'] else 'NOT ok'} | {f['steps']} "
            f"| {f['planning_median_s']:.2f} | {f['planning_per_m_s']:.2f} "
            f"| {f['total_median_s']:.2f} | {_f(ratio, '.2f')} |"
        )
    return "\n".join(lines) + "\n"


def _verdict(run: dict | None) -> str:
    if run is None:
        return "-"
    if run["fell"]:
        return "fell"
    return "reached" if run["reached"] else "not reached"


def add_speed_parser(subparsers) -> Any:
    """Add ``bench speed [--courses C,C] [--repeats N] [--flat-lengths L,L] [--out DIR]``."""
    p = subparsers.add_parser("speed", help="planning time per course, where it goes, by length")
    p.add_argument("--courses", default=",".join(COURSES), help="comma-separated terrains")
    p.add_argument("--goal-x", type=float, default=2.2, help="[m] the walks' goal x")
    p.add_argument("--repeats", type=int, default=5, help="runs per course (median)")
    p.add_argument(
        "--flat-lengths",
        default=",".join(f"{v:g}" for v in FLAT_LENGTHS_M),
        help="[m] flat walks, comma-separated",
    )
    p.add_argument(
        "--presets",
        default=",".join(PRESETS),
        help="settings compared side by side: default and/or presets of plan --preset; "
        f"NAME{SERIAL}: that preset without the overlap worker",
    )
    p.add_argument("--out", default="bench/results", help="output folder")
    p.set_defaults(func=cmd_speed)
    return p


def cmd_speed(args) -> int:
    """Run ``stratawalk bench speed`` and print the markdown."""
    from planner.core.outputs import check_folder

    check_folder(args.out, "--out")
    if args.repeats < 1:
        raise InputError(f"--repeats: must be >= 1, got {args.repeats}")
    try:
        lengths = tuple(float(v) for v in args.flat_lengths.split(",") if v.strip())
    except ValueError:
        raise InputError(
            f"--flat-lengths: expected metres, comma-separated, got {args.flat_lengths!r}"
        ) from None
    if any(not 0.1 <= v <= 50.0 for v in lengths):
        raise InputError(f"--flat-lengths: each in [0.1, 50] m, got {args.flat_lengths!r}")
    courses = tuple(s.strip() for s in args.courses.split(",") if s.strip())
    presets = tuple(s.strip() for s in args.presets.split(",") if s.strip())
    from planner.planning.settings import PRESETS as KNOWN
    from planner.world.terrain import load_terrain

    for p in presets:
        name = _preset_and_mode(p)[0]
        if name != "default" and name not in KNOWN:
            raise InputError(
                f"--presets: unknown {p!r}; known: default, {', '.join(KNOWN)} (each also "
                f"as NAME{SERIAL}: without the overlap worker)"
            )
    if not presets:
        raise InputError("--presets: name at least one (default, fast)")

    for c in courses:
        load_terrain(c)  # a bad name fails here, before any planning
    result = run_speed_bench(courses, args.goal_x, lengths, args.repeats, args.out, presets)
    print(render_markdown(result))
    print(f"wrote {Path(args.out) / 'speed.md'} and speed.json")
    return 0
