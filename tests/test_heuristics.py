"""Lambda_c and Lambda_t (sections 8.2.1-8.2.2, eq. 12-13), reference directions (7.2)."""

import numpy as np
import pinocchio as pin
import pytest

from planner.body.kinematics import kinematics_of
from planner.body.state import State
from planner.motion.heuristics import (
    BODY_TARGET_CLEARANCE_M,
    MAX_SUPPORT_TILT_RAD,
    body_pose_on_trajectory,
    default_step_m,
    frame_from_directions,
    lambda_c,
    lambda_t,
    nominal_height_m,
    normal_smoothing_radius_m,
    reach_height_cap_m,
    reference_directions,
    support_body_target_W,
    support_centroid_W,
    support_incentre_W,
)
from planner.motion.trajectory import Trajectory

SLOPE = np.tan(np.radians(10.0))


class _Plane:
    """Test double of planner.world.terrain.Terrain: the plane z = a x + b y + c."""

    def __init__(self, a=0.0, b=0.0, c=0.0):
        self.a, self.b, self.c = a, b, c

    def height(self, x, y):
        return self.a * np.asarray(x, float) + self.b * np.asarray(y, float) + self.c

    height_sharp = height

    def f_T(self, p_W):
        p = np.asarray(p_W, float)
        return p[..., 2] - self.height(p[..., 0], p[..., 1])

    def normal(self, p_W):
        n = np.array([-self.a, -self.b, 1.0]) / np.sqrt(1 + self.a**2 + self.b**2)
        return np.broadcast_to(n, np.shape(p_W)).copy()

    def smoothed_normal(self, p_W, radius):
        return self.normal(p_W)


def _real(name):
    terrain = pytest.importorskip("planner.world.terrain")
    return terrain.load_terrain(name)


TERRAINS = {
    "flat": (lambda: _Plane(), lambda: _real("flat")),
    "slope": (lambda: _Plane(a=SLOPE, b=-0.3 * SLOPE, c=0.01), lambda: _real("slope10")),
}


@pytest.fixture(params=["double", "real"])
def source(request):
    return request.param


def _terrain(kind, source):
    return TERRAINS[kind][0 if source == "double" else 1]()


def _state_on(terrain, feet_xy, base=(0.0, 0.0, 0.15)):
    feet_xy = np.asarray(feet_xy, float)
    feet = np.column_stack([feet_xy, terrain.height(feet_xy[:, 0], feet_xy[:, 1])])
    return State(base, np.eye(3), feet, np.zeros((4, 3)))


def _pin_foot_W(robot, p, R, joints, leg):
    model, data = robot.model, robot.model.createData()
    q = robot.q_from(p, pin.Quaternion(R).coeffs(), joints)
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[model.getFrameId(robot.foot_frames[leg])].translation.copy()


FEET_XY = [[0.12, 0.09], [0.10, -0.08], [-0.11, 0.07], [-0.09, -0.10]]


def test_nominal_height_from_pinocchio(littledog):
    # independent: the lowest foot frame at theta_nor with the body at the origin, level
    z = min(
        _pin_foot_W(littledog, np.zeros(3), np.eye(3), littledog.theta_nor, i)[2] for i in range(4)
    )
    assert nominal_height_m(littledog) == pytest.approx(-z + littledog.foot_radius_m, abs=1e-12)
    assert 0.12 < nominal_height_m(littledog) < 0.18  # LittleDog stands ~0.15 m high
    assert default_step_m(littledog) == pytest.approx(0.35 * 0.1795, abs=1e-3)


@pytest.mark.parametrize("i_f", range(4))
def test_lambda_c_flat_is_centroid_lifted(littledog, source, i_f):
    terrain = _terrain("flat", source)
    st = _state_on(terrain, FEET_XY)
    others = [i for i in range(4) if i != i_f]
    want = st.feet_W[others].mean(axis=0)
    want[2] = float(terrain.height(want[0], want[1])) + nominal_height_m(littledog)
    np.testing.assert_allclose(lambda_c(littledog, terrain, st, i_f), want, atol=1e-15)
    want[2] += 0.03 - nominal_height_m(littledog)
    np.testing.assert_allclose(lambda_c(littledog, terrain, st, i_f, d_c_m=0.03), want, atol=1e-15)


def test_lambda_c_on_a_slope_lifts_from_the_terrain_under_it(littledog, source):
    terrain = _terrain("slope", source)
    st = _state_on(terrain, np.array(FEET_XY) + [1.2, 0.0])  # on the incline of slope10
    r = lambda_c(littledog, terrain, st, 2, d_c_m=0.14)
    np.testing.assert_allclose(r[:2], st.feet_W[[0, 1, 3], :2].mean(axis=0), atol=1e-15)
    assert r[2] == pytest.approx(float(terrain.height(r[0], r[1])) + 0.14, abs=1e-12)


def _edge_distances(tri_xy, p):
    out = []
    for k in range(3):
        a, b = tri_xy[k], tri_xy[(k + 1) % 3]
        e = b - a
        out.append(abs(e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0])) / np.linalg.norm(e))
    return np.array(out)


def test_lambda_c_shrink_moves_toward_the_incentre(littledog):
    terrain = _Plane()
    st = _state_on(terrain, [[0.25, 0.02], [0.10, -0.08], [-0.11, 0.07], [-0.09, -0.10]])
    tri = st.feet_W[[0, 1, 2], :2]
    inc = support_incentre_W(st, 3)
    d = _edge_distances(tri, inc)
    assert np.ptp(d) < 1e-12  # equidistant from the three edges
    cen = support_centroid_W(st, 3)
    assert _edge_distances(tri, cen).min() < d.min()
    r0 = lambda_c(littledog, terrain, st, 3)
    r1 = lambda_c(littledog, terrain, st, 3, shrink=1.0)
    rh = lambda_c(littledog, terrain, st, 3, shrink=0.5)
    np.testing.assert_allclose(r0[:2], cen[:2], atol=1e-15)
    np.testing.assert_allclose(r1[:2], inc[:2], atol=1e-15)
    np.testing.assert_allclose(rh[:2], 0.5 * (cen[:2] + inc[:2]), atol=1e-15)
    assert _edge_distances(tri, rh).min() > _edge_distances(tri, cen).min()
    with pytest.raises(ValueError, match="shrink"):
        lambda_c(littledog, terrain, st, 3, shrink=1.5)
    with pytest.raises(ValueError, match="0..3"):
        lambda_c(littledog, terrain, st, 4)


@pytest.mark.parametrize("leg", range(4))
def test_lambda_t_straight_flat_is_nominal_foot_plus_step(littledog, source, leg):
    terrain = _terrain("flat", source)
    h = nominal_height_m(littledog)
    tau = Trajectory.polyline([[0, 0, h], [2, 0, h]])
    st = _state_on(terrain, FEET_XY, base=(0.3, 0.02, h + 0.01))
    step = 0.05
    # independent reference: Pinocchio foot frame at theta_nor, body level at (0.3, 0, h)
    c = _pin_foot_W(littledog, [0.3, 0.0, h], np.eye(3), littledog.theta_nor, leg)
    want = np.array([c[0] + step, c[1], 0.0])
    got = lambda_t(littledog, terrain, st, leg, tau, step_m=step)
    np.testing.assert_allclose(got, want, atol=1e-12)
    # the default stride is the robot's
    got = lambda_t(littledog, terrain, st, leg, tau)
    assert got[0] - c[0] == pytest.approx(default_step_m(littledog), abs=1e-12)


def test_lambda_t_turns_with_the_path_and_stops_at_its_end(littledog):
    terrain = _Plane()
    h = nominal_height_m(littledog)
    tau = Trajectory.polyline([[1, 1, h], [1, 2, h]])  # heading +y: yaw 90 deg
    st = _state_on(terrain, FEET_XY, base=(1.01, 1.2, h))
    R = pin.utils.rpyToMatrix(0, 0, np.pi / 2)
    c = _pin_foot_W(littledog, [1, 1.2, h], R, littledog.theta_nor, 0)
    got = lambda_t(littledog, terrain, st, 0, tau, step_m=0.06)
    np.testing.assert_allclose(got, [c[0], c[1] + 0.06, 0.0], atol=1e-12)
    assert got[0] < 1.0  # FL is on the robot's left: -x when heading +y
    # near the end the body target stops at R_tau(L)
    st_end = _state_on(terrain, FEET_XY, base=(1.0, 1.98, h))
    c_end = _pin_foot_W(littledog, [1, 2, h], R, littledog.theta_nor, 0)
    got = lambda_t(littledog, terrain, st_end, 0, tau, step_m=0.06)
    np.testing.assert_allclose(got, [c_end[0], c_end[1], 0.0], atol=1e-12)


def test_body_pose_and_reference_directions_on_a_slope(littledog, source):
    terrain = _terrain("slope", source)
    tau = Trajectory.spline([[1.0, 0, 0.3], [1.5, 0.2, 0.4], [2.0, 0.1, 0.5]])
    radius = normal_smoothing_radius_m(littledog)
    for lam in (0.1, 0.5, 0.9):
        p, R = body_pose_on_trajectory(littledog, terrain, tau, lam)
        np.testing.assert_allclose(p, tau.point(lam), atol=1e-15)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
        u_f, u_n = reference_directions(tau, terrain, p, radius, lam=lam)
        assert np.linalg.norm(u_f) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(u_n, terrain.smoothed_normal(p, radius), atol=1e-12)
        # sigma_2 = u_n . z_B is maximal (1); x_B is u_f's component normal to u_n
        assert u_n @ R[:, 2] == pytest.approx(1.0, abs=1e-12)
        x = u_f - (u_f @ u_n) * u_n
        np.testing.assert_allclose(R[:, 0], x / np.linalg.norm(x), atol=1e-12)
        # the closest-lambda form gives the same u_f for a point on the path
        u_f2, _ = reference_directions(tau, terrain, p, radius)
        np.testing.assert_allclose(u_f2, u_f, atol=1e-6)


# ---- the body follows its footholds (issue 15 item 2) ---------------------------------------
def _step_terrain(height):
    from planner.world.terrain import Terrain

    return Terrain.from_spec(
        {"name": "step", "friction": 0.7, "x_min": -0.5, "length": 2.0, "kind": "step",
         "x": 0.0, "height": height}
    )  # fmt: skip


def test_support_target_on_level_feet_is_the_standing_pose(littledog):
    terrain = _real("flat")
    feet = kinematics_of(littledog).feet_B(littledog.theta_nor) + [0.3, 0.0, 0.0]
    feet[:, 2] = 0.0
    d_c = 0.147
    z, n = support_body_target_W(littledog, terrain, feet, [0.3, 0.0], d_c, [1, 0, 0], [0, 0, 1])
    assert z == pytest.approx(d_c, abs=1e-12)  # d_c over the ground, as Lambda_c
    np.testing.assert_allclose(n, [0, 0, 1], atol=1e-12)


@pytest.mark.parametrize("rise", [0.1, -0.08])
def test_support_target_pitches_with_a_step_and_sits_between_the_levels(littledog, rise):
    """Front feet on one level, hind feet on the other (a step at x = 0)."""
    terrain = _step_terrain(rise)
    f_B = kinematics_of(littledog).feet_B(littledog.theta_nor)
    feet = f_B.copy()
    feet[:, 2] = [rise, rise, 0.0, 0.0]
    h = nominal_height_m(littledog)
    z, n = support_body_target_W(littledog, terrain, feet, [0.0, 0.0], h, [1, 0, 0], [0, 0, 1])
    spacing = f_B[0, 0] - f_B[2, 0]
    assert n[1] == pytest.approx(0.0, abs=1e-12)  # no roll
    assert -n[0] / n[2] == pytest.approx(rise / spacing, rel=1e-9)  # pitched by the rise
    assert z == pytest.approx(0.5 * rise + h, abs=1e-12)  # between the levels
    # independent: at that pose each hip (Pinocchio) stands about as high over its foot
    R = frame_from_directions(np.array([1.0, 0.0, 0.0]), n)
    p = np.array([0.0, 0.0, z])
    data = littledog.model.createData()
    q = littledog.q_from(p, pin.Quaternion(R).coeffs(), littledog.theta_nor)
    pin.forwardKinematics(littledog.model, data, q)
    hip_z = [data.oMi[littledog.model.getJointId(lg.joint_names[0])].translation[2]
             for lg in littledog.legs]  # fmt: skip
    over = np.array(hip_z) - feet[:, 2]
    assert np.ptp(over) <= 0.15 * abs(rise)  # a level body would differ by |rise|


def test_support_target_keeps_the_terrain_roll_and_clears_a_barrier(littledog):
    from planner.world.terrain import Terrain

    barrier = Terrain.from_spec(
        {"name": "b", "friction": 0.7, "x_min": -0.5, "length": 2.0, "kind": "barrier",
         "x": 0.0, "height": 0.1, "thickness": 0.03}
    )  # fmt: skip
    feet = kinematics_of(littledog).feet_B(littledog.theta_nor)
    feet[:, 2] = 0.0
    tilt = np.array([0.0, -0.2, 1.0]) / np.hypot(0.2, 1.0)
    z, n = support_body_target_W(littledog, barrier, feet, [0.0, 0.0], 0.147, [1, 0, 0], tilt)
    np.testing.assert_allclose(n, tilt, atol=1e-12)  # level feet: the terrain's roll stays
    # the rolled body's bottom face, placed with its origin at z: its lowest point over the
    # barrier's top is the clearance above it (1 mm: the footprint's xy is taken untilted)
    lo, hi = np.asarray(littledog.body_box_B)
    x_ax = np.array([1.0, 0.0, 0.0]) - n[0] * n
    R = np.column_stack([x_ax / np.linalg.norm(x_ax), np.cross(n, x_ax / np.linalg.norm(x_ax)), n])
    u, v = np.meshgrid(np.linspace(lo[0], hi[0], 67), np.linspace(lo[1], hi[1], 23))
    face_W = np.column_stack([u.ravel(), v.ravel(), np.full(u.size, lo[2])]) @ R.T + [0, 0, z]
    over = face_W[np.abs(face_W[:, 0]) <= 0.015]
    assert float(over[:, 2].min()) - 0.1 == pytest.approx(BODY_TARGET_CLEARANCE_M, abs=1e-3)
    level = support_body_target_W(
        littledog, barrier, feet, [0.0, 0.0], 0.147, [1, 0, 0], [0.0, 0.0, 1.0]
    )[0]
    assert level == pytest.approx(0.1 - lo[2] + BODY_TARGET_CLEARANCE_M, abs=1e-9)


def test_support_tilt_is_bounded(littledog):
    terrain = _step_terrain(0.5)
    feet = kinematics_of(littledog).feet_B(littledog.theta_nor)
    feet[:, 2] = [0.5, 0.5, 0.0, 0.0]
    _, n = support_body_target_W(littledog, terrain, feet, [0.0, 0.0], 0.15, [1, 0, 0], [0, 0, 1])
    assert np.arccos(n[2]) == pytest.approx(MAX_SUPPORT_TILT_RAD, abs=1e-9)


def test_lambda_c_with_footholds_follows_them(littledog):
    terrain = _step_terrain(0.1)
    f_B = kinematics_of(littledog).feet_B(littledog.theta_nor)
    st = _state_on(_real("flat"), f_B[:, :2])
    feet = st.feet_W.copy()
    feet[:2, 2] = 0.1
    st.feet_W = feet
    paper = lambda_c(littledog, terrain, st, 3)
    follow = lambda_c(littledog, terrain, st, 3, feet_plane_W=feet)
    np.testing.assert_allclose(follow[:2], paper[:2], atol=1e-15)  # same xy (eq. 12)
    assert follow[2] < paper[2]  # between the levels, not over the step top


def test_reach_cap_sinks_the_body_until_every_hip_reaches(littledog):
    rng = np.random.default_rng(2)
    reach = np.asarray(littledog.reach_m, float)
    for _ in range(50):
        centres = rng.uniform(-0.15, 0.15, (4, 3)) * [1.0, 1.0, 0.2]
        hips = centres + rng.uniform(-0.08, 0.08, (4, 3)) + [0.0, 0.0, 0.16]
        dz = reach_height_cap_m(littledog, hips, centres, range(4), fraction=0.9)
        assert dz <= 0.0
        lowered = hips + [0.0, 0.0, dz]
        dist = np.linalg.norm(lowered - centres, axis=1)
        assert np.all(dist <= 0.9 * reach + 1e-9)  # every hip within reach, ...
        if dz < 0.0:  # ... and one of them exactly at it: no lower than needed
            assert np.isclose(dist, 0.9 * reach, atol=1e-9).any()
    # a hip beside its foot farther than the reach is left to Theta2 (sinking cannot help)
    centres = np.zeros((4, 3))
    hips = np.array([[0.0, 0.0, 0.1]] * 3 + [[0.5, 0.0, 0.1]])
    assert reach_height_cap_m(littledog, hips, centres, range(4), 0.9) == 0.0
    # only the listed legs count
    hips[0, 2] = 0.5
    assert reach_height_cap_m(littledog, hips, centres, [1, 2], 0.9) == 0.0
    assert reach_height_cap_m(littledog, hips, centres, [0], 0.9) < -0.3
