"""One step of section 8.5: body move, swing and placement, with the footholds to try.

:meth:`Stepping.step` makes the cycle of figure 6 for one leg i_f: a body move onto the
other three legs (swing-ready where it can, :mod:`planner.planning.body_move`), the swing
and placement with Theta3 (:mod:`planner.planning.swing`). Beyond the paper, other
footholds are tried when the first fails, footholds that leave the gait's next leg no
stance come last, a foothold may be required to leave the next leg a body move (the
recursive planner's look-ahead) or not to block the body (:mod:`planner.planning.landing`).

:class:`Stepping` is a part of :class:`planner.planning.local.LocalPlanner`; it uses the
planner's ``settings``, ``_deadline_s`` (:func:`planner.planning.driver.plan_run`),
``foothold_lookahead`` and ``foothold_passage``, its Theta2 problems (:meth:`theta2`,
:meth:`_count`), the targets (:class:`planner.planning.targets.Targets`), the body moves,
the swing and the knee choice.
"""

from __future__ import annotations

import time

import numpy as np

from planner.body.robot import LEG_NAMES
from planner.body.stability import triangle_inradius_m
from planner.body.state import State
from planner.core import interrupts
from planner.core.failures import FailureKind
from planner.motion.trajectory import Trajectory
from planner.planning.step import Step

__all__ = ["DEAD_END_LATERAL_M", "Stepping"]

DEAD_END_LATERAL_M = 0.08  # a dead end's other footholds: this near the nominal one aside [m]


class Stepping:
    """A step of one leg (:meth:`step`) and the look-ahead of its foothold choice."""

    def step(
        self,
        state: State,
        leg: int,
        tau: Trajectory,
        step_m: float,
        shrink: float | None = None,
        target_W=None,
        try_others: bool = True,
        body_hint: State | None = None,
        knee: int | None = None,
    ) -> Step:
        """One step of ``leg`` from ``state``: body move (swing-ready), swing, placement.

        The body move is first asked to keep ``leg`` within reach of its next foothold
        (Theta2's swing-ready constraint); if that is infeasible, the paper's plain Theta2.
        When that foothold fails (no landing-ready body pose, or no swing), up to
        ``OTHER_FOOTHOLDS`` others of the leg's reachable, safe region are tried
        (:meth:`other_footholds`), while time is left (:meth:`out_of_time`). A failed
        placement keeps the body move (``Step.moved``) of the first attempt: the robot
        stands safely on three legs there.
        A foothold that would leave the gait's next leg no stance to swing from
        (:meth:`leaves_no_support`) is tried after those around the leg's nominal
        placement that do not. With ``foothold_lookahead`` a foothold after which the next
        leg finds no body move is passed over for the next one that leaves it one (the
        first such step is returned when none does). ``shrink`` overrides
        ``settings.shrink`` of Lambda_c.
        ``target_W``: the foothold to try first (a terrain point, world frame; e.g. a
        precomputed plan's), instead of Lambda_t's; ``try_others`` False: no other
        foothold is tried. ``body_hint``: a body pose near the one expected for the first
        foothold (the precomputed plan's, feedback 8.3), Theta2's last starting point.
        ``knee``: the knee branch the leg lands on (the precomputed plan's, :meth:`swing`).
        With the contact-sequence search (``footholds`` "search") the first foothold is the
        search's, and where it fails from Lambda_c's body target it is tried once more
        with its certificate's COM as the target (:mod:`planner.planning.sequence`).
        """
        searched = searched_com = None
        if target_W is not None:
            target = np.asarray(target_W, float).reshape(3)
        else:
            target, _ = self.foothold_target(state, leg, tau, step_m, shrink)
            found = self.searched_foothold(state, leg, tau, step_m, target)
            if found is not None:
                target = searched = found[0]
                searched_com = found[1]
        order = [target]  # the footholds to try, in order
        extended = False  # the other footholds are in ``order``
        if try_others and self.leaves_no_support(state, leg, target):
            # a dead end for the next leg: first the footholds around the nominal placement
            # (wider sideways: the stance width may have to change) that leave it a stance
            order = self.other_footholds(
                state, leg, tau, target, shrink,
                centre_W=self.stride_target(state, leg, tau, step_m, shrink),
                max_lateral_m=DEAD_END_LATERAL_M,
                keep=lambda c: not self.leaves_no_support(state, leg, c),
            ) + [target]  # fmt: skip
            order = self.certified_first(state, leg, tau, step_m, order[:-1]) + [target]
        first = None  # the first failure, reported when no foothold works
        dead_end = None  # the first step made that leaves the next leg no body move
        k = 0
        while k < len(order):
            if k > 0 and self.out_of_time():
                break  # the run's budget is spent (or Ctrl-C): the first failure stands
            target = order[k]
            hint = body_hint if k == 0 else None
            step = self._placed(state, leg, tau, step_m, shrink, target, hint,
                                knee if k == 0 else None, plain=k == 0)  # fmt: skip
            if not step.ok and k == 0 and searched_com is not None and target is searched:
                # the searched foothold from its certificate's body pose (the COM target)
                aimed = self._placed(state, leg, tau, step_m, shrink, target, hint, knee,
                                     plain=False, aim=searched_com)  # fmt: skip
                step = aimed if aimed.ok else step
            if step.ok:
                if k == 0 and searched is not None:
                    self.mark_realised()
                if (
                    not try_others
                    or not self.foothold_lookahead
                    or self.next_leg_can_move(step.end, leg, tau, shrink)
                ):
                    return step
                dead_end = dead_end or step
                step = Step(
                    leg, False, state, step.moved, None, step.body_path, [], "foot_placement",
                    "the foothold leaves the next leg no body move",
                )  # fmt: skip
            first = first or step
            if k == 0 and searched is not None:  # the search repairs from here next time
                self.mark_unrealised(state, leg, searched)
            if FailureKind.BALANCE_MARGIN in step.failure and step.phase == "body_move" and k == 0:
                break  # the COM cannot shift onto the other three legs: no foothold helps
            if not try_others:
                break
            if not extended:
                others = self.other_footholds(state, leg, tau, target, shrink)
                order += self.certified_first(state, leg, tau, step_m, others)
                extended = True
            k += 1
        return dead_end or first

    def out_of_time(self) -> bool:
        """Whether the run's time budget is spent or Ctrl-C asked it to stop.

        A failing step then tries no other foothold (:meth:`step`): the driver's stop rules
        (:class:`planner.planning.driver.StopRules`) are checked between cycles, and one
        failing step may try a dozen footholds for tens of seconds.
        """
        return interrupts.requested() or time.perf_counter() > self._deadline_s

    def _placed(self, state, leg, tau, step_m, shrink, target, hint, knee, plain, aim=None):
        """The body move and the swing to ``target``: the step made, or why not.

        The body move is swing-ready for ``target`` (with ``plain`` the paper's plain
        Theta2 where that fails; ``aim``: its COM target instead of Lambda_c's).
        """
        sol2, body_path = self._body_move_once(state, leg, tau, target, shrink, hint, aim)
        if plain and not sol2.feasible:
            # the paper's plain Theta2 (no swing-ready pose) for the first foothold
            sol2, body_path = self._body_move_once(state, leg, tau, None, shrink, hint)
        if not sol2.feasible:
            step = Step(leg, False, state, None, None, [], [], "body_move", sol2.diagnosis)
            step.failure = sol2.failure
            return step
        sol3, swing_path = self.swing(sol2.state, leg, tau, step_m, target, knee)
        if sol3.feasible and self.foothold_passage and self.blocks_passage(sol3.state, leg):
            # a landing the body cannot pass over fails like one out of reach
            sol3.feasible = False
            sol3.diagnosis = (
                f"swing of {LEG_NAMES[leg]}: standing there, its links would meet "
                "the edge ahead as the body passes over the foot"
            )
        if sol3.feasible:
            return Step(leg, True, state, sol2.state, sol3.state, body_path, swing_path)
        return Step(
            leg, False, state, sol2.state, None, body_path, [], "foot_placement", sol3.diagnosis
        )

    def next_leg_can_move(self, state: State, leg: int, tau: Trajectory, shrink=None) -> bool:
        """Whether the gait's next leg finds a body move (plain Theta2) after ``leg``'s step.

        Beyond the paper: a one-step look-ahead of the foothold choice. Climbing a step the
        front feet reach far ahead onto it while the hind feet stay below; a foothold that
        leaves no body pose keeping the next leg's stance within reach and balance is a
        dead end (the soft planner would stall there). When every foothold tried is one,
        :meth:`step` returns the first that was made.
        """
        return self.legs_can_move(state, [self._next_leg(leg)], tau, shrink)

    def legs_can_move(self, state: State, legs, tau: Trajectory, shrink=None) -> bool:
        """Whether each of ``legs`` finds a body move onto the other three (plain Theta2)."""
        for nxt in legs:
            rc = self.body_target(state, nxt, shrink, tau=tau)
            u_f, u_n = self.body_directions(tau, state, rc, nxt)
            sol = self.theta2(tuple(i for i in range(4) if i != nxt)).solve(state, rc, u_f, u_n)
            self._count("theta2_lookahead", sol.feasible)
            if not sol.feasible:
                return False
        return True

    def leaves_no_support(self, state: State, leg: int, foothold_W) -> bool:
        """Whether ``leg`` on ``foothold_W`` leaves the gait's next leg no stance to swing from.

        The next leg of ``settings.gait`` swings on the other three feet; when their
        triangle's inradius is below the balance margin no COM keeps Theta2's balance
        margin on it (e.g. both front feet on one stepping stone: the hind legs can no
        longer step). Beyond the paper: a one-step look-ahead of the foothold choice.
        """
        nxt = self._next_leg(leg)
        feet = np.array(state.feet_W, float).reshape(4, 3)
        feet[leg] = np.asarray(foothold_W, float).reshape(3)
        return triangle_inradius_m(np.delete(feet, nxt, axis=0)) < self.balance_margin_m
