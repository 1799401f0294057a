"""Execute a plan on a body with mass: MuJoCo (paper section 10; DESIGN.md section 2, step 6).

The model (:mod:`planner.sim.model`: the plan's URDF and terrain grid, servos, contact)
is driven by a :class:`~planner.sim.simulator.Simulator` and judged by a
:class:`~planner.sim.monitor.Monitor` (:mod:`planner.sim.monitor`: its metrics).

Execution (this module: open loop; :mod:`planner.sim.execution`: feedback 8.3 and
precompute-then-correct 8.4) runs in cycles, one per gait step (from a touchdown to the
next): the joint set-points follow the samples linearly in time, slowed by
``time_scale`` (1: the plan's own timing), each servo given as feed-forward the torque
that holds the planned configuration on its planned feet (``SimSettings.feedforward``),
and the monitor measures what the plan promised: stance feet that do not slip (motion
along a leaf), no body-terrain contact, the base where the plan puts it.
:class:`SimResult` carries the metrics and the executed motion as a ``stratawalk.plan/1``
:class:`~planner.planfile.plan.Plan` (executed ``q``, MuJoCo foot contacts), for a replay
beside the plan.
"""

from __future__ import annotations

import contextlib
import time as _time
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from planner.core import interrupts
from planner.core.errors import InputError
from planner.planfile.plan import Plan, Samples, loaded_feet
from planner.sim.model import (
    MUJOCO_VERSION,
    SimSettings,
    TerrainModel,
    build_mjcf,
    terrain_model,
)
from planner.sim.monitor import Metrics, Monitor
from planner.sim.simulator import Simulator, Touches

__all__ = [
    "MUJOCO_VERSION",
    "Execution",
    "Metrics",
    "Monitor",
    "SimResult",
    "SimSettings",
    "Simulator",
    "TerrainModel",
    "Touches",
    "build_mjcf",
    "cycle_starts",
    "loaded_feet",
    "executed_plan",
    "finish_run",
    "new_run",
    "run_open_loop",
    "terrain_model",
]

_Array = NDArray[np.float64]


# ------------------------------------------------------------------------------ execution
_progress: ContextVar[Callable[[Simulator], None] | None] = ContextVar(
    "stratawalk_simulation_progress", default=None
)


@contextlib.contextmanager
def reporting_progress(callback: Callable[[Simulator], None] | None) -> Iterator[None]:
    """Runs started in the block call ``callback(simulator)`` every 50 control ticks."""
    token = _progress.set(callback)
    try:
        yield
    finally:
        _progress.reset(token)


class Execution:
    """Drive a :class:`Simulator` through reference segments with a :class:`Monitor`.

    Segments are given in plan time; each starts at the scheduled end of the previous one
    and lasts ``time_scale`` times its plan duration.
    """

    def __init__(self, sim: Simulator, monitor: Monitor):
        self.sim = sim
        self.monitor = monitor
        self.clock = sim.time
        self._last_contact: NDArray[np.bool_] | None = None
        self.interrupted = False  # Ctrl-C or SIGTERM stopped the run (planner.core.interrupts)
        self.progress = _progress.get()  # called with the simulator now and then

    def interrupt(self) -> None:
        """Stop here (Ctrl-C or SIGTERM): the motion so far is kept and judged."""
        self.interrupted = True
        self.monitor.metrics.message = (
            f"interrupted at {self.sim.time:.1f} s of simulated time; the motion so far is kept"
        )

    @property
    def stopped(self) -> bool:
        """A fall ends the run (when ``stop_on_fall``)."""
        return self.monitor.metrics.fell and self.sim.settings.stop_on_fall

    def follow(self, times: Any, q: Any, contact: Any, torque_ff: Any = None) -> bool:
        """Track samples (plan times (N,), Pinocchio q (N, 19), contact (N, 4)); False on a fall.

        ``torque_ff`` (N, 12): the servos' feed-forward torques (computed when None).
        """
        times = np.asarray(times, float)
        if len(times) == 0:
            return not self.stopped
        t_sim = self.clock + self.sim.settings.time_scale * (times - times[0])
        q, contact = np.asarray(q, float), np.asarray(contact, bool)
        loaded = loaded_feet(contact, self._last_contact)
        self._last_contact = contact[-1].copy()
        if torque_ff is None or not self.sim.settings.feedforward:
            torque_ff = self.sim.holding_torques_nm(q, loaded)
        self.monitor.extend(t_sim, q, contact, np.asarray(torque_ff, float))
        end = float(t_sim[-1])
        return self._run_until(end)

    def hold(self, duration_s: float) -> bool:
        """Keep the last set-points for ``duration_s`` of simulated time."""
        return self._run_until(self.clock + duration_s)

    def _run_until(self, end: float) -> bool:
        sim, mon = self.sim, self.monitor
        half = 0.5 * sim.settings.control_dt_s
        ticks = 0
        while sim.time < end - half and not self.stopped:
            joints, _, _, _ = mon.reference_at(sim.time + half)
            sim.set_targets(joints, mon.feedforward_at(sim.time + half))
            sim.tick()
            mon.update()
            ticks += 1
            if ticks % 50 == 0:
                interrupts.check()  # Ctrl-C / SIGTERM: stop here (planner.core.interrupts)
                if self.progress is not None:
                    self.progress(sim)
        self.clock = max(self.clock, end)
        return not self.stopped


def cycle_starts(contact: NDArray[np.bool_]) -> list[int]:
    """Sample indices where a cycle (gait step) begins: 0 and every touchdown onto S0."""
    allc = np.asarray(contact, bool).all(axis=1)
    out = [0]
    out += [k for k in range(1, len(allc)) if allc[k] and not allc[k - 1]]
    return out


@dataclass
class SimResult:
    """A run: its metrics and the executed motion as a plan (stats hold metrics and settings)."""

    metrics: Metrics
    executed: Plan
    settings: SimSettings = field(repr=False)


def new_run(plan: Plan, settings: SimSettings | None, mode: str) -> tuple[Simulator, Execution]:
    """A simulator for the plan, settled at its first configuration, and an execution."""
    settings = (settings or SimSettings()).check()
    if len(plan.samples) < 2:
        raise InputError(f"{plan.source}: samples: need at least 2 samples to execute a plan")
    robot = plan.load_robot()
    try:
        terrain = plan.load_terrain()
    except InputError:
        terrain = None  # the grid is enough; edges are then placed to half a cell
    sim = Simulator(robot, plan.terrain_grid, plan.friction, terrain, settings)
    sim.settle(plan.samples.q[0], settings.settle_s)
    monitor = Monitor(sim, mode)
    return sim, Execution(sim, monitor)


def finish_run(
    plan: Plan, ex: Execution, wall0: float, t0: float, extra: dict | None = None
) -> SimResult:
    """Hold the last set-point, close the metrics, build the executed plan."""
    from planner.core.interrupts import shielded

    sim, mon = ex.sim, ex.monitor
    with shielded():  # a second Ctrl-C does not lose the run
        if not mon.t:  # nothing executed (every step failed): the settled start is held
            ex.follow(plan.samples.time[:1], plan.samples.q[:1], plan.samples.contact[:1])
        if not ex.stopped and not ex.interrupted:
            ex.hold(sim.settings.hold_s)
        mon.finish(plan, _time.perf_counter() - wall0, t0)
        m = mon.metrics
        if not m.message:
            m.message = _verdict(m)
        executed = executed_plan(plan, mon, sim.settings, extra)
    return SimResult(m, executed, sim.settings)


def _verdict(m: Metrics) -> str:
    parts = []
    if m.fell:
        parts.append(f"fell at {m.fall_time_s:.1f} s ({m.fall_reason})")
    if m.tipped:
        parts.append(f"tipped {m.max_tilt_error_deg:.0f} deg off the plan")
    if m.slipped:
        parts.append(f"{m.max_sliding_leg} slid {1000 * m.max_sliding_m:.0f} mm")
    if m.body_contact and not m.fell:
        parts.append("body touched the terrain")
    if not parts:
        parts.append("executed as planned" if m.reached else "did not reach the plan's end")
    return "; ".join(parts)


def executed_plan(plan: Plan, mon: Monitor, settings: SimSettings, extra: dict | None) -> Plan:
    """The executed motion in the plan format (same robot, terrain, grid, goal)."""
    m = mon.metrics
    t = np.array(mon.rec_t) - mon.rec_t[0]
    q = np.array(mon.rec_q)
    q[:, 3:7] /= np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)
    stats = {
        "simulation": m.to_dict(),
        "settings": asdict(settings),
        "source_plan": plan.source,
        "mujoco": MUJOCO_VERSION,
        "note": "executed motion: samples are measured (MuJoCo), keyframes are the measured "
        "configurations at each cycle start with measured contact forces; times are "
        "simulated seconds (plan time x time_scale)",
    }
    stats.update(extra or {})
    return Plan(
        robot=dict(plan.robot),
        terrain=dict(plan.terrain),
        terrain_grid=plan.terrain_grid,
        friction=plan.friction,
        start=plan.start.copy(),
        goal=plan.goal.copy(),
        keyframes=list(mon.keyframes),
        samples=Samples(t, q, np.array(mon.rec_c, bool).reshape(-1, 4)),
        outcome={
            "reached_goal": bool(m.ok and plan.outcome.get("reached_goal", False)),
            "distance_to_goal": float(m.com_to_goal_m),
            "message": f"simulated ({m.mode}): {m.message}",
        },
        stats=stats,
        source=f"{plan.source} (simulated)",
    )


def run_open_loop(
    plan: Plan, settings: SimSettings | None = None, torque_ff: _Array | None = None
) -> SimResult:
    """Execute ``plan`` open loop: joint set-points from the samples, slowed by time_scale.

    ``torque_ff`` (N, 12): feed-forward torques at the samples (e.g. an exported
    trajectory's); computed from the plan when None.
    """
    wall0 = _time.perf_counter()
    sim, ex = new_run(plan, settings, "open loop")
    t0 = sim.time
    s = plan.samples
    starts = sorted(set(cycle_starts(s.contact)) | {len(s) - 1})
    try:
        for a, b in zip(starts[:-1], starts[1:], strict=True):
            ex.monitor.keyframe(0)
            ex.monitor.metrics.cycles += 1
            ff = None if torque_ff is None else torque_ff[a : b + 1]
            if not ex.follow(s.time[a : b + 1], s.q[a : b + 1], s.contact[a : b + 1], ff):
                break
    except KeyboardInterrupt:
        ex.interrupt()
    return finish_run(plan, ex, wall0, t0)
