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
- the walk is planned in windows of ``lookahead`` steps (receding horizon). Each window
  has a budget of step attempts (``node_budget``), and the whole run the time budget of
  the settings, so F always returns. A window that fails within its budget commits the
  deepest sequence of steps it found; when it found none with the first
  ``legs_per_level`` legs of the queue it is searched once more with every leg; none at
  all then traces back across windows: the last committed one is planned again with its
  most cautious moves first (at most ``MAX_WINDOW_RETRACES`` times a run), and only then
  is the robot stuck;
- a window may take up to ``node_budget`` attempts for its ``lookahead`` steps, so an
  attempt counts as a fraction of a cycle in the no-progress stop
  (``no_progress_cycles`` x node_budget / lookahead attempts);
- a window is complete only where the queue's next leg can still shift the body onto the
  other three (:meth:`planner.planning.local.LocalPlanner.legs_can_move`, a plain Theta2): a
  sequence ending in a *dead end* is traced back like a failed step (``stats.dead_ends``
  counts the windows refused). Each step already looks one leg ahead when it picks its
  foothold (:meth:`~planner.planning.local.LocalPlanner.next_leg_can_move`), and next to a
  tall edge refuses a landing the body could not pass over
  (:meth:`~planner.planning.local.LocalPlanner.blocks_passage`: barrier75mm's hind foot 4.6 cm
  before the barrier, knee ahead, stopped the walk 133 cm short). Asking it of
  every leg (``check_all_legs``) refused sound windows: stairs with every leg checked
  traced back 15 windows of 15 and stopped by its 240 s budget 0.6 m short; with the
  next leg it reaches in 29 s, and up step10cm in 39 s instead of 110 s.

Where it beats 8.2: the soft planner commits every step greedily and, when a leg then
cannot step, only swaps legs and shortens that one leg's stride; the recursive planner
also undoes the steps that led there (for instance a long stride of the leg before) and
tries them shorter or with a more cautious body move.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

from planner.planning.local import LocalPlanner, NearestWalk, Step, Walk, _Run

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


class _Budget(Exception):
    """A window ran out of step attempts or the run out of time."""


@dataclass
class _Window:
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

    def F(self, walk: Walk, queue: tuple[int, ...], n: int, run: _Run, win: _Window, path):
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
                    self.failed(run, step)
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
        """A window's ``node_budget`` attempts make its ``lookahead`` steps (see above)."""
        rs = self.recursion
        return max(1, rs.node_budget // max(1, rs.lookahead))

    def _search(self, walk: Walk, queue: tuple[int, ...], run: _Run, rs: RecursiveSettings):
        """One window of F under the budgets ``rs``: (queue after it or None, the window)."""
        win = _Window(rs)
        try:
            out = self.F(walk, queue, rs.lookahead, run, win, [])
        except _Budget:
            out = None
        self.extra_stats["backtracks"] += win.backtracks
        self.extra_stats["dead_ends"] += win.dead_ends
        return out, win

    def _run(self, walk: Walk, run: _Run) -> str:
        queue = tuple(self.settings.gait)
        committed: list[tuple[tuple, tuple[int, ...]]] = []  # (mark, queue) before each window
        cautious = False
        nearest, stalled = self.distance_to_goal(walk.state, run), 0
        thorough_to = math.inf  # every leg checked while the COM is farther from the goal [m]
        nearest_walk = NearestWalk()
        while not (message := self.stop_reason(walk, run)):
            self.extra_stats["windows"] += 1
            root = walk.mark()
            rs = self.recursion
            if cautious:  # a window planned again: its most cautious moves first
                rs = replace(rs, ambitions=tuple(reversed(rs.ambitions)))
                cautious = False
            if self.distance_to_goal(walk.state, run) > thorough_to:
                rs = replace(rs, check_all_legs=True)  # past a stall: every leg checked
            out, win = self._search(walk, queue, run, rs)
            if out is None and not win.best and rs.legs_per_level < len(queue):
                # not one step with the first legs of the queue: every leg before giving up
                self.extra_stats["all_legs_windows"] += 1
                out, win = self._search(walk, queue, run, replace(rs, legs_per_level=len(queue)))
            if out is None:  # no full window: the deepest sequence found, if any
                walk.rewind(root)
                if not win.best:
                    if committed and self.extra_stats["window_retraces"] < MAX_WINDOW_RETRACES:
                        # trace back across windows (8.5: as far back as needed): the last
                        # committed window is planned again, its most cautious moves first
                        self.extra_stats["window_retraces"] += 1
                        nearest_walk.offer(walk, self.distance_to_goal(walk.state, run))
                        root, queue = committed.pop()
                        walk.rewind(root)
                        cautious = True
                        continue
                    message = (
                        f"stuck: no step possible from here with any leg or ambition; last: "
                        f"{run.last_failure}"
                    )
                    break
                self.extra_stats["partial_windows"] += 1
                for step in win.best:
                    walk.add(step)
                out = win.best_queue
            committed.append((root, queue))
            queue = out
            self.report(walk, run)
            d = self.distance_to_goal(walk.state, run)
            nearest, stalled = (d, 0) if d < nearest - PROGRESS_M else (nearest, stalled + 1)
            if (
                stalled >= STALLED_WINDOWS
                and len(committed) > stalled
                and self.extra_stats["window_retraces"] < MAX_WINDOW_RETRACES
            ):
                # shuffling in place (hind legs that cannot follow the front ones over a
                # barrier): the stalled windows and the one before are traced back (the
                # second time: the whole walk) and planned again with every leg checked
                # at their ends, until the COM is past where it stalled
                self.extra_stats["window_retraces"] += 1
                self.extra_stats["stall_retraces"] += 1
                first = self.extra_stats["stall_retraces"] == 1
                nearest_walk.offer(walk, d)
                for _ in range(stalled + 1 if first else len(committed)):
                    root, queue = committed.pop()
                walk.rewind(root)
                thorough_to = nearest - PROGRESS_M
                nearest, stalled = self.distance_to_goal(walk.state, run), 0
        return nearest_walk.settle(walk, self.distance_to_goal(walk.state, run), message)


__all__ = ["AMBITIONS", "RecursivePlanner", "RecursiveSettings"]
