"""Joint torques of a quasi-static stance: can the motors hold it? (beyond the paper, section 10).

Eq. 3-5 and the friction cones say whether *forces* exist that hold the robot still; the
motors must also produce the joint torques those forces need. In static equilibrium
(Pinocchio's free-flyer dynamics with zero velocity and acceleration)

    g(q) = sum_i J_i(q)^T f_i + S^T tau,

with g the generalized gravity of every link (``pinocchio.computeGeneralizedGravity``),
J_i the Jacobian of the contact point r_i = c_i - rho n_i (world-aligned linear part,
from the foot frame's ``LOCAL_WORLD_ALIGNED`` Jacobian moved from the sphere centre to the
contact point), f_i the contact force and tau the 12 joint torques. The 6 base rows are
the balance of eq. 4; the joint rows give tau. :func:`torque_feasibility` solves, over
all forces in the exact friction cones that balance the robot (an SOCP, Clarabel as in
:mod:`planner.body.statics`),

    min_f  max_j |tau_j(f)| / effort_j,

so ``ratio`` <= 1 means some admissible force distribution needs no joint beyond its URDF
effort limit (LittleDog: 1.7 N m hips, 0.6 N m knees). Joints without a finite, positive
effort limit are not constrained.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca
import clarabel
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from planner.body.margins import COMMANDED_TORQUE_FRACTION
from planner.body.statics import _csc, _tangent_bases, _zero_csc
from planner.core.units import GRAVITY_M_S2

if TYPE_CHECKING:
    from planner.body.robot import Robot
    from planner.world.terrain import Terrain

__all__ = [
    "COMMANDED_FRICTION_SHARES",
    "COMMANDED_TORQUE_FRACTION",
    "TorqueCheck",
    "TorqueFeasibility",
    "holding_load",
    "joint_efforts_nm",
    "least_squares_ratios_ca",
]

_Array = NDArray[np.float64]
_SOLVED = ("Solved", "AlmostSolved")
# shares of the friction coefficient the commanded (feed-forward) distribution may use, the
# smallest first whose forces load no joint beyond COMMANDED_TORQUE_FRACTION (else the whole
# cone): the least-squares forces lean along the legs, so on an incline they sat on the
# cone's edge (most samples of an 18 degree incline's plan had a stance foot at
# |f_t| = mu f_n) and the servos' errors pushed feet over it, down the incline. Chosen from
# MuJoCo runs (bench/notes/2026-11-27-friction-reserve.md): within 0.7 mu the same plan's
# feet slid a fifth as far and the walk reached; 0.7 alone loads the hind knees beyond the
# fraction in a third of its samples, where 0.8 does not
COMMANDED_FRICTION_SHARES = (0.7, 0.8, 0.9)
CONE_SLACK = 1e-6  # least-squares forces this far (x the weight) inside every cone skip the SOCP
_E_Z = np.array([0.0, 0.0, 1.0])


@dataclass
class TorqueFeasibility:
    """Outcome of :meth:`TorqueCheck.solve` at one configuration.

    ``ratio``: least achievable max_j |tau_j| / effort_j (inf when no force distribution
    in the cones balances the robot, nan when the solver failed); ``torques_nm`` (12,) in
    the robot's joint order for that distribution; ``forces_W`` (4, 3) [N];
    ``worst_joint``: robot joint index of the largest ratio; ``status``: Clarabel's.
    """

    ratio: float
    torques_nm: _Array
    forces_W: _Array
    worst_joint: int
    status: str

    @property
    def feasible(self) -> bool:
        """Some admissible forces keep every joint within its effort limit."""
        return bool(self.ratio <= 1.0)


def joint_efforts_nm(robot: Robot) -> _Array:
    """(12,) URDF effort limits [N m] in the robot's joint order (inf where none is given)."""
    m = robot.model
    out = []
    for name in robot.joint_names:
        e = float(m.effortLimit[m.joints[m.getJointId(name)].idx_v])
        out.append(e if math.isfinite(e) and 0.0 < e < 1e6 else math.inf)
    return np.array(out)


class TorqueCheck:
    """Joint-torque feasibility of stances of one robot (module docstring)."""

    def __init__(self, robot: Robot):
        self.robot = robot
        self.model = robot.model
        self.data = self.model.createData()
        self.foot_ids = [self.model.getFrameId(f) for f in robot.foot_frames]
        self.v_idx = np.array(
            [self.model.joints[self.model.getJointId(n)].idx_v for n in robot.joint_names]
        )
        self.base_idx = np.setdiff1d(np.arange(self.model.nv), self.v_idx)  # free-flyer rows
        self.effort = joint_efforts_nm(robot)
        finite = self.effort[np.isfinite(self.effort)]
        # least squares in torque / effort (unlimited joints weigh as the strongest limited one)
        self.weights = 1.0 / np.where(
            np.isfinite(self.effort), self.effort, finite.max() if finite.size else 1.0
        )

    def _contact_jacobian_T(self, q: _Array, support, normals_W: _Array) -> _Array:
        """(nv, 3 k) generalized force of the contact forces on ``support``, stacked."""
        model, data = self.model, self.data
        rho = self.robot.foot_radius_m
        n = np.asarray(normals_W, float).reshape(4, 3)[list(support)]
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        jac = np.zeros((3 * len(n), model.nv))
        for j, i in enumerate(support):
            J = pin.getFrameJacobian(model, data, self.foot_ids[i], pin.LOCAL_WORLD_ALIGNED)
            d = -rho * n[j]  # contact point minus sphere centre
            hat = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
            jac[3 * j : 3 * j + 3] = J[:3] - hat @ J[3:]
        return jac.T

    def commanded_ratio_map(self, q: _Array, support, normals_W: _Array) -> _Array:
        """(12, 3) map M with tau_j / effort_j = (M @ g_W)_j in the commanded distribution.

        The effort-weighted least-squares forces of :meth:`solve` (``least_squares``)
        without the friction cones (the same wherever they lie inside them) balance the
        generalized gravity, which is linear in the gravity vector g_W; so are they and
        the joint torques. With g_W - a (a body moving at the acceleration a, every joint
        held: d'Alembert, exact for the generalized forces) it gives the torques the
        motion needs (:meth:`planner.planning.local.LocalPlanner.body_offsets_s`). Joints
        without a finite effort limit map to 0.
        """
        model, data = self.model, self.data
        q = np.asarray(q, float)
        sup = [int(i) for i in support]
        jt = self._contact_jacobian_T(q, sup, normals_W)
        saved = model.gravity.linear.copy()
        try:
            gens = []
            for e in np.eye(3):
                model.gravity.linear = e
                gens.append(pin.computeGeneralizedGravity(model, data, q).copy())
        finally:
            model.gravity.linear = saved
        g = np.column_stack(gens)  # (nv, 3): generalized gravity per unit gravity component
        kkt, a = self._weighted_kkt(jt)
        nf = jt.shape[1]
        rhs = np.vstack([2.0 * a.T @ (self.weights[:, None] * g[self.v_idx]), g[self.base_idx]])
        f = np.linalg.lstsq(kkt, rhs, rcond=None)[0][:nf]  # (3k, 3)
        tau = g[self.v_idx] - jt[self.v_idx] @ f
        scale = np.where(np.isfinite(self.effort), 1.0 / self.effort, 0.0)
        return scale[:, None] * tau

    def _weighted_kkt(self, jt: _Array) -> tuple[_Array, _Array]:
        """KKT matrix of min |W (g_a - A f)|^2 s.t. B f = g_b, and W A (= W J^T, (12, 3k)).

        A, B: the joint and the balance (free-flyer) rows of ``jt``; W = 1 / effort.
        """
        a = self.weights[:, None] * jt[self.v_idx]  # W J^T (12, 3k)
        b = jt[self.base_idx]  # balance rows (6, 3k)
        nf = a.shape[1]
        kkt = np.zeros((nf + len(b), nf + len(b)))
        kkt[:nf, :nf] = 2.0 * a.T @ a
        kkt[:nf, nf:] = b.T
        kkt[nf:, :nf] = b
        return kkt, a

    def _feasibility(self, g: _Array, jt: _Array, sup, f: _Array, status: str):
        """The :class:`TorqueFeasibility` of balancing forces ``f`` (3k,) on ``sup``."""
        forces = np.zeros((4, 3))
        forces[sup] = f.reshape(len(sup), 3)
        tau = g[self.v_idx] - jt[self.v_idx] @ f
        ratios = np.abs(tau) / self.effort
        worst = int(np.argmax(ratios))
        return TorqueFeasibility(float(ratios[worst]), tau, forces, worst, status)

    def _least_squares_forces(self, jt: _Array, g: _Array):
        """The effort-weighted least-squares balancing forces (3k,) without cones, or None.

        Without the friction cones the problem of :meth:`solve` (``least_squares``) is an
        equality-constrained least-squares problem, solved by its KKT system (once per
        configuration: only the cone test depends on the friction share). None where the
        system is singular or its solution does not balance the robot.
        """
        kkt, a = self._weighted_kkt(jt)
        b = jt[self.base_idx]
        nf = a.shape[1]
        rhs = np.concatenate([2.0 * a.T @ (self.weights * g[self.v_idx]), g[self.base_idx]])
        try:
            f = np.linalg.solve(kkt, rhs)[:nf]
        except np.linalg.LinAlgError:
            return None
        weight = float(np.linalg.norm(g[self.base_idx][:3]))
        if not np.all(np.isfinite(f)) or np.linalg.norm(b @ f - g[self.base_idx]) > 1e-9 * weight:
            return None
        return f

    @staticmethod
    def _inside_cones(f: _Array, n: _Array, mu: float, weight_n: float) -> bool:
        """Whether forces ``f`` (3k,) lie inside every cone of ``mu`` by ``CONE_SLACK``.

        There the cones are not active and the least-squares forces are also the optimum
        with them, so the SOCP is not needed.
        """
        fk = f.reshape(-1, 3)
        normal = np.einsum("ij,ij->i", fk, n)
        tangential = np.linalg.norm(fk - normal[:, None] * n, axis=1)
        return bool(np.all(mu * normal - tangential >= CONE_SLACK * weight_n))

    def solve(
        self, q: _Array, support, mu: float, normals_W: _Array, least_squares: bool = False
    ) -> TorqueFeasibility:
        """Torque feasibility at Pinocchio ``q`` on the feet ``support`` (0-based legs).

        ``normals_W`` (4, 3): terrain normals at the contacts; ``mu``: friction coefficient.
        ``least_squares``: minimise sum_j (tau_j / effort_j)^2 instead, the distribution the
        executor commands as feed-forward and the planner keeps within its margin; ``ratio``
        is then that distribution's, not the least achievable. Unweighted (sum tau_j^2, what
        uniform servos settle into without feed-forward) it loaded LittleDog's 0.6 N m knees
        to 80 % in half the three-leg samples of a stepping-stones plan (max 107 %), weighted
        to 42 % (max 62 %); the least achievable ratio (37 %, max 61 %) needs internal foot
        forces at the edge of the friction cones. The least-squares forces stay in the cones
        of the first of ``COMMANDED_FRICTION_SHARES`` x ``mu`` that admit a balance loading
        no joint beyond ``COMMANDED_TORQUE_FRACTION`` of its effort, else in those of ``mu``.
        """
        model, data = self.model, self.data
        q = np.asarray(q, float)
        sup = [int(i) for i in support]
        n = np.asarray(normals_W, float).reshape(4, 3)[sup]
        g = pin.computeGeneralizedGravity(model, data, q)
        jt = self._contact_jacobian_T(q, sup, normals_W)  # (nv, 3k)
        if not least_squares:
            return self._socp(g, jt, sup, n, mu, False)
        # the largest friction reserve that loads no joint beyond the commanded fraction
        f = self._least_squares_forces(jt, g)
        weight_n = float(np.linalg.norm(g[self.base_idx][:3]))
        for share in COMMANDED_FRICTION_SHARES:
            res = self._least_squares(g, jt, sup, n, share * mu, f, weight_n)
            if res.status in _SOLVED and res.ratio <= COMMANDED_TORQUE_FRACTION:
                return res
        return self._least_squares(g, jt, sup, n, mu, f, weight_n)

    def _least_squares(self, g, jt, sup, n, mu: float, f, weight_n: float) -> TorqueFeasibility:
        """The least-squares distribution in the cones of ``mu``.

        The cone-free forces ``f`` (:meth:`_least_squares_forces`, None: singular) where
        they lie inside, else the SOCP.
        """
        if f is not None and self._inside_cones(f, n, mu, weight_n):
            return self._feasibility(g, jt, sup, f, "Solved")
        return self._socp(g, jt, sup, n, mu, least_squares=True)

    def _socp(self, g, jt, sup, n, mu: float, least_squares: bool) -> TorqueFeasibility:
        """:meth:`solve`'s SOCP (Clarabel) in the friction cones of ``mu``."""
        k = len(sup)
        base = self.base_idx
        limited = [c for c in range(12) if math.isfinite(self.effort[c])]
        nv = 3 * k + 1  # forces, then s
        rows, b, cones = [], [], []
        a_eq = np.zeros((len(base), nv))
        a_eq[:, : 3 * k] = jt[base]
        rows.append(a_eq)
        b.append(g[base])
        cones.append(clarabel.ZeroConeT(len(base)))
        # |g_j - (J^T f)_j| <= s e_j  <=>  -(J^T f)_j - e_j s <= -g_j, (J^T f)_j - e_j s <= g_j
        a_t = np.zeros((2 * len(limited), nv))
        b_t = np.zeros(2 * len(limited))
        for r, c in enumerate(limited):
            v = self.v_idx[c]
            a_t[2 * r, : 3 * k], a_t[2 * r, -1], b_t[2 * r] = -jt[v], -self.effort[c], -g[v]
            a_t[2 * r + 1, : 3 * k], a_t[2 * r + 1, -1], b_t[2 * r + 1] = (
                jt[v],
                -self.effort[c],
                g[v],
            )
        rows.append(a_t)
        b.append(b_t)
        cones.append(clarabel.NonnegativeConeT(len(b_t)))
        t1, t2 = _tangent_bases(n)
        a_c = np.zeros((3 * k, nv))
        for j in range(k):
            a_c[3 * j, 3 * j : 3 * j + 3] = -mu * n[j]
            a_c[3 * j + 1, 3 * j : 3 * j + 3] = -t1[j]
            a_c[3 * j + 2, 3 * j : 3 * j + 3] = -t2[j]
        rows.append(a_c)
        b.append(np.zeros(3 * k))
        cones += [clarabel.SecondOrderConeT(3) for _ in range(k)]
        cost = np.zeros(nv)
        hess = _zero_csc(nv)
        if least_squares:  # |W (g_a - A f)|^2 = f'A'W'W A f - 2 g_a'W'W A f + const
            a = self.weights[:, None] * jt[self.v_idx]
            h = np.zeros((nv, nv))
            h[: 3 * k, : 3 * k] = 2.0 * a.T @ a
            hess = _csc(np.triu(h))
            cost[: 3 * k] = -2.0 * a.T @ (self.weights * g[self.v_idx])
            cost[-1] = 1e-6
        else:
            cost[-1] = 1.0
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        solver = clarabel.DefaultSolver(
            hess, cost, _csc(np.vstack(rows)), np.concatenate(b), cones, settings
        )
        res = solver.solve()
        status = str(res.status)
        if status in _SOLVED:
            return self._feasibility(g, jt, sup, np.asarray(res.x)[: 3 * k], status)
        ratio = math.inf if "Infeasible" in status else math.nan
        return TorqueFeasibility(ratio, np.full(12, np.nan), np.zeros((4, 3)), -1, status)


def holding_load(
    check: TorqueCheck, q: _Array, contact: NDArray[np.bool_], mu: float, terrain: Terrain | None
) -> tuple[_Array, _Array]:
    """Forces (N, 4, 3) [N] and joint torques (N, 12) [N m] holding each ``q`` (N, 19) still.

    Per sample, the least-squares solution of :meth:`TorqueCheck.solve` on the ``contact``
    feet (balancing forces in the friction cones; normals from ``terrain`` at the foot
    centres, vertical without a terrain), effort-weighted so the weak knees carry least.
    Measured in MuJoCo (the same plans, open loop): with this feed-forward the plans walked
    to their ends; with the unweighted one (what uniform servos settle into: a four-leg
    stand does, keeping 0.7 degrees of sag) a stepping-stones walk fell and a barrier walk
    ended twice as far off its plan. A sample where
    no admissible forces balance the robot keeps the previous sample's values (zeros
    before the first): these are feed-forward for the servos, not a check.
    """
    q = np.asarray(q, float)
    contact = np.asarray(contact, bool)
    model, data = check.model, check.data
    forces, torques = np.zeros((len(q), 4, 3)), np.zeros((len(q), 12))
    last_f, last_tau = np.zeros((4, 3)), np.zeros(12)
    for k, (qk, ck) in enumerate(zip(q, contact, strict=True)):
        if ck.any():
            pin.framesForwardKinematics(model, data, qk)
            centres = np.array([data.oMf[f].translation for f in check.foot_ids])
            normals = terrain.normal(centres) if terrain is not None else np.tile(_E_Z, (4, 1))
            res = check.solve(qk, np.flatnonzero(ck), mu, normals, least_squares=True)
            if np.all(np.isfinite(res.torques_nm)):
                last_f, last_tau = res.forces_W, res.torques_nm
        forces[k], torques[k] = last_f, last_tau
    return forces, torques


def least_squares_ratios_ca(
    kin, base_rotation_W, joints12, support, contacts_W, normals_W, com_W, effort_nm, mass_kg
):
    """Symbolic tau_j / effort_j of the support joints in the commanded force distribution.

    The distribution is the effort-weighted least squares the feed-forward commands
    (:meth:`TorqueCheck.solve` with ``least_squares``), here without the friction cones.

    ``contacts_W``, ``normals_W``: lists of 4 CasADi 3-vectors (contact points, unit
    normals); ``com_W`` the whole-body COM; ``effort_nm`` (12,) finite URDF efforts. With
    tau_i = g_i - J_i^T f_i per support leg (:meth:`LegKinematics.gravity_torque_ca`,
    :meth:`LegKinematics.contact_jacobian_W_ca`) and the balance A f = b (forces sum to m g
    up, moments about the COM to zero: eq. 4), the minimiser of sum_j (tau_j / e_j)^2
    solves the KKT system ``[2 B^T B, A^T; A, 0] [f; l] = [2 B^T c; b]``, B = W J^T, c = W g,
    W = diag(1 / e), solved by blocks (B is block diagonal). Equal to the SOCP's
    distribution wherever that lies inside the cones (tested). Returns the (3 k,) ratios
    and the k forces [N] (CasADi), in the order of ``support``.
    """
    b = ca.vertcat(0, 0, mass_kg * GRAVITY_M_S2, 0, 0, 0)
    legs = []  # per support leg: B_i^-1, (B_i^T B_i)^-1, A_i, c_i
    for i in (int(i) for i in support):
        th = joints12[3 * i : 3 * i + 3]
        w = ca.DM(1.0 / np.asarray(effort_nm, float)[3 * i : 3 * i + 3])
        offset = -kin.robot.foot_radius_m * normals_W[i]
        jac = kin.contact_jacobian_W_ca(i, base_rotation_W, th, offset)
        b_inv = ca.inv(ca.mtimes(ca.diag(w), jac.T))  # 3 x 3: the leg is not singular
        a = ca.vertcat(ca.DM.eye(3), ca.skew(contacts_W[i] - com_W))
        c = w * kin.gravity_torque_ca(i, base_rotation_W, th)
        legs.append((b_inv, ca.mtimes(b_inv, b_inv.T), a, c))
    # the KKT system, block by block: f_i = B_i^-1 c_i - (B_i^T B_i)^-1 A_i^T m with
    # (sum_i A_i (B_i^T B_i)^-1 A_i^T) m = sum_i A_i B_i^-1 c_i - b, and the weighted
    # torques c_i - B_i f_i = B_i^-T A_i^T m
    schur = sum(ca.mtimes([a, bb, a.T]) for _, bb, a, _ in legs)
    rhs = sum(ca.mtimes([a, bi, c]) for bi, _, a, c in legs) - b
    m = ca.solve(schur, rhs)
    ratios, forces = [], []
    for bi, bb, a, c in legs:
        at_m = ca.mtimes(a.T, m)
        ratios.append(ca.mtimes(bi.T, at_m))
        forces.append(ca.mtimes(bi, c) - ca.mtimes(bb, at_m))
    return ca.vertcat(*ratios), forces
