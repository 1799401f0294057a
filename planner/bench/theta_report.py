"""The Theta benchmark's report: ``theta.md`` and the layout of ``theta.json``.

What :func:`planner.bench.theta.run_theta_bench` measured (IPOPT with exact derivatives
against SLSQP with finite differences on the Theta programs of section 7) as markdown
tables, and its result as JSON with each group's per-instance columns on one line.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

__all__ = ["dump_json", "render_markdown"]


def dump_json(result: dict[str, Any]) -> str:
    """Indented JSON, with the per-instance columns one compact line per group."""
    head = {k: v for k, v in result.items() if k != "instances"}
    text = json.dumps(_jsonable(head), indent=1)
    rows = ",\n  ".join(json.dumps(_jsonable(g)) for g in result["instances"])
    return text[:-2] + ',\n "instances": [\n  ' + rows + "\n ]\n}\n"


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def _row_md(r: dict[str, Any]) -> str:
    if not r["instances"]:
        return f"| {r['theta']} | {r['terrain']} | {r['solver']} | 0 | | | | | | |"
    return (
        f"| {r['theta']} | {r['terrain']} | {r['solver']} | {r['instances']} | "
        f"{r['success_rate']:.1%} | {r['converged_rate']:.1%} | {r['time_ms_median']:.2f} | "
        f"{r['time_ms_p95']:.2f} | {r['iterations_median']:.0f} | "
        + (f"{r['speed_ratio']:.0f}x |" if r["solver"].startswith("ipopt") else " |")
    )


def render_markdown(result: dict[str, Any]) -> str:
    """The markdown report of a :func:`run_theta_bench` result."""
    m, c = result["machine"], result["config"]
    head = (
        "| Theta | terrain | solver | instances | success | converged | median [ms] "
        "| p95 [ms] | median iters | speed ratio |\n"
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|"
    )
    lines = [
        f"# Theta benchmark: IPOPT (exact derivatives) vs SLSQP (finite differences), "
        f"{result['robot']}",
        "",
        f"{m['date']}; {m['nproc']} cores ({m['cpu']}); python {m['python']}, casadi "
        f"{m['casadi']}, scipy {m['scipy']}, numpy {m['numpy']}; commit {m['git_commit']}; "
        f"seed {c['seed']}; total run time {result['total_time_s']:.0f} s. Load average (1, 5, "
        f"15 min) at the start {m['load_average_1_5_15_at_start']}, at the end "
        f"{m['load_average_1_5_15_at_end']}: other work on the machine slows both solvers; "
        "they are run interleaved, instance by instance, so that both see the same load.",
        "",
        "## Per Theta (all terrains pooled)",
        "",
        head,
        *[_row_md(r) for r in result["summary"]],
        "",
        "## Per Theta and terrain",
        "",
        head,
        *[_row_md(r) for r in result["groups"]],
        "",
        "- **success**: the independent numpy/Pinocchio check (not the solver's own view) "
        f"finds every constraint violated by at most {c['feasibility_tol']:g}; the same "
        "judge for both solvers.",
        "- **converged**: the solver reported success and its own constraints (the CasADi "
        "g and the bounds) hold to 1e-6. Converged but not successful would mean the NLP "
        "and the independent check disagree (a model mismatch, not a solver failure); "
        "successful but not converged, that the solver stopped with an error status at a "
        "point that happens to be feasible.",
        "- **time**: IPOPT's is the solver call only (`solve_time_s`), SLSQP's the "
        "`scipy.optimize.minimize` call, over all instances (failures included); one "
        "untimed warm-up solve per problem object. Problem build time is separate (below).",
        "- **speed ratio**: median SLSQP time / median IPOPT time on the same instances.",
        "- **ipopt+C** (if present): the same NLPs with their functions compiled to C "
        "(`ThetaOptions.jit`, cached per machine; compile time in the build times).",
        f"- SLSQP: `jac=None` (its own forward differences for every gradient and Jacobian), "
        f"maxiter {c['slsqp_options']['maxiter']}, ftol {c['slsqp_options']['ftol']:g}, same "
        "objective, constraints, bounds, p and x0 as IPOPT."
        + (
            ""
            if c["slsqp_n"] is None
            else f" Run on a seeded subset of {c['slsqp_n']} instances per Theta and terrain."
        ),
        "",
        "Largest independent violation among solutions reported feasible: "
        + ", ".join(
            f"{r['theta']} {r['solver']} {r.get('max_violation_of_feasible', 0.0):.1e}"
            for r in result["summary"]
        )
        + ".",
        "",
        "## Targets (measured, not asserted)",
        "",
        *[f"- {k}: {_target_text(v)}" for k, v in result["targets"].items()],
        "",
        "## Failures by worst constraint group",
        "",
        *(
            [
                f"- {r['theta']} {r['terrain']} {r['solver']}: {r['failure_groups']}"
                for r in result["groups"]
                if r.get("failure_groups")
            ]
            or ["- none"]
        ),
        "",
        "## Problem build times (once per terrain and support/leg, not in the solve times)",
        "",
        "| terrain | Theta | support / leg | build [ms] |\n|---|---|---|---:|",
        *[
            f"| {b['terrain']} | {b['theta']} | {b['key']} | {b['build_time_s'] * 1e3:.1f} |"
            for b in result["build_times_s"]
        ],
        "",
        "Instance generation (Theta4 placements, Theta2 moves for Theta3) [s]: "
        + ", ".join(f"{k} {v:.1f}" for k, v in result["instance_generation_s"].items())
        + ".",
        "",
    ]
    return "\n".join(lines)


def _target_text(v: dict[str, Any]) -> str:
    if "target" in v:
        return f"target {v['target']:g}, measured {v['measured']:.2f}: " + (
            "met" if v["met"] else "NOT met"
        )
    return f"IPOPT {v['ipopt']:.1%} vs SLSQP {v['slsqp']:.1%}: " + (
        "met" if v["met"] else "NOT met"
    )
