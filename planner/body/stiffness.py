"""Sway stiffness of a stance on compliant servos (beyond the paper, sections 6 and 10).

The paper's stances are static equilibria of a rigid robot. A real robot's joints are
position servos of finite stiffness kp (LittleDog: 20 N m/rad, :mod:`planner.body.servo_model`)
given the holding torques as feed-forward. With its feet held on the ground, the body can
still move: the legs' joints deflect, and gravity and the loaded joints push along. The
potential of that motion, as a function of the body's pose xi (6: translation, and
rotation times a length L, the legs' mean reach, so both are in metres), with every
support foot's sphere centre fixed and the joints following by inverse kinematics, is

    V(xi) = sum_support [kp |theta_i - theta_i0|^2 / 2 - tau_i . (theta_i - theta_i0)]
            + m g z_com(xi),

tau_i the feed-forward torques. Its gradient at the planned pose is zero when the torques
hold forces at the sphere centres (the commanded ones hold them at the contact points, a
foot radius below: 2 % of the weight on a crawl stance); its Hessian H is the stance's
stiffness [N/m]. If H has an eigenvalue near or
below zero, the body drifts along that direction when anything disturbs it: the load
moves toward a foot, that leg sags under it, which moves more load there.

Chosen from MuJoCo runs (open loop, LittleDog; bench/notes/2026-11-25-physics-named.md):
plans that fell did so from the three-leg stances with the least stiffness of their
plans, 44-83 N/m (flat walking: 450-550); the same plans on stiffer servos fell up to
125 N/m and walked from 128 N/m; in the plans that did not fall every three-leg stance had
186 N/m or more. Hence two levels: a three-leg stance needs
:data:`SWAY_STIFFNESS_MIN_MG_PER_L`, 0.8 m g / L (131 N/m for LittleDog, above every
stance that fell), and Theta2 aims for :data:`SWAY_STIFFNESS_AIM_MG_PER_L`, 1.2 m g / L
(197 N/m, 1.6 times the stiffest that fell) where it finds such a pose. Asking 1.2 of
every stance loses courses at the limits of the legs.
Between dynamically similar robots stiffness scales as m g / L (kp scales with m g L,
:mod:`planner.body.servo_model`). The boundary itself is MuJoCo's: a crawl stance held on
its three legs stays put (within 8 mm for 1.5 s) at 1.25 times the servo stiffness where
the least eigenvalue crosses zero, and falls at 0.8 times it (``tests/test_stiffness.py``).

The Hessian is exact (CasADi algorithmic differentiation): the joints are two Newton steps
of the legs' inverse kinematics from theta_0, whose error is fourth order in xi, so the
second derivatives at xi = 0 are those of the exact IK. The feet are held at their sphere
centres (a foot that rolls moves its centre by the foot radius times its turn: second
order, left out).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from planner.body.kinematics import kinematics_of, robot_cached
from planner.body.margins import SWAY_STIFFNESS_AIM_MG_PER_L, SWAY_STIFFNESS_MIN_MG_PER_L
from planner.body.servo_model import servo_model
from planner.core.lie import hat_ca, rotation_from_vector_ca
from planner.core.units import GRAVITY_M_S2

if TYPE_CHECKING:
    from planner.body.robot import Robot

__all__ = [
    "SWAY_STIFFNESS_AIM_MG_PER_L",
    "SWAY_STIFFNESS_MIN_MG_PER_L",
    "StanceStiffness",
    "SwayStiffness",
    "joint_sway_matrix_ca",
    "sway_stiffness_of",
]

_Array = NDArray[np.float64]

_NEWTON_STEPS = 2  # IK steps in the potential: error O(|xi|^4), exact Hessian at xi = 0


@dataclass
class StanceStiffness:
    """The stiffness of one stance: eigenvalues (ascending) [N/m] and their directions.

    ``directions[:, 0]`` is the softest motion (unit; translation [m], then rotation x L);
    ``joint_part`` is the servos' share of H (kp sum G_i^T G_i), ``gradient`` the
    potential's gradient at the pose [N] (zero when the feed-forward holds it).
    """

    eigenvalues: _Array
    directions: _Array
    hessian: _Array
    joint_part: _Array
    gradient: _Array
    length_m: float

    @property
    def least(self) -> float:
        """The smallest eigenvalue [N/m]."""
        return float(self.eigenvalues[0])


class SwayStiffness:
    """Sway stiffness of one robot's stances (module docstring); CasADi, built once per support."""

    def __init__(self, robot: Robot, kp_nm_per_rad: float | None = None):
        self.robot = robot
        self.kin = kinematics_of(robot)
        if kp_nm_per_rad is None:
            kp_nm_per_rad = servo_model(robot).kp_nm_per_rad
        self.kp = float(kp_nm_per_rad)
        self.length_m = float(np.mean(robot.reach_m))
        self.minimum_n_per_m = self.bound_n_per_m(SWAY_STIFFNESS_MIN_MG_PER_L)
        self._functions: dict[tuple[int, ...], ca.Function] = {}

    def bound_n_per_m(self, mg_per_l: float) -> float:
        """A stiffness given in units of m g / L, in N/m for this robot."""
        return float(mg_per_l) * self.robot.total_mass_kg * GRAVITY_M_S2 / self.length_m

    def _function(self, support: tuple[int, ...]) -> ca.Function:
        fun = self._functions.get(support)
        if fun is not None:
            return fun
        kin, r = self.kin, self.robot
        xi = ca.SX.sym("xi", 6)
        p0, th0, tau = ca.SX.sym("p0", 3), ca.SX.sym("theta0", 12), ca.SX.sym("tau", 12)
        R0 = ca.SX.sym("R0", 3, 3)
        kp = ca.SX.sym("kp")
        p = p0 + xi[:3]
        R = ca.mtimes(rotation_from_vector_ca(xi[3:] / self.length_m), R0)
        energy, joints, jac_parts = 0, [], []
        for i in range(4):
            t0 = th0[3 * i : 3 * i + 3]
            if i not in support:
                joints.append(t0)
                continue
            centre_W = p0 + ca.mtimes(R0, kin.foot_B_ca(i, t0))  # held fixed
            target_B = ca.mtimes(R.T, centre_W - p)
            th = t0
            for _ in range(_NEWTON_STEPS):
                foot = kin.foot_B_ca(i, th)
                th = th + ca.solve(kin.foot_jacobian_B_ca(i, th), target_B - foot)
            d = th - t0
            energy = energy + 0.5 * kp * ca.dot(d, d) - ca.dot(tau[3 * i : 3 * i + 3], d)
            joints.append(th)
            jac_parts.append(ca.jacobian(th, xi))
        com = p + ca.mtimes(R, kin.com_B_ca(ca.vertcat(*joints)))
        energy = energy + r.total_mass_kg * GRAVITY_M_S2 * com[2]
        hess, grad = ca.hessian(energy, xi)
        joint_part = kp * sum(ca.mtimes(G.T, G) for G in jac_parts)
        fun = ca.Function(
            "sway_" + "".join(map(str, support)),
            [xi, p0, ca.vec(R0), th0, tau, kp],
            [hess, grad, joint_part],
        )
        self._functions[support] = fun
        return fun

    def stance(
        self, base_position_W, base_rotation_W, joints_rad, support, tau_ff_nm
    ) -> StanceStiffness:
        """The stiffness of a stance (feet fixed where ``joints_rad`` put them).

        ``tau_ff_nm`` (12,): the servos' feed-forward, robot joint order (the holding
        torques of :func:`planner.body.torques.holding_load`).
        """
        fun = self._function(tuple(sorted(int(i) for i in support)))
        out = fun(
            np.zeros(6),
            np.asarray(base_position_W, float),
            np.asarray(base_rotation_W, float).T.ravel(),  # column-major vec
            np.asarray(joints_rad, float).ravel(),
            np.asarray(tau_ff_nm, float).ravel(),
            self.kp,
        )
        hess, grad, joint_part = (np.array(o, dtype=float) for o in out)
        hess = 0.5 * (hess + hess.T)
        if not (np.all(np.isfinite(hess)) and np.all(np.isfinite(joint_part))):
            # a singular support leg (its Jacobian): no stiffness can be certified
            return StanceStiffness(
                np.full(6, -np.inf), np.eye(6), hess, joint_part, grad.ravel(), self.length_m
            )
        w, U = np.linalg.eigh(hess)
        return StanceStiffness(w, U, hess, joint_part, grad.ravel(), self.length_m)


def sway_stiffness_of(robot: Robot) -> SwayStiffness:
    """The (cached) :class:`SwayStiffness` of a robot, at its servo model's stiffness."""
    return robot_cached(robot, "_sway_stiffness", SwayStiffness)


def joint_sway_matrix_ca(kin, kp: float, length_m: float, p_W, R_W, joints12, centres, support):
    """The servos' part of the stance stiffness, kp sum_i G_i^T G_i (6 x 6, CasADi) [N/m].

    ``centres``: the support feet's sphere centres (3-vectors, world frame), held fixed;
    G_i = J_i^-1 d b_i / d xi with b_i = R^T (c_i - p) the foot in body frame and xi the
    body motion (translation, then rotation x ``length_m``). The joint part of
    :meth:`SwayStiffness.stance`'s Hessian, a smooth function of the pose and joints.
    """
    K = 0
    for i in support:
        J = kin.foot_jacobian_B_ca(i, joints12[3 * i : 3 * i + 3])
        rel = centres[i] - p_W
        B = -ca.mtimes(R_W.T, ca.horzcat(ca.DM.eye(3), -hat_ca(rel) / length_m))
        G = ca.solve(J, B)
        K = K + ca.mtimes(G.T, G)
    return kp * K
