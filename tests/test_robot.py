"""The LittleDog URDF against LITTLEDOG.md, and the loader's acceptance and refusals."""

import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from planner.body.robot import LEG_NAMES, load_robot
from planner.core.errors import RobotModelError

URDF = Path(__file__).resolve().parents[1] / "models" / "littledog" / "littledog.urdf"


def test_littledog_numbers_match_user_guide(littledog):
    """Offsets, axes, limits, masses and geometry as Pinocchio reads them (LITTLEDOG.md)."""
    r = littledog
    assert [leg.name for leg in r.legs] == list(LEG_NAMES)
    for leg in r.legs:
        sx = 1 if leg.is_front else -1
        sy = 1 if leg.is_left else -1
        # body -> hip roll, hip roll -> hip pitch, hip pitch -> knee (zero config, body frame)
        np.testing.assert_allclose(leg.points_B[0], [0.101 * sx, 0.036 * sy, 0], atol=1e-12)
        np.testing.assert_allclose(leg.points_B[1], [0.101 * sx, 0.066 * sy, 0], atol=1e-12)
        np.testing.assert_allclose(leg.points_B[2], [0.101 * sx, 0.066 * sy, -0.075], atol=1e-12)
        knee_to_foot = [-0.0265 if leg.is_front else 0.0265, 0, -0.0985]
        np.testing.assert_allclose(leg.foot_B0 - leg.points_B[2], knee_to_foot, atol=1e-12)
        np.testing.assert_allclose(leg.axes_B, [[1, 0, 0], [0, 1, 0], [0, 1, 0]], atol=1e-12)
        if leg.is_front:
            np.testing.assert_allclose(leg.lower_rad, [-0.6, -3.5, -3.1])
            np.testing.assert_allclose(leg.upper_rad, [0.6, 2.4, 1.0])
        else:
            np.testing.assert_allclose(leg.lower_rad, [-0.6, -2.4, -1.0])
            np.testing.assert_allclose(leg.upper_rad, [0.6, 3.5, 3.1])
        # knees form an X: front rearward, hind forward
        assert leg.knee_direction == (-1 if leg.is_front else 1)
    assert r.foot_radius_m == pytest.approx(0.0103)
    np.testing.assert_allclose(
        r.body_box_B, [[-0.172, -0.054, -0.046], [0.158, 0.054, 0.097]], atol=1e-12
    )
    assert r.body_mass_kg == pytest.approx(2.240)
    np.testing.assert_allclose(r.body_com_B, [0, 0, 0.012])
    assert r.total_mass_kg == pytest.approx(3.0, abs=0.01)
    model = r.model
    for leg in r.legs:
        upper = model.inertias[leg.joint_ids[1]].mass
        lower = model.inertias[leg.joint_ids[2]].mass
        assert (upper, lower) == (pytest.approx(0.120), pytest.approx(0.070))
    # effective lengths: upper 0.075 m, lower 0.102 m
    leg = r.legs[0]
    assert np.linalg.norm(leg.points_B[2] - leg.points_B[1]) == pytest.approx(0.075)
    assert np.linalg.norm(leg.foot_B0 - leg.points_B[2]) == pytest.approx(0.102, abs=5e-4)


def test_theta_nor_is_in_limits_and_under_the_hips(littledog):
    from planner.body.kinematics import kinematics_of

    r = littledog
    assert np.all(r.theta_nor >= r.lower_rad) and np.all(r.theta_nor <= r.upper_rad)
    feet = kinematics_of(r).feet_B(r.theta_nor)
    np.testing.assert_allclose(feet[:, 0], [0.101, 0.101, -0.101, -0.101], atol=1e-9)
    # body bottom clears the ground when the feet stand on it
    clearance = -feet[:, 2].max() - r.foot_radius_m + r.body_box_B[0, 2]
    assert 0.08 < clearance < 0.13


@pytest.mark.parametrize("name", ["solo12", "anymal", "hyq", "go1", "a1"])
def test_example_robot_data_quadrupeds_load(name):
    r = load_robot(name)
    assert len(r.legs) == 4 and len(r.joint_names) == 12
    assert r.total_mass_kg > 1.0
    assert np.all(np.isfinite(r.theta_nor))
    for leg in r.legs:
        assert "foot" in leg.foot_frame.lower()


def _one_line(exc) -> str:
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


def test_missing_file_error(tmp_path):
    with pytest.raises(RobotModelError) as exc:
        load_robot(tmp_path / "nope.urdf")
    msg = _one_line(exc)
    assert "nope.urdf" in msg and "not found" in msg


def test_malformed_urdf_error(tmp_path):
    bad = tmp_path / "bad.urdf"
    bad.write_text(URDF.read_text()[:2000])  # truncated XML
    with pytest.raises(RobotModelError) as exc:
        load_robot(bad)
    msg = _one_line(exc)
    assert "bad.urdf" in msg and "malformed" in msg


def test_five_legs_refused(tmp_path):
    text = URDF.read_text()
    # copy the FL leg as a fifth leg "ML" in the middle of the body
    block = re.search(
        r'  <joint name="FL_hip_roll".*?<link name="FL_foot">.*?</link>\n', text, re.S
    ).group(0)
    fifth = block.replace("FL_", "ML_").replace('xyz="0.101 0.036 0"', 'xyz="0.0 0.036 0"')
    five = tmp_path / "five.urdf"
    five.write_text(text.replace("</robot>", fifth + "</robot>"))
    with pytest.raises(RobotModelError) as exc:
        load_robot(five)
    msg = _one_line(exc)
    assert "five.urdf" in msg and "found 5 leg chains" in msg


def test_two_joint_leg_refused(tmp_path):
    text = URDF.read_text().replace(
        '<joint name="HR_knee" type="revolute">', '<joint name="HR_knee" type="fixed">'
    )
    path = tmp_path / "twojoint.urdf"
    path.write_text(text)
    with pytest.raises(RobotModelError) as exc:
        load_robot(path)
    msg = _one_line(exc)
    assert "twojoint.urdf" in msg and "3 revolute joints" in msg


def test_unknown_name():
    with pytest.raises(RobotModelError) as exc:
        load_robot("littlecat")
    assert "littlecat" in _one_line(exc) and "littledog" in str(exc.value)


def test_q_layout_roundtrip(littledog):
    r = littledog
    joints = r.theta_nor + 0.1
    q = r.q_from([1, 2, 3], [0, 0, 0, 1], joints)
    assert q.shape == (r.model.nq,)
    np.testing.assert_array_equal(r.joints_from_q(q), joints)
    pin.normalize(r.model, q)  # a valid Pinocchio configuration


def test_an_offset_foot_sphere_gets_a_frame_at_its_centre():
    """ANYmal's foot sphere sits 22.5 mm up its foot link: the foot point is its centre."""
    import pinocchio as pin

    r = load_robot("anymal")
    assert r.foot_radius_m == pytest.approx(0.03)
    assert r.foot_radius_source == "urdf collision sphere"
    m = r.model
    d = m.createData()
    q = pin.neutral(m)
    pin.framesForwardKinematics(m, d, q)
    for leg in r.legs:
        link = leg.foot_frame.removesuffix("_sphere_centre")
        assert link != leg.foot_frame and m.existFrame(link)
        M = d.oMf[m.getFrameId(link)]
        expected = M.translation + M.rotation @ np.array([0.0, 0.0, 0.0225])
        np.testing.assert_allclose(d.oMf[m.getFrameId(leg.foot_frame)].translation, expected,
                                   atol=1e-12)  # fmt: skip
        np.testing.assert_allclose(leg.foot_B0, expected, atol=1e-12)


def test_a_foot_without_a_sphere_gets_a_tenth_of_its_shank():
    """go2's and solo12's feet are meshes: radius 0.1 x knee-to-foot, said so."""
    for name in ("go2", "solo12"):
        r = load_robot(name)
        shank = min(np.linalg.norm(leg.foot_B0 - leg.points_B[2]) for leg in r.legs)
        assert r.foot_radius_m == pytest.approx(0.1 * shank)
        assert "shank" in r.foot_radius_source
    assert load_robot("go2", foot_radius_m=0.02).foot_radius_m == 0.02
