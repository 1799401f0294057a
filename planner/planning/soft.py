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

Beyond the paper (see :meth:`planner.planning.local.LocalPlanner.step`): footholds are moved
off edges of the sharp terrain, and the body move keeps the swinging leg within reach of
its next foothold. Where the greedy steps lead into a dead end (``RETRACE_FAILS`` failed
attempts in a row, or ``no_progress_cycles / 2`` cycles without progress) the walk is
traced back ``RETRACE_STEPS`` steps before its best point and those steps are planned
again with the foothold look-ahead of the recursive planner (8.5): each foothold must leave
the next leg a body move. A dead end met again at the same point is traced back again
with 8.5's less ambitious moves, shorter strides, and then from farther back
(``RETRACES``), and only when none is left does it stop the planner. On step10cm the full
strides put the front feet up the step with the hind feet stretched below, a stance no
hind body move leaves; planned again alike it met the same dead end, and at 0.6 of the
stride it climbed on one machine. On another its cause lay before the steps retraced: the
right hind foot left 14 cm before the riser a crawl cycle earlier while the left one
climbed, and from the same step at 0.6 and 0.3 of the stride the walk met the same stance
(135 cm short); the 4th and 5th retraces start one and two crawl cycles farther back (it
climbs at the 5th: 66 steps). They come after the first three, so a walk that got out
with those is planned as before (mix4m's, which farther back at the 2nd retrace stalled
108 cm short). The first retrace keeps the full stride: where one retrace sufficed the
plans stay as they were (barrier9cm's soft plan, which walks in MuJoCo; its plan retraced
at 0.6 fell there).
"""

from __future__ import annotations

from planner.motion.gait_queue import GaitQueue
from planner.planning.local import (
    PROGRESS_M,
    LocalPlan,
    LocalPlanner,
    LocalSettings,
    NearestWalk,
    Walk,
    _Run,
)

RETRACE_FAILS = 4  # failed step attempts in a row that trigger a retrace
RETRACE_STEPS = 4  # steps traced back before the best point (one crawl cycle)
LOOKAHEAD_STEPS = 8  # steps past the dead end planned with the look-ahead
# the retraces at one point: (crawl cycles farther back than the first, stride fraction)
RETRACES = ((0, 1.0), (0, 0.6), (0, 0.3), (1, 0.6), (2, 0.3))


class SoftPlanner(LocalPlanner):
    """The gait-queue driver of section 8.2 for one robot on one terrain."""

    name = "soft"
    fixed_sequence = False  # True: a failed leg waits a whole cycle (8.1's sequence S)
    retraces = RETRACES  # the tracing back at a dead end (empty: none, the paper's 8.2)

    def __init__(self, robot, terrain, mu=None, settings=None):
        super().__init__(robot, terrain, mu, settings)
        self.extra_stats = {"retraces": 0}

    def _run(self, walk: Walk, run: _Run) -> str:
        st = self.settings
        queue = GaitQueue(st.gait)
        step_scale = {i: 1.0 for i in range(4)}
        fails_in_row = 0
        # before each committed step: (walk mark, queue, run cycle)
        history: list[tuple[tuple, tuple, int]] = []
        retrace_dist = float("inf")  # the best distance to the goal at the last retrace
        level = 0  # retraces at that point: the steps retraced take RETRACES[level - 1]
        retrace_k = 0  # ... the first from this step of history
        lookahead_until = -1  # walk steps up to which footholds are looked ahead
        nearest_walk = NearestWalk()
        while not (message := self.stop_reason(walk, run, fails_in_row)):
            stalled = run.cycles - run.best_at >= st.no_progress_cycles // 2
            new_point = run.best_dist_m < retrace_dist - PROGRESS_M
            if (
                self.retraces
                and (fails_in_row >= RETRACE_FAILS or stalled)
                and history
                and (new_point or level < len(self.retraces))
            ):
                # a dead end: back to RETRACE_STEPS steps before the best point, and plan
                # from there with the look-ahead and shorter strides (8.5's tracing back)
                if new_point:  # full strides
                    level, retrace_dist = 1, run.best_dist_m
                    lookahead_until = walk.steps + LOOKAHEAD_STEPS
                    at_best = max(k for k, h in enumerate(history) if h[2] <= run.best_at or k == 0)
                    retrace_k = max(at_best - RETRACE_STEPS, 0)
                else:  # the same dead end again: shorter strides, then farther back
                    level += 1
                back = self.retraces[level - 1][0] * RETRACE_STEPS
                k = min(max(retrace_k - back, 0), len(history) - 1)
                mark, legs, _ = history[k]
                del history[k:]
                nearest_walk.offer(walk, self.distance_to_goal(walk.state, run))
                walk.rewind(mark)
                queue = GaitQueue(legs)
                step_scale = {i: 1.0 for i in range(4)}
                fails_in_row = 0
                run.best_at = run.cycles
                self.extra_stats["retraces"] += 1
            self.foothold_lookahead = walk.steps < lookahead_until
            ambition = self.retraces[level - 1][1] if self.foothold_lookahead else 1.0
            run.cycles += 1
            mark = walk.mark()
            before = tuple(queue)
            leg = queue.pop()
            stride = self.stride_at(walk.state, leg, run.tau) * step_scale[leg] * ambition
            step = self.step(walk.state, leg, run.tau, stride)
            walk.add(step)  # a failed placement keeps its body move
            if not step.ok:
                self.failed(run, step)
                if step.phase == "foot_placement":
                    step_scale[leg] = max(step_scale[leg] * 0.5, st.min_step_fraction)
                fails_in_row += 1
                if self.fixed_sequence:
                    queue.push(leg)
                else:
                    queue.swap(leg, fails_in_row)
                continue
            history.append((mark, before, run.cycles))
            step_scale[leg] = 1.0
            fails_in_row = 0
            queue.push(leg)
            self.report(walk, run)
        self.foothold_lookahead = False
        return nearest_walk.settle(walk, self.distance_to_goal(walk.state, run), message)


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
