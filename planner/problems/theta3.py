"""Theta3, foot placement (paper section 7.4, eq. 9).

With the body pose g* and the three stance feet fixed, search the swing leg's three joint
angles (the paper's choice of search space: simple box bounds) for a foothold on the
terrain: the sphere rests on the terrain (f_T(r_if) = 0 at its contact point), on ground
no steeper than atan(mu). Objective (section 7.4): sigma1 = h_m(|r_if - r_t|) with the
paper's free choice of the decreasing h_m made h_m(d) = exp(-d^2 / (2 l^2)), l =
``target_length_m`` (closeness to the target foothold of Lambda_t), sigma2 = 1 - g^.n
(flat ground), sigma3 as in :func:`~planner.problems.base.sigma3_ca`; as a sum of logs.

For the recursive planner of 8.5 the ambition rho_3 scales the stride of the target
(:mod:`planner.planning.recursive`); the problem itself is unchanged.

Beyond the paper: the touch-down joints are first sought ``LANDING_LIMIT_MARGIN_RAD``
inside the URDF limits (:func:`~planner.problems.base.landing_bounds_rad`; a foot landed
with a joint at its stop may not lift off again along the normal), and within the full
limits only where no such landing exists (a stone reached sideways with the hip roll at
its stop: with the margin alone soft stalled on generated stepping stones that it walks
without it).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from planner.body.state import State
from planner.problems.base import (
    ThetaOptions,
    ThetaProblem,
    ThetaSolution,
    contact_on_terrain_ca,
    gaussian_ca,
    landing_bounds_rad,
    sigma3_ca,
    terrain_height_function,
)

NO_TARGET_RADIUS_M = 1e3  # target radius that leaves the constraint inactive [m]


class Theta3(ThetaProblem):
    """Foot placement of leg ``leg`` (0-based) on a leaf of S_{leg+1}."""

    name = "Theta3"

    def __init__(self, robot, terrain, leg: int, options=None, mu: float = 0.7):
        if leg not in range(4):
            raise ValueError(f"leg must be 0..3, got {leg!r}")
        self.leg = int(leg)
        super().__init__(robot, terrain, options or ThetaOptions(), mu)

    def _declare(self) -> None:
        o, r, i = self.options, self.robot, self.leg
        th = self.var("theta", 3, r.lower_rad[i], r.upper_rad[i])
        pos = self.par("p", 3)
        rot = self.par("R", 9)
        target = self.par("target_W", 3)
        R = ca.reshape(rot, 3, 3)
        centre = ca.mtimes(R, self.kin.foot_B_ca(i, th)) + pos
        hfun = terrain_height_function(self.terrain)
        contact_xy = self.var("contact_xy", 2)
        contact, centre_on, normal, slope2 = contact_on_terrain_ca(
            hfun, contact_xy, r.foot_radius_m
        )
        self.constrain("foot_on_terrain", centre - centre_on)
        self.constrain_leg_links(pos, R, {i: th})
        radius = self.par("target_radius_m", 1)
        miss = contact - target
        self.constrain("target_radius", ca.dot(miss, miss) - radius**2, -np.inf, 0.0)
        if o.slope_limit:
            self.constrain("slope", slope2, -np.inf, self.mu**2)
        self.maximise_log(
            "sigma1", o.placement_weights[0], gaussian_ca(contact - target, o.target_length_m)
        )
        self.maximise_log("sigma2", o.placement_weights[1], 1 + normal[2])  # 1 - g^.n, g^ = -z
        d_theta = th - ca.DM(r.theta_nor[i])
        self.maximise_log("sigma3", o.placement_weights[2], sigma3_ca(d_theta, o))
        self._contact_fun = ca.Function("contact", [contact_xy], [contact])

    def solve(
        self, state: State, target_W, x0=None, target_radius_m: float | None = None
    ) -> ThetaSolution:
        """Theta3(g*, tau, {r_i*}, i_f) of eq. 9 from a state whose leg ``leg`` swings.

        The result keeps ``state``'s body pose and other legs and puts leg ``leg`` down.
        ``target_radius_m`` (beyond the paper) makes closeness to the target a hard
        constraint: the contact point within that distance of it (a foothold chosen clear
        of edges stays clear); None leaves only the objective's pull.
        """
        self._radius = NO_TARGET_RADIUS_M if target_radius_m is None else float(target_radius_m)
        self._context = state  # the solve's fixed part, read by _state_from_x
        # CasADi reshapes column-major: R^T flattened row-major is R column-major.
        p = self.pack_params(
            {
                "p": state.base_position_W,
                "R": state.base_rotation_W.T.ravel(),
                "target_W": target_W,
                "target_radius_m": [self._radius],
            }
        )
        if x0 is None:
            x0 = self.initial_guess(state, target_W)
        x0 = np.asarray(x0, float)
        sol = self._solve_within(p, x0, landing_bounds_rad(self.robot, self.leg))
        if not sol.feasible:
            r = self.robot
            full = self._solve_within(p, x0, (r.lower_rad[self.leg], r.upper_rad[self.leg]))
            if full.feasible:
                sol = full
        return sol

    def _solve_within(self, p: np.ndarray, x0: np.ndarray, bounds_rad) -> ThetaSolution:
        """:meth:`solve_packed` with the swing leg's joints within ``bounds_rad`` (lo, hi).

        The problem's own bounds (the URDF limits) are restored afterwards.
        """
        sl = self._x_slices["theta"]
        kept = self.lbx[sl].copy(), self.ubx[sl].copy()
        self.lbx[sl], self.ubx[sl] = bounds_rad
        try:
            return self.solve_packed(p, x0)
        finally:
            self.lbx[sl], self.ubx[sl] = kept

    def initial_guess(self, state: State, target_W=None) -> np.ndarray:
        """Decision vector: IK of the foot on ``target_W`` when reachable, else ``state``'s.

        Starting at the target matters where the terrain between the foot and the target
        is a gap or an edge: from the current foot IPOPT would have to drag the contact
        point across it and stalls in the trench.
        """
        if target_W is not None:
            from planner.body.contact import foot_centre_from_contact

            t = np.asarray(target_W, float).reshape(3).copy()
            t[2] = float(self.terrain.height(t[0], t[1]))
            centre_W = foot_centre_from_contact(self.terrain, t, self.robot.foot_radius_m)
            centre_B = state.base_rotation_W.T @ (centre_W - state.base_position_W)
            ik = self.kin.ik_leg(self.leg, centre_B, reference_rad=state.joints_rad[self.leg])
            if ik.reachable:
                return np.concatenate([ik.joints_rad, t[:2]])
        foot_B = self.kin.foot_B(self.leg, state.joints_rad[self.leg])
        centre_W = state.base_rotation_W @ foot_B + state.base_position_W
        return np.concatenate([state.joints_rad[self.leg], centre_W[:2]])

    def _state_from_x(self, x: np.ndarray, p: np.ndarray) -> State:
        base = self._context
        contact = np.array(self._contact_fun(self.x_block(x, "contact_xy"))).ravel()
        joints = base.joints_rad.copy()
        joints[self.leg] = self.x_block(x, "theta")
        feet = base.feet_W.copy()
        feet[self.leg] = contact
        return State(base.base_position_W, base.base_rotation_W, feet, joints, stratum=0)

    def _violations(self, state: State, x, p) -> dict[str, float]:
        ck = self.check
        v = {
            "joint_limits": ck.joint_limits(state),
            "foot_on_terrain": ck.on_terrain(state, [self.leg]),
            "contact": ck.contacts(state, [self.leg]),
        }
        if self.options.slope_limit:
            v["slope"] = ck.slope(state, [self.leg], self.mu)
        miss = float(np.linalg.norm(state.feet_W[self.leg] - p[self._p_slices["target_W"]]))
        v["target_radius"] = max(miss - float(p[self._p_slices["target_radius_m"]][0]), 0.0)
        return v
