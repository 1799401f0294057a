"""Local planning by recursion with backtracking (paper section 8.5, eq. 14).

The paper outlines, but never implemented, [Psi_f, e] = F(Psi_i, Q, n, rho): from Psi_i,
with the gait step queue Q, make n steps, trying ambitious moves first; when a step
cannot be made, go back as far as needed and try the earlier steps differently. Here:

- a *move* is one step (:meth:`planner.planning.local.LocalPlanner.step`) of a leg with an
  ambition rho = (rho_2, rho_3): rho_3 scales the stride of Lambda_t (how far the foot
  goes), rho_2 is Lambda_c's shrink toward the support's incentre (how cautious the body
  move is). :data:`AMBITIONS` lists them most ambitious first;
- F tries, for the leg at the front of Q and then the next one (the queue's swap), each
  ambition in turn; a feasible step recurses with n - 1 and the leg pushed to the back;
  when the recursion fails, the step is undone (the walk is rewound) and the next option
  tried: this is the tracing back of 8.5;
- the walk is planned in windows of ``lookahead`` steps (receding horizon), each a cycle
  of the gait-queue driver (:class:`planner.planning.driver.GaitDriver`, whose stop rules
  end the run). Each window has a budget of step attempts (``node_budget``), and the
  whole run the time budget of the settings, so F always returns. A window that fails
  within its budget commits the deepest sequence of steps it found; when it found none
  with the first ``legs_per_level`` legs of the queue it is searched once more with every
  leg; none at all then traces back across windows: the last committed one is planned
  again with its most cautious moves first (at most ``MAX_WINDOW_RETRACES`` times a run),
  and only then is the robot stuck;
- a window may take several attempts for its ``lookahead`` steps, so an attempt counts as
  a fraction of a cycle in the no-progress stop (``no_progress_cycles`` x
  ``attempts_per_cycle`` attempts);
- a window is complete only where the queue's next leg can still shift the body onto the
  other three (:meth:`planner.planning.local.LocalPlanner.legs_can_move`, a plain Theta2): a
  sequence ending in a *dead end* is traced back like a failed step (``stats.dead_ends``
  counts the windows refused). Each step already looks one leg ahead when it picks its
  foothold (:meth:`~planner.planning.local.LocalPlanner.next_leg_can_move`), and next to a
  tall edge refuses a landing the body could not pass over
  (:meth:`~planner.planning.local.LocalPlanner.blocks_passage`). Asking it of every leg
  (``check_all_legs``) refuses sound windows, so it is asked only past a stall.

Where it beats 8.2: the soft planner commits every step greedily and, when a leg then
cannot step, only swaps legs and shortens that one leg's stride; the recursive planner
also undoes the steps that led there (for instance a long stride of the leg before) and
tries them shorter or with a more cautious body move.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

from planner.planning.driver import GaitDriver, NearestWalk, PlannedStates, Run, Walk
from planner.planning.local import LocalPlanner
from planner.planning.step import Step

AMBITIONS = ((1.0, None), (0.6, None), (0.3, 0.6))  # (rho_3 stride fraction, rho_2 shrink)
MAX_WINDOW_RETRACES = 4  # committed windows planned again when no step is left, per run
STALLED_WINDOWS = 2  # committed windows in a row that bring the COM no nearer the goal ...
PROGRESS_M = 0.01  # ... by this [m] are traced back, with every leg checked at their ends


@dataclass
class RecursiveSettings:
    """Budgets of F: steps per window, step attempts per window, legs tried per level."""

    lookahead: int = 3
    node_budget: int = 24
    legs_per_level: int = 2
    ambitions: tuple = AMBITIONS
    check_all_legs: bool = False  # a window's end: every leg can move, not only the next
    # step attempts that count as one cycle of the no-progress stop: 32 x 4 = 128 attempts
    # without the COM 1 cm nearer; the longest such stretch of a recursive walk that then
    # reached, on the named and hard courses, was 86 (bench/notes/2026-12-04-restarts.md),
    # and a walk stopped there is planned again (planner.planning.restarts)
    attempts_per_cycle: int = 4


class _Budget(Exception):
    """A window ran out of step attempts or the run out of time."""


@dataclass
class _Window:
    driver: GaitDriver  # the run's (its failure log)
    rs: RecursiveSettings = field(default_factory=RecursiveSettings)  # its budgets
    attempts: int = 0
    best: list[Step] = field(default_factory=list)
    best_queue: tuple[int, ...] = ()
    backtracks: int = 0
    dead_ends: int = 0


class RecursivePlanner(LocalPlanner):
    """F(Psi, Q, n, rho) of section 8.5 in receding windows."""

    name = "recursive"
    foothold_lookahead = True
    foothold_passage = True

    def __init__(self, robot, terrain, mu=None, settings=None, recursion=None):
        super().__init__(robot, terrain, mu, settings)
        self.recursion = recursion or RecursiveSettings()
        self.extra_stats = {
            "backtracks": 0, "dead_ends": 0, "windows": 0, "partial_windows": 0,
            "all_legs_windows": 0, "window_retraces": 0, "stall_retraces": 0,
        }  # fmt: skip

    def F(self, walk: Walk, queue: tuple[int, ...], n: int, run: Run, win: _Window, path):
        """Make ``n`` steps from ``walk.state``; returns the queue after them, or None.

        ``path`` holds the steps made so far in this window (for the best partial result).
        """
        if self.distance_to_goal(walk.state, run) <= self.settings.goal_tol_m:
            return queue
        if n == 0:
            # a window ends where the next leg can still shift the body onto the other
            # three: otherwise it leads into a dead end and is traced back like a failed step
            legs = queue if win.rs.check_all_legs else queue[:1]
            if self.legs_can_move(walk.state, legs, run.tau):
                return queue
            win.dead_ends += 1
            return None
        rs = win.rs
        for j in range(min(rs.legs_per_level, len(queue))):
            leg = queue[j]
            rest = queue[:j] + queue[j + 1 :] + (leg,)
            for rho3, rho2 in rs.ambitions:
                if win.attempts >= rs.node_budget:
                    raise _Budget
                if time.perf_counter() - run.t_begin > self.settings.time_budget_s:
                    raise _Budget
                win.attempts += 1
                run.cycles += 1
                stride = self.stride_at(walk.state, leg, run.tau)
                step = self.step(walk.state, leg, run.tau, stride * rho3, rho2)
                if not step.ok:
                    win.driver.failed(step)
                    continue
                mark = walk.mark()
                walk.add(step)
                path.append(step)
                if len(path) > len(win.best):
                    win.best, win.best_queue = list(path), rest
                out = self.F(walk, rest, n - 1, run, win, path)
                if out is not None:
                    return out
                path.pop()
                walk.rewind(mark)  # trace back (8.5): undo the step, try the next option
                win.backtracks += 1
        return None

    def attempts_per_cycle(self) -> int:
        """Step attempts of F that count as one cycle of the no-progress stop (see above)."""
        return max(1, int(self.recursion.attempts_per_cycle))

    def _search(self, driver: GaitDriver, queue: tuple[int, ...], rs: RecursiveSettings):
        """One window of F under the budgets ``rs``: (queue after it or None, the window)."""
        win = _Window(driver, rs)
        try:
            out = self.F(driver.source.walk, queue, rs.lookahead, driver.run, win, [])
        except _Budget:
            out = None
        self.extra_stats["backtracks"] += win.backtracks
        self.extra_stats["dead_ends"] += win.dead_ends
        return out, win

    def _run(self, walk: Walk, run: Run) -> str:
        """Windows of F driven until a stop rule (:class:`planner.planning.driver.GaitDriver`)."""
        windows = _Windows(self, walk, run)
        message = GaitDriver(self, run, PlannedStates(walk)).drive(windows)
        return windows.nearest_walk.settle(walk, self.distance_to_goal(walk.state, run), message)


class _Windows:
    """The driver's cycle of the recursive planner: one window of F, traced back (8.5)."""

    def __init__(self, planner: RecursivePlanner, walk: Walk, run: Run):
        self.planner, self.walk = planner, walk
        self.queue = tuple(planner.settings.gait)
        self.committed: list[tuple[tuple, tuple[int, ...]]] = []  # (mark, queue) before each
        self.cautious = False
        self.nearest, self.stalled = planner.distance_to_goal(walk.state, run), 0
        self.thorough_to = math.inf  # every leg checked while the COM is farther [m]
        self.nearest_walk = NearestWalk()

    def __call__(self, driver: GaitDriver) -> str:
        """Plan and commit one window; "" to go on, or why the planner is stuck."""
        p, walk, run, stats = self.planner, self.walk, driver.run, self.planner.extra_stats
        stats["windows"] += 1
        root = walk.mark()
        rs = p.recursion
        if self.cautious:  # a window planned again: its most cautious moves first
            rs = replace(rs, ambitions=tuple(reversed(rs.ambitions)))
            self.cautious = False
        if p.distance_to_goal(walk.state, run) > self.thorough_to:
            rs = replace(rs, check_all_legs=True)  # past a stall: every leg checked
        out, win = p._search(driver, self.queue, rs)
        if out is None and not win.best and rs.legs_per_level < len(self.queue):
            # not one step with the first legs of the queue: every leg before giving up
            stats["all_legs_windows"] += 1
            out, win = p._search(driver, self.queue, replace(rs, legs_per_level=len(self.queue)))
        if out is None:  # no full window: the deepest sequence found, if any
            walk.rewind(root)
            if not win.best:
                if self.committed and stats["window_retraces"] < MAX_WINDOW_RETRACES:
                    # trace back across windows (8.5: as far back as needed): the last
                    # committed window is planned again, its most cautious moves first
                    stats["window_retraces"] += 1
                    self.nearest_walk.offer(walk, p.distance_to_goal(walk.state, run))
                    root, self.queue = self.committed.pop()
                    walk.rewind(root)
                    self.cautious = True
                    return ""
                return (
                    f"stuck: no step possible from here with any leg or ambition; last: "
                    f"{run.last_failure}"
                )
            stats["partial_windows"] += 1
            for step in win.best:
                walk.add(step)
            out = win.best_queue
        self.committed.append((root, self.queue))
        self.queue = out
        driver.report()
        self._stall(driver)
        return ""

    def _stall(self, driver: GaitDriver) -> None:
        """Trace back windows that bring the COM no nearer the goal (8.5)."""
        p, walk, run, stats = self.planner, self.walk, driver.run, self.planner.extra_stats
        d = p.distance_to_goal(walk.state, run)
        if d < self.nearest - PROGRESS_M:
            self.nearest, self.stalled = d, 0
        else:
            self.stalled += 1
        if (
            self.stalled >= STALLED_WINDOWS
            and len(self.committed) > self.stalled
            and stats["window_retraces"] < MAX_WINDOW_RETRACES
        ):
            # shuffling in place (hind legs that cannot follow the front ones over a
            # barrier): the stalled windows and the one before are traced back (the
            # second time: the whole walk) and planned again with every leg checked
            # at their ends, until the COM is past where it stalled
            stats["window_retraces"] += 1
            stats["stall_retraces"] += 1
            first = stats["stall_retraces"] == 1
            self.nearest_walk.offer(walk, d)
            for _ in range(self.stalled + 1 if first else len(self.committed)):
                root, self.queue = self.committed.pop()
            walk.rewind(root)
            self.thorough_to = self.nearest - PROGRESS_M
            self.nearest, self.stalled = p.distance_to_goal(walk.state, run), 0


__all__ = ["AMBITIONS", "RecursivePlanner", "RecursiveSettings"]
