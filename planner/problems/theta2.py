"""Theta2, soft persuasion (paper section 7.3, eq. 8).

Find a point on the current leaf of S0 (all four footholds fixed) whose centre of mass is
near a target r_c*, with the body parallel to the terrain and facing along tau.

Decision variables: the body pose as compact exponential coordinates eps = [p, phi]
(section 4.7) and the twelve joint angles. Where the paper recovers the joints by inverse
kinematics inside the objective (and asks fmincon for a zero imaginary part), here the
joints are variables tied to the footholds by the forward kinematics equalities
FK_i(p, phi, theta_i) = r_i* + rho n_i: the same leaf, with smooth exact derivatives;
reachability and joint limits become ordinary constraints and bounds.

Beyond the paper's leaf, whose contact points stay still, the sphere feet can roll
(``ThetaOptions.rolling_feet``, off by default; :mod:`planner.body.rolling`): a stance
sphere's centre ends
at r_i* + rho n_i + rho w_i x n_i, w_i its shank's rotation vector since the start (a
smooth function of the pose and joints, exact derivatives), and the pose is solved for
those centres, the contacts, forces and balance taken there. The interpolated path rolls
the feet the same way, so it ends on this pose (3-4 mm median, 1 cm at a riser, off it
with the contact points held).

Constraints (section 7.3): (a) |phi| <= pi, (b) every vertex of P at least delta_c above
the terrain, (c) joint limits, (d) F_i.n_i > 0 and (e) friction cones for the eq. 5 forces
of the weight-carrying feet (switchable). Objective: sigma1 (forward axis along u_f),
sigma2 (up axis along u_n), sigma3 (joints near theta_nor), sigma4 (COM near r_c*),
sigma5 (forces inside the cones), combined as a weighted sum of logs (see base).

Beyond the paper, with three supporting legs the body move can be made *swing-ready*: the
hip centre of the leg about to swing must lie within ``SWING_REACH_FRACTION`` of its reach
of the sphere centre at the foothold it will be placed at (parameter ``swing_target_W``).
Without it the body drifts to where the COM target wants it and leaves a lagging leg
unable to reach its next foothold (the planner then stalls on steps and slopes).
With ``landing=True`` it is also *landing-ready*: three more variables, the swing leg's
joints at touch-down, must put its foot on the target's sphere centre from this body pose
with its thigh and shank clear of the terrain (planner.body.links margins). Stepping down an
edge, the body then moves to where the shank can pass the edge, which Theta3 (body fixed)
cannot do. With ``ThetaOptions.lift_ready`` it is also *lift-ready*: the swing leg can lift
its foot off from this body pose (:mod:`planner.problems.lift_ready`).

On three legs the pose must also be one the servos can hold: no support joint beyond
``torque_fraction`` of its URDF effort in the commanded (effort-weighted least-squares)
force distribution, checked with Clarabel. Those rows cost 2-3x per solve, so a pose that
fails the check only is solved again, from itself, by a sibling NLP that has them
(``torque_rows``): the forces are the KKT solution in closed form (exact derivatives) and
are kept inside the friction cones, where they equal the check's.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from planner.body import stability, statics
from planner.body.kinematics import hip_point_B
from planner.body.rolling import leg_rotations_W, rolled_centres_W, rolled_centres_W_ca
from planner.body.state import S0, State
from planner.body.stiffness import joint_sway_matrix_ca, sway_stiffness_of
from planner.body.torques import TorqueCheck, joint_efforts_nm, least_squares_ratios_ca
from planner.core.failures import FailureKind, kinds_of_groups
from planner.core.lie import coords_from_pose
from planner.core.units import GRAVITY_M_S2
from planner.motion.heuristics import frame_from_directions
from planner.problems.base import (
    FEASIBILITY_TOL,
    ThetaOptions,
    ThetaProblem,
    ThetaSolution,
    com_W_ca,
    gaussian_ca,
    landing_bounds_rad,
    sigma3_ca,
    state_from_pose_coords,
)
from planner.problems.lift_ready import LiftReady

SWING_REACH_FRACTION = 0.92  # swing-ready: hip within this fraction of reach of the target
NO_SWING_TARGET_M = 1e3  # reach bound that switches the swing-ready constraint off
STANCE_REACH_FRACTION = 0.96  # body-move ends keep every hip within this of its foot's reach
# the independent torque check is an SOCP (Clarabel) solved to about this accuracy in
# tau / effort; IPOPT holds the bound to 1e-9 and sits on it when it is active
TORQUE_SOCP_TOL = 1e-4
LANDING_WEIGHT = 0.1  # gamma of the landing joints' closeness to theta_nor (keeps them defined)
SWAY_ROUNDS = 3  # re-solves with the sway-stiffness rows, at most (each refreezes G)
SWAY_SLACK = 0.10  # the rows ask this much more than the bound (their G part is frozen)
_TRIL = np.tril_indices(6)  # the 21 entries of a symmetric 6 x 6 matrix's lower triangle


def _only_torque_or_sway(sol: ThetaSolution) -> bool:
    """Whether a solution misses only the torque or sway check (solved with their rows next)."""
    rest = [v for k, v in sol.violations.items() if k not in ("torque", "sway")]
    return sol.x is not None and max(rest, default=0.0) <= FEASIBILITY_TOL


def _sway_of(sol: ThetaSolution) -> float:
    """The sway stiffness [N/m] the independent check found for a solution's pose."""
    return float(sol.state.info.get("sway_n_per_m", np.inf)) if sol.state is not None else -np.inf


def _symmetric(tril):
    """A symmetric 6 x 6 CasADi matrix from its 21 lower-triangle entries (``_TRIL`` order)."""
    M = ca.SX.zeros(6, 6)
    for n, (i, j) in enumerate(zip(*_TRIL, strict=True)):
        M[i, j] = tril[n]
        M[j, i] = tril[n]
    return M


class Theta2(LiftReady, ThetaProblem):
    """Soft persuasion on a leaf of S0, built once per support pattern."""

    name = "Theta2"
    fix_com = False
    rolls = True  # the stance feet roll over the move (ThetaOptions.rolling_feet)
    height_band_m = 0.0  # Theta1's band for the pinned COM's height (0: pinned in 3-D)

    def __init__(
        self,
        robot,
        terrain,
        support=(0, 1, 2, 3),
        options=None,
        mu: float = 0.7,
        landing: bool = False,
        torque_rows: bool = False,
        sway_rows: bool = False,
    ):
        # torque_rows, sway_rows: the siblings that :meth:`solve` uses where a pose fails
        self.support = tuple(sorted(int(i) for i in support))
        if len(self.support) not in (3, 4):
            raise ValueError(f"support must name 3 or 4 legs, got {support!r}")
        self.landing = bool(landing) and len(self.support) == 3
        self.torque_rows = bool(torque_rows)
        self.sway_rows = bool(sway_rows) and self.torque_rows
        self._torque_problem = None  # the same NLP with the torque rows, built when needed
        self._sway_problem = None  # ... and with the sway-stiffness rows
        super().__init__(robot, terrain, options or ThetaOptions(), mu)

    @property
    def rolls_feet(self) -> bool:
        """Whether the stance spheres roll with their shanks (``rolling_feet``, 4.3).

        The paper's leaves hold each contact point still; a sphere foot that does not slide
        rolls, millimetres per body move (:mod:`planner.body.rolling`), and the pose is
        solved for the centres it rolls to: ``c + rho w x n``, w the shank's rotation from
        the start. The state's ``feet_W`` stay the start's (the move's leaf); its joints
        reach the rolled centres.
        """
        return self.rolls and self.options.rolling_feet

    def _declare(self) -> None:
        o, r = self.options, self.robot
        lo, hi = r.lower_rad.ravel(), r.upper_rad.ravel()
        pos = self.var("p", 3)
        phi = self.var("phi", 3, -np.pi, np.pi)
        th = self.var("theta", 12, lo, hi)
        s1 = self.var("s1", 1, o.sigma_floor)
        tilt_floor = o.sigma_floor if o.max_tilt_rad is None else float(np.cos(o.max_tilt_rad))
        s2 = self.var("s2", 1, max(o.sigma_floor, tilt_floor))
        rc = self.par("rc_star", 3)
        feet = self.par("feet_W", 12)  # contact points r_i*
        centres = self.par("centres_W", 12)  # sphere centres r_i* + rho n_i
        normals = self.par("normals_W", 12)
        u_f = self.par("u_f", 3)
        u_n = self.par("u_n", 3)

        R = self.rotation(phi)
        contacts = feet
        if self.rolls_feet:
            # the stance spheres roll with their shanks over the move (planner.body.rolling):
            # the pose reached holds where the feet will be, not where they were
            shanks = ca.reshape(self.par("shank_rotations_W", 36), 9, 4)
            normal_cols = ca.reshape(normals, 3, 4)
            rolled = rolled_centres_W_ca(
                self.kin, R, th, ca.reshape(centres, 3, 4), normal_cols, shanks
            )
            centres = ca.vec(rolled)
            contacts = ca.vec(rolled - self.robot.foot_radius_m * normal_cols)
        self.constrain("contact", ca.vec(self.kin.feet_W_ca(pos, R, th)) - centres)
        self._constrain_reach(pos, R, centres)
        self.constrain_body_pose(pos, R, phi, s1, s2, u_f, u_n)
        self.constrain_leg_links(pos, R, {i: th[3 * i : 3 * i + 3] for i in range(4)})
        com = com_W_ca(self, pos, R, th)
        band = self.height_band_m
        free_height = self.fix_com and band > 0.0
        if free_height:  # Theta1 with the COM pinned over r_c*, its height within a band
            self.constrain("com", com[0:2] - rc[0:2])
            self.constrain("com_height", com[2] - rc[2], -band, band)
        elif self.fix_com:
            self.constrain("com", com - rc)
        th_land = self._constrain_swing(pos, R, th, centres, normals)
        if o.forces and (free_height or not self.fix_com):
            self._constrain_forces(pos, R, th, contacts, normals, centres, com, th_land)
        d_theta = th - ca.DM(r.theta_nor.ravel())
        self.maximise_log("sigma1", o.weights[0], s1)
        self.maximise_log("sigma2", o.weights[1], s2)
        self.maximise_log("sigma3", o.weights[2], sigma3_ca(d_theta, o))
        if free_height:
            self.maximise_log("sigma4", o.weights[3], gaussian_ca(com[2] - rc[2], o.com_length_m))
        elif not self.fix_com:
            self.maximise_log("sigma4", o.weights[3], gaussian_ca(com - rc, o.com_length_m))

    def _constrain_reach(self, pos, R, centres) -> None:
        """Reach margin: no stance leg ends stretched to its reach.

        A singular leg cannot follow the few millimetres its rolling foot moves, nor
        correct a tracking error: each hip stays within ``STANCE_REACH_FRACTION`` of its
        leg's reach from its foot's sphere centre.
        """
        r = self.robot
        hips_B = [hip_point_B(lg) for lg in r.legs]
        centre_cols = ca.reshape(centres, 3, 4)
        stretch = [
            ca.sumsqr(ca.mtimes(R, ca.DM(hips_B[i])) + pos - centre_cols[:, i])
            - (STANCE_REACH_FRACTION * float(r.reach_m[i])) ** 2
            for i in range(4)
        ]
        self.constrain("reach", ca.vertcat(*stretch), -np.inf, 0.0)

    def _constrain_swing(self, pos, R, th, centres, normals):
        """On three feet: the swing leg's hip within reach of its target (swing-ready).

        Landing-ready too (``landing``): the swing leg's joints at touch-down (variables
        ``theta_land``, returned; None without ``landing``) reach the target's sphere
        centre from this body pose, thigh and shank clear of the terrain. Lift-ready
        (``lift_ready``, :meth:`_constrain_lift`): its joints at lift-off too.
        """
        o, r = self.options, self.robot
        th_land = None
        if len(self.support) == 3:
            (leg,) = set(range(4)) - set(self.support)
            hip_W = ca.mtimes(R, ca.DM(hip_point_B(r.legs[leg]))) + pos
            target = self.par("swing_target_W", 3)
            reach = self.par("swing_reach_m", 1)
            d = hip_W - target
            self.constrain("swing_ready", ca.dot(d, d) - reach**2, -np.inf, 0.0)
        if self.landing:
            # landing-ready: the swing leg's joints at touch-down (from this body pose) reach
            # the target's sphere centre with thigh and shank clear of the terrain
            th_land = self.var("theta_land", 3, *landing_bounds_rad(r, leg))
            land_W = ca.mtimes(R, self.kin.foot_B_ca(leg, th_land)) + pos
            self.constrain("landing", land_W - target)
            self.constrain_leg_links(pos, R, {leg: th_land}, name="landing_clearance")
            self.maximise_log(
                "sigma_land", LANDING_WEIGHT, sigma3_ca(th_land - ca.DM(r.theta_nor[leg]), o)
            )
            if o.lift_ready:
                self._constrain_lift(pos, R, leg, th[3 * leg : 3 * leg + 3], centres, normals)
        return th_land

    def _constrain_forces(self, pos, R, th, feet, normals, centres, com, th_land) -> None:
        """The support's eq.-5 forces inside the friction cones, and the COM's balance.

        Rows (d) and (e) of section 7.3 on the forces of eq. 5 with a least normal force,
        sigma5 (how far inside the cones they are) as a variable and an objective term;
        on three feet the COM inside the support triangle by ``balance_margin_m``, the
        joint torques and the sway stiffness when asked, and with ``landing`` the same
        forces and balance with the swing leg at touch-down (``th_land``).
        """
        o, r = self.options, self.robot
        feet_cols = ca.reshape(feet, 3, 4)
        normal_cols = ca.reshape(normals, 3, 4)
        F = self._eq5_forces_ca(feet_cols, com)
        ns = [normal_cols[:, i] for i in range(4)]
        fmin = o.min_normal_force_frac * r.total_mass_kg * GRAVITY_M_S2
        cone = statics.friction_cone_residuals_ca(
            F, self.mu, self.support, ns, eps_N=o.friction_eps_N
        )
        self.constrain("forces_normal", cone[0::2], fmin, np.inf)
        self.constrain("forces_cone", cone[1::2], 0.0, np.inf)
        s5 = self.var("s5", 1, o.sigma_floor)
        ratio = ca.vertcat(
            *[
                ca.dot(F[i], ns[i]) / ca.sqrt(ca.dot(F[i], F[i]) + o.friction_eps_N**2)
                for i in self.support
            ]
        )
        self.constrain("sigma5", ratio - s5, 0.0, np.inf)
        if len(self.support) == 3:  # the COM inside the support triangle with margin
            tri = [feet_cols[:, i] for i in self.support]
            self.constrain(
                "balance_margin",
                stability.support_margins_ca(tri, com),
                o.balance_margin_m,
                np.inf,
            )
        self.maximise_log("sigma5", o.weights[4], s5)
        if len(self.support) == 3 and o.torque_fraction is not None and self.torque_rows:
            self._constrain_torques(R, th, feet_cols, normal_cols, com)
        if len(self.support) == 3 and o.sway_stiffness is not None and self.sway_rows:
            self._constrain_sway(pos, R, th, ca.reshape(centres, 3, 4))
        if self.landing:
            # balance holds with the swing leg's mass at touch-down too (the COM set of
            # feasible eq. 5 forces is convex: the swing's COM between the two holds)
            (leg,) = set(range(4)) - set(self.support)
            th_all = ca.vertcat(*[th_land if i == leg else th[3 * i : 3 * i + 3] for i in range(4)])
            F_land = self._eq5_forces_ca(feet_cols, com_W_ca(self, pos, R, th_all))
            cone = statics.friction_cone_residuals_ca(
                F_land, self.mu, self.support, ns, eps_N=o.friction_eps_N
            )
            self.constrain("forces_landing_normal", cone[0::2], fmin, np.inf)
            self.constrain("forces_landing_cone", cone[1::2], 0.0, np.inf)
            self.constrain(
                "balance_margin_landing",
                stability.support_margins_ca(tri, com_W_ca(self, pos, R, th_all)),
                stability.PATH_BALANCE_MARGIN_M,
                np.inf,
            )

    def _constrain_torques(self, R, th, feet_cols, normal_cols, com) -> None:
        """Support joints within ``torque_fraction`` of their effort (commanded forces).

        The servos get the effort-weighted least-squares forces as feed-forward
        (:mod:`planner.body.torques`); a joint they load beyond its effort saturates. Joints
        without a finite effort are not constrained (and weigh as the strongest one).
        """
        effort = joint_efforts_nm(self.robot)
        finite = effort[np.isfinite(effort)]
        if not finite.size:
            return
        weighted = np.where(np.isfinite(effort), effort, finite.max())
        ratios, forces = least_squares_ratios_ca(
            self.kin,
            R,
            th,
            self.support,
            [feet_cols[:, i] for i in range(4)],
            [normal_cols[:, i] for i in range(4)],
            com,
            weighted,
            self.robot.total_mass_kg,
        )
        rows = [
            3 * n + j
            for n, i in enumerate(self.support)
            for j in range(3)
            if np.isfinite(effort[3 * i + j])
        ]
        frac = float(self.options.torque_fraction)
        self.constrain("torque", ratios[rows], -frac, frac)
        # those forces inside the friction cones: the commanded distribution is then this
        # one (the SOCP's optimum over the cones is the unconstrained one)
        F = [ca.SX.zeros(3, 1)] * 4
        for n, i in enumerate(self.support):
            F[i] = forces[n]
        cone = statics.friction_cone_residuals_ca(
            F,
            self.mu,
            self.support,
            [normal_cols[:, i] for i in range(4)],
            eps_N=self.options.friction_eps_N,
        )
        self.constrain("torque_forces", cone, 0.0, np.inf)

    def _constrain_sway(self, pos, R, th, centre_cols) -> None:
        """The sway-stiffness bound as rows (:mod:`planner.body.stiffness`).

        H = K_joint(x) + G with K_joint the servos' part (exact, a function of the pose
        and joints) and G the gravity and feed-forward part, frozen at the pose being
        improved (parameter ``sway_G``, lower triangle in units of the bound k_min):
        H / k_min - t I = L L^T, L lower triangular (21 variables ``sway_L``), so H is at
        least t k_min in every direction (parameter ``sway_target``: t).
        """
        sway = sway_stiffness_of(self.robot)
        need = sway.bound_n_per_m(self.options.sway_stiffness)
        G = _symmetric(self.par("sway_G", len(_TRIL[0])))
        target = self.par("sway_target", 1)
        factor = self.var("sway_L", len(_TRIL[0]))
        L = ca.SX.zeros(6, 6)
        for n, (i, j) in enumerate(zip(*_TRIL, strict=True)):
            L[i, j] = factor[n]
        centres = [centre_cols[:, i] for i in range(4)]
        K = joint_sway_matrix_ca(
            self.kin, sway.kp, sway.length_m, pos, R, th, centres, self.support
        )
        M = K / need + G - target * ca.DM.eye(6) - ca.mtimes(L, L.T)
        self.constrain("sway_psd", ca.vertcat(*[M[i, j] for i, j in zip(*_TRIL, strict=True)]))

    def _eq5_forces_ca(self, feet_cols, com):
        """Eq. 3-5 forces with the footholds fixed: linear in the COM.

        With positions rho_i = r_i - c relative to the support centroid c, force balance
        gives w = -m g / n, and moment balance S u = rho_c x (-m g) with the constant
        S = sum_i (|rho_i|^2 I - rho_i rho_i^T) (non-singular unless the feet are
        collinear). S^-1 is computed once per solve from the footholds and passed as a
        parameter, so F_i = u x rho_i + w costs a few flops inside IPOPT. Equal to
        :func:`planner.body.statics.equilibrating_forces` (tested).
        """
        weight = -self.robot.total_mass_kg * ca.DM(statics.GRAVITY_W)  # -m g
        if not hasattr(self, "_eq5_pars"):  # declared once, shared by every call
            self._eq5_pars = (
                self.par("support_centroid", 3),
                ca.reshape(self.par("support_S_inv", 9), 3, 3),
            )
        centroid, s_inv = self._eq5_pars
        w = weight / len(self.support)
        u = ca.mtimes(s_inv, ca.cross(com - centroid, weight))
        zero = ca.SX.zeros(3, 1)
        return [
            ca.cross(u, feet_cols[:, i] - centroid) + w if i in self.support else zero
            for i in range(4)
        ]

    def support_geometry(self, feet_W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centroid and S^-1 of the support feet (see :meth:`_eq5_forces_ca`)."""
        pts = np.asarray(feet_W, float)[list(self.support)]
        centroid = pts.mean(axis=0)
        rho = pts - centroid
        S = sum(float(q @ q) * np.eye(3) - np.outer(q, q) for q in rho)
        return centroid, np.linalg.inv(S)

    # ---- solving -------------------------------------------------------------------------
    def params(self, start: State, rc_star_W, u_f, u_n, swing_target_W=None) -> np.ndarray:
        """Parameter vector for footholds of ``start``, target r_c*, directions u_f, u_n.

        ``swing_target_W``: the contact point the swinging leg will be placed at (three
        supporting legs only); None switches the swing-ready constraint off.
        """
        from planner.body.contact import foot_centre_from_contact

        centres = foot_centre_from_contact(self.terrain, start.feet_W, self.robot.foot_radius_m)
        values = {}
        if "swing_target_W" in self._p_slices:
            (leg,) = set(range(4)) - set(self.support)
            if swing_target_W is None:
                target, reach = start.base_position_W, NO_SWING_TARGET_M
            else:
                target = foot_centre_from_contact(
                    self.terrain, np.asarray(swing_target_W, float), self.robot.foot_radius_m
                )
                reach = SWING_REACH_FRACTION * float(self.robot.reach_m[leg])
            if self.landing and swing_target_W is None:
                raise ValueError("Theta2(landing=True) needs the swing target")
            values |= {"swing_target_W": target, "swing_reach_m": [reach]}
        if "sway_G" in self._p_slices:  # set by ``_solve_sibling``
            values |= {"sway_G": np.zeros(len(_TRIL[0])), "sway_target": [0.0]}
        if "support_S_inv" in self._p_slices:
            centroid, s_inv = self.support_geometry(start.feet_W)
            values |= {"support_centroid": centroid, "support_S_inv": s_inv.T.ravel()}
        if self.rolls_feet:  # the shanks' start orientations, each column-major
            shanks = leg_rotations_W(self.kin, start.base_rotation_W, start.joints_rad)
            values["shank_rotations_W"] = np.concatenate([R.T.ravel() for R in shanks])
        return self.pack_params(
            values
            | {
                "rc_star": rc_star_W,
                "feet_W": start.feet_W,
                "centres_W": centres,
                "normals_W": self.terrain.normal(start.feet_W),
                "u_f": np.asarray(u_f, float) / np.linalg.norm(u_f),
                "u_n": np.asarray(u_n, float) / np.linalg.norm(u_n),
            }
        )

    def initial_guess(self, start: State, p: np.ndarray, turned: bool = False) -> np.ndarray:
        """Decision vector near ``start`` on its leaf, with the COM moved to r_c*.

        The body is translated by r_c* - COM(start) (half of it if a foot would be out of
        reach) and the legs re-solved by Paden-Kahan IK onto the same foot centres, so
        IPOPT starts on the leaf next to the optimum (9 iterations instead of 14 on the
        benchmark); if neither fits, the start itself. ``turned``: the body also turned to
        the reference directions (u_f, u_n), the retry of :meth:`solve`.
        """
        u_f = p[self._p_slices["u_f"]]
        u_n = p[self._p_slices["u_n"]]
        R = frame_from_directions(u_f, u_n) if turned else start.base_rotation_W
        pos, joints = self._com_shifted(start, p, R)
        floor = self.options.sigma_floor
        x = [
            pos,
            coords_from_pose(np.column_stack([R, pos]))[3:],
            joints.ravel(),
            [max(float(u_f @ R[:, 0]), floor)],
            [max(float(u_n @ R[:, 2]), floor)],
        ]
        if "s5" in self._x_slices:
            x.append([0.5])
        out = np.concatenate([np.asarray(v, float).ravel() for v in x])
        if "theta_land" in self._x_slices:  # variables are declared in this order
            guess = self._landing_guess(start, p)
            if "theta_lift" in self._x_slices:  # declared right after theta_land
                guess = np.concatenate([guess, self._lift_guess(start, p, R, pos, joints)])
            out = np.insert(out, self._x_slices["theta_land"].start, guess)
        return out

    def _link_state(self, name: str, state: State, x: np.ndarray) -> State:
        """The swing leg at theta_land (``landing_clearance``) or theta_lift (``lift_...``)."""
        var = {"landing_clearance": "theta_land", "lift_clearance": "theta_lift"}.get(name)
        if var is None:
            return state
        (leg,) = set(range(4)) - set(self.support)
        moved = state.copy()
        moved.joints_rad = state.joints_rad.copy()
        moved.joints_rad[leg] = self.x_block(x, var)
        return moved

    def _com_shifted(self, start: State, p: np.ndarray, R) -> tuple[np.ndarray, np.ndarray]:
        """Body position and (4, 3) joints, body rotation ``R``, the COM moved toward r_c*.

        The same feet; the start's position and joints when no shift keeps them in reach.
        """
        com_B = start.base_rotation_W.T @ (self.check.com_W(start) - start.base_position_W)
        target = p[self._p_slices["rc_star"]] - R @ com_B  # the body origin at r_c*
        centres = p[self._p_slices["centres_W"]].reshape(4, 3)
        for frac in (1.0, 0.5, 0.0):
            pos = start.base_position_W + frac * (target - start.base_position_W)
            legs = self.kin.ik(pos, R, centres, start.joints_rad, closest=False)
            if all(r.reachable and not r.knee_flipped for r in legs):
                return pos, np.array([r.joints_rad for r in legs])
        return start.base_position_W, start.joints_rad

    def solve(
        self, start: State, rc_star_W, u_f, u_n, swing_target_W=None, hint: State | None = None
    ) -> ThetaSolution:
        """Theta2(r_c*, tau, r_1*..r_4*, i_f) of eq. 8, warm-started at ``start``.

        ``swing_target_W`` (optional, three supporting legs): the next foothold of the leg
        that will swing; the body then keeps that leg's hip within reach of it.
        ``hint`` (optional): a pose near the expected optimum, e.g. the precomputed plan's
        for this step (8.3-8.4), tried as the start when the others fail.
        """
        if (room := self._support_room_m(start)) < self.options.balance_margin_m - FEASIBILITY_TOL:
            return self._support_too_small(start, rc_star_W, u_f, u_n, swing_target_W, room)
        p = self.params(start, rc_star_W, u_f, u_n, swing_target_W)
        sol = self.solve_packed(p, self.initial_guess(start, p))
        if not sol.feasible:
            # IPOPT may stall on the far side of a leaf from its start (a 10 cm step: a
            # feasible pose a few cm away, "Infeasible_Problem_Detected" from the start):
            # once more from the start turned to (u_f, u_n) and moved to r_c*
            again = self.solve_packed(p, self.initial_guess(start, p, turned=True))
            if again.feasible or again.max_violation() < sol.max_violation():
                sol = again
        if not sol.feasible and hint is not None:
            # from the hint's body pose, the legs re-solved onto the start's feet: from a
            # measured state 1 cm off the plan's (a knee near its limit) IPOPT can stall at
            # "Maximum_Iterations_Exceeded" 0.5 mm from the plan's pose
            near = hint.copy()
            near.feet_W = np.array(start.feet_W, float).copy()
            again = self.solve_packed(p, self.initial_guess(near, p))
            if (
                again.feasible
                or _only_torque_or_sway(again)
                or (not _only_torque_or_sway(sol) and again.max_violation() < sol.max_violation())
            ):
                sol = again  # (a pose short only of torque or sway: their rows next)
        if (
            not sol.feasible
            and sol.x is not None
            and (sol.violations.get("torque", 0.0) > 0.0 or sol.violations.get("sway", 0.0) > 0.0)
        ):
            # the torque rows cost 2-3x per solve and bind only where a stance is heavily
            # loaded (inclines, steps), the sway cuts only where it is soft: solved with
            # them, from this pose, only then. Also where the pose misses another constraint
            # too: the rows make some such poses feasible, and a barrier climb that lacked
            # them ran out of time
            sol = self._solve_sibling(sol, p)
        aim = self.options.sway_stiffness_aim
        if sol.feasible and aim is not None and self.options.sway_stiffness is not None:
            if _sway_of(sol) < sway_stiffness_of(self.robot).bound_n_per_m(aim):
                sol = self._solve_sibling(sol, p, aim=aim)  # stiffer, where it finds one
        sol.state.info["rc_star"] = np.asarray(rc_star_W, float)
        if self.landing and sol.x is not None:
            # the touch-down joints this pose was found with: Theta3's starting point, so
            # it finds the clear landing Theta2 proved (from IK of the target it may take
            # the other side of an edge and fail)
            land = self.x_block(sol.x, "theta_land").copy()
            sol.state.info["landing"] = (np.asarray(swing_target_W, float).copy(), land)
        return sol

    def _support_room_m(self, start: State) -> float:
        """The largest balance margin [m] any body pose has on ``start``'s three support feet.

        The inradius of their horizontal triangle
        (:func:`planner.body.stability.triangle_inradius_m`);
        inf where Theta2 keeps no balance margin (four feet, no force rows, a pinned COM).
        """
        if not self._keeps_balance_margin():
            return np.inf
        return stability.triangle_inradius_m(np.asarray(start.feet_W, float)[list(self.support)])

    def _keeps_balance_margin(self) -> bool:
        """Whether the problem holds the COM ``balance_margin_m`` inside a support triangle."""
        free = not self.fix_com or self.height_band_m > 0.0
        return bool(self.options.forces and free and len(self.support) == 3)

    def _support_too_small(self, start, rc_star_W, u_f, u_n, swing_target_W, room_m):
        """Theta2 where the support triangle is narrower than the balance margin: no solve.

        Beyond the paper: the margin is a constraint on the COM's horizontal distance to
        the triangle's edges, and no point is farther from them than the inradius, so no
        body pose satisfies it. The start itself is returned (:meth:`_at_start`, not
        checked), with one violation: the balance margin short by the margin less the inradius. The
        three solves from other starts and the torque or sway re-solves that IPOPT would
        otherwise spend before "Infeasible_Problem_Detected" took 1-5 s a body move in
        the greedy planner's dead end (tests/test_local.py: triangles of 10-13 mm inradius).
        """
        x, p, state = self._at_start(start, rc_star_W, u_f, u_n, swing_target_W)
        margin = self.options.balance_margin_m
        diagnosis = (
            f"{self.name}: no solve; violated: 'balance_margin' by {margin - room_m:.3g} m "
            f"(the support triangle's inradius is {1000 * room_m:.1f} mm: no body pose "
            f"keeps the {1000 * margin:.0f} mm margin)"
        )
        # the one shortfall no pose removes (the start's own violations are moot)
        violations = {"balance_margin": margin - room_m}
        return self._unsolved(
            x, p, state, "support_too_small", False, diagnosis, violations,
            failure=(FailureKind.BALANCE_MARGIN,),
        )  # fmt: skip

    def hold(self, start: State, rc_star_W, u_f, u_n, swing_target_W=None) -> ThetaSolution:
        """Theta2's constraints at ``start`` itself: the body stays where it stands.

        Beyond the paper (the two-beat crawl, :func:`planner.motion.heuristics.two_beat_xy_W`):
        where the COM already stands inside the three legs' triangle with margin, the
        optimum lies millimetres away, and a move of millimetres is a rest-to-rest body
        move all the same (0.08 s at 1.5 m/s^2). The start's pose and joints are checked
        with the independent tests of every solution (reach, contact, joint limits,
        clearance, forces, balance margin, torque, sway stiffness, swing- and
        landing-ready; the landing joints by IK of the swing target); ``feasible`` when
        they all hold. No IPOPT solve; the objective is the start's.
        """
        x, p, state = self._at_start(start, rc_star_W, u_f, u_n, swing_target_W)
        violations = self._violations(state, x, p)
        worst = max(violations.values(), default=0.0)
        feasible = bool(np.isfinite(worst) and worst <= FEASIBILITY_TOL)
        diagnosis = "" if feasible else self._diagnose("held", violations)
        return self._unsolved(x, p, state, "held", feasible, diagnosis, violations)

    def _unsolved(
        self, x, p, state, status, feasible, diagnosis, violations, failure=None
    ) -> ThetaSolution:
        """The solution of the start itself (:meth:`_at_start`), with no IPOPT solve.

        ``failure``: the kinds of what failed (default: those of the violated groups).
        """
        if failure is None:
            failure = () if feasible else kinds_of_groups(self.violated_groups(violations))
        return ThetaSolution(
            problem=self.name,
            status=status,
            feasible=feasible,
            state=state,
            objective=self.objective_at(x, p),
            objective_terms={},
            iterations=0,
            solve_time_s=0.0,
            build_time_s=self.build_time_s,
            diagnosis=diagnosis,
            violations=violations,
            failure=failure,
            x=x,
            p=p,
        )

    def _at_start(self, start: State, rc_star_W, u_f, u_n, swing_target_W=None):
        """(x, p, state): the decision vector and pose of ``start`` itself, unchecked.

        The start's body pose and joints; s1, s2, s5 and the landing joints as the
        initial guess has them (the landing joints by IK of the swing target).
        """
        p = self.params(start, rc_star_W, u_f, u_n, swing_target_W)
        x = self.initial_guess(start, p)  # s1, s2, s5 and the landing joints
        x[self._x_slices["p"]] = start.base_position_W
        x[self._x_slices["phi"]] = coords_from_pose(
            np.column_stack([start.base_rotation_W, start.base_position_W])
        )[3:]
        x[self._x_slices["theta"]] = np.asarray(start.joints_rad, float).ravel()
        state = self._state_from_x(x, p)
        state.info["rc_star"] = np.asarray(rc_star_W, float)
        if self.landing:
            land = self.x_block(x, "theta_land").copy()
            state.info["landing"] = (np.asarray(swing_target_W, float).copy(), land)
        return x, p, state

    def _sibling(self, sway: bool) -> Theta2:
        """The same problem with the torque rows (and the sway rows where ``sway``)."""
        return Theta2(
            self.robot, self.terrain, self.support, self.options, self.mu,
            self.landing, torque_rows=True, sway_rows=sway,
        )  # fmt: skip

    def _solve_sibling(
        self, sol: ThetaSolution, p: np.ndarray, aim: float | None = None
    ) -> ThetaSolution:
        """Re-solve a pose that failed the torque or sway check with their rows.

        ``aim`` (m g / L): a feasible pose, solved again to be this stiff. The sway rows
        freeze their gravity part at the latest pose: up to ``SWAY_ROUNDS`` solves, each
        from the last. The best solution (feasible, or least violating) is kept.
        """
        sway = aim is not None or sol.violations.get("sway", 0.0) > 0.0
        sib = self._sway_problem if sway else self._torque_problem
        if sib is None:
            sib = self._sibling(sway)
            if sway:
                self._sway_problem = sib
            else:
                self._torque_problem = sib
        p2 = np.zeros(sib._p_sym.numel())
        for name, sl in self._p_slices.items():
            p2[sib._p_slices[name]] = p[sl]
        if not sway:
            again = sib.solve_packed(p2, sol.x)
            return again if again.feasible or again.max_violation() < sol.max_violation() else sol
        floor = self.options.sway_stiffness
        need = sway_stiffness_of(self.robot).bound_n_per_m(floor)
        target = (1.0 + SWAY_SLACK) * (1.0 if aim is None else aim / floor)
        best, latest, x = sol, sol, sol.x
        for _ in range(SWAY_ROUNDS):
            st = self._stiffness(latest.state)
            if not np.isfinite(st.least):
                break  # a singular support leg: no rows to build here
            G = (st.hessian - st.joint_part) / need
            M = st.joint_part / need + G - target * np.eye(6)
            w = np.linalg.eigvalsh(M)
            shift = max(0.0, -float(w[0])) + 0.05 + 1e-9 * float(np.abs(w).max())
            try:  # the factor's start: M lifted to positive definite
                L = np.linalg.cholesky(M + shift * np.eye(6))
            except np.linalg.LinAlgError:
                break  # ill-conditioned (a leg near a singularity): no rows here
            p2[sib._p_slices["sway_G"]] = G[_TRIL]
            p2[sib._p_slices["sway_target"]] = target
            x2 = np.zeros(sib._x_sym.numel())
            for name, sl in self._x_slices.items():
                x2[sib._x_slices[name]] = x[sl]
            x2[sib._x_slices["sway_L"]] = L[_TRIL]
            again = sib.solve_packed(p2, x2)
            if again.state is None or again.x is None:
                break
            again.x = np.concatenate([again.x[sib._x_slices[n]] for n in self._x_slices])
            if aim is None:
                if again.feasible or again.max_violation() < best.max_violation():
                    best = again
                if again.feasible or again.violations.get("sway", 0.0) <= 0.0:
                    break  # feasible, or what is left is not the sway bound
            else:  # improving a feasible pose: keep only feasible, stiffer ones
                if not again.feasible:
                    break
                if _sway_of(again) > _sway_of(best):
                    best = again
                if _sway_of(again) >= sway_stiffness_of(self.robot).bound_n_per_m(aim):
                    break
            latest, x = again, again.x
        return best

    def _commanded(self, state: State):
        """The commanded force distribution's torques (:class:`TorqueFeasibility`, Clarabel)."""
        if not hasattr(self, "_torques"):
            self._torques = TorqueCheck(self.robot)
        q = self.robot.q_from(state.base_position_W, state.base_quaternion_xyzw, state.joints_rad)
        normals = self.terrain.normal(state.feet_W)
        return self._torques.solve(q, self.support, self.mu, normals, least_squares=True)

    def _stiffness(self, state: State, torques_nm=None):
        """The sway stiffness of a three-leg pose, the commanded torques as feed-forward."""
        if torques_nm is None:
            torques_nm = self._commanded(state).torques_nm
        return sway_stiffness_of(self.robot).stance(
            state.base_position_W, state.base_rotation_W, state.joints_rad, self.support,
            np.nan_to_num(torques_nm),
        )  # fmt: skip

    def _state_from_x(self, x: np.ndarray, p: np.ndarray) -> State:
        eps = np.concatenate([self.x_block(x, "p"), self.x_block(x, "phi")])
        feet = p[self._p_slices["feet_W"]].reshape(4, 3)
        state = state_from_pose_coords(
            eps, feet, self.x_block(x, "theta").reshape(4, 3), S0, self.support
        )
        return state

    def rolled_feet(self, state: State, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(centres, contacts), each (4, 3): where the stance spheres roll to at ``state``.

        The start's own centres and contacts without rolling (:attr:`rolls_feet`).
        """
        cen = p[self._p_slices["centres_W"]].reshape(4, 3)
        feet = p[self._p_slices["feet_W"]].reshape(4, 3)
        if not self.rolls_feet:
            return cen, feet
        n = p[self._p_slices["normals_W"]].reshape(4, 3)
        shanks = p[self._p_slices["shank_rotations_W"]].reshape(4, 3, 3).transpose(0, 2, 1)
        rolled = rolled_centres_W(self.kin, state.base_rotation_W, state.joints_rad, cen, shanks, n)
        return rolled, rolled - self.robot.foot_radius_m * n

    def _violations(self, state: State, x, p) -> dict[str, float]:
        ck = self.check
        cen, rolled_feet = self.rolled_feet(state, p)
        stance = state  # the checks of the feet (contacts, forces, balance): rolled ones
        if self.rolls_feet:
            stance = state.copy()
            stance.feet_W = rolled_feet
        far = 0.0
        for i, lg in enumerate(self.robot.legs):
            hip_B = hip_point_B(lg)
            d = float(
                np.linalg.norm(state.base_rotation_W @ hip_B + state.base_position_W - cen[i])
            )
            far = max(far, d - STANCE_REACH_FRACTION * float(self.robot.reach_m[i]))
        v = {
            "reach": far,
            "contact": (
                float(np.max(np.linalg.norm(ck.foot_centres_W(state) - cen, axis=1)))
                if self.rolls_feet
                else ck.contacts(state, range(4))
            ),
            "joint_limits": ck.joint_limits(state),
            "clearance": ck.clearance(state),
            "orientation": ck.orientation(state),
        }
        if "swing_target_W" in self._p_slices:
            (leg,) = set(range(4)) - set(self.support)
            hip_B = hip_point_B(self.robot.legs[leg])
            hip_W = state.base_rotation_W @ hip_B + state.base_position_W
            d = float(np.linalg.norm(hip_W - p[self._p_slices["swing_target_W"]]))
            v["swing_ready"] = max(d - float(p[self._p_slices["swing_reach_m"]][0]), 0.0)
            if self.landing:
                landed = self._link_state("landing_clearance", stance, x)
                if self.options.forces:
                    v["forces_landing"] = max(ck.forces(landed, self.support, self.mu)[0], 0.0)
                foot = (
                    state.base_rotation_W @ self.kin.foot_B(leg, landed.joints_rad[leg])
                    + state.base_position_W
                )
                v["landing"] = float(np.linalg.norm(foot - p[self._p_slices["swing_target_W"]]))
                if "theta_lift" in self._x_slices:
                    v |= self._lift_violations(state, x, p, cen, leg)
                if self.options.forces:
                    need = stability.PATH_BALANCE_MARGIN_M
                    have = stability.support_margin_m(
                        stance.feet_W[list(self.support)], ck.com_W(landed)
                    )
                    v["balance_margin_landing"] = max(need - have, 0.0)
        band = self.height_band_m
        if self.fix_com:
            off = ck.com_W(state) - p[self._p_slices["rc_star"]]
            if band > 0.0:  # horizontal pin, height within the band
                v["com"] = max(float(np.linalg.norm(off[:2])), abs(float(off[2])) - band, 0.0)
            else:
                v["com"] = float(np.linalg.norm(off))
        if self.options.forces or self.fix_com:
            viol, forces = ck.forces(stance, self.support, self.mu)
            state.forces_W = forces
            if self.options.forces:
                v["forces"] = max(viol, 0.0)
        if self._keeps_balance_margin():
            have = stability.support_margin_m(stance.feet_W[list(self.support)], ck.com_W(state))
            v["balance_margin"] = max(self.options.balance_margin_m - have, 0.0)
            res = None
            if self.options.torque_fraction is not None:
                res = self._commanded(stance)
                ratio = float(res.ratio) if np.isfinite(res.ratio) else float("inf")
                v["torque"] = max(ratio - self.options.torque_fraction - TORQUE_SOCP_TOL, 0.0)
            if self.options.sway_stiffness is not None:
                if res is None:
                    res = self._commanded(stance)
                need = sway_stiffness_of(self.robot).bound_n_per_m(self.options.sway_stiffness)
                have = self._stiffness(state, res.torques_nm).least
                state.info["sway_n_per_m"] = have
                v["sway"] = max((need - have) / need, 0.0)
        return v
