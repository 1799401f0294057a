"""The swing of a step: Theta3 (section 7.4) and the sampled path of the leg to its foothold.

Section 8.5's step lifts leg i_f on S_if and places it with Theta3; the swing's samples
follow the terrain (:func:`planner.motion.interpolate.interpolate_swing`), lower where the
higher path fails, and where a leg link cannot pass that way the leg is folded in joint
space (:func:`planner.motion.leg_swing.joint_space_swing`). A foothold on an edge is
refused; next to a tall edge the leg may land on its other knee branch
(:mod:`planner.planning.landing`).

:class:`Swings` is a part of :class:`planner.planning.local.LocalPlanner`; it uses the
planner's ``robot``, ``terrain``, ``mu``, ``settings`` and ``kin``, its Theta3 problems
(:meth:`theta3`, :meth:`_count`), the path checks
(:class:`planner.planning.path_checks.PathChecks`), the level-ground swing height and
samples (:class:`planner.planning.level.LevelGround`) and the knee choice
(:class:`planner.planning.landing.Landing`).
"""

from __future__ import annotations

import numpy as np

from planner.body.robot import LEG_NAMES
from planner.body.state import State
from planner.core.failures import FailureKind, kind_of
from planner.motion.heuristics import EDGE_MARGIN_M, foothold_hazard, lambda_t, reference_directions
from planner.motion.interpolate import interpolate_swing
from planner.motion.leg_swing import joint_space_swing
from planner.motion.trajectory import Trajectory

__all__ = ["TARGET_RADIUS_M", "WIDE_TARGET_RADIUS_M", "Swings"]

TARGET_RADIUS_M = 0.01  # a placed foot lands within this of its (edge-free) target [m]
WIDE_TARGET_RADIUS_M = 0.04  # ... or this, when the leg's links forbid the near footholds


class Swings:
    """Theta3 and the swing path of a step's leg (:meth:`swing`)."""

    def swing(
        self,
        state: State,
        leg: int,
        tau: Trajectory,
        step_m: float,
        target_W=None,
        knee: int | None = None,
    ):
        """Theta3 for ``leg`` toward ``target_W`` (default Lambda_t); returns (solution, samples).

        A swing path that leaves the leg's reach is retried once with half the clearance.
        ``knee`` (+1 forward, -1 rearward: :meth:`LegKinematics.knee_direction`): the knee
        branch to land on (a precomputed plan's, 8.3), instead of
        :meth:`_other_knee_landing`'s choice; the swing fails where it cannot land there
        (the feedback then tries a body nearer the support's incentre).
        """
        if target_W is None:
            target_W = lambda_t(self.robot, self.terrain, state, leg, tau, step_m=step_m)
        lifted = state.copy()
        lifted.stratum = leg + 1
        x0 = None
        land = state.info.get("landing")  # (target, joints) of a landing-ready Theta2
        if land is not None and np.allclose(land[0], target_W, atol=1e-9):
            x0 = np.concatenate([land[1], np.asarray(target_W, float)[:2]])
        for radius in (TARGET_RADIUS_M, WIDE_TARGET_RADIUS_M):
            sol = self.theta3(leg).solve(lifted, target_W, x0=x0, target_radius_m=radius)
            self._count("theta3", sol.feasible)
            # near an edge the leg's links may forbid every foothold close to the target:
            # let the foot land farther (the edge test below still applies)
            near = ("leg_clearance", "target_radius")
            if sol.feasible or not any(sol.violations.get(k, 0.0) > 1e-6 for k in near):
                break
        if not sol.feasible:
            return sol, []
        touch = sol.state
        touch.support = tuple(range(4))
        # the target keeps EDGE_MARGIN_M from edges, the foot lands within TARGET_RADIUS_M
        hazard = foothold_hazard(
            self.terrain,
            touch.feet_W[leg],
            self.robot.foot_radius_m,
            self.mu,
            EDGE_MARGIN_M - TARGET_RADIUS_M,
            forward_W=reference_directions(tau, self.terrain, touch.feet_W[leg])[0],
        )
        if hazard:
            sol.feasible = False
            sol.diagnosis = f"foothold of {LEG_NAMES[leg]} has {hazard}"
            return sol, []
        other = self._other_knee_landing(touch, leg, knee)
        if other is not None:  # a knee over an edge: land on the branch that clears it
            path, why = self._joint_space_swing(lifted, other, leg)
            if not why:
                sol.state = self.path_end(path, tuple(range(4)))
                return sol, path
        if knee is not None and self.kin.knee_direction(leg, touch.joints_rad[leg]) != knee:
            # the branch asked for (a plan's) or none: the plan's next steps assume it
            sol.feasible = False
            sol.diagnosis = (
                f"swing of {LEG_NAMES[leg]}: no landing on the plan's knee branch from here"
                + (f" ({why})" if other is not None else " (out of reach on it)")
            )
            return sol, []
        clearance = self.swing_clearance_m(lifted, leg, touch.feet_W[leg])
        for clr in (clearance, 0.5 * clearance):
            path = interpolate_swing(
                self.robot,
                self.terrain,
                lifted,
                touch,
                self.swing_samples_at(lifted, leg, touch.feet_W[leg]),
                clr,
                swing_leg=leg,
            )
            why = self.path_problem(path)
            self._count("swing_ik", not why)
            if not why:
                sol.state = self.path_end(path, tuple(range(4)))
                return sol, path
            if kind_of(why) is FailureKind.BALANCE:  # a lower swing does not move the COM less
                break
        if kind_of(why) is not FailureKind.BALANCE:  # the foot's path is clear, a link not:
            # fold the leg
            path, why2 = self._joint_space_swing(lifted, touch, leg)
            if not why2:
                sol.state = self.path_end(path, tuple(range(4)))
                return sol, path
        sol.feasible = False
        sol.diagnosis = f"swing of {LEG_NAMES[leg]}: {why}"
        sol.failure = (kind_of(why),)
        return sol, []

    def _joint_space_swing(self, lifted: State, touch: State, leg: int):
        """(samples, why): :func:`joint_space_swing` and the path checks ("" if executable)."""
        path = joint_space_swing(
            self.robot, self.terrain, lifted, touch, 2 * self.settings.swing_samples, leg
        )
        for sample in path or ():  # it passes an edge closely: slower (planner.motion.time_law)
            sample.info["over_edge"] = True
        why = "no path in the leg's joint space" if path is None else self.path_problem(path)
        self._count("swing_joint_space", not why)
        return path, why
