"""Theta3, foot placement (paper section 7.4, eq. 9).

With the body pose g* and the three stance feet fixed, search the swing leg's three joint
angles (the paper's choice of search space: simple box bounds) for a foothold on the
terrain: the sphere rests on the terrain (f_T(r_if) = 0 at its contact point), on ground
no steeper than atan(mu). Objective (section 7.4): sigma1 = h_m(|r_if - r_t|) with the
paper's free choice of the decreasing h_m made h_m(d) = exp(-d^2 / (2 l^2)), l =
``target_length_m`` (closeness to the target foothold of Lambda_t), sigma2 = 1 - g^.n
(flat ground), sigma3 as in :func:`~planner.problems.base.sigma3_ca`; as a sum of logs.

For the recursive planner of 8.5 the ambition parameter rho_3 scales the target's
distance; see :mod:`planner.local.recursive`.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from planner.problems.base import (
    ThetaOptions,
    ThetaProblem,
    ThetaSolution,
    contact_on_terrain_ca,
    gaussian_ca,
    sigma3_ca,
    terrain_height_function,
)
from planner.state import State


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
        if o.slope_limit:
            self.constrain("slope", slope2, -np.inf, self.mu**2)
        self.maximise_log(
            "sigma1", o.placement_weights[0], gaussian_ca(contact - target, o.target_length_m)
        )
        self.maximise_log("sigma2", o.placement_weights[1], 1 + normal[2])  # 1 - g^.n, g^ = -z
        d_theta = th - ca.DM(r.theta_nor[i])
        self.maximise_log("sigma3", o.placement_weights[2], sigma3_ca(d_theta, o))
        self._contact_fun = ca.Function("contact", [contact_xy], [contact])

    def solve(self, state: State, target_W, x0=None) -> ThetaSolution:
        """Theta3(g*, tau, {r_i*}, i_f) of eq. 9 from a state whose leg ``leg`` swings.

        The result keeps ``state``'s body pose and other legs and puts leg ``leg`` down.
        """
        self._context = state  # the solve's fixed part, read by _state_from_x
        # CasADi reshapes column-major: R^T flattened row-major is R column-major.
        p = self.pack_params(
            {"p": state.base_position_W, "R": state.base_rotation_W.T.ravel(), "target_W": target_W}
        )
        if x0 is None:
            x0 = self.initial_guess(state)
        return self.solve_packed(p, np.asarray(x0, float))

    def initial_guess(self, state: State) -> np.ndarray:
        """Decision vector at ``state``: the leg's joints and its foot's current xy."""
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
        return v
