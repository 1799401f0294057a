"""Local planning by soft persuasion with a gait step queue (paper section 8.2).

One cycle moves one leg, as in figure 6 of the paper:

1. take the next leg i_f from the gait queue;
2. move the body on the current leaf of S0 so that the three other feet carry the weight:
   Theta2 with the target r_c* = Lambda_c(Psi, i_f) (sections 7.3, 8.2.1), the path
   interpolated along the leaf (eq. 6b);
3. lift leg i_f (S0 -> S_if) and place it with Theta3 at a foothold near
   Lambda_t(Psi, i_f, tau) (sections 7.4, 8.2.2); the swing follows a path that clears the
   terrain (beyond eq. 6a, :func:`planner.motion.interpolate.swing_path`); back on S0;
4. push i_f to the back of the queue. On a failure of Theta2 or Theta3 the leg is swapped
   with the next one and retried after it (comment ii of 8.2); a failed foothold is
   retried with a shorter stride.

The cycles are the gait-queue driver's (:class:`planner.planning.driver.GaitDriver`,
which also holds the stop rules); this module adds the stride and the tracing back.
Beyond the paper (see :meth:`planner.planning.local.LocalPlanner.step`): footholds are moved
off edges of the sharp terrain, and the body move keeps the swinging leg within reach of
its next foothold. Where the greedy steps lead into a dead end (``RETRACE_FAILS`` failed
attempts in a row, or ``no_progress_cycles / 2`` cycles without progress) the walk is
traced back ``RETRACE_STEPS`` steps before its best point and those steps are planned
again with the foothold look-ahead of the recursive planner (8.5): each foothold must leave
the next leg a body move. A dead end met again at the same point is traced back again
with 8.5's less ambitious moves, shorter strides, and then from farther back
(``RETRACES``: a dead end's cause may lie a crawl cycle or two before the steps
retraced), and only when none is left does it stop the planner. The first retrace keeps
the full stride, so a walk that one retrace gets out of is planned as without the later
ones.
"""

from __future__ import annotations

from planner.motion.gait_queue import GaitQueue
from planner.planning.driver import (
    PROGRESS_M,
    GaitDriver,
    LocalPlan,
    NearestWalk,
    PlannedStates,
    QueueCycle,
    Run,
    Walk,
)
from planner.planning.local import LocalPlanner, LocalSettings
from planner.planning.step import Step

RETRACE_FAILS = 4  # failed step attempts in a row that trigger a retrace
RETRACE_STEPS = 4  # steps traced back before the best point (one crawl cycle)
LOOKAHEAD_STEPS = 8  # steps past the dead end planned with the look-ahead
# the retraces at one point: (crawl cycles farther back than the first, stride fraction)
RETRACES = ((0, 1.0), (0, 0.6), (0, 0.3), (1, 0.6), (2, 0.3))


class SoftPlanner(LocalPlanner):
    """The soft-persuasion planner of section 8.2 for one robot on one terrain."""

    name = "soft"
    fixed_sequence = False  # True: a failed leg waits a whole cycle (8.1's sequence S)
    retraces = RETRACES  # the tracing back at a dead end (empty: none, the paper's 8.2)

    def __init__(self, robot, terrain, mu=None, settings=None):
        super().__init__(robot, terrain, mu, settings)
        self.extra_stats = {"retraces": 0}

    def _run(self, walk: Walk, run: Run) -> str:
        """The driver's cycles (:class:`planner.planning.driver.GaitDriver`) with retraces."""
        driver = GaitDriver(self, run, PlannedStates(walk), gait=self.settings.gait)
        cycle = _Retracing(self, walk)
        message = driver.drive(cycle)
        self.foothold_lookahead = False
        return cycle.nearest_walk.settle(walk, self.distance_to_goal(walk.state, run), message)


class _Retracing(QueueCycle):
    """Soft's cycle: Lambda_t's stride, the walk traced back at a dead end (8.2 with 8.5)."""

    def __init__(self, planner: SoftPlanner, walk: Walk):
        self.planner, self.walk = planner, walk
        self.fixed_sequence = planner.fixed_sequence
        # before each committed step: (walk mark, queue, run cycle)
        self.history: list[tuple[tuple, tuple, int]] = []
        self.retrace_dist = float("inf")  # the best distance to the goal at the last retrace
        self.level = 0  # retraces at that point: the steps retraced take RETRACES[level - 1]
        self.retrace_k = 0  # ... the first from this step of history
        self.lookahead_until = -1  # walk steps up to which footholds are looked ahead
        self.nearest_walk = NearestWalk()
        self.ambition = 1.0  # the stride's fraction in this cycle
        self.mark: tuple = ()  # the walk and the queue before this cycle's step
        self.queue_before: tuple = ()

    def before(self, driver: GaitDriver) -> None:
        """At a dead end, trace back; the look-ahead and stride of the cycle."""
        p, run, walk = self.planner, driver.run, self.walk
        stalled = run.cycles - run.best_at >= p.settings.no_progress_cycles // 2
        new_point = run.best_dist_m < self.retrace_dist - PROGRESS_M
        if (
            p.retraces
            and (run.fails_in_row >= RETRACE_FAILS or stalled)
            and self.history
            and (new_point or self.level < len(p.retraces))
        ):
            # a dead end: back to RETRACE_STEPS steps before the best point, and plan
            # from there with the look-ahead and shorter strides (8.5's tracing back)
            history = self.history
            if new_point:  # full strides
                self.level, self.retrace_dist = 1, run.best_dist_m
                self.lookahead_until = walk.steps + LOOKAHEAD_STEPS
                at_best = max(k for k, h in enumerate(history) if h[2] <= run.best_at or k == 0)
                self.retrace_k = max(at_best - RETRACE_STEPS, 0)
            else:  # the same dead end again: shorter strides, then farther back
                self.level += 1
            back = p.retraces[self.level - 1][0] * RETRACE_STEPS
            k = min(max(self.retrace_k - back, 0), len(history) - 1)
            mark, legs, _ = history[k]
            del history[k:]
            self.nearest_walk.offer(walk, p.distance_to_goal(walk.state, run))
            walk.rewind(mark)
            driver.queue = GaitQueue(legs)
            driver.step_scale = {i: 1.0 for i in range(4)}
            run.fails_in_row = 0
            run.restart_stall()
            p.extra_stats["retraces"] += 1
        p.foothold_lookahead = walk.steps < self.lookahead_until
        self.ambition = p.retraces[self.level - 1][1] if p.foothold_lookahead else 1.0

    def leg(self, driver: GaitDriver) -> int:
        self.mark, self.queue_before = self.walk.mark(), tuple(driver.queue)
        return driver.queue.pop()

    def attempt(self, driver: GaitDriver, leg: int) -> Step:
        """Lambda_t's stride, shortened after failed placements and by the ambition."""
        p, walk, tau = self.planner, self.walk, driver.run.tau
        stride = p.stride_at(walk.state, leg, tau) * driver.step_scale[leg] * self.ambition
        step = p.step(walk.state, leg, tau, stride)
        walk.add(step)  # a failed placement keeps its body move
        return step

    def stepped(self, driver: GaitDriver, leg: int, step: Step) -> None:
        self.history.append((self.mark, self.queue_before, driver.run.cycles))
        driver.queue.push(leg)
        driver.report()


class GreedyPlanner(SoftPlanner):
    """Section 8.2 as the paper has it: greedy steps, no tracing back at a dead end.

    The baseline that shows what tracing back (8.5) earns: where its greedy steps lead into
    a stance no leg can step from, it swaps legs and shortens strides until
    ``max_fails_in_row`` or ``no_progress_cycles`` stop it; the soft planner (its retraces)
    and the recursive planner undo the steps that led there.
    """

    name = "greedy"
    retraces = ()


__all__ = ["GreedyPlanner", "LocalPlan", "LocalSettings", "SoftPlanner"]
