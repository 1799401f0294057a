"""Local planning by soft persuasion with a gait step queue (paper section 8.2).

One cycle moves one leg, as in figure 6 of the paper:

1. take the next leg i_f from the gait queue;
2. move the body on the current leaf of S0 so that the three other feet carry the weight:
   Theta2 with the target r_c* = Lambda_c(Psi, i_f) (sections 7.3, 8.2.1), the path
   interpolated along the leaf (eq. 6b);
3. lift leg i_f (S0 -> S_if) and place it with Theta3 at a foothold near
   Lambda_t(Psi, i_f, tau) (sections 7.4, 8.2.2); the swing follows a path that clears the
   terrain (beyond eq. 6a, :func:`planner.interpolate.swing_path`); back on S0;
4. push i_f to the back of the queue. On a failure of Theta2 or Theta3 the leg is swapped
   with the next one and retried after it (comment ii of 8.2); a failed foothold is
   retried with a shorter stride.

Beyond the paper (see :meth:`planner.local.base.LocalPlanner.step`): footholds are moved
off edges of the sharp terrain, and the body move keeps the swinging leg within reach of
its next foothold.
"""

from __future__ import annotations

from planner.local.base import LocalPlan, LocalPlanner, LocalSettings, Walk, _Run
from planner.local.gait_queue import GaitQueue


class SoftPlanner(LocalPlanner):
    """The gait-queue driver of section 8.2 for one robot on one terrain."""

    name = "soft"

    def _run(self, walk: Walk, run: _Run) -> str:
        st = self.settings
        queue = GaitQueue(st.gait)
        step_scale = {i: 1.0 for i in range(4)}
        fails_in_row = 0
        while not (message := self.stop_reason(walk, run, fails_in_row)):
            run.cycles += 1
            leg = queue.pop()
            step = self.step(walk.state, leg, run.tau, self.stride_m() * step_scale[leg])
            walk.add(step)  # a failed placement keeps its body move
            if not step.ok:
                self.failed(run, step)
                if step.phase == "foot_placement":
                    step_scale[leg] = max(step_scale[leg] * 0.5, st.min_step_fraction)
                fails_in_row += 1
                queue.swap(leg, fails_in_row)
                continue
            step_scale[leg] = 1.0
            fails_in_row = 0
            queue.push(leg)
            self.report(walk, run)
        return message


__all__ = ["LocalPlan", "LocalSettings", "SoftPlanner"]
