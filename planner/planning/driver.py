"""The gait-queue driver: one loop of cycles for planning (8.2, 8.5) and feedback (8.3).

A *cycle* (figure 6) takes the next leg from the gait queue, makes a step of it from the
current state, pushes the leg to the back when it stepped and swaps it with the next one
when it failed (comment ii of 8.2), a failed placement halving the leg's stride.
:class:`GaitDriver` runs cycles until a stop rule (:class:`StopRules`) ends the run; the
rules and the counters they read (cycles, failures in a row, the nearest the COM came to
the goal and when) live here once.

Where the state comes from is a *source* (:class:`Source`): when planning, the walk's
last state (:class:`PlannedStates`); when executing with feedback (8.3), the robot as
measured (:class:`planner.sim.feedback.MeasuredStates`). What a cycle does besides the
queue is a set of hooks (:class:`QueueCycle`): the soft planner traces back at dead ends
(:mod:`planner.planning.soft`), feedback follows the precomputed plan's steps, corrects
them (8.4) and executes them (:mod:`planner.sim.execution`). The recursive planner (8.5)
drives windows of steps instead of single cycles (:meth:`GaitDriver.drive` takes any
cycle). :func:`plan_run` is a planner's whole run: the walk (:class:`Walk`), its cycles,
its outcome (:class:`LocalPlan`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from planner.body.state import State
from planner.core import interrupts
from planner.core.legs import LEG_NAMES
from planner.motion.gait_queue import GaitQueue
from planner.planning.step import Step

if TYPE_CHECKING:
    from collections.abc import Callable

    from planner.motion.trajectory import Trajectory

__all__ = [
    "ARRIVAL_M",
    "PROGRESS_M",
    "GaitDriver",
    "LocalPlan",
    "NearestWalk",
    "PlannedStates",
    "QueueCycle",
    "Run",
    "Source",
    "StopRules",
    "Walk",
    "plan_run",
]

PROGRESS_M = 0.01  # the COM coming this much nearer the goal counts as progress
ARRIVAL_M = 0.01  # a walk ending within goal_tol_m but farther than this tries the arrival


@dataclass
class LocalPlan:
    """What a local planner produced: key configurations, dense samples, outcome."""

    keyframes: list[State]
    samples: list[State]
    times: list[float]
    reached_goal: bool
    distance_to_goal_m: float
    message: str
    stats: dict
    interrupted: bool = False  # stopped by Ctrl-C or SIGTERM (the walk so far is kept)


@dataclass
class Run:
    """The fixed inputs and the counters of one run of the driver."""

    goal: np.ndarray
    tau: Trajectory
    t_begin: float
    progress: object = None  # progress(distance_m, steps) after each step (planning)
    cycles: int = 0
    fails_in_row: int = 0  # failed cycles since the last step made
    last_failure: str = ""
    halted: bool = False  # the source halted the run (an interrupt, a fall)
    best_dist_m: float = float("inf")  # nearest the COM came to the goal ...
    best_at: int = 0  # ... and in which cycle
    longest_stall: int = 0  # most cycles between two such approaches (the stop's patience)
    arrival_tried: object = -1  # the state (Source.stamp) of the last arrival attempt
    arrivals: int = 0  # arrival moves made

    @property
    def longest_stall_cycles(self) -> int:
        """Most cycles without progress so far, the open stretch since ``best_at`` included."""
        return max(self.longest_stall, self.cycles - self.best_at)

    def restart_stall(self) -> None:
        """A stretch without progress begins now (the one ending is kept in the longest)."""
        self.longest_stall = self.longest_stall_cycles
        self.best_at = self.cycles


class Walk:
    """Keyframes and timed dense samples of a walk being planned; can be rewound.

    The steps are kept as recorded; their samples and times, which need each step's swing
    overlap (:meth:`planner.planning.timing.Timing.step_samples`), are put together when
    first asked for, the overlaps searched meanwhile by ``worker`` where there is one
    (:class:`planner.planning.prefetch.OverlapWorker`).
    """

    def __init__(self, planner, state: State, worker=None):
        self.planner = planner
        self.start = state
        self.parts: list[Step] = []  # the recorded steps (placements, failed ones, arrivals)
        self.steps = 0
        self.worker = worker
        self._timed: tuple | None = None  # (keyframes, samples, times) of ``parts``

    @property
    def state(self) -> State:
        """The current configuration (the last keyframe)."""
        if not self.parts:
            return self.start
        last = self.parts[-1]
        return last.end if last.ok else last.moved

    @property
    def n_keyframes(self) -> int:
        """How many keyframes the walk has (without timing it)."""
        return 1 + sum(3 if s.ok else 1 for s in self.parts)

    def add(self, step: Step) -> None:
        """Record a step: its body move (also of a failed placement) and its swing."""
        if step.moved is None:
            return
        self.parts.append(step)
        self.steps += int(step.ok)
        self._timed = None
        if self.worker is not None:
            self.worker.submit(step)

    def add_body_move(self, end: State, path: list[State]) -> None:
        """Record a body move on the current feet (no swing), e.g. the arrival."""
        self.add(Step(-1, False, self.state, end, None, path, [], "arrival"))

    @property
    def keyframes(self) -> list[State]:
        """Start; per step its body move's end (a placement: its mid-swing, its landing)."""
        return self._time()[0]

    @property
    def samples(self) -> list[State]:
        """The walk's dense samples (the executor's)."""
        return self._time()[1]

    @property
    def times(self) -> list[float]:
        """The samples' times [s] from the walk's start."""
        return self._time()[2]

    def _time(self) -> tuple:
        """(keyframes, samples, times) of the recorded steps, in the executor's timing."""
        if self._timed is not None:
            return self._timed
        p, w = self.planner, self.worker
        if w is not None:
            w.finish(self.parts)
        keyframes, samples, times = [self.start], [self.start], [0.0]
        for step in self.parts:
            if w is not None:
                w.wait_for(step)
            states, t = p.step_samples(step)
            t = times[-1] + t
            n_body = max(len(step.body_path) - 1, 0)
            if step.overlap is not None:  # the leg lifts at this body sample (local.overlap)
                n_body = step.overlap.lift
            p._append(samples, times, states[: 1 + n_body], t[1 : 1 + n_body])
            keyframes.append(step.moved)
            if step.ok:
                p._append(samples, times, states[n_body:], t[1 + n_body :])
                swing = step.swing_path if step.overlap is None else states[n_body:]
                keyframes += [p._swing_keyframe(swing, step.leg, p.check), step.end]
        self._timed = (keyframes, samples, times)
        return self._timed

    def mark(self) -> tuple[int, int]:
        """A bookmark for :meth:`rewind`."""
        return len(self.parts), self.steps

    def rewind(self, mark: tuple[int, int]) -> None:
        """Forget everything recorded after ``mark`` (backtracking, section 8.5)."""
        k, n = mark
        if self.worker is not None:
            self.worker.forget(self.parts[k:])
        del self.parts[k:]
        self.steps = n
        self._timed = None

    def copy(self) -> tuple:
        """The walk so far, for :meth:`restore` after a rewind (states are not copied)."""
        return list(self.parts), self.steps

    def restore(self, kept: tuple) -> None:
        """Back to a walk kept by :meth:`copy`."""
        parts, self.steps = kept
        self.parts = list(parts)
        self._timed = None


class NearestWalk:
    """The walk that came nearest the goal before a planner traced back across it.

    Tracing back (8.5; soft's retraces) forgets steps; a planner that then stops short of
    where it had been returns this walk instead (nothing computed is lost).
    """

    def __init__(self) -> None:
        self.kept: tuple | None = None
        self.dist_m = np.inf

    def offer(self, walk: Walk, dist_m: float) -> None:
        """Keep ``walk`` (about to be rewound) if it is the nearest so far."""
        if dist_m < self.dist_m:
            self.kept, self.dist_m = walk.copy(), dist_m

    def settle(self, walk: Walk, dist_m: float, message: str) -> str:
        """Restore the kept walk where it ends ``PROGRESS_M`` nearer than ``walk``."""
        if self.kept is None or self.dist_m >= dist_m - PROGRESS_M:
            return message
        walk.restore(self.kept)
        return (
            f"{message}; the plan is the walk that came nearest ({100 * self.dist_m:.0f} cm "
            f"from the goal) before it was traced back"
        )


# ------------------------------------------------------------------------------ stop rules
@dataclass(frozen=True)
class StopRules:
    """When the driver stops; checked before every cycle, in this order (8.2, 8.3).

    1. the source halts (Ctrl-C when planning, a fall when executing);
    2. the arrival move (:meth:`planner.planning.local.LocalPlanner.arrival`) where the
       COM is farther than ``ARRIVAL_M`` from the goal, also within ``goal_tol_m``: a
       walk ends over its goal where the feet allow, not at the tolerance's edge;
    3. the COM within ``goal_tol_m`` of the goal; 4. ``max_cycles``; 5. the time budget;
    6. ``max_fails_in_row`` failed cycles in a row; 7. no ``PROGRESS_M`` nearer the goal
       in ``patience_cycles`` cycles.

    Planning and feedback (8.3) differ in these fields: ``time_budget_s`` (None: no
    budget, feedback); ``progress_first`` (feedback: the progress is noted from the state
    as measured, before rule 1, so from the distance before an arrival move; planning:
    after rule 6); ``max_arrivals`` (None, planning: the arrival is tried once per
    keyframe of the walk, counts no cycle, and the rules go on from its end; a number,
    feedback: at most that many, below ``max_cycles``, each a cycle, executed, the rules
    then starting over from a new measurement); ``measured`` (the messages' words).
    """

    goal_tol_m: float
    max_cycles: int
    max_fails_in_row: int
    patience_cycles: int
    time_budget_s: float | None = None
    progress_first: bool = False
    max_arrivals: int | None = None
    measured: bool = False

    @classmethod
    def for_planning(cls, planner) -> StopRules:
        """A planner's rules: its settings, a cycle ``attempts_per_cycle`` attempts (8.5)."""
        st = planner.settings
        return cls(
            goal_tol_m=st.goal_tol_m,
            max_cycles=st.max_cycles,
            max_fails_in_row=st.max_fails_in_row,
            patience_cycles=st.no_progress_cycles * planner.attempts_per_cycle(),
            time_budget_s=st.time_budget_s,
        )

    @classmethod
    def for_feedback(cls, settings, max_cycles: int, no_progress_cycles: int, max_arrivals: int):
        """The rules of a feedback run (8.3) with the planner's ``settings``."""
        return cls(
            goal_tol_m=settings.goal_tol_m,
            max_cycles=max_cycles,
            max_fails_in_row=settings.max_fails_in_row,
            patience_cycles=no_progress_cycles,
            progress_first=True,
            max_arrivals=max_arrivals,
            measured=True,
        )


class Source(Protocol):
    """Where the driver's states come from: a planned walk, or the robot as measured."""

    def state(self) -> State:
        """The state the next cycle starts from (measured anew where measured)."""

    def stamp(self) -> object:
        """What identifies the last :meth:`state` (the arrival is tried once per stamp)."""

    def halted(self) -> str:
        """Why the run must stop before anything else ("" to go on)."""

    def arrive(self, end: State, path: list[State]) -> str:
        """Record or execute an arrival move; why the run must stop ("" to go on)."""


class PlannedStates:
    """The source of a planner's run: the last state of the walk it plans."""

    def __init__(self, walk: Walk):
        self.walk = walk

    def state(self) -> State:
        """The walk's last keyframe."""
        return self.walk.state

    def stamp(self) -> int:
        """The walk's keyframe count."""
        return self.walk.n_keyframes

    def halted(self) -> str:
        """Ctrl-C or SIGTERM (:mod:`planner.core.interrupts`): the walk so far is kept."""
        if interrupts.requested():
            return f"interrupted after {self.walk.steps} steps; the plan so far is kept"
        return ""

    def arrive(self, end: State, path: list[State]) -> str:
        """Record the move in the walk."""
        self.walk.add_body_move(end, path)
        return ""


# ------------------------------------------------------------------------------ the driver
class QueueCycle:
    """The hooks of one gait-queue cycle (:meth:`GaitDriver.gait_cycle`); defaults of 8.2.

    ``fixed_sequence``: a failed leg goes to the back of the queue, waiting a whole cycle
    (8.1's sequence S), instead of swapping with the next one.
    """

    fixed_sequence = False

    def __call__(self, driver: GaitDriver) -> str:
        """One cycle of ``driver`` with these hooks."""
        return driver.gait_cycle(self)

    def before(self, driver: GaitDriver) -> None:
        """Before the cycle is counted (e.g. trace back at a dead end)."""

    def leg(self, driver: GaitDriver) -> int:
        """The leg that steps: the queue's front."""
        return driver.queue.pop()

    def attempt(self, driver: GaitDriver, leg: int) -> Step | None:
        """The step of ``leg`` (None: the hook settled the cycle itself)."""
        raise NotImplementedError

    def stepped(self, driver: GaitDriver, leg: int, step: Step) -> None:
        """After a step was made: the leg goes to the back."""
        driver.queue.push(leg)

    def missed(self, driver: GaitDriver, leg: int, step: Step) -> None:
        """After a failed step: the leg changes places with the next (or waits a cycle)."""
        if self.fixed_sequence:
            driver.queue.push(leg)
        else:
            driver.queue.swap(leg, driver.run.fails_in_row)

    def after(self, driver: GaitDriver, step: Step | None) -> str:
        """The cycle's end (e.g. execute the step); why the run must stop ("" to go on)."""
        return ""


class GaitDriver:
    """Cycles of a gait queue from a source of states until a stop rule ends them (8.2).

    ``source`` gives the states (:class:`Source`), ``rules`` the stop rules (by default
    the planner's), ``gait`` the queue's first order. The counters are ``run``'s
    (:class:`Run`); ``queue`` and ``step_scale`` (each leg's stride fraction) may be
    replaced by a cycle's hooks (a retrace starts them anew).
    """

    def __init__(self, planner, run: Run, source: Source, rules: StopRules | None = None,
                 gait=None):  # fmt: skip
        self.planner = planner
        self.run = run
        self.source = source
        self.rules = rules if rules is not None else StopRules.for_planning(planner)
        self.queue = GaitQueue(gait) if gait is not None else None
        self.step_scale = {i: 1.0 for i in range(4)}  # stride fraction per leg

    def drive(self, cycle: Callable[[GaitDriver], str]) -> str:
        """Run ``cycle`` until a stop rule or the cycle itself (its message) stops; the reason."""
        while not (message := self.stop_reason()):
            if message := cycle(self):
                break
        return message

    def gait_cycle(self, hooks: QueueCycle) -> str:
        """One cycle: a leg from the queue, its step, the queue and counters after it."""
        run = self.run
        hooks.before(self)
        run.cycles += 1
        leg = hooks.leg(self)
        step = hooks.attempt(self, leg)
        if step is not None and step.ok:
            self.step_scale[leg] = 1.0
            run.fails_in_row = 0
            hooks.stepped(self, leg, step)
        elif step is not None:
            self.failed(step)
            if step.phase == "foot_placement":  # a shorter stride next time
                least = self.planner.settings.min_step_fraction
                self.step_scale[leg] = max(self.step_scale[leg] * 0.5, least)
            run.fails_in_row += 1
            hooks.missed(self, leg, step)
        return hooks.after(self, step)

    def distance(self, state: State) -> float:
        """Horizontal distance of the whole-body COM to the goal [m]."""
        return self.planner.distance_to_goal(state, self.run)

    def stop_reason(self) -> str:
        """Why the run must stop now ("" to go on): :class:`StopRules` in their order."""
        r, run, source = self.rules, self.run, self.source
        while True:
            state = source.state()
            dist = self.distance(state)
            if r.progress_first:
                self._note_progress(dist)
            if why := source.halted():
                run.halted = True
                return why
            if self._arrival_due(dist):
                moved = self.planner.arrival(state, run.goal, run.tau, dist <= r.goal_tol_m)
                if moved is not None:
                    run.arrivals += 1
                    if r.max_arrivals is not None:
                        run.cycles += 1
                    if why := source.arrive(*moved):
                        return why
                    if r.max_arrivals is not None:
                        continue  # measured again
                    dist = self.distance(source.state())
            return self._limits(dist)

    def _arrival_due(self, dist: float) -> bool:
        """Whether the arrival move is tried now (:class:`StopRules`, rule 2)."""
        r, run = self.rules, self.run
        if r.max_arrivals is not None:
            return run.arrivals < r.max_arrivals and dist > ARRIVAL_M and run.cycles < r.max_cycles
        if dist <= ARRIVAL_M or run.arrival_tried == (stamp := self.source.stamp()):
            return False
        run.arrival_tried = stamp
        return True

    def _limits(self, dist: float) -> str:
        """Rules 3-7 of :class:`StopRules` at the distance ``dist`` [m]."""
        r, run = self.rules, self.run
        if dist <= r.goal_tol_m:
            com = "measured COM" if r.measured else "COM"
            return f"reached the goal: {com} {dist * 100:.1f} cm from it"
        if run.cycles >= r.max_cycles:
            return f"stopped after {run.cycles} cycles (max_cycles)"
        if r.time_budget_s is not None and time.perf_counter() - run.t_begin > r.time_budget_s:
            return f"stopped by the time budget ({r.time_budget_s:.0f} s)"
        if run.fails_in_row >= r.max_fails_in_row:
            last = "" if r.measured else f"; last: {run.last_failure}"
            return f"stuck: {run.fails_in_row} failed step attempts in a row{last}"
        if not r.progress_first:
            self._note_progress(dist)
        if run.cycles - run.best_at >= r.patience_cycles:
            if r.measured:
                com = f"COM {100 * dist:.0f} cm from goal"
                return f"no progress in {r.patience_cycles} cycles ({com})"
            return (
                f"stuck: no progress in {r.patience_cycles} cycles (the COM came no nearer "
                f"than {100 * run.best_dist_m:.0f} cm to the goal); last: {run.last_failure}"
            )
        return ""

    def _note_progress(self, dist: float) -> None:
        run = self.run
        if dist < run.best_dist_m - PROGRESS_M:
            run.restart_stall()
            run.best_dist_m = dist

    def failed(self, step: Step) -> None:
        """Note a failed step: the last failure (stop messages), the planner's failure log."""
        phase = "body move" if step.phase == "body_move" else "foot placement"
        self.run.last_failure = f"{LEG_NAMES[step.leg]} {phase}: {step.diagnosis}"
        where = step.moved if step.moved is not None else step.start
        self.planner._log_failure(self.run.cycles, step.leg, step.phase, where, step.diagnosis)

    def report(self) -> None:
        """Call the run's progress callback with the walk's distance and steps (planning)."""
        run, walk = self.run, self.source.walk
        if run.progress is not None:
            run.progress(self.distance(walk.state), walk.steps)


def plan_run(planner, start_xy, goal_xy, tau, progress, start_state) -> LocalPlan:
    """A planner's run from ``start_xy`` (or ``start_state``) to ``goal_xy``: its plan.

    The walk starts at Theta4's initial placement (7.5) and is chosen by the planner's
    ``_run(walk, run)`` (the driver's cycles, or 8.5's windows); Ctrl-C keeps the walk so
    far. The time budget holds inside a cycle too: past it (or after Ctrl-C) a failing step
    tries no further foothold (:meth:`planner.planning.stepping.Stepping.out_of_time`), so
    a run ends within one foothold's attempt of its budget. Its samples are timed inside
    the planning time, the swing overlaps searched meanwhile in a worker process where the
    settings ask for one.
    """
    from planner.motion.trajectory import Trajectory

    t_begin = time.perf_counter()
    planner._failed_moves.clear()  # keyed by tau's id, which a new run may reuse
    if tau is None:
        tau = Trajectory.straight(start_xy, goal_xy, planner.terrain, planner.com_height_m())
    state = start_state if start_state is not None else planner.initial_state(start_xy, tau)
    run = Run(np.asarray(goal_xy, float)[:2], tau, t_begin, progress)
    worker = None
    if planner.settings.overlap_worker and planner.settings.swing_overlap > 0.0:
        from planner.planning.prefetch import OverlapWorker

        worker = OverlapWorker.start(planner)
    walk = Walk(planner, state, worker)
    budget = planner.settings.time_budget_s
    planner._deadline_s = t_begin + budget if budget is not None else math.inf
    try:
        try:
            message = planner._run(walk, run)
        except KeyboardInterrupt:
            message = f"interrupted after {walk.steps} steps; the plan so far is kept"
            run.halted = True
        with interrupts.shielded():  # timed now (the overlaps), inside planning time
            walk.keyframes  # noqa: B018
    finally:
        planner._deadline_s = math.inf
        if worker is not None:
            worker.close()
            walk.worker = None
    dist = planner.distance_to_goal(walk.state, run)
    stats = (
        {
            "planner": planner.name,
            "cycles": run.cycles,
            # cycles without PROGRESS_M of progress, at most (the open stretch at the end
            # included), against the stop's patience: how near a walk came to that stop
            "longest_stall_cycles": run.longest_stall_cycles,
            "steps": walk.steps,
            "planning_time_s": time.perf_counter() - t_begin,
            "overlap_worker_steps": 0 if worker is None else worker.used,  # timed by it
            "solves": {k: {"count": v[0], "feasible": v[1]} for k, v in planner.stats.items()},
            "failures": planner.failures[-50:],
        }
        | planner.extra_stats
    )
    return LocalPlan(
        keyframes=walk.keyframes,
        samples=walk.samples,
        times=walk.times,
        reached_goal=dist <= planner.settings.goal_tol_m,
        distance_to_goal_m=dist,
        message=message,
        stats=stats,
        interrupted=run.halted,
    )
