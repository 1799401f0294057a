"""Leg kinematics generated from the Pinocchio model (paper section 5.1).

Forward kinematics is the product of exponentials of eq. 1-2: with the twist of joint j
of leg i a pure rotation about the unit axis omega_{i,j} through r^0_{i,j} (both read from
Pinocchio at zero joint angles, body frame B),

    ^B r_i = exp(xi_1 theta_1) exp(xi_2 theta_2) exp(xi_3 theta_3) ^B r^0_i.

The same chain is written once in numpy and once in CasADi (exact derivatives for IPOPT).
Inverse kinematics (section 5.1.2) uses Paden-Kahan subproblem 3 for the knee, then
subproblem 2 for the two hip joints, when the first two axes intersect; otherwise a bounded
least-squares fallback. The centre of mass is whole-body (every link's inertia moves with
its joint) or, as the paper assumes, the body link's alone.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from planner.body import paden_kahan as pk
from planner.core.units import GRAVITY_M_S2

if TYPE_CHECKING:
    from planner.body.robot_model import Leg, Robot

AXES_INTERSECT_TOL_M = 1e-9
NOMINAL_DEPTH_FRACTION = 0.8  # theta_nor puts the foot at 80 % of the leg's vertical reach


def axis_rotation_ca(axis: np.ndarray, angle):
    """exp(hat(axis) angle) by Rodrigues' formula: a unit ``axis`` (3,), a symbolic angle."""
    w = ca.DM([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return ca.DM.eye(3) + ca.sin(angle) * w + (1 - ca.cos(angle)) * ca.mtimes(w, w)


def twist_apply_np(leg: Leg, theta: np.ndarray, point_B: np.ndarray, upto: int = 3) -> np.ndarray:
    """exp(xi_1 th_1) ... exp(xi_upto th_upto) applied to a body-frame point (eq. 2).

    Rodrigues' formula on the vector, in Python floats: the planner calls this ~10^5 times
    per walk (IK of the rolling stance feet), where 3x3 numpy products cost 10x more.
    """
    x, y, z = (float(v) for v in point_B)
    axes, points = leg.axes_B, leg.points_B
    for j in reversed(range(upto)):
        kx, ky, kz = axes[j].tolist()
        rx, ry, rz = points[j].tolist()
        vx, vy, vz = x - rx, y - ry, z - rz
        c, s = math.cos(theta[j]), math.sin(theta[j])
        d = (kx * vx + ky * vy + kz * vz) * (1.0 - c)
        x = vx * c + (ky * vz - kz * vy) * s + kx * d + rx
        y = vy * c + (kz * vx - kx * vz) * s + ky * d + ry
        z = vz * c + (kx * vy - ky * vx) * s + kz * d + rz
    return np.array([x, y, z])


def foot_and_jacobian_np(leg: Leg, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Foot centre (eq. 2) and its exact (3, 3) Jacobian in body frame.

    Column j is omega'_j x (p - r'_j), the joint's axis and point moved by the joints
    after it in the product (exp(xi_1 th_1) ... exp(xi_{j-1} th_{j-1}) applied to them:
    the spatial twist of a revolute joint). Python floats, as in :func:`twist_apply_np`.
    """
    p, cols = _foot_and_columns(_leg_floats(leg), [float(v) for v in theta])
    return np.array(p), np.array(cols).T


def _leg_floats(leg: Leg) -> tuple:
    """(axes, points, foot) of a leg as tuples of Python floats, for the scalar FK."""
    axes = tuple(tuple(leg.axes_B[j].tolist()) for j in range(3))
    points = tuple(tuple(leg.points_B[j].tolist()) for j in range(3))
    return axes, points, tuple(leg.foot_B0.tolist())


def _foot_and_columns(consts: tuple, th: list) -> tuple[tuple, list]:
    """Foot centre and Jacobian columns of :func:`foot_and_jacobian_np`, as Python floats.

    ``consts`` from :func:`_leg_floats` (cached per leg by :class:`LegKinematics`): the
    rolling stance feet call this ~60 000 times a walk, where the per-call conversions of
    the leg's arrays cost as much as the arithmetic. The joint rotations are written out,
    each applied to all the points it moves at once (the same arithmetic, in the same
    order, as applying exp(xi_j th_j) point by point: :func:`_rotate`).
    """
    axes, points, foot = consts
    c0, c1, c2 = math.cos(th[0]), math.cos(th[1]), math.cos(th[2])
    s0, s1, s2 = math.sin(th[0]), math.sin(th[1]), math.sin(th[2])
    (p1x, p1y, p1z), (p2x, p2y, p2z) = points[1], points[2]
    (a1x, a1y, a1z), (a2x, a2y, a2z) = axes[1], axes[2]
    # exp(xi_2 th_2): the foot
    f = _rotate(axes[2], points[2], c2, s2, foot[0], foot[1], foot[2])
    # exp(xi_1 th_1): the foot, joint 2's point and axis tip
    f = _rotate(axes[1], points[1], c1, s1, *f)
    r2 = _rotate(axes[1], points[1], c1, s1, p2x, p2y, p2z)
    t2 = _rotate(axes[1], points[1], c1, s1, p2x + a2x, p2y + a2y, p2z + a2z)
    # exp(xi_0 th_0): all of them and joint 1's point and axis tip
    px, py, pz = _rotate(axes[0], points[0], c0, s0, *f)
    r2 = _rotate(axes[0], points[0], c0, s0, *r2)
    t2 = _rotate(axes[0], points[0], c0, s0, *t2)
    r1 = _rotate(axes[0], points[0], c0, s0, p1x, p1y, p1z)
    t1 = _rotate(axes[0], points[0], c0, s0, p1x + a1x, p1y + a1y, p1z + a1z)
    (a0x, a0y, a0z), r0 = axes[0], points[0]
    t0 = (r0[0] + a0x, r0[1] + a0y, r0[2] + a0z)
    cols = []
    for (rx, ry, rz), tip in ((r0, t0), (r1, t1), (r2, t2)):
        wx, wy, wz = tip[0] - rx, tip[1] - ry, tip[2] - rz
        dx, dy, dz = px - rx, py - ry, pz - rz
        cols.append((wy * dz - wz * dy, wz * dx - wx * dz, wx * dy - wy * dx))
    return (px, py, pz), cols


def _rotate(axis: tuple, point: tuple, c: float, s: float, x: float, y: float, z: float):
    """exp(xi th) (x, y, z) for a revolute twist (``axis`` through ``point``), Rodrigues."""
    kx, ky, kz = axis
    rx, ry, rz = point
    vx, vy, vz = x - rx, y - ry, z - rz
    d = (kx * vx + ky * vy + kz * vz) * (1.0 - c)
    return (
        vx * c + (ky * vz - kz * vy) * s + kx * d + rx,
        vy * c + (kz * vx - kx * vz) * s + ky * d + ry,
        vz * c + (kx * vy - ky * vx) * s + kz * d + rz,
    )


def _solve3(cols, b):
    """Solve sum_j x_j cols[j] = b for x (Cramer's rule); None when singular."""
    (a, d, g), (b_, e, h), (c, f, i) = cols  # columns of the matrix [[a b c] [d e f] [g h i]]
    det = a * (e * i - f * h) - b_ * (d * i - f * g) + c * (d * h - e * g)
    if abs(det) < 1e-14:
        return None
    x, y, z = b
    return (
        (x * (e * i - f * h) - b_ * (y * i - f * z) + c * (y * h - e * z)) / det,
        (a * (y * i - f * z) - x * (d * i - f * g) + c * (d * z - y * g)) / det,
        (a * (e * z - y * h) - b_ * (d * z - y * g) + x * (d * h - e * g)) / det,
    )


def twist_apply_ca(leg: Leg, theta, point_B, upto: int = 3):
    """CasADi version of :func:`twist_apply_np` (theta a 3-vector SX/MX)."""
    p = ca.DM(point_B) if isinstance(point_B, np.ndarray) else point_B
    for j in reversed(range(upto)):
        r = ca.DM(leg.points_B[j])
        p = ca.mtimes(axis_rotation_ca(leg.axes_B[j], theta[j]), p - r) + r
    return p


@dataclass
class IKResult:
    """Result of leg inverse kinematics in body frame.

    ``joints_rad`` always holds finite angles: the chosen solution when ``reachable``,
    otherwise the in-limit angles whose foot comes closest to the target.
    """

    joints_rad: np.ndarray
    reachable: bool
    error_m: float  # |FK(joints) - target|
    method: str  # "paden-kahan" or "numeric"
    knee_flipped: bool = False  # True when only the non-preferred knee branch reaches
    solutions: list | None = None  # every in-limit exact solution (3,) found
    reason: str = ""


def hip_centre_B(leg: Leg) -> np.ndarray | None:
    """Intersection of the first two joint axes, or None when they do not intersect."""
    w1, w2 = leg.axes_B[0], leg.axes_B[1]
    r1, r2 = leg.points_B[0], leg.points_B[1]
    n = np.cross(w1, w2)
    if np.linalg.norm(n) < 1e-12:
        return None
    if abs(np.dot(r2 - r1, n)) / np.linalg.norm(n) > AXES_INTERSECT_TOL_M:
        return None
    # solve r1 + a w1 = r2 + b w2 in least squares
    a, b = np.linalg.lstsq(np.column_stack([w1, -w2]), r2 - r1, rcond=None)[0]
    return 0.5 * ((r1 + a * w1) + (r2 + b * w2))


def hip_point_B(leg: Leg) -> np.ndarray:
    """The point a leg's reach is measured from: :func:`hip_centre_B`, else its first joint."""
    centre = hip_centre_B(leg)
    return leg.points_B[0] if centre is None else centre


def _wrap_into_limits(angle: float, lo: float, hi: float, tol: float = 1e-12) -> list[float]:
    out = []
    for k in (-1, 0, 1):
        a = angle + 2 * np.pi * k
        if lo - tol <= a <= hi + tol:
            out.append(float(np.clip(a, lo, hi)))
    return out


class LegKinematics:
    """Numeric and symbolic kinematics of every leg of a :class:`Robot`."""

    def __init__(self, robot: Robot):
        self.robot = robot
        self.legs = robot.legs
        th = ca.SX.sym("theta", 3)
        self._foot_fun = []
        for leg in self.legs:
            p = twist_apply_ca(leg, th, leg.foot_B0)
            self._foot_fun.append(ca.Function(f"foot_{leg.name}", [th], [p, ca.jacobian(p, th)]))
        self._centres = [hip_centre_B(leg) for leg in self.legs]
        self._newton_consts = [  # per leg, Python floats for ik_leg_near's Newton steps
            (_leg_floats(leg), leg.lower_rad.tolist(), leg.upper_rad.tolist()) for leg in self.legs
        ]
        # link masses and COMs at zero configuration (body frame), grouped by leg joint
        model = robot.model
        import pinocchio as pin

        data = model.createData()
        pin.forwardKinematics(model, data, pin.neutral(model))
        self._link_mass = []  # per leg: list of (joint number 0..2, mass, com_B0)
        for leg in self.legs:
            items = []
            for j, jid in enumerate(leg.joint_ids):
                inertia = model.inertias[jid]
                if inertia.mass > 0:
                    items.append((j, float(inertia.mass), data.oMi[jid].act(inertia.lever)))
            self._link_mass.append(items)
        theta12 = ca.SX.sym("theta", 12)
        self._com_fun = ca.Function("com_B", [theta12], [self.com_B_ca(theta12)])

    # ---- forward kinematics -------------------------------------------------------------
    def foot_B(self, leg: int, theta_rad) -> np.ndarray:
        """Foot sphere centre of one leg in body frame (eq. 2)."""
        return twist_apply_np(self.legs[leg], np.asarray(theta_rad, float), self.legs[leg].foot_B0)

    def foot_jacobian_B(self, leg: int, theta_rad) -> np.ndarray:
        """(3, 3) d foot_B / d theta, exact (CasADi algorithmic differentiation)."""
        return np.array(self._foot_fun[leg](np.asarray(theta_rad, float))[1])

    def feet_B(self, joints_rad) -> np.ndarray:
        """(4, 3) foot centres in body frame for (4, 3) joint angles."""
        joints = np.asarray(joints_rad, float).reshape(4, 3)
        return np.array([self.foot_B(i, joints[i]) for i in range(4)])

    def feet_W(self, base_position_W, base_rotation_W, joints_rad) -> np.ndarray:
        """(4, 3) foot centres in world frame."""
        return self.feet_B(joints_rad) @ np.asarray(base_rotation_W).T + np.asarray(base_position_W)

    def foot_B_ca(self, leg: int, theta):
        """Symbolic foot centre of one leg in body frame (CasADi 3-vector)."""
        return twist_apply_ca(self.legs[leg], theta, self.legs[leg].foot_B0)

    def foot_jacobian_B_ca(self, leg: int, theta):
        """Symbolic (3, 3) d foot_B / d theta of one leg at ``theta`` (any CasADi expression)."""
        return self._foot_fun[leg](theta)[1]

    def feet_W_ca(self, base_position_W, base_rotation_W, joints12):
        """Symbolic (3 x 4) foot centres in world frame; joints12 legs in order FL..HR."""
        cols = [
            ca.mtimes(base_rotation_W, self.foot_B_ca(i, joints12[3 * i : 3 * i + 3]))
            + base_position_W
            for i in range(4)
        ]
        return ca.horzcat(*cols)

    def contact_jacobian_W_ca(self, leg: int, base_rotation_W, theta, offset_W):
        """Symbolic (3, 3) world-frame Jacobian of a foot's contact point w.r.t. its leg's joints.

        The point is the shank's point at ``offset_W`` from the foot centre (the contact
        point: offset -rho n). Column j is R (d centre_B / d theta_j) + omega_j x offset_W,
        with omega_j the joint's axis in world frame: the point moves with the shank, as in
        Pinocchio's frame Jacobian moved from the sphere centre to the contact point
        (:mod:`planner.body.torques`).
        """
        lg = self.legs[leg]
        centre_B = twist_apply_ca(lg, theta, lg.foot_B0)
        jac = ca.mtimes(base_rotation_W, ca.jacobian(centre_B, theta))
        cols = []
        for j in range(3):
            r = ca.DM(lg.points_B[j])
            axis_B = twist_apply_ca(lg, theta, r + ca.DM(lg.axes_B[j]), upto=j) - (
                twist_apply_ca(lg, theta, r, upto=j)
            )
            cols.append(jac[:, j] + ca.cross(ca.mtimes(base_rotation_W, axis_B), offset_W))
        return ca.horzcat(*cols)

    def gravity_torque_ca(self, leg: int, base_rotation_W, theta, g_m_s2: float = GRAVITY_M_S2):
        """Symbolic (3,) generalized gravity of a leg's joints [N m]: d V / d theta.

        V = g sum_l m_l z_l over the leg's links (their world heights, base fixed): the leg's
        rows of Pinocchio's ``computeGeneralizedGravity`` (the joint torque that holds the
        leg's own weight is this minus J^T f).
        """
        lg = self.legs[leg]
        height = 0
        for j, mass, com0 in self._link_mass[leg]:
            height = height + mass * ca.mtimes(
                base_rotation_W[2, :], twist_apply_ca(lg, theta, com0, upto=j + 1)
            )
        return ca.gradient(g_m_s2 * height, theta) if self._link_mass[leg] else ca.DM.zeros(3)

    # ---- centre of mass -----------------------------------------------------------------
    def com_B(self, joints_rad, whole_body: bool = True) -> np.ndarray:
        """Centre of mass in body frame: whole-body (default) or body link only (paper)."""
        if not whole_body:
            return self.robot.body_com_B.copy()
        return np.array(self._com_fun(np.asarray(joints_rad, float).ravel())).ravel()

    def com_B_ca(self, joints12, whole_body: bool = True):
        """Symbolic centre of mass in body frame (CasADi 3-vector)."""
        r = self.robot
        if not whole_body:
            return ca.DM(r.body_com_B)
        acc = ca.DM(r.body_mass_kg * r.body_com_B)
        for i, items in enumerate(self._link_mass):
            th = joints12[3 * i : 3 * i + 3]
            for j, mass, com0 in items:
                acc = acc + mass * twist_apply_ca(self.legs[i], th, com0, upto=j + 1)
        return acc / r.total_mass_kg

    # ---- inverse kinematics -------------------------------------------------------------
    def knee_direction(self, leg: int, theta_rad) -> int:
        """+1 when the knee lies forward (+x_B) of the hip-foot line, -1 when rearward."""
        lg = self.legs[leg]
        th = np.asarray(theta_rad, float)
        hip = twist_apply_np(lg, th, lg.points_B[1], upto=1)
        knee = twist_apply_np(lg, th, lg.points_B[2], upto=2)
        foot = self.foot_B(leg, th)
        d = foot - hip
        v = (knee - hip) - np.dot(knee - hip, d) / max(np.dot(d, d), 1e-300) * d
        return 1 if v[0] >= 0 else -1

    def ik_leg(
        self,
        leg: int,
        target_B,
        reference_rad=None,
        knee: int | None = None,
        tol_m: float = 1e-9,
        closest: bool = True,
    ) -> IKResult:
        """Joint angles putting leg ``leg``'s foot centre at ``target_B`` (section 5.1.2).

        ``knee`` (+1 forward, -1 rearward) defaults to the leg's knee configuration;
        among the in-limit solutions of that branch the one nearest ``reference_rad``
        (default theta_nor) is returned. If only the other branch reaches, it is returned
        with ``knee_flipped=True``; if none does, ``reachable=False`` with the closest
        in-limit angles (a numeric search), or with ``reference_rad`` when not ``closest``.
        """
        lg = self.legs[leg]
        target = np.asarray(target_B, dtype=float)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise ValueError(f"ik_leg: target_B must be 3 finite numbers, got {target_B!r}")
        want = lg.knee_direction if knee is None else knee
        ref = self._reference(leg, reference_rad)
        centre = self._centres[leg]
        if centre is None:
            return self._ik_numeric(leg, target, ref, want, tol_m)
        groups = self._ik_paden_kahan(leg, target, centre, tol_m)
        sols = [s for g in groups for s in g]
        if not sols and not closest:
            return IKResult(
                joints_rad=ref.copy(),
                reachable=False,
                error_m=math.nan,
                method="paden-kahan",
                reason="no exact in-limit solution",
            )
        if not sols:
            # no exact solution: only the closest in-limit angles are wanted (few starts)
            res = self._ik_numeric(leg, target, ref, want, tol_m, n_starts=4)
            res.method = "paden-kahan"
            res.reason = res.reason or "no exact in-limit solution"
            return res
        preferred = [
            s for g in groups if want == 0 or self.knee_direction(leg, g[0]) == want for s in g
        ]
        pool = preferred or sols
        best = min(pool, key=lambda s: float(np.sum((s - ref) ** 2)))
        err = float(np.linalg.norm(self.foot_B(leg, best) - target))
        return IKResult(
            joints_rad=best,
            reachable=True,
            error_m=err,
            method="paden-kahan",
            knee_flipped=not preferred,
            solutions=sols,
        )

    def ik_leg_near(
        self,
        leg: int,
        target_B,
        joints_rad,
        tol_m: float = 1e-10,
        max_step_rad: float = 0.2,
        closest: bool = True,
    ) -> IKResult:
        """IK for a target a few millimetres from the foot at ``joints_rad``: Newton steps.

        The rolling stance feet (planner.body.rolling) ask for thousands of such small moves
        per walk; Newton from the nearby solution stays on its branch and costs a few FK
        evaluations. Falls back to :meth:`ik_leg` (Paden-Kahan, reference ``joints_rad``)
        when Newton leaves the joint limits, moves more than ``max_step_rad`` or does not
        converge in 6 steps (``closest``: as :meth:`ik_leg`'s, for an unreachable target).
        """
        consts, lower, upper = self._newton_consts[leg]
        th0 = [float(v) for v in joints_rad]
        th = th0
        tx, ty, tz = (float(v) for v in target_B)
        err_m = math.inf
        for _ in range(7):
            p, cols = _foot_and_columns(consts, th)
            ex, ey, ez = tx - p[0], ty - p[1], tz - p[2]
            err_m = math.sqrt(ex * ex + ey * ey + ez * ez)
            if err_m <= tol_m:
                break
            step = _solve3(cols, (ex, ey, ez))
            if step is None:
                break
            th = [a + b for a, b in zip(th, step, strict=True)]
        in_limits = all(
            lo - 1e-12 <= t <= hi + 1e-12 for t, lo, hi in zip(th, lower, upper, strict=True)
        )
        if (
            err_m <= tol_m
            and in_limits
            and max(abs(a - b) for a, b in zip(th, th0, strict=True)) <= max_step_rad
        ):
            return IKResult(joints_rad=np.array(th), reachable=True, error_m=err_m, method="newton")
        th0 = np.array(th0)
        target = np.asarray(target_B, dtype=float)
        return self.ik_leg(leg, target, th0, knee=self.knee_direction(leg, th0), closest=closest)

    def _reference(self, leg: int, reference_rad) -> np.ndarray:
        if reference_rad is not None:
            return np.asarray(reference_rad, dtype=float)
        if self.robot.theta_nor is not None:
            return self.robot.theta_nor[leg]
        lg = self.legs[leg]
        return np.clip(np.zeros(3), lg.lower_rad, lg.upper_rad)

    def _ik_paden_kahan(self, leg: int, target, centre, tol_m: float) -> list[list[np.ndarray]]:
        """All in-limit exact solutions: subproblem 3 (knee) then subproblem 2 (hip).

        Grouped by branch: each group holds the 2 pi wraps into the limits of one solution
        (same foot position and knee direction; many for joints with wide limits).
        """
        lg = self.legs[leg]
        delta = float(np.linalg.norm(target - centre))
        knees = pk.subproblem3(lg.axes_B[2], lg.points_B[2], lg.foot_B0, centre, delta)
        out: dict[tuple, list[np.ndarray]] = {}  # base solution -> its wraps into limits
        for th3 in knees:
            wraps3 = _wrap_into_limits(th3, lg.lower_rad[2], lg.upper_rad[2])
            if not wraps3:
                continue
            p = twist_apply_np(lg, np.array([0.0, 0.0, th3]), lg.foot_B0)
            for th1, th2 in pk.subproblem2(lg.axes_B[0], lg.axes_B[1], centre, p, target):
                base = np.array([th1, th2, th3])
                key = tuple(np.round(base, 9))
                # tangent cases give a solution twice; FK is 2 pi periodic: check the base
                # solution once, then wrap it into the limits
                if key in out or np.linalg.norm(self.foot_B(leg, base) - target) > 1e3 * tol_m:
                    continue
                wraps = [
                    np.array(w)
                    for w in itertools.product(
                        _wrap_into_limits(th1, lg.lower_rad[0], lg.upper_rad[0]),
                        _wrap_into_limits(th2, lg.lower_rad[1], lg.upper_rad[1]),
                        wraps3,
                    )
                ]
                if wraps:
                    out[key] = wraps
        return list(out.values())

    def _ik_numeric(
        self, leg: int, target, ref, want: int, tol_m: float, n_starts: int = 24
    ) -> IKResult:
        """Bounded least squares from several starts (legs whose hip axes do not meet)."""
        from scipy.optimize import least_squares  # imported here: ~0.5 s, rarely needed

        lg = self.legs[leg]
        lo, hi = lg.lower_rad, lg.upper_rad
        lo_f = np.where(np.isfinite(lo), lo, -np.pi)
        hi_f = np.where(np.isfinite(hi), hi, np.pi)
        starts = [np.clip(ref, lo_f, hi_f)]
        rng = np.random.default_rng(leg)
        starts += [lo_f + (hi_f - lo_f) * rng.random(3) for _ in range(n_starts - 1)]

        def resid(th):
            return self.foot_B(leg, th) - target

        def jac(th):
            return self.foot_jacobian_B(leg, th)

        found: list[np.ndarray] = []
        best, best_err = starts[0], np.inf
        for s in starts:
            sol = least_squares(
                resid,
                s,
                jac=jac,
                bounds=(lo_f, hi_f),
                xtol=1e-15,
                ftol=1e-15,
                gtol=1e-15,
                max_nfev=200,
            )
            err = float(np.linalg.norm(resid(sol.x)))
            if err < best_err:
                best, best_err = sol.x, err
            if err <= tol_m:
                found.append(sol.x)
                if want == 0 or self.knee_direction(leg, sol.x) == want:
                    break
        if found:
            preferred = [s for s in found if want == 0 or self.knee_direction(leg, s) == want]
            pool = preferred or found
            pick = min(pool, key=lambda s: float(np.sum((s - ref) ** 2)))
            return IKResult(
                joints_rad=pick,
                reachable=True,
                error_m=float(np.linalg.norm(resid(pick))),
                method="numeric",
                knee_flipped=not preferred,
                solutions=found,
            )
        return IKResult(
            joints_rad=np.asarray(best, float),
            reachable=False,
            error_m=best_err,
            method="numeric",
            reason=f"target out of reach: closest in-limit foot position is {best_err:.4g} m away",
        )

    def ik(
        self, base_position_W, base_rotation_W, feet_W, reference_rad=None, closest: bool = True
    ) -> list[IKResult]:
        """Leg IK for a body pose and four world-frame foot centres.

        With ``reference_rad`` each leg keeps the knee branch of its reference joints
        (``knee_flipped`` then means: only the other branch reaches); without, the leg's
        own knee configuration is preferred (:meth:`ik_leg`). ``closest=False``: an
        unreachable leg gets its reference angles, not the numeric closest ones (a caller
        that asks only whether the pose reaches: the search costs 6 ms a leg).
        """
        rot = np.asarray(base_rotation_W, float)
        feet_B = (np.asarray(feet_W, float) - np.asarray(base_position_W, float)) @ rot
        if reference_rad is None:
            return [self.ik_leg(i, feet_B[i], closest=closest) for i in range(4)]
        # a path keeps each leg on its reference's knee branch (a flip mid-path is a jump)
        ref = np.asarray(reference_rad, float).reshape(4, 3)
        return [
            self.ik_leg(i, feet_B[i], ref[i], knee=self.knee_direction(i, ref[i]), closest=closest)
            for i in range(4)
        ]


def _max_reach(lg: Leg, centre: np.ndarray) -> float:
    """Largest distance from the hip centre to the foot over the knee's range."""
    lo = lg.lower_rad[2] if np.isfinite(lg.lower_rad[2]) else -np.pi
    hi = lg.upper_rad[2] if np.isfinite(lg.upper_rad[2]) else np.pi
    ths = np.linspace(lo, hi, 721)
    return max(
        float(np.linalg.norm(twist_apply_np(lg, np.array([0, 0, t]), lg.foot_B0) - centre))
        for t in ths
    )


def finalize_robot(robot: Robot) -> None:
    """Set knee configurations, reach and the normal configuration theta_nor (section 4.2).

    Knee configuration: LittleDog's "X" (front knees rearward, hind knees forward); a
    leg whose joint limits forbid that branch at the nominal stance keeps the other one.
    theta_nor puts each foot below its hip centre, at its zero-configuration lateral
    offset, at ``NOMINAL_DEPTH_FRACTION`` of the leg's vertical reach.
    """
    kin = LegKinematics(robot)
    thetas, reaches = [], []
    for leg in robot.legs:
        centre = hip_centre_B(leg)
        if centre is None:
            centre = leg.points_B[0]
        reach = _max_reach(leg, centre)
        lateral = leg.foot_B0[1] - centre[1]
        depth = NOMINAL_DEPTH_FRACTION * np.sqrt(max(reach**2 - lateral**2, 0.0))
        target = np.array([centre[0], leg.foot_B0[1], centre[2] - depth])
        leg.knee_direction = -1 if leg.is_front else 1
        res = kin.ik_leg(leg.index, target, reference_rad=np.zeros(3))
        if res.reachable and res.knee_flipped:
            leg.knee_direction = -leg.knee_direction
        thetas.append(res.joints_rad)
        reaches.append(reach)
    robot.theta_nor = np.array(thetas)
    robot.reach_m = np.array(reaches)
    robot._kinematics = kin  # cached, see kinematics_of


def robot_cached(robot: Robot, attr: str, build):
    """``build(robot)``, made once per robot and kept on it as ``attr`` (derived models)."""
    value = getattr(robot, attr, None)
    if value is None:
        value = build(robot)
        setattr(robot, attr, value)
    return value


def kinematics_of(robot: Robot) -> LegKinematics:
    """The (cached) :class:`LegKinematics` of a robot."""
    return robot_cached(robot, "_kinematics", LegKinematics)
