"""Local planning by hard persuasion and the search Omega (paper section 8.1).

The most basic planner of the paper: a fixed gait step sequence S (the crawl by default)
is cycled; for each leg i_f of S

1. the body moves on the current leaf of S0 onto the three other legs with its COM
   *exactly on tau*: the search Omega_1 (section 7.6, eq. 11) looks along tau for the
   largest lambda at which hard persuasion Theta1 (7.2) is feasible. Feasibility along
   lambda is an interval (the COM must lie over the support triangle and every leg within
   reach), which need not contain the body's current lambda, so a few probes at
   lambda_now + stride x (1, 1/2, 0, -1/2, -1) find a feasible lambda first, and bisection
   (:func:`planner.search.omega`) then pushes it forward toward the first infeasible probe;
2. i_f is lifted, swung and placed with Theta3 near Lambda_t, as in the soft planner.

A failure (no feasible lambda, or no foothold) moves on to the next leg of S: unlike the
gait step queue of 8.2, a failed leg waits a whole cycle (section 8.2, comment ii). The
planner is stuck after ``max_fails_in_row`` failures in a row (two cycles by default).
Less robust than 8.2: the COM cannot leave tau to find balance. Beyond the paper, one
freedom: the COM may sit beside tau, by at most ``LATERAL_BAND_M``, on the side of the
support triangle's incentre. On tau itself a crawl's three-leg COM is 16 mm from the
diagonal edge at best on flat ground, and MuJoCo tips over below about 20 mm
(:mod:`planner.stability`); lambda is still searched along tau.
"""

from __future__ import annotations

import numpy as np

from planner.heuristics import (
    reference_directions,
    support_body_target_W,
    support_incentre_W,
)
from planner.interpolate import interpolate_leaf
from planner.local.base import TORQUE_FRACTION, LocalPlanner, Step, Walk, _Run
from planner.problems import Theta1
from planner.search import omega
from planner.state import State
from planner.trajectory import Trajectory

PROBES = (1.0, 0.5, 0.0, -0.5, -1.0)  # lambda offsets in strides, most ambitious first
LATERAL_BAND_M = 0.03  # the COM target may sit this far beside tau, toward the incentre


class HardPlanner(LocalPlanner):
    """The fixed-sequence, hard-persuasion planner of section 8.1."""

    name = "hard"

    def __init__(self, robot, terrain, mu: float | None = None, settings=None):
        super().__init__(robot, terrain, mu, settings)
        self._theta1: dict[tuple[int, ...], Theta1] = {}
        self.stats["theta1"] = [0, 0]

    def theta1(self, support) -> Theta1:
        """Theta1 for a support pattern (built on first use)."""
        key = tuple(sorted(support))
        if key not in self._theta1:
            self._theta1[key] = Theta1(
                self.robot, self.terrain, support=key, options=self.settings.theta, mu=self.mu
            )
        return self._theta1[key]

    def holds_on_three(self, state: State, leg: int) -> bool:
        """With ``leg`` lifted, the joint torques stay within ``TORQUE_FRACTION`` of the limits.

        Theta1 pins the COM on tau and knows nothing of the motors; a pose that needs a
        knee at its effort limit once the leg lifts cannot be held by the servos.
        """
        sup = [i for i in range(4) if i != leg]
        q = self.robot.q_from(state.base_position_W, state.base_quaternion_xyzw, state.joints_rad)
        res = self.torques.solve(
            q, sup, self.mu, self.terrain.normal(state.feet_W), least_squares=True
        )
        return bool(res.ratio <= TORQUE_FRACTION)

    def lateral_offset(self, state: State, leg: int, tau: Trajectory, lam: float) -> np.ndarray:
        """Horizontal offset [m] of the COM target from tau, toward the support incentre."""
        p = np.asarray(tau.point(lam), float).reshape(3)
        u_f, _ = reference_directions(tau, self.terrain, p, lam=lam)
        side = np.cross([0.0, 0.0, 1.0], u_f)
        side /= max(float(np.linalg.norm(side)), 1e-12)
        s = float(side @ (support_incentre_W(state, leg) - p))
        return float(np.clip(s, -LATERAL_BAND_M, LATERAL_BAND_M)) * side

    def search_body(self, state: State, leg: int, tau: Trajectory, stride_m: float, target_W):
        """Omega_1 for the body move before ``leg`` swings: (Theta1 solution, lambda) or None.

        Returns the feasible solution with the largest lambda found, else (last failed
        solution, None).
        """
        problem = self.theta1([i for i in range(4) if i != leg])
        lam_now = float(tau.closest_lambda(self.check.com_W(state)))
        lams = [float(tau.clip(lam_now + f * stride_m)) for f in PROBES]
        offset = self.lateral_offset(state, leg, tau, lam_now)
        feet = self._plane_feet(state, leg, target_W)  # the same for every lambda

        def targets(lam: float):
            """r_c* on tau (beside it by ``offset``), at the height the footholds ask for."""
            rc = np.asarray(tau.point(lam), float).reshape(3) + offset
            u_f, u_n = reference_directions(tau, self.terrain, rc, lam=lam)
            if feet is not None:
                rc[2], u_n = support_body_target_W(
                    self.robot, self.terrain, feet, rc, self.com_height_m(), u_f, u_n
                )
            return rc, u_f, u_n

        last = None
        for k, lam in enumerate(lams):
            rc, u_f, u_n = targets(lam)
            sol = problem.solve(state, rc, u_f, u_n, target_W)
            self._count("theta1", sol.feasible)
            if sol.feasible and not self.holds_on_three(sol.state, leg):
                sol.feasible = False
                sol.diagnosis = "the three-leg stance needs joint torques near the limits"
            if not sol.feasible:
                last = sol
                continue
            if k == 0:
                return sol, lam
            # push forward by bisection toward the last infeasible probe (eq. 11)
            res = omega(
                problem,
                sol.state,
                tau,
                lam,
                lams[k - 1],
                com_offset_W=offset,
                max_solves=4,
                swing_target_W=target_W,
                targets=targets,
            )
            self.stats["theta1"][0] += res.solves
            self.stats["theta1"][1] += len(res.xi)
            if res.best is not None and res.best[1] > lam and self.holds_on_three(res.best[0], leg):
                best_state, best_lam = res.best
                sol.state = best_state
                return sol, best_lam
            return sol, lam
        return last, None

    def hard_step(self, state: State, leg: int, tau: Trajectory, stride_m: float) -> Step:
        """One step of section 8.1: Omega_1 body move, then Theta3 placement.

        When Lambda_t's foothold fails, up to ``OTHER_FOOTHOLDS`` others of the leg's
        reachable, safe region are tried, as in the soft planner (issue 15 item 3).
        """
        target, _ = self.foothold_target(state, leg, tau, stride_m)
        first = self._hard_step_to(state, leg, tau, stride_m, target)
        if first.ok:
            return first
        for other in self.other_footholds(state, leg, tau, target):
            step = self._hard_step_to(state, leg, tau, stride_m, other)
            if step.ok:
                return step
        return first

    def _hard_step_to(self, state: State, leg: int, tau: Trajectory, stride_m: float, target):
        """Omega_1 body move ready for the foothold ``target``, then Theta3 placement."""
        sol, lam = self.search_body(state, leg, tau, stride_m, target)
        if lam is None:
            why = sol.diagnosis if sol is not None else "no probe"
            return Step(leg, False, state, None, None, [], [], "body_move", f"Omega_1: {why}")
        moved = sol.state
        moved.support = tuple(i for i in range(4) if i != leg)
        body_path = interpolate_leaf(
            self.robot, self.terrain, state, moved, self.settings.body_samples
        )
        why = self.path_problem(body_path)
        if why:
            return Step(leg, False, state, None, None, [], [], "body_move", f"Omega_1: {why}")
        moved = self.path_end(body_path, moved.support)
        sol3, swing_path = self.swing(moved, leg, tau, stride_m, target)
        if not sol3.feasible:
            return Step(
                leg, False, state, moved, None, body_path, [], "foot_placement", sol3.diagnosis
            )
        return Step(leg, True, state, moved, sol3.state, body_path, swing_path)

    def _run(self, walk: Walk, run: _Run) -> str:
        sequence = list(self.settings.gait)
        fails_in_row = 0
        k = 0
        while not (message := self.stop_reason(walk, run, fails_in_row)):
            run.cycles += 1
            leg = sequence[k % len(sequence)]
            k += 1
            step = self.hard_step(walk.state, leg, run.tau, self.stride_m())
            walk.add(step)
            if step.ok:
                fails_in_row = 0
                self.report(walk, run)
            else:
                self.failed(run, step)
                fails_in_row += 1
        return message


__all__ = ["HardPlanner"]
