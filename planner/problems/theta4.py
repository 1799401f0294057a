"""Theta4, initial placement (paper section 7.5, eq. 10).

Given only the body position v(g) = r_c* near the start, search the orientation and all
twelve joint angles so that the four feet rest on the terrain (f_T(r_i) = 0), on ground no
steeper than atan(mu), with the body clear of the terrain and, when forces are on, the
eq. 5 forces of all four feet positive and inside their friction cones (section 7.5 d, e).
Objective sigma1 * sigma2 * sigma3 (as logs).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from planner.body import statics
from planner.body.state import S0, State
from planner.core.lie import rotation_from_vector, vector_from_rotation
from planner.core.units import GRAVITY_M_S2
from planner.problems.base import (
    ThetaOptions,
    ThetaProblem,
    ThetaSolution,
    com_W_ca,
    contact_on_terrain_ca,
    sigma3_ca,
    terrain_height_function,
)


class Theta4(ThetaProblem):
    """Initial placement on S0 around a given body position."""

    name = "Theta4"

    def __init__(self, robot, terrain, options=None, mu: float = 0.7):
        super().__init__(robot, terrain, options or ThetaOptions(), mu)

    def _declare(self) -> None:
        o, r = self.options, self.robot
        phi = self.var("phi", 3, -np.pi, np.pi)
        th = self.var("theta", 12, r.lower_rad.ravel(), r.upper_rad.ravel())
        s1 = self.var("s1", 1, o.sigma_floor)
        s2 = self.var("s2", 1, o.sigma_floor)
        pos = self.par("rc_star", 3)
        u_f = self.par("u_f", 3)
        u_n = self.par("u_n", 3)
        R = self.rotation(phi)
        centres = self.kin.feet_W_ca(pos, R, th)
        hfun = terrain_height_function(self.terrain)
        contacts_xy = self.var("contacts_xy", 8)
        gaps, contacts, normals, slopes = [], [], [], []
        for i in range(4):
            contact, centre_on, normal, slope2 = contact_on_terrain_ca(
                hfun, contacts_xy[2 * i : 2 * i + 2], r.foot_radius_m
            )
            gaps.append(centres[:, i] - centre_on)
            contacts.append(contact)
            normals.append(normal)
            slopes.append(slope2)
        self.constrain("foot_on_terrain", ca.vertcat(*gaps))
        if o.slope_limit:
            self.constrain("slope", ca.vertcat(*slopes), -np.inf, self.mu**2)
        self.constrain_body_pose(pos, R, phi, s1, s2, u_f, u_n)
        if o.forces:
            com = com_W_ca(self, pos, R, th)
            F = statics.equilibrating_forces_ca(contacts, com, r.total_mass_kg, (0, 1, 2, 3))
            cone = statics.friction_cone_residuals_ca(
                F, self.mu, (0, 1, 2, 3), normals, eps_N=o.friction_eps_N
            )
            fmin = o.min_normal_force_frac * r.total_mass_kg * GRAVITY_M_S2
            self.constrain("forces_normal", cone[0::2], fmin, np.inf)
            self.constrain("forces_cone", cone[1::2], 0.0, np.inf)
        self.maximise_log("sigma1", o.weights[0], s1)
        self.maximise_log("sigma2", o.weights[1], s2)
        d_theta = th - ca.DM(r.theta_nor.ravel())
        self.maximise_log("sigma3", o.weights[2], sigma3_ca(d_theta, o))
        self._contacts_fun = ca.Function("contacts", [contacts_xy], [ca.horzcat(*contacts)])

    def solve(self, rc_star_W, u_f, u_n, heading_rad: float | None = None) -> ThetaSolution:
        """Theta4(r_c*, tau) of eq. 10: a standing configuration with body origin r_c*."""
        u_f = np.asarray(u_f, float) / np.linalg.norm(u_f)
        u_n = np.asarray(u_n, float) / np.linalg.norm(u_n)
        p = self.pack_params({"rc_star": rc_star_W, "u_f": u_f, "u_n": u_n})
        yaw = np.arctan2(u_f[1], u_f[0]) if heading_rad is None else heading_rad
        R0 = rotation_from_vector(np.array([0.0, 0.0, yaw]))
        x0 = np.concatenate(
            [
                vector_from_rotation(R0),
                self.robot.theta_nor.ravel(),
                [max(float(u_f @ R0[:, 0]), self.options.sigma_floor)],
                [max(float(u_n @ R0[:, 2]), self.options.sigma_floor)],
                (self.kin.feet_B(self.robot.theta_nor) @ R0.T + p[:3])[:, :2].ravel(),
            ]
        )
        return self.solve_packed(p, x0)

    def _state_from_x(self, x: np.ndarray, p: np.ndarray) -> State:
        pos = p[self._p_slices["rc_star"]]
        phi = self.x_block(x, "phi")
        th = self.x_block(x, "theta")
        contacts = np.array(self._contacts_fun(self.x_block(x, "contacts_xy"))).T
        return State(pos, rotation_from_vector(phi), contacts, th.reshape(4, 3), stratum=S0)

    def _violations(self, state: State, x, p) -> dict[str, float]:
        ck = self.check
        v = {
            "joint_limits": ck.joint_limits(state),
            "clearance": ck.clearance(state),
            "orientation": ck.orientation(state),
            "foot_on_terrain": ck.on_terrain(state, range(4)),
            "contact": ck.contacts(state, range(4)),
        }
        if self.options.slope_limit:
            v["slope"] = ck.slope(state, range(4), self.mu)
        viol, forces = ck.forces(state, (0, 1, 2, 3), self.mu)
        state.forces_W = forces
        if self.options.forces:
            v["forces"] = max(viol, 0.0)
        return v
