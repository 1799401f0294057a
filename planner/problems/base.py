"""The shared machinery of the Theta problems (paper sections 7.2-7.5).

Each Theta problem is declared once per (robot, terrain, support pattern) as a CasADi NLP

    min_x f(x, p)   s.t.   lbx <= x <= ubx,   lbg <= g(x, p) <= ubg,

with exact first and second derivatives (CasADi's algorithmic differentiation, SX graphs),
and solved many times by IPOPT with new parameters p and the previous solution as the
warm start (the pattern of rockit's ``repeated_solve``). The constraints come in named
groups so that a failed solve can say which one it could not meet.

The paper's objective is a product ``sigma = -prod_k sigma_k^gamma_k`` of positive terms.
IPOPT is given the equivalent ``-sum_k gamma_k log sigma_k``: log is increasing, so both
rank any two configurations the same way and have the same minimisers, while the sum has
a far better conditioned Hessian. Terms that could turn non-positive (sigma1, sigma2,
sigma5) are slack variables bounded below by ``sigma_floor`` and tied to their
expression by an equality, so the logarithm is always defined. They have no upper bound:
s1 = u_f . R e_x <= 1 already, and a bound at 1 would be active exactly where the
equality's derivative vanishes (body aligned), which cost IPOPT 10 extra iterations.

A solve returns a :class:`ThetaSolution`, whose :meth:`~ThetaSolution.max_violation`
recomputes every constraint with numpy and Pinocchio, not with the CasADi graph the solver
saw. A solution is called feasible only when that check passes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import pinocchio as pin

from planner.body import statics
from planner.body.kinematics import kinematics_of
from planner.body.state import State
from planner.core.failures import FailureKind, kinds_of_groups
from planner.core.lie import coords_from_pose, pose_from_coords, rotation_from_vector_ca
from planner.core.units import GRAVITY_M_S2
from planner.problems.options import ThetaOptions

FEASIBILITY_TOL = 1e-6  # [m, rad, N]: an independent violation above this is infeasible
CLEARANCE_ACTIVE_POINTS = 8  # points of P held besides its bottom corners (2 per quarter)
CLEARANCE_ROUNDS = 4  # solves at most, each one re-picking the lowest points
# the NLP holds a capsule this much farther than the check asks: the witness of the next
# round is another cloud point (2 mm grid), up to ~1 mm nearer than the plane it replaces
WITNESS_SLACK_M = 0.001
# a swing leg's touch-down joints keep this far inside the URDF limits [rad]: at a limit the
# leg cannot lift its foot off again along the normal (the swing's pre-pose,
# planner.motion.leg_swing) nor correct a tracking error; a landing onto a 10 cm step put the hip
# roll at its -0.6 rad stop, and no swing path reached it
LANDING_LIMIT_MARGIN_RAD = 0.1


@dataclass
class ThetaSolution:
    """The outcome of one Theta solve (data, as qpsolvers' ``Solution``).

    ``feasible`` is decided by :meth:`max_violation` (numpy + Pinocchio), not by IPOPT's
    status alone; ``status`` is IPOPT's return status; ``diagnosis`` says what went wrong.
    """

    problem: str
    status: str
    feasible: bool
    state: State | None
    objective: float
    objective_terms: dict[str, float]
    iterations: int
    solve_time_s: float
    build_time_s: float
    diagnosis: str = ""
    violations: dict[str, float] = field(default_factory=dict)
    failure: tuple[FailureKind, ...] = ()  # the kinds of the violated groups named
    x: np.ndarray | None = field(default=None, repr=False)
    p: np.ndarray | None = field(default=None, repr=False)  # parameters of the last solve

    @property
    def joints_rad(self) -> np.ndarray | None:
        """(4, 3) joint angles of the solution."""
        return None if self.state is None else self.state.joints_rad

    @property
    def forces_W(self) -> np.ndarray | None:
        """(4, 3) eq. 5 contact forces [N] of the solution (zero for non-support feet)."""
        return None if self.state is None else self.state.forces_W

    def max_violation(self) -> float:
        """Largest constraint violation, recomputed independently of the solver."""
        return max(self.violations.values(), default=0.0)


class ConstraintCheck:
    """Independent numeric check of a configuration (numpy, Pinocchio, statics).

    Each group returns a violation (0 when satisfied) in its own unit: metres for
    positions, radians for angles, newtons for forces.
    """

    def __init__(self, robot, terrain, options: ThetaOptions):
        self.robot = robot
        self.terrain = terrain
        self.options = options
        self.model = robot.model
        self.data = robot.model.createData()
        self.foot_ids = [self.model.getFrameId(f) for f in robot.foot_frames]

    def foot_centres_W(self, state: State) -> np.ndarray:
        """(4, 3) foot sphere centres by Pinocchio forward kinematics."""
        q = self.robot.q_from(state.base_position_W, state.base_quaternion_xyzw, state.joints_rad)
        pin.framesForwardKinematics(self.model, self.data, q)
        return np.array([self.data.oMf[f].translation for f in self.foot_ids])

    def com_W(self, state: State) -> np.ndarray:
        """Centre of mass by Pinocchio (whole body) or the body link's (paper)."""
        if not self.options.whole_body_com:
            return state.base_position_W + state.base_rotation_W @ self.robot.body_com_B
        q = self.robot.q_from(state.base_position_W, state.base_quaternion_xyzw, state.joints_rad)
        return pin.centerOfMass(self.model, self.data, q)

    def joint_limits(self, state: State) -> float:
        """Largest excursion of a joint past its limits [rad] (constraint c)."""
        lo, hi = self.robot.lower_rad, self.robot.upper_rad
        return float(max(np.max(lo - state.joints_rad), np.max(state.joints_rad - hi), 0.0))

    def clearance(self, state: State) -> float:
        """delta_c - min over P of f_T [m], if positive (constraint b)."""
        pts_B = self.robot.body_clearance_points_B
        verts_W = pts_B @ state.base_rotation_W.T + state.base_position_W
        f = self.terrain.f_T(verts_W)
        return float(max(np.max(self.options.clearance_m - f), 0.0))

    def leg_clearance(self, state: State, legs) -> tuple[float, list]:
        """Margin minus clearance of the given legs' capsules [m], if positive.

        The margin is :mod:`planner.body.links`' keyframe margin (2 mm + 3 degrees x distance
        to the foot). Also returns every capsule's :class:`planner.body.links.Witness` (None
        when farther than ``planner.body.links.WITNESS_SEARCH_M`` or not of these legs).
        """
        from planner.body.links import leg_links

        links = leg_links(self.robot)
        legs = set(legs)
        caps = [c for c, cap in enumerate(links.capsules) if cap.leg in legs]
        q = self.robot.q_from(state.base_position_W, state.base_quaternion_xyzw, state.joints_rad)
        wit = links.witnesses(self.terrain, q, caps)
        gaps = [w.need_m - w.clearance_m for w in wit if w is not None]
        return float(max(max(gaps, default=0.0), 0.0)), wit

    def orientation(self, state: State) -> float:
        """|theta omega| - pi [rad], if positive (constraint a)."""
        phi = coords_from_pose(state.pose)[3:]
        return float(max(np.linalg.norm(phi) - np.pi, 0.0))

    def contacts(self, state: State, legs) -> float:
        """Stance feet: Pinocchio's sphere centre equals contact point + rho n."""
        from planner.body.contact import foot_centre_from_contact

        centres = self.foot_centres_W(state)
        want = foot_centre_from_contact(self.terrain, state.feet_W, self.robot.foot_radius_m)
        legs = list(legs)
        if not legs:
            return 0.0
        return float(np.max(np.linalg.norm(centres[legs] - want[legs], axis=1)))

    def on_terrain(self, state: State, legs) -> float:
        """|f_T(r_i)| of the contact points of the given legs."""
        legs = list(legs)
        if not legs:
            return 0.0
        return float(np.max(np.abs(self.terrain.f_T(state.feet_W[legs]))))

    def slope(self, state: State, legs, mu: float) -> float:
        """tan(slope) - mu at the contact points (section 7.4 inequality), if positive."""
        legs = list(legs)
        if not legs or not self.options.slope_limit:
            return 0.0
        n = self.terrain.normal(state.feet_W[legs])
        tan = np.sqrt(np.maximum(1 - n[:, 2] ** 2, 0.0)) / np.maximum(n[:, 2], 1e-12)
        return float(max(np.max(tan - mu), 0.0))

    def forces(self, state: State, support, mu: float) -> tuple[float, np.ndarray]:
        """Violation of (d), (e) for the eq. 5 forces [N], and the forces."""
        com = self.com_W(state)
        eq = statics.equilibrating_forces(state.feet_W, com, self.robot.total_mass_kg, support)
        if eq.degenerate:
            return float("inf"), eq.forces
        normals = self.terrain.normal(state.feet_W)
        fmin = self.options.min_normal_force_frac * self.robot.total_mass_kg * GRAVITY_M_S2
        worst = 0.0
        for i in support:
            fn = float(eq.forces[i] @ normals[i])
            ft = np.linalg.norm(eq.forces[i] - fn * normals[i])
            worst = max(worst, fmin - fn, ft - mu * fn)
        return float(worst), eq.forces


class ThetaProblem:
    """Base class: variables, parameters, named constraint groups, objective, IPOPT.

    Subclasses implement :meth:`_declare`, which fills ``self._x``, ``self._p``, the
    constraint groups and the objective terms, and :meth:`_state_from_x`.
    """

    name = "Theta"

    def __init__(self, robot, terrain, options: ThetaOptions | None = None, mu: float = 0.7):
        self.robot = robot
        self.terrain = terrain
        self.options = options or ThetaOptions()
        self.mu = float(mu)
        self.kin = kinematics_of(robot)
        self.check = ConstraintCheck(robot, terrain, self.options)
        self._xs: list[tuple[str, ca.SX, np.ndarray, np.ndarray]] = []
        self._ps: list[tuple[str, ca.SX]] = []
        self._groups: list[tuple[str, ca.SX, np.ndarray, np.ndarray]] = []
        self._terms: list[tuple[str, float, ca.SX]] = []
        verts_B = robot.body_vertices_B
        self._corners_B = verts_B[np.isclose(verts_B[:, 2], robot.body_box_B[0][2])]
        pts_B = robot.body_clearance_points_B  # the others are picked at each solve
        near = np.linalg.norm(pts_B[:, None] - self._corners_B[None], axis=2).min(axis=1)
        self._candidates_B = pts_B[near > 1e-9]
        centre = self._corners_B.mean(axis=0)
        front = self._candidates_B[:, 0] >= centre[0]
        left = self._candidates_B[:, 1] >= centre[1]
        self._quarters = [
            np.flatnonzero((front == a) & (left == b)) for a in (0, 1) for b in (0, 1)
        ]
        t0 = time.perf_counter()
        self._declare()
        self._build()
        self.build_time_s = time.perf_counter() - t0

    # ---- declaration helpers ----------------------------------------------------------
    def var(self, name: str, n: int, lb=-np.inf, ub=np.inf) -> ca.SX:
        """A decision variable block with bounds."""
        x = ca.SX.sym(name, n)
        self._xs.append(
            (name, x, np.broadcast_to(lb, n).astype(float), np.broadcast_to(ub, n).astype(float))
        )
        return x

    def par(self, name: str, n: int) -> ca.SX:
        """A parameter block (set at each solve)."""
        p = ca.SX.sym(name, n)
        self._ps.append((name, p))
        return p

    def constrain(self, name: str, expr, lb=0.0, ub=0.0) -> None:
        """A named group of constraints lb <= expr <= ub."""
        expr = ca.vec(expr)
        n = expr.numel()
        self._groups.append(
            (name, expr, np.broadcast_to(lb, n).astype(float), np.broadcast_to(ub, n).astype(float))
        )

    def maximise_log(self, name: str, weight: float, sigma) -> None:
        """Add gamma * log(sigma) to the objective (the paper's sigma^gamma factor)."""
        if weight:
            self._terms.append((name, float(weight), sigma))

    def constrain_body_pose(self, pos, R, phi, s1, s2, u_f, u_n) -> None:
        """Constraints (a), (b) of section 7.2 and the sigma1, sigma2 slack equalities.

        (a) |theta omega| <= pi; (b) every vertex of the body box P, and points of its
        bottom face every 2 cm (beyond the paper: a thin barrier fits between vertices),
        at least delta_c above the terrain; s1 = u_f . R e_x and s2 = u_n . R e_z (sigma1,
        sigma2 of 7.2).

        The NLP holds the 4 corners of the bottom face and ``CLEARANCE_ACTIVE_POINTS``
        more of these points given as parameters: :meth:`solve_rounds` picks the lowest
        over the terrain and solves again if the independent check (all points) finds one
        violated (constraint generation). On planar ground the corners alone bound the
        face; the others matter only over uneven terrain, and 58 constraints (on rough
        ground 58 terrain evaluations and their Hessians) made every iteration dearer.
        """
        extra_B = ca.reshape(self.par("clearance_points_B", 3 * CLEARANCE_ACTIVE_POINTS), 3, -1)
        pts_B = ca.horzcat(ca.DM(self._corners_B.T), extra_B)
        verts = ca.mtimes(R, pts_B) + ca.repmat(pos, 1, pts_B.shape[1])
        clear = ca.vertcat(*[self.terrain.f_T_ca(verts[:, k]) for k in range(pts_B.shape[1])])
        self.constrain("orientation", ca.dot(phi, phi), -np.inf, np.pi**2)
        self.constrain("clearance", clear, self.options.clearance_m, np.inf)
        self.constrain("sigma1", s1 - ca.dot(u_f, R[:, 0]))
        self.constrain("sigma2", s2 - ca.dot(u_n, R[:, 2]))

    def constrain_leg_links(self, pos, R, thetas: dict, name: str = "leg_clearance") -> None:
        """Thigh and shank capsules of the legs in ``thetas`` (leg -> its 3 joint SX) clear.

        Beyond the paper (planner.body.links): for each capsule a half-space constraint
        n . (a + u (b - a) - w) >= radius + margin + WITNESS_SLACK_M, with w the
        sharp-terrain point nearest the capsule's axis, n the unit vector from w to the
        axis and u where along the axis (parameters, :meth:`solve_rounds` picks them at
        each round from the pose reached: constraint generation, as for the body's
        clearance points). At the witness this is the exact distance; elsewhere the plane
        is a conservative local model of the terrain. A capsule farther than
        ``planner.body.links.WITNESS_SEARCH_M`` gets an inactive row (n = 0). The margin grows
        with the witness's distance from the leg's foot (planner.body.links'
        ``KEYFRAME_ANGLE_RAD``): execution errors turn a stance leg about its foot.
        ``name`` names the constraint group; the pose whose witnesses are used is
        :meth:`_link_state` of it (the solution's, or another pose of the same solve).
        """
        from planner.body.links import leg_links

        links = leg_links(self.robot)
        caps = [c for c, cap in enumerate(links.capsules) if cap.leg in thetas]
        self._link_blocks = getattr(self, "_link_blocks", {})
        self._link_blocks[name] = (sorted(thetas), caps)
        w = ca.reshape(self.par(f"{name}_witnesses", 8 * len(caps)), 8, -1)
        rows = []
        for k, c in enumerate(caps):
            a_B, b_B = links.ends_B_ca(c, thetas[links.capsules[c].leg])
            a = ca.mtimes(R, a_B) + pos
            b = ca.mtimes(R, b_B) + pos
            point = a + w[0, k] * (b - a)
            rows.append(ca.dot(w[4:7, k], point - w[1:4, k]) - w[7, k])
        self.constrain(name, ca.vertcat(*rows), 0.0, np.inf)

    def _link_state(self, name: str, state: State, x: np.ndarray) -> State:
        """The pose whose links the group ``name`` holds (default: the solution's)."""
        return state

    def _link_witness_params(self, witnesses: list, name: str = "leg_clearance") -> np.ndarray:
        """The witness block of group ``name`` (:meth:`constrain_leg_links`), 8 per capsule."""
        from planner.body.links import leg_links

        links = leg_links(self.robot)
        out = []
        for c in self._link_blocks[name][1]:
            w = witnesses[c]
            if w is None:
                out.append([0.0, 0, 0, 0, 0, 0, 0, -1.0])  # 0 - (-1) >= 0: inactive
            else:
                need = links.capsules[c].radius_m + w.need_m + WITNESS_SLACK_M
                out.append([w.u, *w.point_W, *w.normal_W, need])
        return np.asarray(out, float).ravel()

    def rotation(self, phi):
        """R(phi) from the rotation-vector half of eps(g) (section 4.7)."""
        return rotation_from_vector_ca(phi)

    # ---- building and solving ----------------------------------------------------------
    def _declare(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _build(self) -> None:
        x = ca.vertcat(*[v for _, v, _, _ in self._xs])
        p = ca.vertcat(*[v for _, v in self._ps])
        g = ca.vertcat(*[e for _, e, _, _ in self._groups])
        f = -sum(w * _log(s) for _, w, s in self._terms)
        self._x_sym, self._p_sym = x, p
        self.lbx = np.concatenate([lb for _, _, lb, _ in self._xs])
        self.ubx = np.concatenate([ub for _, _, _, ub in self._xs])
        self.lbg = np.concatenate([lb for _, _, lb, _ in self._groups])
        self.ubg = np.concatenate([ub for _, _, _, ub in self._groups])
        self._x_slices = {}
        k = 0
        for name, v, _, _ in self._xs:
            self._x_slices[name] = slice(k, k + v.numel())
            k += v.numel()
        self._g_slices = {}
        k = 0
        for name, e, _, _ in self._groups:
            self._g_slices[name] = slice(k, k + e.numel())
            k += e.numel()
        self._p_slices = {}
        k = 0
        for name, v in self._ps:
            self._p_slices[name] = slice(k, k + v.numel())
            k += v.numel()
        opts = {
            "print_time": False,
            "ipopt": {
                "print_level": 0,
                "sb": "yes",
                "tol": self.options.tol,
                "constr_viol_tol": 1e-9,
                "acceptable_tol": 1e-6,
                "acceptable_constr_viol_tol": 1e-8,
                "max_iter": self.options.max_iter,
                "mu_strategy": "adaptive",
                "hessian_approximation": "exact",
            },
        }
        if self.options.mu_init is not None:
            opts["ipopt"] |= {"mu_init": self.options.mu_init, "mu_strategy": "monotone"}
        self.solver = ca.nlpsol(self.name, "ipopt", {"x": x, "p": p, "f": f, "g": g}, opts)
        self.library = None  # the compiled NLP functions in use (ThetaOptions.jit), if any
        if self.options.jit:
            from planner.problems.compiled import compiled_library

            self.library = compiled_library(self.solver, ca.Function("nlp", [x, p], [f, g]))
            if self.library is not None:
                self.solver = ca.nlpsol(self.name, "ipopt", str(self.library), opts)
        self._terms_fun = ca.Function(
            "terms",
            [x, p],
            [ca.vertcat(*[s for _, _, s in self._terms]) if self._terms else ca.DM.zeros(0)],
        )
        self._g_fun = ca.Function("g", [x, p], [g])
        self._f_fun = ca.Function("f", [x, p], [f])

    def objective_at(self, x: np.ndarray, p: np.ndarray) -> float:
        """The objective -sum gamma_k log sigma_k at a decision vector."""
        return float(self._f_fun(x, p))

    def pack_params(self, values: dict[str, np.ndarray]) -> np.ndarray:
        """Parameter vector from a dict of named blocks (every block must be given).

        The clearance points and link witnesses are set by :meth:`solve_rounds`.
        """
        out = np.zeros(self._p_sym.numel())
        for name, sl in self._p_slices.items():
            if (name == "clearance_points_B" or name.endswith("_witnesses")) and name not in values:
                continue
            if name not in values:
                raise KeyError(f"{self.name}: parameter '{name}' missing")
            out[sl] = np.asarray(values[name], dtype=float).ravel()
        return out

    def x_block(self, x: np.ndarray, name: str) -> np.ndarray:
        """A named block of a decision vector."""
        return np.asarray(x, dtype=float)[self._x_slices[name]]

    def solve_packed(self, p: np.ndarray, x0: np.ndarray) -> ThetaSolution:
        """Run IPOPT from ``x0`` and check the result independently."""
        x, p, status, iterations, state, violations, solve_time = self.solve_rounds(
            p, x0, self._ipopt
        )
        worst = max(violations.values(), default=0.0)
        feasible = bool(np.isfinite(worst) and worst <= FEASIBILITY_TOL)
        terms = np.array(self._terms_fun(x, p)).ravel()
        term_dict = {name: float(v) for (name, _, _), v in zip(self._terms, terms, strict=True)}
        diagnosis, failure = "", ()
        if not feasible:
            diagnosis = self._diagnose(status, violations)
            failure = kinds_of_groups(self.violated_groups(violations))
        return ThetaSolution(
            problem=self.name,
            status=status,
            feasible=feasible,
            state=state,
            objective=self.objective_at(x, p),
            objective_terms=term_dict,
            iterations=iterations,
            solve_time_s=solve_time,
            build_time_s=self.build_time_s,
            diagnosis=diagnosis,
            violations=violations,
            failure=failure,
            x=x,
            p=p,
        )

    def _ipopt(self, p: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, str, int]:
        res = self.solver(x0=x0, p=p, lbx=self.lbx, ubx=self.ubx, lbg=self.lbg, ubg=self.ubg)
        st = self.solver.stats()
        status = str(st.get("return_status", "unknown"))
        return np.array(res["x"]).ravel(), status, int(st.get("iter_count", 0))

    def solve_rounds(self, p: np.ndarray, x0: np.ndarray, inner):
        """Run ``inner(p, x0) -> (x, status, iterations)`` with constraint generation.

        Before each round the NLP's clearance parameters are set to the points of P
        lowest over the terrain at the current pose, and its link witnesses to the
        terrain points nearest each leg capsule; a round whose solution the independent
        check finds too close to the terrain (body or legs) is solved again from there (at
        most ``CLEARANCE_ROUNDS``). Returns (x, p, status, iterations, state, violations,
        solve_time_s) with p as used by the last round, the iterations summed and the
        time of the rounds without the independent checks (reported by every solve anyway).
        """
        x = np.clip(np.asarray(x0, dtype=float), self.lbx, self.ubx)
        p = np.array(p, dtype=float)
        picked = self._p_slices.get("clearance_points_B")
        blocks = getattr(self, "_link_blocks", {})
        generated = picked is not None or bool(blocks)
        iterations, solve_time = 0, 0.0
        state = self._state_from_x(x, p) if generated else None
        witnesses = {}
        for _ in range(CLEARANCE_ROUNDS):
            t0 = time.perf_counter()
            if picked is not None:
                p[picked] = self._lowest_points_B(state).ravel()
            for name, (legs, _) in blocks.items():
                if name not in witnesses:
                    at = self._link_state(name, state, x)
                    witnesses[name] = self.check.leg_clearance(at, legs)[1]
                p[self._p_slices[f"{name}_witnesses"]] = self._link_witness_params(
                    witnesses[name], name
                )
            x, status, n = inner(p, x)
            solve_time += time.perf_counter() - t0
            iterations += n
            x = np.clip(x, self.lbx, self.ubx) if np.all(np.isfinite(x)) else x
            state = self._state_from_x(x, p)
            violations = self._violations(state, x, p)
            for name, (legs, _) in blocks.items():
                at = self._link_state(name, state, x)
                violations[name], witnesses[name] = self.check.leg_clearance(at, legs)
            again = ("clearance", *blocks) if generated else ()
            if not any(violations.get(k, 0.0) > FEASIBILITY_TOL for k in again):
                break
        return x, p, status, iterations, state, violations, solve_time

    def _lowest_points_B(self, state: State) -> np.ndarray:
        """The candidate points of P nearest the terrain, 2 per quarter of the body.

        Quarters: front/rear x left/right of the body's centre. Spread over them rather
        than the lowest overall: points along one line (a barrier under the belly) would
        leave the body free to roll onto the points beside them, and one point per
        quarter let the rounds oscillate on that barrier.
        """
        pts_B = self._candidates_B
        f = self.terrain.f_T(pts_B @ state.base_rotation_W.T + state.base_position_W)
        f = np.nan_to_num(f, nan=-np.inf)
        per = CLEARANCE_ACTIVE_POINTS // 4
        return np.vstack(
            [pts_B[idx[np.argsort(f[idx], kind="stable")[:per]]] for idx in self._quarters]
        )

    def solver_violations(self, x: np.ndarray, p: np.ndarray) -> dict[str, float]:
        """Violation of each group as the solver's CasADi graph sees it (for diagnosis)."""
        g = np.array(self._g_fun(x, p)).ravel()
        out = {}
        for name, sl in self._g_slices.items():
            v = np.maximum(self.lbg[sl] - g[sl], g[sl] - self.ubg[sl])
            out[name] = float(max(np.max(v, initial=0.0), 0.0))
        return out

    def violated_groups(self, violations: dict[str, float]) -> list[str]:
        """The groups violated past ``FEASIBILITY_TOL``, most severe first (relative to scale)."""
        mg = self.robot.total_mass_kg * GRAVITY_M_S2
        scale = {
            "forces": 0.01 * mg,
            "joint_limits": 0.01,
            "orientation": 0.01,
            "slope": 0.01,
            "torque": 0.01,
            "sway": 0.01,
        }
        bad = {k: v for k, v in violations.items() if not v <= FEASIBILITY_TOL}
        return sorted(bad, key=lambda k: -bad[k] / scale.get(k, 1e-3))

    def _diagnose(self, status: str, violations: dict[str, float]) -> str:
        """Name the violated groups, most severe first (each relative to its unit scale)."""
        order = self.violated_groups(violations)
        if not order:
            return f"{self.name}: IPOPT status {status}"
        unit = {
            "forces": "N",
            "joint_limits": "rad",
            "orientation": "rad",
            "slope": "",
            "torque": "of the effort",
            "sway": "of the least sway stiffness",
        }
        listed = ", ".join(
            f"'{k}' by {violations[k]:.3g} {unit.get(k, 'm')}".rstrip() for k in order
        )
        return f"{self.name}: IPOPT status {status}; violated: {listed}" + self._explain(order[0])

    def _explain(self, group: str) -> str:
        hints = {
            "contact": ": a stance foot is out of reach of this body pose",
            "com": ": the COM target cannot be reached with these footholds",
            "clearance": ": the body box P would touch the terrain; lower clearance_m?",
            "leg_clearance": ": a thigh or shank would come too near the terrain (an edge)",
            "landing_clearance": ": the swinging leg's thigh or shank would meet the terrain"
            " (an edge) when its foot lands on the next foothold",
            "landing": ": the swinging leg cannot reach its next foothold from this body pose",
            "lift": ": the swinging leg cannot lift its foot from this body pose (a joint limit)",
            "lift_branch": ": the swinging leg lifts its foot only on its other knee branch",
            "lift_clearance": ": the swinging leg's thigh or shank would meet the terrain as"
            " it lifts off",
            "reach": ": a stance leg would be stretched to its reach",
            "forces": ": no eq. 5 forces inside the friction cones; the COM is outside the"
            " support or the slope too steep",
            "foot_on_terrain": ": the swing foot cannot reach the terrain",
            "slope": ": every reachable foothold is steeper than atan(mu)",
            "target_radius": ": no foothold within the target radius is reachable",
            "swing_ready": ": the swinging leg's next foothold is out of its reach from here",
            "torque": ": a support joint would need more than torque_fraction of its effort"
            " limit on three legs",
            "sway": ": the three-leg stance is too soft on the servos (planner.body.stiffness)",
        }
        for key, text in hints.items():
            if group.startswith(key):
                return text
        return ""

    # ---- to be provided by the problems ------------------------------------------------
    def _state_from_x(self, x: np.ndarray, p: np.ndarray) -> State:  # pragma: no cover
        raise NotImplementedError

    def _violations(self, state: State, x, p) -> dict[str, float]:  # pragma: no cover
        raise NotImplementedError


# ---- shared symbolic pieces ----------------------------------------------------------------


def landing_bounds_rad(robot, leg: int) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) bounds of ``leg``'s touch-down joints: ``LANDING_LIMIT_MARGIN_RAD`` in."""
    lo, hi = np.asarray(robot.lower_rad[leg], float), np.asarray(robot.upper_rad[leg], float)
    m = np.minimum(LANDING_LIMIT_MARGIN_RAD, 0.25 * (hi - lo))
    return lo + m, hi - m


def _log(sigma):
    """log(sigma), simplified for exp(...) terms so the objective stays polynomial."""
    if sigma.is_op(ca.OP_EXP):
        return sigma.dep(0)
    return ca.log(sigma)


def com_W_ca(problem: ThetaProblem, p_W, R_W, joints12):
    """Centre of mass in world frame (whole-body or body link only)."""
    return p_W + ca.mtimes(
        R_W, problem.kin.com_B_ca(joints12, whole_body=problem.options.whole_body_com)
    )


def gaussian_ca(v, length: float):
    """exp(-|v|^2 / (2 length^2)): a decreasing function of the distance |v|.

    The paper's closeness terms are 1 / (1 + |v|) (sigma3, sigma4) and an unspecified
    decreasing h_m (Theta3 sigma1). Any decreasing function of the same distance plays the
    same role; this one makes the term's logarithm a convex quadratic, which IPOPT
    handles far better than log(1 + |v|) (concave in |v|, non-smooth at 0).
    """
    return ca.exp(-ca.sumsqr(v) / (2 * length**2))


def sigma3_ca(d_theta, options: ThetaOptions):
    """sigma3 of sections 7.2-7.5: joints near theta_nor, K = I / joint_scale_rad."""
    return gaussian_ca(d_theta, options.joint_scale_rad)


def state_from_pose_coords(eps: np.ndarray, feet_W, joints, stratum: int, support) -> State:
    """A :class:`State` from compact exponential coordinates eps = [p, phi]."""
    g = pose_from_coords(eps)
    return State(g[:3, 3], g[:3, :3], feet_W, joints, stratum=stratum, support=tuple(support))


def terrain_height_function(terrain) -> ca.Function:
    """CasADi function (x, y) -> (z_T, grad z_T) with exact derivatives of the terrain."""
    xy = ca.SX.sym("xy", 2)
    z = terrain.height_ca(xy[0], xy[1])
    return ca.Function("terrain_height", [xy], [z, ca.gradient(z, xy)])


def contact_on_terrain_ca(height_fun: ca.Function, contact_xy, radius_m: float):
    """A contact point on the terrain and the sphere centre above it (sections 4.4-4.5).

    The contact point r = (x, y, z_T(x, y)) is parametrised by its horizontal position
    (decision variables), so f_T(r) = 0 holds exactly; the foot sphere's centre is then
    r + rho n(r), n the pseudo-normal, exactly as
    :func:`planner.body.contact.foot_centre_from_contact`
    computes it. Returns (contact_W, centre_W, normal_W, slope2) with slope2 = tan^2 of
    the terrain's inclination at r (bounded by mu^2 in section 7.4).
    """
    z, grad = height_fun(contact_xy)
    slope2 = ca.sumsqr(grad)
    normal = ca.vertcat(-grad[0], -grad[1], 1) / ca.sqrt(1 + slope2)
    contact = ca.vertcat(contact_xy[0], contact_xy[1], z)
    return contact, contact + radius_m * normal, normal, slope2
