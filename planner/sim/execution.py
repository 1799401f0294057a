"""Simulate a plan: open loop, with feedback (paper 8.3) or precompute-then-correct (8.4).

:func:`simulate_plan` runs one of the three modes: open loop
(:func:`planner.sim.simulate.run_open_loop`), feedback from the measured state
(:func:`planner.sim.feedback.run_feedback`, 8.3) and precompute-then-correct
(:func:`planner.sim.correction.run_corrected`, 8.4), their states measured by
:mod:`planner.sim.measure`. The ``stratawalk simulate`` command and its progress bar are
here too; the modes' public names are importable from here.
"""

from __future__ import annotations

import math
import sys
import time as _time
from pathlib import Path
from typing import Any

import numpy as np

from planner.core.errors import InputError
from planner.planfile.plan import Plan
from planner.sim.correction import blend_in, correct_cycle, run_corrected, shift_body
from planner.sim.feedback import MeasuredStates, PlanFollowing, run_feedback
from planner.sim.measure import Measurement, SimulatedMocap, StateSource, measured_state
from planner.sim.simulate import SimResult, SimSettings, reporting_progress, run_open_loop

__all__ = [
    "Measurement",
    "MeasuredStates",
    "PlanFollowing",
    "SimulatedMocap",
    "StateSource",
    "blend_in",
    "correct_cycle",
    "measured_state",
    "run_corrected",
    "run_feedback",
    "shift_body",
    "simulate_plan",
    "cmd_simulate",
]


def simulate_plan(
    plan: Plan | str | Path,
    mode: str = "open",
    settings: SimSettings | None = None,
    **kwargs: Any,
) -> SimResult:
    """Simulate a plan: ``mode`` "open" (open loop), "correct" (8.4) or "feedback" (8.3).

    ``kwargs`` go to :func:`run_corrected` or
    :func:`run_feedback` (noise, latency, ...).
    """
    if not isinstance(plan, Plan):
        plan = Plan.load(plan)
    if mode == "open":
        return run_open_loop(plan, settings)
    if mode == "correct":
        return run_corrected(plan, settings, **kwargs)
    if mode == "feedback":
        return run_feedback(plan, settings, **kwargs)
    raise InputError(f"simulate: unknown mode {mode!r}; use open, correct or feedback")


# ------------------------------------------------------------------------------ command line
def cmd_simulate(args) -> int:
    """Run ``stratawalk simulate``; exit 0 when the run is OK, 1 otherwise.

    Ctrl-C or SIGTERM stop the run: the motion so far is judged and written (``--out``),
    exit 130 / 143 (:mod:`planner.core.interrupts`).
    """
    from planner.core.interrupts import Interrupts
    from planner.core.outputs import check_file
    from planner.planfile.loader import load_plan

    plan = load_plan(args.plan, robot=args.robot)
    if args.out is not None:  # the executed motion: about the plan's size (grid and samples)
        check_file(args.out, "--out", size_b=2 * Path(args.plan).stat().st_size)
    settings = SimSettings(
        time_scale=args.time_scale, timestep_s=args.timestep, feedforward=not args.no_feedforward
    )
    settings.control_dt_s = max(settings.control_dt_s, settings.timestep_s)
    mode = "feedback" if args.feedback else "correct" if args.correct else "open"
    if args.plan_steps_first and mode != "feedback":
        raise InputError("--plan-steps-first: a feedback option; add --feedback")
    kwargs = {}
    if mode != "open":
        kwargs = {
            "position_noise_m": args.noise_mm / 1000.0,
            "angle_noise_rad": math.radians(args.noise_deg),
            "latency_s": args.latency,
            "seed": args.seed,
        }
    if args.plan_steps_first:
        kwargs["plan_steps_first"] = True
    if args.trajectory:
        from planner.planfile.export import load_trajectory, plan_from_trajectory

        if mode != "open":
            raise InputError("--trajectory: executes open loop; drop --feedback/--correct")
        traj = load_trajectory(args.trajectory)
    bar = None if args.quiet else _progress_bar(plan)
    with Interrupts() as stop, reporting_progress(bar):
        if args.trajectory:
            res = run_open_loop(plan_from_trajectory(plan, traj), settings, traj.torque_ff)
        else:
            res = simulate_plan(plan, mode, settings, **kwargs)
        if bar is not None:
            print(file=sys.stderr)
        print(res.metrics.summary())
        if args.out is not None:
            with stop.shielded():
                path = res.executed.save(args.out)
            print(f"wrote {path}: {len(res.executed.samples)} executed samples")
    if stop.exit_code is not None:
        return stop.exit_code
    return 0 if res.metrics.ok else 1


def _progress_bar(plan: Plan):
    """A ``progress(sim)`` that prints a bar of the simulated walk.

    The bar is how far the COM has come towards the plan's goal (the furthest so far:
    monotone), with the simulated time; at most twice a second.
    """
    start, goal = plan.start[:2], plan.goal[:2]
    total = max(float(np.linalg.norm(goal - start)), 1e-9)
    state = {"done": 0.0, "shown": 0.0}

    def progress(sim) -> None:
        now = _time.monotonic()
        if now - state["shown"] < 0.5:
            return
        state["shown"] = now
        dist = float(np.linalg.norm(sim.com_W()[:2] - goal))
        state["done"] = max(state["done"], min(1.0, 1.0 - dist / total))
        bar = "#" * int(30 * state["done"])
        print(f"\r[{bar:<30}] {100 * state['done']:5.1f}%  simulated {sim.time:6.1f} s",
              end="", file=sys.stderr, flush=True)  # fmt: skip

    return progress
