"""Theta1, hard persuasion (paper section 7.2, eq. 7).

The centre of mass is fixed at a point r_c* of the trajectory; only the orientation (and,
through the footholds, the joints) is searched. Same variables and constraints as
:class:`~planner.problems.theta2.Theta2` plus the equality COM = r_c*. With footholds and
COM fixed the eq. 5 forces are fixed too, so (as the paper says) they are checked once
before solving: if they leave the cones, no orientation can help and the solve is skipped.
On three legs the precheck also asks the COM ``options.balance_margin_m`` inside the support
triangle (:mod:`planner.body.stability`): Omega's largest feasible lambda then stops short of
the edge by that margin instead of at it.
Objective: sigma1 * sigma2 * sigma3 (as logs).

Beyond the paper, ``height_band_m`` > 0 pins only the COM's horizontal position to r_c*
(its height within the band, preferring r_c*'s by sigma4, the eq. 5 forces then checked in
the problem as Theta2 does): tau is a path over the ground whose height the planner only
guesses (:func:`planner.motion.heuristics.support_body_target_W`), and a COM pinned 7 mm too high
can leave a leg out of reach on a slope. The default 0 is eq. 7 as written.
"""

from __future__ import annotations

import time

import numpy as np

from planner.body import statics
from planner.body.stability import support_margin_m
from planner.body.state import State
from planner.core.failures import FailureKind
from planner.core.units import GRAVITY_M_S2
from planner.problems.base import ThetaSolution
from planner.problems.theta2 import Theta2


class Theta1(Theta2):
    """Hard persuasion: COM pinned to r_c*, orientation searched (section 7.2)."""

    name = "Theta1"
    fix_com = True
    rolls = False  # a via pose on the path's own samples (planner.planning.body_move)

    def __init__(self, robot, terrain, support=(0, 1, 2, 3), options=None, mu: float = 0.7,
                 height_band_m: float = 0.0, torque_rows: bool = False,
                 sway_rows: bool = False):  # fmt: skip
        self.height_band_m = float(height_band_m)
        super().__init__(robot, terrain, support, options, mu, torque_rows=torque_rows,
                         sway_rows=sway_rows)  # fmt: skip

    def _sibling(self, sway: bool) -> Theta1:
        """The same problem, COM still pinned, with the torque (and sway) rows."""
        return Theta1(
            self.robot, self.terrain, self.support, self.options, self.mu, self.height_band_m,
            torque_rows=True, sway_rows=sway,
        )  # fmt: skip

    def force_precheck(self, start: State, rc_star_W) -> tuple[bool, str]:
        """Whether the eq. 5 forces at COM r_c* satisfy (d) and (e) (section 7.2)."""
        eq = statics.equilibrating_forces(
            start.feet_W, rc_star_W, self.robot.total_mass_kg, self.support
        )
        if eq.degenerate:
            return False, f"degenerate support: {eq.message}"
        normals = self.terrain.normal(start.feet_W)
        fmin = self.options.min_normal_force_frac * self.robot.total_mass_kg * GRAVITY_M_S2
        for i in self.support:
            fn = float(eq.forces[i] @ normals[i])
            ft = float(np.linalg.norm(eq.forces[i] - fn * normals[i]))
            if fn < fmin:
                return False, f"leg {i + 1}: eq. 5 normal force {fn:.3g} N below {fmin:.3g} N"
            if ft > self.mu * fn:
                return False, f"leg {i + 1}: eq. 5 force outside the friction cone"
        if len(self.support) == 3:  # and a margin from tipping (planner.body.stability)
            have = support_margin_m(start.feet_W[list(self.support)], rc_star_W)
            if have < self.options.balance_margin_m:
                return False, (
                    f"the COM is {1000 * have:.1f} mm inside the support triangle "
                    f"(< {1000 * self.options.balance_margin_m:.0f} mm)"
                )
        return True, ""

    def solve(self, start: State, rc_star_W, u_f, u_n, swing_target_W=None) -> ThetaSolution:
        """Theta1(r_c*, tau, r_1*..r_4*, i_f) of eq. 7, warm-started at ``start``."""
        if self.options.forces:
            ok, why = self.force_precheck(start, rc_star_W)
            if not ok:
                return ThetaSolution(
                    problem=self.name,
                    status="Infeasible_Forces",
                    feasible=False,
                    state=None,
                    objective=float("inf"),
                    objective_terms={},
                    iterations=0,
                    solve_time_s=0.0,
                    build_time_s=self.build_time_s,
                    diagnosis=f"Theta1: COM target r_c* cannot be held: {why}",
                    violations={"forces": float("inf")},
                    failure=(FailureKind.FORCES,),
                )
        t0 = time.perf_counter()
        sol = super().solve(start, rc_star_W, u_f, u_n, swing_target_W)
        sol.solve_time_s = time.perf_counter() - t0
        return sol
