"""Interpolation along leaves (section 7.1, eq. 6a/6b), swing paths, contact points."""

import numpy as np
import pinocchio as pin
import pytest
from scipy.special import expit

from planner.body.contact import (
    contact_from_foot_centre,
    foot_centre_from_contact,
    foot_centres_W,
)
from planner.body.kinematics import kinematics_of
from planner.body.state import State
from planner.core.lie import coords_from_pose, interpolate_coords, pose_from_coords
from planner.motion.heuristics import nominal_height_m
from planner.motion.interpolate import (
    interpolate_leaf,
    interpolate_swing,
    swing_path,
)

SLOPE = np.tan(np.radians(10.0))
STEP_H_M, STEP_X_M, STEP_W_M = 0.05, 0.5, 0.005


class _Terrain:
    """Test double of planner.world.terrain.Terrain from a height function and its gradient."""

    def __init__(self, h, grad):
        self._h, self._grad = h, grad

    def height(self, x, y):
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        return self._h(x, y)

    height_sharp = height

    def f_T(self, p_W):
        p = np.asarray(p_W, float)
        return p[..., 2] - self.height(p[..., 0], p[..., 1])

    def normal(self, p_W):
        p = np.asarray(p_W, float)
        hx, hy = self._grad(p[..., 0], p[..., 1])
        n = np.stack(np.broadcast_arrays(-hx, -hy, np.ones_like(p[..., 0])), axis=-1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def smoothed_normal(self, p_W, radius):
        return self.normal(p_W)


def _zero(x, y):
    return np.zeros_like(np.asarray(x, float) + np.asarray(y, float))


DOUBLES = {
    "flat": lambda: _Terrain(_zero, lambda x, y: (_zero(x, y), _zero(x, y))),
    "slope": lambda: _Terrain(
        lambda x, y: SLOPE * x + 0.2 * SLOPE * y,
        lambda x, y: (_zero(x, y) + SLOPE, _zero(x, y) + 0.2 * SLOPE),
    ),
    "step": lambda: _Terrain(
        lambda x, y: STEP_H_M * expit((x - STEP_X_M) / STEP_W_M) + 0 * y,
        lambda x, y: (
            STEP_H_M
            * expit((x - STEP_X_M) / STEP_W_M)
            * (1 - expit((x - STEP_X_M) / STEP_W_M))
            / STEP_W_M,
            _zero(x, y),
        ),
    ),
}
REAL = {"flat": "flat", "slope": "slope10", "step": "step5cm"}


@pytest.fixture(params=["double", "real"])
def source(request):
    return request.param


def _terrain(kind, source):
    if source == "double":
        return DOUBLES[kind]()
    mod = pytest.importorskip("planner.world.terrain")
    return mod.load_terrain(REAL[kind])


def _step_edge_x(terrain):
    """x where the terrain along y = 0 crosses half the step height (the step's edge)."""
    x = np.linspace(-1.0, 5.0, 60001)
    h = terrain.height(x, np.zeros_like(x))
    lo, hi = h.min(), h.max()
    if hi - lo < 0.04:
        pytest.skip("terrain has no ~5 cm step along x at y = 0")
    k = int(np.argmax(h > 0.5 * (lo + hi)))
    return float(x[k]), float(lo), float(hi)


def _stance(robot, terrain, base_xy, yaw=0.0, dz=0.0, roll=0.0):
    """A state on S0: body at nominal height over the terrain, feet at theta_nor put down."""
    kin = kinematics_of(robot)
    h0 = float(terrain.height(*base_xy))
    p = np.array([*base_xy, h0 + nominal_height_m(robot) + dz])
    R = pin.utils.rpyToMatrix(roll, 0.0, yaw)
    centres = kin.feet_W(p, R, robot.theta_nor)
    feet = contact_from_foot_centre(terrain, centres, robot.foot_radius_m)
    feet[:, 2] = terrain.height(feet[:, 0], feet[:, 1])  # exactly on the terrain
    # re-solve the joints for the exact sphere centres over those contacts
    c = foot_centre_from_contact(terrain, feet, robot.foot_radius_m)
    joints = np.array([r.joints_rad for r in kin.ik(p, R, c)])
    return State(p, R, feet, joints)


def _pin_feet(robot, state):
    model, data = robot.model, robot.model.createData()
    q = robot.q_from(state.base_position_W, state.base_quaternion_xyzw, state.joints_rad)
    pin.framesForwardKinematics(model, data, q)
    return np.array([data.oMf[model.getFrameId(f)].translation for f in robot.foot_frames])


def _assert_on_leaf(robot, terrain, states, stance):
    rho = robot.foot_radius_m
    feet0 = states[0].feet_W
    for st in states:
        np.testing.assert_array_equal(st.feet_W[stance], feet0[stance])  # stance feet fixed
        assert st.info["ik_ok"], st.info
        assert np.all(np.isfinite(st.joints_rad))
        centres = foot_centres_W(terrain, st.feet_W, st.in_contact, rho)
        np.testing.assert_allclose(_pin_feet(robot, st), centres, atol=1e-9, rtol=0)


# ---- contact points -------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["flat", "slope"])
def test_contact_and_centre_are_inverse_on_a_plane(kind, source):
    terrain = _terrain(kind, source)
    rho = 0.0103
    xy = np.random.default_rng(1).uniform([1.0, -0.3], [1.6, 0.3], size=(7, 2))
    r = np.column_stack([xy, terrain.height(xy[:, 0], xy[:, 1])])
    c = foot_centre_from_contact(terrain, r, rho)
    np.testing.assert_allclose(np.linalg.norm(c - r, axis=1), rho, atol=1e-15)
    # distance from the centre to the plane is rho: f_T grows by rho / cos(slope) vertically
    np.testing.assert_allclose(contact_from_foot_centre(terrain, c, rho), r, atol=1e-12)
    assert np.all(terrain.f_T(c) > 0)


# ---- leaves of S0 (eq. 6b) -------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["flat", "slope"])
def test_s0_leaf_keeps_feet_and_lands_fk_on_sphere_centres(littledog, kind, source):
    terrain = _terrain(kind, source)
    a = _stance(littledog, terrain, (1.2, 0.05))  # on the incline of slope10
    b = a.copy()
    g_b = a.pose @ pose_from_coords([0.03, -0.015, -0.012, 0.05, -0.04, 0.15])
    b.base_position_W, b.base_rotation_W = g_b[:3, 3], g_b[:3, :3]
    states = interpolate_leaf(littledog, terrain, a, b, 9, rolling=False)  # the paper's leaf
    assert len(states) == 9
    _assert_on_leaf(littledog, terrain, states, [0, 1, 2, 3])
    # base follows eq. 6b, ends exact
    eps = interpolate_coords(a.coords, b.coords, np.linspace(0, 1, 9))
    for st, e in zip(states, eps, strict=True):
        np.testing.assert_allclose(st.coords, e, atol=1e-12)
    np.testing.assert_array_equal(states[0].pose, a.pose)
    np.testing.assert_array_equal(states[-1].pose, b.pose)
    np.testing.assert_allclose(states[0].joints_rad, a.joints_rad, atol=1e-9)
    assert [s.info["nu"] for s in states] == pytest.approx(np.linspace(0, 1, 9))
    assert all(s.stratum == 0 for s in states)


def test_leaf_refuses_states_on_different_leaves(littledog):
    terrain = DOUBLES["flat"]()
    a = _stance(littledog, terrain, (0.0, 0.0))
    b = a.copy()
    b.feet_W[1, 0] += 1e-6
    with pytest.raises(ValueError, match="FR"):
        interpolate_leaf(littledog, terrain, a, b, 5)
    b.stratum = 2  # FR in the air: now a leaf of S2, FR may move
    assert len(interpolate_leaf(littledog, terrain, a, b, 5)) == 5
    b.feet_W[0, 0] += 1e-6
    with pytest.raises(ValueError, match="FL"):
        interpolate_leaf(littledog, terrain, a, b, 5)
    c = a.copy()
    c.stratum, a.stratum = 3, 2
    with pytest.raises(ValueError, match="different strata"):
        interpolate_leaf(littledog, terrain, a, c, 5)


def test_unreachable_samples_are_marked_and_finite(littledog):
    terrain = DOUBLES["flat"]()
    a = _stance(littledog, terrain, (0.0, 0.0))
    b = a.copy()
    b.base_position_W = a.base_position_W + [0.0, 0.0, 0.15]  # legs too short up there
    states = interpolate_leaf(littledog, terrain, a, b, 3)
    assert states[0].info["ik_ok"]
    assert not states[-1].info["ik_ok"]
    assert states[-1].info["unreachable_legs"] == [0, 1, 2, 3]
    assert states[-1].info["ik_error_m"] > 0.01
    assert all(np.all(np.isfinite(s.joints_rad)) for s in states)


def test_a_leg_at_its_knee_stop_keeps_its_branch(littledog):
    """A stance leg measured at its knee stop on its non-default branch (8.3: a hard plan's
    FR at barrier75mm), its contact 1 mm higher than its joints put it: the path must not
    jump to the other branch (which reaches exactly); the first sample keeps the measured
    joints and is marked out of reach by the 1 mm, the body rising brings the foot back."""
    kin = kinematics_of(littledog)
    rho = littledog.foot_radius_m
    terrain = DOUBLES["flat"]()
    a = _stance(littledog, terrain, (0.0, 0.0))
    fr = kin.legs[1]
    th = np.array([0.0, np.radians(-41.5), fr.upper_rad[2] - 1e-4])  # knee at its stop
    assert kin.knee_direction(1, th) == -fr.knee_direction  # the non-default branch
    R = a.base_rotation_W
    p = a.base_position_W.copy()
    p[2] = rho - kin.foot_B(1, th)[2]  # FR's sphere resting on the ground
    centres = kin.feet_W(p, R, littledog.theta_nor)
    centres[1] = R @ kin.foot_B(1, th) + p
    centres[:, 2] = rho
    joints = np.array([r.joints_rad for r in kin.ik(p, R, centres)])
    joints[1] = th
    feet = centres - [0.0, 0.0, rho]
    feet[1, 2] += 0.001  # the contact as the planner's terrain has it
    start = State(p, R, feet, joints)
    end = start.copy()
    end.base_position_W = p + [0.0, 0.0, 0.005]
    states = interpolate_leaf(littledog, terrain, start, end, 5)
    assert [kin.knee_direction(1, s.joints_rad[1]) for s in states] == [-fr.knee_direction] * 5
    assert not states[0].info["ik_ok"] and states[0].info["unreachable_legs"] == [1]
    assert states[0].info["ik_error_m"] == pytest.approx(0.001, abs=2e-4)
    np.testing.assert_array_equal(states[0].joints_rad[1], th)
    assert all(s.info["ik_ok"] for s in states[1:])
    steps = np.abs(np.diff([s.joints_rad[1] for s in states], axis=0))
    assert steps.max() < np.radians(3.0)  # no jump between samples


# ---- swing paths ------------------------------------------------------------------------------
def test_swing_path_clears_a_step(source):
    terrain = _terrain("step", source)
    x_edge, lo, hi = _step_edge_x(terrain)
    clearance, rho = 0.03, 0.0103
    lift = np.array([x_edge - 0.07, 0.0, 0.0])
    touch = np.array([x_edge + 0.06, 0.0, 0.0])
    lift[2] = terrain.height(lift[0], lift[1])
    touch[2] = terrain.height(touch[0], touch[1])
    sp = swing_path(terrain, lift, touch, clearance, 41, radius_m=rho)
    pts = sp.points_W
    np.testing.assert_array_equal(pts[0], lift)
    np.testing.assert_array_equal(pts[-1], touch)
    sharp = terrain.height_sharp(pts[:, 0], pts[:, 1])
    assert np.all(pts[:, 2] >= sharp - 1e-9)  # never below the surface (smooth ends: 1e-9)
    mid = sp.phase == 2
    assert mid.sum() >= 5
    assert np.all(pts[mid, 2] - sharp[mid] >= clearance - 1e-12)
    assert sp.travel_z_m >= terrain.height_sharp(touch[0], touch[1]) + clearance - 1e-12
    assert sp.travel_z_m >= hi + clearance - 1e-6
    # dense check between samples: the sphere's lowest point in travel is above step + clearance
    dense = swing_path(terrain, lift, touch, clearance, 2001, radius_m=rho)
    d_mid = dense.phase == 2
    d_sharp = terrain.height_sharp(dense.points_W[:, 0], dense.points_W[:, 1])
    assert np.all(dense.points_W[:, 2] >= d_sharp - 1e-9)
    assert np.all(dense.points_W[d_mid, 2] - d_sharp[d_mid] >= clearance - 1e-12)
    # centres continuous, leaving and arriving along the terrain normals
    assert np.max(np.linalg.norm(np.diff(dense.centres_W, axis=0), axis=1)) < 1e-3
    for k, end in ((1, lift), (-2, touch)):
        d = dense.centres_W[k] - dense.centres_W[0 if k == 1 else -1]
        n = terrain.normal(end)
        np.testing.assert_allclose(d / np.linalg.norm(d), n, atol=1e-9)
    # eq. 6a's straight line would cut through the step: this test can tell the difference
    line = lift + np.linspace(0, 1, 41)[:, None] * (touch - lift)
    assert np.any(line[:, 2] < terrain.height_sharp(line[:, 0], line[:, 1]) - 0.01)


def test_swing_path_on_flat_ground_has_the_clearance_height():
    terrain = DOUBLES["flat"]()
    sp = swing_path(terrain, [0, 0, 0], [0.08, 0.01, 0], 0.03, 21, radius_m=0.01)
    assert sp.travel_z_m == pytest.approx(0.03, abs=1e-15)
    np.testing.assert_allclose(sp.points_W[sp.phase == 2, 2], 0.03, atol=1e-15)
    assert np.all(sp.points_W[1:-1, 2] > 0)


# ---- swing with the base (eq. 6a with the swing path) ----------------------------------------
def test_interpolate_swing_over_a_step(littledog, source):
    terrain = _terrain("step", source)
    x_edge, lo, hi = _step_edge_x(terrain)
    rho = littledog.foot_radius_m
    a = _stance(littledog, terrain, (x_edge - 0.16, 0.0))
    # FL steps from ~6 cm before the edge onto the step; the body moves 2 cm and rises 1 cm
    b = a.copy()
    touch = a.feet_W[0] + [0.11, 0.0, 0.0]
    touch[2] = terrain.height(touch[0], touch[1])
    assert touch[2] > hi - 1e-3
    b.feet_W[0] = touch
    b.base_position_W = a.base_position_W + [0.02, 0.0, 0.01]
    kin = kinematics_of(littledog)
    c = foot_centres_W(terrain, b.feet_W, b.in_contact, rho)
    b.joints_rad = np.array([r.joints_rad for r in kin.ik(b.base_position_W, b.base_rotation_W, c)])
    states = interpolate_swing(littledog, terrain, a, b, 15, clearance_m=0.03, rolling=False)
    assert [s.stratum for s in states] == [0] + [1] * 13 + [0]
    assert all(s.support == (1, 2, 3) for s in states[1:-1])
    _assert_on_leaf(littledog, terrain, states, [1, 2, 3])
    swing = np.array([s.feet_W[0] for s in states])
    np.testing.assert_array_equal(swing[0], a.feet_W[0])
    np.testing.assert_array_equal(swing[-1], touch)
    sharp = terrain.height_sharp(swing[:, 0], swing[:, 1])
    assert np.all(swing[:, 2] >= sharp - 1e-9)
    assert swing[:, 2].max() >= touch[2] + 0.03 - 1e-12
    # the swing foot's sphere centre is one radius above its stored point in the air
    for st in states[1:-1]:
        np.testing.assert_allclose(_pin_feet(littledog, st)[0], st.feet_W[0] + [0, 0, rho], 1e-9)
    # same leg found from the states alone
    b1 = b.copy()
    b1.stratum = 1
    again = interpolate_swing(littledog, terrain, a, b1, 15, clearance_m=0.03, rolling=False)
    np.testing.assert_array_equal(again[7].feet_W, states[7].feet_W)


def test_interpolate_swing_needs_one_moving_foot(littledog):
    terrain = DOUBLES["flat"]()
    a = _stance(littledog, terrain, (0.0, 0.0))
    with pytest.raises(ValueError, match="swing_leg"):
        interpolate_swing(littledog, terrain, a, a.copy(), 5)
    states = interpolate_swing(littledog, terrain, a, a.copy(), 5, swing_leg=3)
    assert states[2].feet_W[3, 2] > 0.0  # stepping in place still lifts the foot
    assert coords_from_pose(states[2].pose) == pytest.approx(a.coords)
