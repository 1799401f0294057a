"""Swings in the leg's joint space (planner.motion.leg_swing) over a barrier, judged by the
validator's
exact distances to the sharp terrain."""

import numpy as np
import pytest

from planner.body.kinematics import kinematics_of
from planner.body.links import leg_links
from planner.body.state import State
from planner.motion.interpolate import interpolate_swing
from planner.motion.leg_swing import joint_space_swing
from planner.planfile.validate import sharp_surface_distance
from planner.world.terrain import Terrain

BARRIER = {"name": "b", "friction": 0.7, "x_min": -0.5, "length": 2.0, "kind": "barrier",
           "x": 0.8, "height": 0.075, "thickness": 0.03}  # fmt: skip


def _stance(robot, terrain, body, fl_contact, knee):
    """A state with the body at ``body`` (level), FL on ``fl_contact`` with knee branch ``knee``,
    the other feet on flat ground around the barrier's near side."""
    kin = kinematics_of(robot)
    rho = robot.foot_radius_m
    feet = np.array([fl_contact, [0.757, -0.065, 0.0], [0.69, 0.07, 0.0], [0.635, -0.065, 0.0]])
    R = np.eye(3)
    joints = []
    for i, f in enumerate(feet):
        centre_B = R.T @ (f + [0.0, 0.0, rho] - body)
        ik = kin.ik_leg(i, centre_B, knee=knee if i == 0 else None)
        assert ik.reachable and not ik.knee_flipped, i
        joints.append(ik.joints_rad)
    return State(body.copy(), R, feet, np.array(joints), stratum=0, support=(0, 1, 2, 3))


def _clearances(robot, terrain, path):
    """Least leg-link and swing-foot clearance of FL over a path (validator's distances)."""
    links = leg_links(robot)
    fl = np.array([links.capsules[c].leg == 0 for c in links.owner])
    leg_worst, foot_worst = np.inf, np.inf
    for s in path:
        q = robot.q_from(s.base_position_W, s.base_quaternion_xyzw, s.joints_rad)
        d = sharp_surface_distance(terrain, links.axis_points_W(q)[fl], 0.05, step_m=1e-3)
        leg_worst = min(leg_worst, float((d - links.radius[fl]).min()))
        centre = s.base_rotation_W @ kinematics_of(robot).foot_B(0, s.joints_rad[0])
        centre = centre + s.base_position_W
        fd = float(sharp_surface_distance(terrain, centre[None], 0.05, step_m=1e-3)[0])
        if 0 < s.info.get("nu", 0.0) < 1:
            foot_worst = min(foot_worst, fd - robot.foot_radius_m)
    return leg_worst, foot_worst


@pytest.fixture(scope="module")
def over_the_barrier(littledog):
    terrain = Terrain.from_spec(BARRIER)
    body = np.array([0.70, 0.0, 0.145])
    lift = _stance(littledog, terrain, body, [0.757, 0.069, 0.0], knee=None)
    # touch down beyond the barrier on the branch whose links clear it
    links = leg_links(littledog)
    for knee in (-1, 1):
        try:
            touch = _stance(littledog, terrain, body, [0.89, 0.069, 0.0], knee=knee)
        except AssertionError:
            continue
        q = littledog.q_from(body, touch.base_quaternion_xyzw, touch.joints_rad)
        if links.clearance_fast(terrain, q)[:2].min() > 0.003:
            break
    else:
        pytest.fail("no clear landing beyond the barrier")
    lift.stratum = 1
    return terrain, lift, touch


def test_joint_space_swing_clears_a_barrier_the_foot_path_does_not(littledog, over_the_barrier):
    terrain, lift, touch = over_the_barrier
    # the foot's path (swing_path) lifts the sphere over the barrier, yet a link cuts it
    cartesian = interpolate_swing(littledog, terrain, lift, touch, 24, swing_leg=0)
    assert _clearances(littledog, terrain, cartesian)[0] < 0.0
    path = joint_space_swing(littledog, terrain, lift, touch, 24, 0)
    assert path is not None
    leg_clear, foot_clear = _clearances(littledog, terrain, path)
    assert leg_clear > 0.0, leg_clear
    assert foot_clear > -1e-4, foot_clear
    # the ends are the given states; the stance legs and the body never move
    np.testing.assert_array_equal(path[0].joints_rad, lift.joints_rad)
    np.testing.assert_array_equal(path[-1].joints_rad, touch.joints_rad)
    for s in path:
        np.testing.assert_array_equal(s.joints_rad[1:], lift.joints_rad[1:])
        np.testing.assert_array_equal(s.base_position_W, lift.base_position_W)
    # a continuous motion: no joint jumps between samples, the stored foot is the FK one
    steps = np.abs(np.diff([s.joints_rad[0] for s in path], axis=0)).max()
    assert steps < 0.6, steps
    kin = kinematics_of(littledog)
    for s in path[1:-1]:
        centre = s.base_rotation_W @ kin.foot_B(0, s.joints_rad[0]) + s.base_position_W
        np.testing.assert_allclose(s.feet_W[0] + [0, 0, littledog.foot_radius_m], centre)


def test_joint_space_swing_refuses_a_moving_body(littledog, over_the_barrier):
    terrain, lift, touch = over_the_barrier
    moved = touch.copy()
    moved.base_position_W = moved.base_position_W + [0.01, 0.0, 0.0]
    assert joint_space_swing(littledog, terrain, lift, moved, 24, 0) is None


def test_a_swing_searched_around_an_edge_is_timed_slower(littledog, over_the_barrier):
    """The planner's joint-space swing is tagged and timed at OVER_EDGE_SPEED_FRACTION of
    the URDF speed limits (the servos' lag must stay under its millimetres of clearance)."""
    from planner.motion.time_law import JOINT_SPEED_FRACTION, OVER_EDGE_SPEED_FRACTION
    from planner.planning.soft import SoftPlanner

    terrain, lift, touch = over_the_barrier
    planner = SoftPlanner(littledog, terrain)
    path, _ = planner._joint_space_swing(lift, touch, 0)  # (this stance is not balanced)
    assert path is not None and all(s.info.get("over_edge") for s in path)
    slow = planner.swing_offsets_s(path, 0)
    plain = [s.copy() for s in path]
    for s in plain:
        s.info.pop("over_edge")
    fast = planner.swing_offsets_s(plain, 0)
    # independently: each interval's joint steps over the URDF velocity limit
    vmax = np.asarray(littledog.model.velocityLimit, float)[-12:]
    th = np.array([s.joints_rad.ravel() for s in path])
    for t, fraction in ((slow, OVER_EDGE_SPEED_FRACTION), (fast, JOINT_SPEED_FRACTION)):
        dt = np.diff(np.concatenate([[0.0], t]))
        ratio = (np.abs(np.diff(th, axis=0)) / dt[:, None] / vmax).max()
        assert ratio <= fraction * (1 + 1e-9)
    assert slow[-1] > fast[-1]


def test_a_knee_flip_near_its_limit_keeps_the_foot_above_the_ground(littledog):
    """A landing on a knee branch near its joint limit is entered from above, on that branch.

    step10cm's feedback (8.3) landed HR on its rearward branch (the plan's) with the knee at
    -0.83 rad, where the 1 cm pre-pose up the normal needs more than the -1 rad limit. IK
    then offered the forward branch, and the last joint segment flipped the knee with the
    foot sphere 2 cm into the ground. The validator's distance is the reference.
    """
    from planner.core.lie import rotation_from_quat
    from planner.world.terrain import load_terrain

    terrain = load_terrain("step10cm")
    kin = kinematics_of(littledog)
    body = np.array([0.807569, 0.021996, 0.196957])
    R = rotation_from_quat(np.array([0.005792, -0.234885, 0.002281, 0.972003]))
    feet = np.array([[0.849193, 0.069611, 0.1], [0.845649, -0.067087, 0.1],
                     [0.738466, 0.061252, 0.0], [0.635022, -0.063706, 0.0]])  # fmt: skip
    joints = np.array([[-0.206161, 1.642804, -1.620878], [-0.244638, 1.478193, -1.420171],
                       [-0.210435, -0.461581, 1.611047],
                       [-0.22353, 0.582006, 0.926549]])  # fmt: skip
    lift = State(body, R, feet, joints, stratum=4, support=(0, 1, 2))
    touch_feet, touch_joints = feet.copy(), joints.copy()
    touch_feet[3] = [0.75875, -0.065133, 0.0]
    touch_joints[3] = [-0.155103, 0.826036, -0.834445]  # rearward, 0.17 rad from the limit
    touch = State(body, R, touch_feet, touch_joints, stratum=0, support=(0, 1, 2, 3))
    for s in (lift, touch):  # the states are consistent: each foot where its joints put it
        centre = R @ kin.foot_B(3, s.joints_rad[3]) + body
        assert np.linalg.norm(centre - s.feet_W[3] - [0, 0, littledog.foot_radius_m]) < 1e-4
    assert kin.knee_direction(3, touch_joints[3]) != kin.knee_direction(3, joints[3])
    path = joint_space_swing(littledog, terrain, lift, touch, 24, 3)
    assert path is not None
    rho = littledog.foot_radius_m
    for s in path[1:-1]:
        centre = R @ kin.foot_B(3, s.joints_rad[3]) + body
        assert sharp_surface_distance(terrain, centre[None], 0.05, step_m=1e-3)[0] >= rho
    # the knee changes branch in the air: the foot's last samples are on the landing's
    assert kin.knee_direction(3, path[-2].joints_rad[3]) == kin.knee_direction(3, touch_joints[3])


@pytest.mark.parametrize("n", [4, 6])
def test_a_coarse_joint_space_swing_keeps_its_corners(littledog, over_the_barrier, n):
    """Few samples over the barrier: the executor's straight joint lines between two
    samples (planner.motion.interpolate.between_q) keep the foot and links as clear as the checked
    segments, since every vertex of the joint path is a sample. Before, samples on either
    side of a vertex cut its corner (a knee flipped 140 degrees between two samples out of
    a 12 cm trench and the foot swept the trench's floor)."""
    from planner.motion.interpolate import between_q

    terrain, lift, touch = over_the_barrier
    path = joint_space_swing(littledog, terrain, lift, touch, n, 0)
    assert path is not None
    assert len(path) >= n
    inner = []
    for a, b in zip(path[:-1], path[1:], strict=True):
        qa = littledog.q_from(a.base_position_W, a.base_quaternion_xyzw, a.joints_rad)
        qb = littledog.q_from(b.base_position_W, b.base_quaternion_xyzw, b.joints_rad)
        for u in np.linspace(0.0, 1.0, 12)[1:-1]:
            q = between_q(qa, qb, u)
            s = a.copy()
            s.joints_rad = littledog.joints_from_q(q)
            s.info = {"nu": 0.5}
            inner.append(s)
    leg_clear, foot_clear = _clearances(littledog, terrain, inner)
    assert leg_clear > 0.0, leg_clear
    assert foot_clear > 0.0, foot_clear
