"""Local planning by hard persuasion and the search Omega (paper section 8.1).

The most basic planner of the paper: a fixed gait step sequence S (the crawl by default)
is cycled; for each leg i_f of S

1. the body moves on the current leaf of S0 onto the three other legs with its COM
   *exactly on tau*: the search Omega_1 (section 7.6, eq. 11) looks along tau for the
   largest lambda at which hard persuasion Theta1 (7.2) is feasible. Feasibility along
   lambda is an interval (the COM must lie over the support triangle and every leg within
   reach), which need not contain the body's current lambda. Theta1's own force precheck
   (no solve) screens a window of lambdas around the body's first, and Omega's bisection
   runs over those that pass, farthest first; a lambda counts as feasible only when the
   body path to its pose passes every sample check too;
2. i_f is lifted, swung and placed with Theta3 near Lambda_t, as in the soft planner
   (:meth:`LocalPlanner.step` with this planner's :meth:`HardPlanner.body_move`: the
   same other footholds as soft).

A failure (no feasible lambda, or no foothold) moves on to the next leg of S: unlike the
gait step queue of 8.2, a failed leg waits a whole cycle (section 8.2, comment ii). The
planner is stuck after ``max_fails_in_row`` failures in a row (two cycles by default).
Less robust than 8.2: the COM cannot leave tau to find balance. Beyond the paper, two
freedoms: the COM may sit beside tau, by at most ``LATERAL_BAND_M`` (``WIDE_LATERAL_BAND_M``
in a second walk where the first stalls), where it is deepest
inside the support triangle (on tau itself a crawl's three-leg COM is 16 mm from the
diagonal edge at best on flat ground, and MuJoCo tips over below about 20 mm,
:mod:`planner.body.stability`); and its height is free within ``HEIGHT_BAND_M`` of the target's
(Theta1's ``height_band_m``: pinned in 3-D, the COM stood 7 mm too high for a leg's reach
on a slope). Lambda is still searched along tau, and the footholds, body paths (rolled
feet, via poses) and swings are the soft planner's, with the recursive planner's refusal
of landings the body cannot pass over next to a tall edge
(:meth:`~planner.planning.local.LocalPlanner.blocks_passage`; without it hard stalls before a
barrier).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from planner.body.stability import support_margin_m
from planner.body.state import State
from planner.motion.heuristics import (
    reference_directions,
    support_body_target_W,
)
from planner.motion.trajectory import Trajectory
from planner.planning.local import TORQUE_FRACTION
from planner.planning.omega import farthest_feasible
from planner.planning.soft import SoftPlanner
from planner.problems import Theta1
from planner.problems.base import ThetaSolution

SCAN_STRIDES = (-1.0, 1.5)  # the window of lambdas screened, in strides from the body's
SCAN_STEP = 0.125  # ... every this many strides
MAX_SCREENED_SOLVES = 4  # Theta1 solves over the screened lambdas before Omega's bisection
LATERAL_BAND_M = 0.03  # the COM target may sit this far beside tau
# ... and this far in a second walk, planned when the first stalls within the time budget
# (:meth:`HardPlanner.plan`). Chosen from planner runs: at 3 cm the front feet can stop
# before a barrier, the hind ones catch up, and no support triangle holds a COM within
# 3 cm of tau; 4 cm for the first walk stalls a step climb that 3 cm walks (5 cm: stairs);
# 5 cm for the second walk did not reach
WIDE_LATERAL_BAND_M = 0.04
HEIGHT_BAND_M = 0.03  # the COM's height is free this far around the target's (Theta1)
LATERAL_SPACING_M = 0.005  # offsets tried across the band this far apart


def _unheld(why: str) -> ThetaSolution:
    """A Theta1 failure for a window of lambdas none of whose COM targets can be held."""
    return ThetaSolution(
        problem="Theta1", status="Infeasible_Forces", feasible=False, state=None,
        objective=float("inf"), objective_terms={}, iterations=0, solve_time_s=0.0,
        build_time_s=0.0, diagnosis=f"Theta1: no COM target along tau can be held: {why}",
        violations={"forces": float("inf")},
    )  # fmt: skip


class HardPlanner(SoftPlanner):
    """The fixed-sequence, hard-persuasion planner of section 8.1."""

    name = "hard"
    fixed_sequence = True
    foothold_passage = True

    def __init__(self, robot, terrain, mu: float | None = None, settings=None):
        super().__init__(robot, terrain, mu, settings)
        self._theta1: dict[tuple[int, ...], Theta1] = {}
        self.stats["theta1"] = [0, 0]
        self.lateral_band_m = LATERAL_BAND_M

    def plan(self, start_xy, goal_xy, tau=None, progress=None, start_state=None):
        """8.1's walk (:meth:`LocalPlanner.plan`), planned twice where the first stalls.

        Where the first walk stops short of the goal with time left in the budget, a
        second one from the start has the COM free within ``WIDE_LATERAL_BAND_M`` of tau
        (the rest of the budget); the walk that ends nearer the goal is returned, its
        ``stats["wide_band_retry"]`` saying so.
        """
        args = (start_xy, goal_xy, tau, progress, start_state)
        first = super().plan(*args)
        budget = float(self.settings.time_budget_s)
        spent = float(first.stats["planning_time_s"])
        if first.reached_goal or first.interrupted or spent >= budget:
            return first
        kept = self.settings
        self.settings = replace(kept, time_budget_s=budget - spent)
        self.lateral_band_m = WIDE_LATERAL_BAND_M
        try:
            second = super().plan(*args)
        finally:
            self.settings, self.lateral_band_m = kept, LATERAL_BAND_M
        best = second if second.distance_to_goal_m < first.distance_to_goal_m else first
        best.stats["planning_time_s"] = spent + float(second.stats["planning_time_s"])
        best.stats["wide_band_retry"] = {
            "first_distance_to_goal_m": first.distance_to_goal_m,
            "first_message": first.message,
            "kept": "second" if best is second else "first",
        }
        return best

    def theta1(self, support) -> Theta1:
        """Theta1 for a support pattern (built on first use)."""
        key = tuple(sorted(support))
        if key not in self._theta1:
            self._theta1[key] = self.shared(Theta1, support=key, height_band_m=HEIGHT_BAND_M)
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
        """Horizontal offset [m] of the COM target from tau(lam), within the lateral band.

        The band is ``lateral_band_m`` (``LATERAL_BAND_M``, or ``WIDE_LATERAL_BAND_M`` in a
        second walk). The offset beside tau (across u_f) that puts the COM deepest inside
        the three stance feet's triangle: the support margin is concave along the line, so
        the best of the offsets ``LATERAL_SPACING_M`` apart is within half a spacing of
        its optimum.
        """
        p = np.asarray(tau.point(lam), float).reshape(3)
        u_f, _ = reference_directions(tau, self.terrain, p, lam=lam)
        side = np.cross([0.0, 0.0, 1.0], u_f)
        side /= max(float(np.linalg.norm(side)), 1e-12)
        sup = state.feet_W[[i for i in range(4) if i != leg]]
        band = self.lateral_band_m
        offsets = np.linspace(-band, band, 2 * int(round(band / LATERAL_SPACING_M)) + 1)
        margins = [support_margin_m(sup, p + s * side) for s in offsets]
        return float(offsets[int(np.argmax(margins))]) * side

    def search_body(self, state: State, leg: int, tau: Trajectory, stride_m: float, target_W):
        """Omega_1 for the body move before ``leg`` swings: ((solution, path), lambda).

        The lambdas of a window around the body's (``SCAN_STRIDES``, every ``SCAN_STEP``
        strides) are screened first by Theta1's own force precheck (eq. 5 forces in their
        cones, the COM ``balance_margin_m`` inside the triangle; no solve), each with its
        best offset beside tau. Theta1 is then solved at the farthest that passes; if it
        fails there, Omega's bisection (eq. 11) runs over the screened lambdas nearer the
        body, ``MAX_SCREENED_SOLVES`` solves in all. A lambda is feasible when Theta1 is
        and its body path passes (:meth:`LocalPlanner.body_path`). Returns the farthest
        feasible solution found with its path, else (the last failure, None).
        """
        problem = self.theta1([i for i in range(4) if i != leg])
        lam_now = float(tau.closest_lambda(self.check.com_W(state)))
        feet = self._plane_feet(state, leg, target_W)  # the same for every lambda

        def targets(lam: float):
            """r_c* beside tau, at the height the footholds ask for, and (u_f, u_n)."""
            rc = np.asarray(tau.point(lam), float).reshape(3)
            rc = rc + self.lateral_offset(state, leg, tau, lam)
            u_f, u_n = reference_directions(tau, self.terrain, rc, lam=lam)
            if feet is not None:
                rc[2], u_n = support_body_target_W(
                    self.robot, self.terrain, feet, rc, self.com_height_m(), u_f, u_n
                )
                rc = self.sunk_target(state, leg, rc, tau, target_W, u_f)
            return rc, u_f, u_n

        lo, hi = SCAN_STRIDES
        count = int(round((hi - lo) / SCAN_STEP)) + 1
        offsets = np.linspace(lo, hi, count) * stride_m
        window = sorted({float(tau.clip(lam_now + f)) for f in offsets})
        held, why = [], ""
        screened = {lam: targets(lam) for lam in window}
        for lam in reversed(window):  # farthest first
            ok, why_not = problem.force_precheck(state, screened[lam][0])
            if ok:
                held.append(lam)
            elif not why:
                why = why_not
        if not held:
            return _unheld(why), None

        last = None

        def solve(lam: float):
            """(solution, body path) at ``lam``, or None (``last`` says why)."""
            nonlocal last
            rc, u_f, u_n = screened[lam]
            sol = problem.solve(state, rc, u_f, u_n, target_W)
            self._count("theta1", sol.feasible)
            if sol.feasible and not self.holds_on_three(sol.state, leg):
                sol.feasible = False
                sol.diagnosis = "the three-leg stance needs joint torques near the limits"
            if sol.feasible:
                sol.state.support = problem.support
                sol, path, why = self.body_path(
                    state, sol, lambda rolled: problem.solve(rolled, rc, u_f, u_n, target_W),
                    u_f, u_n,
                )  # fmt: skip
                if not why:
                    return sol, path
                sol.feasible = False
                sol.diagnosis = why
            last = sol
            return None

        # the farthest held lambda; else a bisection over the held list (Omega, eq. 11)
        found, lam = farthest_feasible(held, solve, MAX_SCREENED_SOLVES)
        return (last, None) if lam is None else (found, lam)

    def body_move(self, state: State, leg: int, tau: Trajectory, swing_target_W=None,
                  shrink: float | None = None, hint: State | None = None,
                  com_target_W=None):  # fmt: skip
        """Omega_1's body move onto the three legs other than ``leg``: (solution, samples).

        Replaces the soft planner's Theta2 in :meth:`LocalPlanner.step`, so a step of 8.1
        has the soft planner's footholds (Lambda_t's, then the others of the leg's safe
        region) and the paper's plain pose (no swing-ready constraint) when the foothold's fails.
        ``shrink``, ``hint`` and ``com_target_W`` (Lambda_c's and Theta2's) do not apply.
        """
        found, lam = self.search_body(
            state, leg, tau, self.stride_at(state, leg, tau), swing_target_W
        )
        if lam is None:
            sol = found
            sol.diagnosis = f"Omega_1: {sol.diagnosis}"
            return sol, []
        sol, path = found
        sol.state = self.path_end(path, sol.state.support)
        return sol, path


__all__ = ["HardPlanner"]
