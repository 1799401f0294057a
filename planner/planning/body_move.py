"""The body move of a step: Theta2 onto three legs (section 7.3) and its sampled path.

Section 8.5's step first moves the body on the current leaf of S0 onto the three legs
other than i_f: Theta2 finds the pose at the body target (eq. 12), the leaf's samples
(eq. 6b) lead there, and where they fail the path checks the move is solved again on the
feet as the path rolled them, or passes through a via pose (Theta1). With the two-beat
COM target a body already placed stays where it is. Failed moves are remembered for the
run (:meth:`_body_move_once`).

:class:`BodyMoves` is a part of :class:`planner.planning.local.LocalPlanner`; it uses the
planner's ``robot``, ``terrain``, ``mu``, ``settings``, ``check``, ``_via_theta1`` and
``_failed_moves``, its Theta2 problems (:meth:`theta2`, :meth:`_count`), the targets
(:class:`planner.planning.targets.Targets`), the path checks
(:class:`planner.planning.path_checks.PathChecks`) and the level-ground samples
(:class:`planner.planning.level.LevelGround`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from planner.body.links import leg_links
from planner.body.stability import support_margin_m
from planner.body.state import State
from planner.core.failures import FailureKind, kind_of
from planner.motion.interpolate import interpolate_leaf
from planner.motion.trajectory import Trajectory
from planner.problems import Theta1

__all__ = ["FAILED_MOVES_KEPT", "BodyMoves"]

FAILED_MOVES_KEPT = 4096  # failed body moves remembered in a run (BodyMoves._body_move_once)


class BodyMoves:
    """Theta2 body moves onto three legs and their paths (:meth:`body_move`)."""

    def body_move(
        self,
        state: State,
        leg: int,
        tau: Trajectory,
        swing_target_W=None,
        shrink: float | None = None,
        hint: State | None = None,
        com_target_W=None,
    ):
        """Theta2 onto the three legs other than ``leg``; returns (solution, samples).

        With ``swing_target_W`` the body also keeps ``leg``'s hip within reach of its next
        foothold (Theta2's swing-ready constraint). ``hint``: Theta2's last starting pose
        (:meth:`planner.problems.theta2.Theta2.solve`). (The hint is not aimed at when the
        optimum's path fails: a feedback run then stalled.) ``com_target_W``: r_c* instead
        of Lambda_c's (a contact-sequence certificate's COM).
        """
        support = tuple(i for i in range(4) if i != leg)
        if com_target_W is None:
            rc = self.body_target(state, leg, shrink, swing_target_W, tau)
        else:
            rc = np.asarray(com_target_W, float).reshape(3)
        u_f, u_n = self.body_directions(tau, state, rc, leg, swing_target_W)
        landing = swing_target_W is not None
        if self._holds_here(state, leg):
            held = self._held(state, support, rc, u_f, u_n, swing_target_W)
            if held is not None:
                return held
        sol = self.theta2(support, landing).solve(state, rc, u_f, u_n, swing_target_W, hint)
        self._count("theta2", sol.feasible)
        if not sol.feasible:
            return sol, []
        sol.state.support = support

        def again(rolled: State):
            return self.theta2(support, landing).solve(rolled, rc, u_f, u_n, swing_target_W)

        sol, path, why = self.body_path(state, sol, again, u_f, u_n)
        if why:
            sol.feasible = False
            sol.diagnosis = f"body move onto three legs: {why}"
            sol.failure = (kind_of(why),)
            return sol, []
        return self._ended(sol, path, support), path

    def _body_move_once(
        self, state: State, leg: int, tau: Trajectory, target, shrink, hint, com_target=None
    ):
        """:meth:`body_move`, remembering its failures for this run.

        A body move is a deterministic function of its inputs (Theta2 starts from the
        state, not from its last solve), and the recursive planner (8.5) asks for the same
        failing one again with every ambition that keeps the body target (the plain pose
        of the first foothold, the other footholds), each repeat costing seconds.
        """
        arrays = [state.base_position_W, state.base_quaternion_xyzw, state.joints_rad,
                  state.feet_W]  # fmt: skip
        if target is not None:
            arrays.append(np.asarray(target, float))
        if hint is not None:
            arrays += [hint.base_position_W, hint.base_quaternion_xyzw, hint.joints_rad]
        if com_target is not None:
            arrays.append(np.asarray(com_target, float))
        key = (
            leg,
            target is None,
            hint is None,
            com_target is None,
            shrink,
            id(tau),
        ) + tuple(np.ascontiguousarray(a, float).tobytes() for a in arrays)
        failed = self._failed_moves.get(key)
        if failed is not None:
            return failed, []
        sol, path = self.body_move(state, leg, tau, target, shrink, hint, com_target)
        if not sol.feasible:
            if len(self._failed_moves) >= FAILED_MOVES_KEPT:
                self._failed_moves.clear()
            self._failed_moves[key] = sol
        return sol, path

    def _holds_here(self, state: State, leg: int) -> bool:
        """Whether the two-beat crawl keeps the body still before ``leg`` swings.

        With ``com_target`` "two_beat" on level ground, where the COM stands
        ``two_beat_margin_m`` inside the triangle of the other three feet already (the
        second swing of a pair).
        """
        if self.settings.com_target != "two_beat" or not self.level_under(state):
            return False
        sup = [i for i in range(4) if i != leg]
        com = self.check.com_W(state)
        return support_margin_m(state.feet_W[sup], com) >= self.two_beat_margin_m

    def _held(self, state: State, support, rc, u_f, u_n, swing_target_W):
        """(solution, samples) of a body move that stays where it is, or None.

        :meth:`planner.problems.theta2.Theta2.hold`: the start passes Theta2's checks on
        three legs; the path is the start twice (a move of no length, no time).
        """
        held = self.theta2(support, swing_target_W is not None).hold(
            state, rc, u_f, u_n, swing_target_W
        )
        self._count("theta2_held", held.feasible)
        if not held.feasible:
            return None
        held.state.support = support
        path = [state, held.state]
        if self.path_problem(path):
            return None
        return self._ended(held, path, support), path

    def _ended(self, sol, path: list[State], support):
        """``sol`` ending on the path's end keyframe (:meth:`path_end`).

        Keeps the landing joints Theta2 found the pose with (Theta3's start).
        """
        land = sol.state.info.get("landing")
        sol.state = self.path_end(path, support)
        if land is not None:
            sol.state.info["landing"] = land
        return sol

    def body_path(self, state: State, sol, again, u_f, u_n):
        """(solution, samples, why) of the body move from ``state`` to ``sol.state``.

        The leaf's samples (eq. 6b); where they fail :meth:`path_problem`, ``again(rolled)``
        solves the move once more from the stance feet where the path left them, and a
        leg link sweeping an edge gets a via pose (:meth:`_via_path`). ``why`` is "" for a
        path that passes. ``sol.state.support`` must be set.
        """
        support = sol.state.support
        path = interpolate_leaf(
            self.robot, self.terrain, state, sol.state, self.body_samples_at(state)
        )
        why = self.path_problem(path)
        if why:
            # the stance feet roll along the path (mm; more when the body pitches), so the
            # path ends on other feet than Theta2 placed its pose on: solve it again on the
            # rolled feet, and interpolate to that pose
            rolled = state.copy()
            rolled.feet_W = path[-1].feet_W.copy()
            second = again(rolled)
            self._count(second.problem.lower(), second.feasible)
            if second.feasible:
                second.state.support = support
                second.state.feet_W = state.feet_W.copy()
                path2 = interpolate_leaf(
                    self.robot, self.terrain, state, second.state, self.body_samples_at(state)
                )
                why2 = self.path_problem(path2)
                margin2 = kind_of(why2) is FailureKind.LINK_MARGIN
                if not why2 or margin2 == (kind_of(why) is FailureKind.LINK_MARGIN):
                    sol, path, why = second, path2, why2
        if kind_of(why) is FailureKind.LINK_MARGIN:  # a leg link sweeps past an edge
            via_path = self._via_path(state, sol.state, path, u_f, u_n)
            if via_path is not None:
                why2 = self.path_problem(via_path)
                if not why2:
                    path, why = via_path, ""
        return sol, path, why

    def _via_path(self, start: State, end: State, path: list[State], u_f, u_n):
        """A body move through a via pose where ``path`` brings a leg link nearest the terrain.

        Beyond the paper: the leaf's straight line in exponential coordinates (eq. 6b) can
        sweep a thigh or shank past a step edge although both ends clear it. Theta1 (the
        COM held where the first failing sample has it, leg links clear by the keyframe margin)
        picks a via pose on the same leaf there; the move is then start -> via -> end.
        Returns the new path, or None when Theta1 finds no via pose.
        """
        links = leg_links(self.robot)
        worst = [
            float(
                links.path_margin(
                    self.terrain,
                    self.robot.q_from(s.base_position_W, s.base_quaternion_xyzw, s.joints_rad),
                ).min()
            )
            for s in path
        ]
        k = next((i for i, m in enumerate(worst) if m < 0.0), int(np.argmin(worst)))
        probe = path[k].copy()
        probe.feet_W = start.feet_W.copy()
        support = end.support
        if support not in self._via_theta1:
            # the via pose is on four feet: no three-leg tip margin
            opts = replace(self.settings.theta, balance_margin_m=-np.inf)
            self._via_theta1[support] = self.shared(Theta1, opts, support=support)
        sol = self._via_theta1[support].solve(probe, self.check.com_W(path[k]), u_f, u_n)
        self._count("theta1", sol.feasible)
        if not sol.feasible:
            return None
        via = sol.state
        via.support = support
        n = self.body_samples_at(start)
        first = interpolate_leaf(self.robot, self.terrain, start, via, n)
        end2 = end.copy()
        end2.feet_W = first[-1].feet_W.copy()
        second = interpolate_leaf(self.robot, self.terrain, first[-1], end2, n)
        return first + second[1:]
