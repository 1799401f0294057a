"""Product-of-exponentials kinematics (eq. 1-2) against Pinocchio; IK (section 5.1.2)."""

from pathlib import Path

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from planner.body.kinematics import foot_and_jacobian_np, kinematics_of
from planner.body.robot import load_robot

ROBOTS = ["littledog", "solo12", "anymal", "hyq", "go1"]


def _random_joints(robot, rng, n):
    lo = np.maximum(robot.lower_rad, -np.pi).ravel()
    hi = np.minimum(robot.upper_rad, np.pi).ravel()
    return lo + (hi - lo) * rng.random((n, 12))


def _random_rotation(rng):
    return pin.Quaternion(*rng.normal(size=4)).normalized().matrix()


@pytest.mark.parametrize("name", ROBOTS)
def test_casadi_fk_and_com_match_pinocchio(name, rng):
    robot = load_robot(name)
    kin = kinematics_of(robot)
    p = ca.SX.sym("p", 3)
    R = ca.SX.sym("R", 3, 3)
    th = ca.SX.sym("th", 12)
    fk = ca.Function(
        "fk", [p, R, th], [ca.vec(kin.feet_W_ca(p, R, th)), ca.mtimes(R, kin.com_B_ca(th)) + p]
    )
    model, data = robot.model, robot.model.createData()
    fids = [model.getFrameId(f) for f in robot.foot_frames]
    joints = _random_joints(robot, rng, 1000)
    worst_foot = worst_com = 0.0
    for k in range(1000):
        pos, rot = rng.normal(size=3), _random_rotation(rng)
        q = robot.q_from(pos, pin.Quaternion(rot).coeffs(), joints[k])
        pin.framesForwardKinematics(model, data, q)
        ref_feet = np.array([data.oMf[f].translation for f in fids])
        ref_com = pin.centerOfMass(model, data, q)
        feet, com = fk(pos, rot, joints[k])
        feet = np.array(feet).reshape(4, 3)
        worst_foot = max(worst_foot, np.abs(feet - ref_feet).max())
        worst_com = max(worst_com, np.abs(np.array(com).ravel() - ref_com).max())
    assert worst_foot < 1e-10, worst_foot
    assert worst_com < 1e-10, worst_com


@pytest.mark.parametrize("name", ["littledog", "solo12", "go1"])
def test_numpy_fk_matches_pinocchio(name, rng):
    robot = load_robot(name)
    kin = kinematics_of(robot)
    model, data = robot.model, robot.model.createData()
    fids = [model.getFrameId(f) for f in robot.foot_frames]
    for joints in _random_joints(robot, rng, 200):
        pos, rot = rng.normal(size=3), _random_rotation(rng)
        q = robot.q_from(pos, pin.Quaternion(rot).coeffs(), joints)
        pin.framesForwardKinematics(model, data, q)
        ref = np.array([data.oMf[f].translation for f in fids])
        np.testing.assert_allclose(kin.feet_W(pos, rot, joints), ref, atol=1e-12)


@pytest.mark.parametrize("name", ["littledog", "anymal"])
def test_foot_jacobian_matches_finite_differences_and_pinocchio(name, rng):
    robot = load_robot(name)
    kin = kinematics_of(robot)
    model, data = robot.model, robot.model.createData()
    h = 1e-6
    for joints in _random_joints(robot, rng, 50):
        joints = joints.reshape(4, 3)
        q = robot.q_from(np.zeros(3), [0, 0, 0, 1], joints)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for i, leg in enumerate(robot.legs):
            J = kin.foot_jacobian_B(i, joints[i])
            fd = np.column_stack(
                [
                    (kin.foot_B(i, joints[i] + h * e) - kin.foot_B(i, joints[i] - h * e)) / (2 * h)
                    for e in np.eye(3)
                ]
            )
            np.testing.assert_allclose(J, fd, atol=1e-6)
            fid = model.getFrameId(leg.foot_frame)
            Jp = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:3]
            vcols = [model.joints[j].idx_v for j in leg.joint_ids]
            np.testing.assert_allclose(J, Jp[:, vcols], atol=1e-12)
            p_np, J_np = foot_and_jacobian_np(leg, joints[i])  # the float version for Newton
            np.testing.assert_allclose(p_np, kin.foot_B(i, joints[i]), atol=1e-14)
            np.testing.assert_allclose(J_np, Jp[:, vcols], atol=1e-12)


def test_newton_ik_near_matches_paden_kahan(littledog, rng):
    """Small moves (the rolling stance feet): Newton from the last angles = Paden-Kahan."""
    robot, kin = littledog, kinematics_of(littledog)
    newton = 0
    for _ in range(200):
        i = int(rng.integers(4))
        start = robot.theta_nor[i] + rng.uniform(-0.3, 0.3, 3)
        start = np.clip(start, robot.legs[i].lower_rad, robot.legs[i].upper_rad)
        target = kin.foot_B(i, start) + rng.uniform(-0.004, 0.004, 3)
        near, exact = kin.ik_leg_near(i, target, start), kin.ik_leg(i, target, start)
        assert near.reachable == exact.reachable
        if near.method == "newton":
            newton += 1
            assert near.error_m < 1e-10
            assert any(np.allclose(near.joints_rad, s, atol=1e-8) for s in exact.solutions)
            assert np.max(np.abs(near.joints_rad - start)) <= 0.2
    assert newton > 150
    # far targets fall back to Paden-Kahan
    far = kin.ik_leg_near(0, kin.foot_B(0, robot.theta_nor[0]) + 0.05, robot.theta_nor[0])
    assert far.method == "paden-kahan"


def test_ik_reproduces_4000_targets(littledog, rng):
    """Paden-Kahan 3 then 2 reproduces FK targets of in-limit joints to 1e-9 m (1000
    random in-limit poses: 1000 targets per leg over its whole joint box)."""
    robot, kin = littledog, kinematics_of(littledog)
    joints = _random_joints(robot, rng, 1000).reshape(-1, 4, 3)
    worst, flipped = 0.0, 0
    for sample in joints:
        for i in range(4):
            target = kin.foot_B(i, sample[i])
            res = kin.ik_leg(i, target)
            assert res.reachable and res.method == "paden-kahan"
            assert np.all(res.joints_rad >= robot.legs[i].lower_rad - 1e-12)
            assert np.all(res.joints_rad <= robot.legs[i].upper_rad + 1e-12)
            worst = max(worst, np.linalg.norm(kin.foot_B(i, res.joints_rad) - target))
            # the true angles are among the exact solutions
            assert any(np.allclose(s, sample[i], atol=1e-6) for s in res.solutions)
            flipped += res.knee_flipped
    assert worst < 1e-9, worst
    assert flipped < 0.5 * joints.size / 3  # the preferred knee branch is usually available


def test_ik_keeps_knee_configuration(littledog):
    robot, kin = littledog, kinematics_of(littledog)
    for i, leg in enumerate(robot.legs):
        target = kin.foot_B(i, robot.theta_nor[i]) + np.array([0.02, 0.01, 0.015])
        res = kin.ik_leg(i, target)
        assert res.reachable and not res.knee_flipped
        assert kin.knee_direction(i, res.joints_rad) == leg.knee_direction
        # X configuration in joint space: front knees bend negative, hind knees positive
        assert np.sign(res.joints_rad[2]) == (-1 if leg.is_front else 1)
        # asking for the mirrored knee gives the other branch or none within limits
        res2 = kin.ik_leg(i, target, knee=-leg.knee_direction)
        assert res2.knee_flipped or kin.knee_direction(i, res2.joints_rad) != leg.knee_direction


def test_unreachable_targets_are_marked(littledog):
    kin = kinematics_of(littledog)
    for i, leg in enumerate(littledog.legs):
        hip = leg.points_B[0]
        for target in (hip + [0, 0, -0.5], hip + [0.3, 0, 0], hip + [0, 0, 0.0]):
            res = kin.ik_leg(i, target)
            assert not res.reachable
            assert np.all(np.isfinite(res.joints_rad)) and res.error_m > 1e-3
            assert res.reason


def _offset_hip_urdf(tmp_path) -> Path:
    """LittleDog with the hip pitch joint 1 cm below the roll axis: axes no longer meet."""
    src = Path(__file__).resolve().parents[1] / "models" / "littledog" / "littledog.urdf"
    text = src.read_text()
    for y in ("0.030", "-0.030"):
        text = text.replace(
            f'<origin xyz="0 {y} 0" rpy="0 0 0"/>\n    <axis xyz="0 1 0"/>',
            f'<origin xyz="0 {y} -0.01" rpy="0 0 0"/>\n    <axis xyz="0 1 0"/>',
        )
    path = tmp_path / "offset_hips.urdf"
    path.write_text(text)
    return path


def test_numeric_ik_fallback_for_offset_hips(tmp_path, rng):
    robot = load_robot(_offset_hip_urdf(tmp_path))
    kin = kinematics_of(robot)
    assert robot.legs[0].points_B[1][2] == pytest.approx(-0.01)
    # 25 random in-limit poses: 100 targets, 25 per leg, each solved to 1e-9 m (a solve is
    # about 60 ms: the solver, not the sample count, is what this test is about)
    for sample in _random_joints(robot, rng, 25).reshape(-1, 4, 3):
        for i in range(4):
            target = kin.foot_B(i, sample[i])
            res = kin.ik_leg(i, target)
            assert res.method == "numeric"
            assert res.reachable, res.reason
            assert np.linalg.norm(kin.foot_B(i, res.joints_rad) - target) < 1e-9
    res = kin.ik_leg(0, robot.legs[0].points_B[0] + [0, 0, -0.6])
    assert not res.reachable and np.all(np.isfinite(res.joints_rad))


def test_paper_mode_com_is_body_origin_offset(littledog):
    kin = kinematics_of(littledog)
    np.testing.assert_allclose(
        kin.com_B(littledog.theta_nor, whole_body=False), littledog.body_com_B
    )
    whole = kin.com_B(littledog.theta_nor)
    # legs are a quarter of the mass and hang below: the whole-body COM is lower
    assert whole[2] < littledog.body_com_B[2] - 0.01


def test_ik_with_a_reference_keeps_its_knee_branch(littledog, rng):
    """A path's IK (reference joints given) stays on the reference's knee branch: a knee
    that flips between two samples is a jump the robot cannot make."""
    kin = kinematics_of(littledog)
    p, R = np.zeros(3), np.eye(3)
    lo, hi = littledog.lower_rad, littledog.upper_rad
    found = kept = 0
    for _ in range(400):
        th = rng.uniform(lo, hi)  # (4, 3)
        centres = kin.feet_W(p, R, th)
        other = []
        for i in range(4):
            ik = kin.ik_leg(i, centres[i], knee=-kin.knee_direction(i, th[i]))
            other.append(ik.joints_rad if ik.reachable and not ik.knee_flipped else None)
        if any(o is None for o in other):
            continue
        found += 1
        moved = centres + rng.normal(scale=0.002, size=(4, 3))
        for ref in (th, np.array(other)):
            res = kin.ik(p, R, moved, reference_rad=ref)
            for i in range(4):
                if not res[i].reachable or res[i].knee_flipped:  # branch left its limits
                    continue
                kept += 1
                assert kin.knee_direction(i, res[i].joints_rad) == kin.knee_direction(i, ref[i])
        if found >= 5:
            break
    assert found >= 5 and kept >= 30, (found, kept)
