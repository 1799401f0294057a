"""Sway stiffness of a stance (planner.body.stiffness) against finite differences and MuJoCo."""

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from planner.body.kinematics import kinematics_of
from planner.body.stiffness import SwayStiffness, joint_sway_matrix_ca
from planner.body.torques import TorqueCheck, holding_load
from planner.core.lie import rotation_from_vector


@pytest.fixture(scope="module")
def stance(short_flat_walk):
    """The first three-leg sample of a planned walk: (plan, q, support, feed-forward)."""
    _, plan, _ = short_flat_walk
    c = np.asarray(plan.samples.contact)
    k = next(k for k in range(1, len(c)) if c[k].sum() == 3 and c[k - 1].sum() == 4)
    q = plan.samples.q[k].copy()
    robot = plan.load_robot()
    tau = holding_load(TorqueCheck(robot), q[None], c[k][None], plan.friction, None)[1][0]
    return plan, q, tuple(np.flatnonzero(c[k])), tau


def _pose(robot, q):
    R = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
    return q[:3].copy(), R, robot.joints_from_q(q).reshape(4, 3)


def _potential(robot, sway, q, support, tau, kp, xi):
    """V(xi) with Pinocchio's COM and the planner's Newton IK (the module's definition)."""
    kin = kinematics_of(robot)
    p0, R0, th0 = _pose(robot, q)
    p = p0 + xi[:3]
    R = rotation_from_vector(xi[3:] / sway.length_m) @ R0
    th = th0.copy()
    energy = 0.0
    for i in support:
        centre_W = p0 + R0 @ kin.foot_B(i, th0[i])
        ik = kin.ik_leg_near(i, R.T @ (centre_W - p), th0[i], tol_m=1e-12)
        th[i] = ik.joints_rad
        d = th[i] - th0[i]
        energy += 0.5 * kp * d @ d - tau.reshape(4, 3)[i] @ d
    qq = robot.q_from(p, pin.Quaternion(R).coeffs(), th.ravel())
    com = pin.centerOfMass(robot.model, robot.model.createData(), qq)
    return energy + pin.computeTotalMass(robot.model) * 9.81 * com[2]


def test_hessian_equals_finite_differences_of_the_potential(stance):
    plan, q, support, tau = stance
    robot = plan.load_robot()
    sway = SwayStiffness(robot)
    p0, R0, th0 = _pose(robot, q)
    st = sway.stance(p0, R0, th0, support, tau)
    h, eye = 2e-4, np.eye(6)

    def V(xi):
        return _potential(robot, sway, q, support, tau, sway.kp, xi)

    H = np.zeros((6, 6))
    for a in range(6):
        for b in range(a, 6):
            H[a, b] = H[b, a] = (
                V(h * eye[a] + h * eye[b])
                - V(h * eye[a] - h * eye[b])
                - V(-h * eye[a] + h * eye[b])
                + V(-h * eye[a] - h * eye[b])
            ) / (4 * h * h)
    scale = np.abs(H).max()
    assert np.abs(st.hessian - H).max() < 1e-3 * scale
    w = np.linalg.eigvalsh(H)
    assert st.least == pytest.approx(w[0], rel=2e-3, abs=1.0)
    # the potential is stationary where the servos hold the stance: torques of the same
    # forces applied at the sphere centres (Pinocchio's static equilibrium, g = J^T f + tau)
    f = holding_load(TorqueCheck(robot), q[None], np.isin(range(4), support)[None],
                     plan.friction, None)[0][0]  # fmt: skip
    model, data = robot.model, robot.model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.framesForwardKinematics(model, data, q)
    gen = pin.computeGeneralizedGravity(model, data, q).copy()
    for i in support:
        fid = model.getFrameId(robot.foot_frames[i])
        J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:3]
        gen -= J.T @ f[i]
    chk = TorqueCheck(robot)
    at_centres = gen[chk.v_idx]
    held = sway.stance(p0, R0, th0, support, at_centres)
    weight = robot.total_mass_kg * 9.81
    assert np.abs(gen[:6]).max() < 1e-9 * weight  # those forces balance the robot
    assert np.abs(held.gradient).max() < 1e-6 * weight
    # on flat ground a crawl stance is well above the bound
    assert st.least > sway.minimum_n_per_m


def test_servo_part_is_the_symbolic_form(stance, rng):
    plan, q, support, tau = stance
    robot = plan.load_robot()
    sway = SwayStiffness(robot)
    p0, R0, th0 = _pose(robot, q)
    st = sway.stance(p0, R0, th0, support, tau)
    kin = kinematics_of(robot)
    centres = [ca.DM(p0 + R0 @ kin.foot_B(i, th0[i])) for i in range(4)]
    K = np.array(
        joint_sway_matrix_ca(
            kin,
            sway.kp,
            sway.length_m,
            ca.DM(p0),
            ca.DM(R0),
            ca.DM(th0.ravel()),
            centres,
            support,
        )  # fmt: skip
    )
    for _ in range(4):
        u = rng.normal(size=6)
        assert u @ K @ u == pytest.approx(u @ st.joint_part @ u, rel=1e-9)
        v = rng.normal(size=6)
        assert u @ K @ v == pytest.approx(u @ st.joint_part @ v, rel=1e-9)
    # the servos' part scales with their stiffness, the rest does not
    stiffer = SwayStiffness(robot, 3 * sway.kp).stance(p0, R0, th0, support, tau)
    np.testing.assert_allclose(stiffer.joint_part, 3 * st.joint_part, rtol=1e-9)
    np.testing.assert_allclose(
        stiffer.hessian - stiffer.joint_part, st.hessian - st.joint_part, atol=1e-6
    )


def _critical_kp(robot, q, support, tau) -> float:
    """The servo stiffness [N m/rad] at which the stance's least eigenvalue crosses zero."""
    p0, R0, th0 = _pose(robot, q)
    st = SwayStiffness(robot, 1.0).stance(p0, R0, th0, support, tau)
    rest = st.hessian - st.joint_part
    lo, hi = 0.0, 100.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if np.linalg.eigvalsh(mid * st.joint_part + rest)[0] > 0.0:
            hi = mid
        else:
            lo = mid
    return hi


def _hold_three_legs(plan, q, support, kp) -> float:
    """MuJoCo: hold the stance on its three legs for 1.5 s; the body's drift [m]."""
    from planner.sim.simulate import SimSettings, Simulator

    robot = plan.load_robot()
    settings = SimSettings(kp_nm_per_rad=kp, kv_nm_s_per_rad=0.25 * kp / 20.0).check()
    sim = Simulator(robot, plan.terrain_grid, plan.friction, plan.load_terrain(), settings)
    contact = np.zeros(4, bool)
    contact[list(support)] = True
    sim.set_q(q, lift_m=0.0005)
    joints = q[sim._pin_idx]
    sim.set_targets(joints, sim.holding_torques_nm(q, contact)[0])
    start = sim.q()[:3].copy()
    drift = 0.0
    end = sim.time + 1.5
    while sim.time < end:
        sim.tick()
        drift = max(drift, float(np.linalg.norm(sim.q()[:3] - start)))
    return drift


def test_mujoco_holds_a_stance_only_above_the_critical_stiffness(stance):
    """The theory's stability boundary, in physics: soft servos let the stance sway away."""
    plan, q, support, tau = stance
    robot = plan.load_robot()
    kp_crit = _critical_kp(robot, q, support, tau)
    assert 0.5 < kp_crit < 20.0  # LittleDog's servos (20 N m/rad) are above it
    stiff = _hold_three_legs(plan, q, support, 1.5 * kp_crit)
    soft = _hold_three_legs(plan, q, support, 0.75 * kp_crit)
    assert stiff < 0.01  # holds: within a centimetre
    assert soft > 0.03  # sways away (falls)


def test_check_reports_the_least_three_leg_sway_stiffness(short_flat_walk):
    from planner.body.stiffness import sway_stiffness_of
    from planner.planfile.validate import check_plan

    _, plan, _ = short_flat_walk
    report = check_plan(plan)
    robot = plan.load_robot()
    c = np.asarray(plan.samples.contact)
    starts = [k for k in range(1, len(c)) if c[k].sum() == 3 and c[k - 1].sum() == 4]
    tau = holding_load(TorqueCheck(robot), plan.samples.q[starts], c[starts], plan.friction,
                       plan.load_terrain())[1]  # fmt: skip
    sway = sway_stiffness_of(robot)
    least = min(
        sway.stance(*_pose(robot, plan.samples.q[k]), np.flatnonzero(c[k]), t).least
        for k, t in zip(starts, tau, strict=True)
    )
    assert report.min_sway_stiffness_N_per_m == pytest.approx(least, rel=1e-9)
    assert report.min_sway_stiffness_N_per_m > sway.minimum_n_per_m  # the planner's bound
    assert "sway stiffness" in report.summary()


def test_no_finite_hessian_certifies_no_stiffness(stance):
    """Where the Hessian is not finite (a singular leg, a bad feed-forward) the least
    eigenvalue is -inf, never NaN, so every bound fails."""
    plan, q, support, tau = stance
    robot = plan.load_robot()
    p0, R0, th0 = _pose(robot, q)
    bad = tau.copy()
    bad[3 * support[0]] = np.nan
    st = SwayStiffness(robot).stance(p0, R0, th0, support, bad)
    assert st.least == -np.inf
    assert not st.least >= SwayStiffness(robot).minimum_n_per_m
