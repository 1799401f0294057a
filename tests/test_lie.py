import math

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from planner.core.lie import (
    coords_from_pose,
    hat,
    hat_ca,
    interpolate_coords,
    pose_from_coords,
    pose_from_coords_ca,
    quat_from_rotation,
    rotation_from_quat,
    rotation_from_vector,
    rotation_from_vector_ca,
    vector_from_rotation,
    vee,
)

TEST_ANGLES = [0.0, 1e-9, 1e-4, 1e-2, 0.5, math.pi / 2, 2.5, math.pi - 1e-3, math.pi - 1e-6]


def _random_axes(rng, n):
    x = rng.normal(size=(n, 3))
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def _round_trip_errors(angle, n=500, seed=0):
    rng = np.random.default_rng(seed)
    err_eps = err_T = 0.0
    for ax in _random_axes(rng, n):
        eps = np.concatenate([rng.uniform(-2, 2, 3), angle * ax])
        T = pose_from_coords(eps)
        eps2 = coords_from_pose(T)
        err_eps = max(err_eps, np.abs(eps2 - eps).max())
        err_T = max(err_T, np.abs(pose_from_coords(eps2) - T).max())
    return err_eps, err_T


@pytest.mark.parametrize("angle", TEST_ANGLES)
def test_round_trip(angle):
    # the symmetric-part log keeps full precision up to theta -> pi, so 1e-12 holds
    # even at pi - 1e-6 (observed ~1e-15)
    err_eps, err_T = _round_trip_errors(angle)
    assert err_eps < 1e-12
    assert err_T < 1e-12


def test_round_trip_axis_aligned_and_at_pi():
    for k in range(3):
        for angle in (0.0, 1e-9, math.pi / 2, math.pi - 1e-6):
            phi = angle * np.eye(3)[k]
            assert np.abs(vector_from_rotation(rotation_from_vector(phi)) - phi).max() < 1e-12
        # exactly pi: +-pi*omega is the same rotation; the rotation must round-trip
        for sgn in (1.0, -1.0):
            R = rotation_from_vector(sgn * math.pi * np.eye(3)[k])
            phi = vector_from_rotation(R)
            assert np.linalg.norm(phi) == pytest.approx(math.pi, abs=1e-12)
            assert np.abs(rotation_from_vector(phi) - R).max() < 1e-12
    rng = np.random.default_rng(5)
    for ax in _random_axes(rng, 200):
        R = rotation_from_vector(math.pi * ax)
        phi = vector_from_rotation(R)
        assert np.linalg.norm(phi) == pytest.approx(math.pi, abs=1e-12)
        assert np.abs(rotation_from_vector(phi) - R).max() < 1e-12


def test_log_angle_in_range():
    rng = np.random.default_rng(6)
    for phi in rng.uniform(-6, 6, (500, 3)):
        out = vector_from_rotation(rotation_from_vector(phi))
        assert np.linalg.norm(out) <= math.pi + 1e-15
        assert np.abs(rotation_from_vector(out) - rotation_from_vector(phi)).max() < 1e-12


def test_hat_vee():
    rng = np.random.default_rng(7)
    a, b = rng.normal(size=3), rng.normal(size=3)
    assert np.allclose(hat(a) @ b, np.cross(a, b), atol=1e-15)
    assert np.array_equal(vee(hat(a)), a)
    assert np.array_equal(np.array(ca.DM(hat_ca(ca.DM(a)))), hat(a))


def test_matches_pinocchio():
    rng = np.random.default_rng(8)
    for angle in TEST_ANGLES[:-2] + [3.0]:
        for ax in _random_axes(rng, 50):
            phi = angle * ax
            R = rotation_from_vector(phi)
            assert np.abs(R - pin.exp3(phi)).max() < 1e-14
            assert np.abs(vector_from_rotation(R) - pin.log3(R)).max() < 1e-12


@pytest.mark.parametrize("sym", [ca.SX, ca.MX])
def test_numpy_casadi_agree(sym):
    x = sym.sym("x", 6)
    R_ca, p_ca = pose_from_coords_ca(x)
    f = ca.Function("f", [x], [R_ca, p_ca])
    rng = np.random.default_rng(9)
    worst = 0.0
    for angle in TEST_ANGLES + [math.pi, 4.0]:
        for ax in _random_axes(rng, 20):
            eps = np.concatenate([rng.normal(size=3), angle * ax])
            R, p = (np.array(v) for v in f(eps))
            T = pose_from_coords(eps)
            worst = max(worst, np.abs(R - T[:3, :3]).max())
            assert np.array_equal(p.ravel(), eps[:3])
    assert worst < 1e-14


@pytest.mark.parametrize("sym", [ca.SX, ca.MX])
def test_casadi_jacobian_vs_finite_differences(sym):
    x = sym.sym("x", 3)
    R = rotation_from_vector_ca(x)
    J = ca.Function("J", [x], [ca.jacobian(ca.vec(R), x)])
    # reverse mode too (gradient of a scalar) and second derivatives
    g = ca.Function("g", [x], [ca.gradient(R[1, 0] + R[0, 2] - R[2, 1], x)])
    H = ca.Function("H", [x], [ca.hessian(ca.sumsqr(R - ca.DM.eye(3)), x)[0]])
    h = 1e-6
    rng = np.random.default_rng(10)
    points = [np.zeros(3), np.array([1e-9, 0, 0]), 3e-3 * rng.normal(size=3)]
    points += [a * ax for a, ax in zip([0.5, 2.0, 3.1], _random_axes(rng, 3), strict=True)]
    for phi in points:
        Jc = np.array(J(phi))
        Jfd = np.column_stack(
            [
                (
                    rotation_from_vector(phi + h * e).ravel(order="F")
                    - rotation_from_vector(phi - h * e).ravel(order="F")
                )
                / (2 * h)
                for e in np.eye(3)
            ]
        )
        assert np.abs(Jc - Jfd).max() < 1e-7
        assert np.all(np.isfinite(np.array(H(phi))))
        assert np.all(np.isfinite(np.array(g(phi))))
    # exact values at 0: dR/dphi_k = hat(e_k); d^2 |R - I|^2 = 4 I
    Jc0 = np.array(J(np.zeros(3)))
    for k in range(3):
        assert np.array_equal(Jc0[:, k], hat(np.eye(3)[k]).ravel(order="F"))
    assert np.array(g(np.zeros(3))).ravel() == pytest.approx([-1.0, 1.0, 1.0], abs=0)
    assert np.array(H(np.zeros(3))) == pytest.approx(4 * np.eye(3), abs=1e-14)


def test_interpolation():
    rng = np.random.default_rng(11)
    e1 = np.concatenate([rng.normal(size=3), 0.7 * _random_axes(rng, 1)[0]])
    e2 = np.concatenate([rng.normal(size=3), 1.3 * _random_axes(rng, 1)[0]])
    assert np.array_equal(interpolate_coords(e1, e2, 0.0), e1)
    assert np.array_equal(interpolate_coords(e1, e2, 1.0), e2)
    many = interpolate_coords(e1, e2, np.linspace(0, 1, 5))
    assert many.shape == (5, 6)
    assert np.array_equal(many[0], e1) and np.array_equal(many[-1], e2)
    # pure rotation about z from 0 to 1 rad: midpoint 0.5 rad
    z0 = np.zeros(6)
    z1 = np.array([0, 0, 0, 0, 0, 1.0])
    mid = interpolate_coords(z0, z1, 0.5)
    assert np.array_equal(mid, [0, 0, 0, 0, 0, 0.5])
    assert np.abs(pose_from_coords(mid)[:3, :3] - rotation_from_vector([0, 0, 0.5])).max() < 1e-15


def test_interpolation_short_way_across_pi():
    # 170 deg and -170 deg about z: the short way is 20 deg through 180 deg
    a = math.radians(170.0)
    e1 = np.array([0, 0, 0, 0, 0, a])
    e2 = np.array([1.0, 0, 0, 0, 0, -a])
    mid = interpolate_coords(e1, e2, 0.5)
    assert mid[:3] == pytest.approx([0.5, 0, 0])
    assert mid[3:] == pytest.approx([0, 0, math.pi])
    end = interpolate_coords(e1, e2, 1.0)
    R_end = pose_from_coords(end)[:3, :3]
    assert np.abs(R_end - rotation_from_vector(e2[3:])).max() < 1e-14
    # all intermediate angles stay within [170, 190] deg
    for nu in np.linspace(0, 1, 11):
        th = np.linalg.norm(interpolate_coords(e1, e2, nu)[3:])
        assert math.radians(170) - 1e-12 <= th <= math.radians(190) + 1e-12


def test_quaternions():
    rng = np.random.default_rng(12)
    for angle in TEST_ANGLES + [math.pi]:
        for ax in _random_axes(rng, 20):
            R = rotation_from_vector(angle * ax)
            q = quat_from_rotation(R)
            assert q.shape == (4,) and q[3] >= 0.0
            assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
            assert np.abs(rotation_from_quat(q) - R).max() < 1e-14
            assert np.abs(pin.Quaternion(q).toRotationMatrix() - R).max() < 1e-14
            # quaternion of angle-axis: (sin(t/2) axis, cos(t/2)) up to sign
            ref = np.concatenate([math.sin(angle / 2) * ax, [math.cos(angle / 2)]])
            assert min(np.abs(q - ref).max(), np.abs(q + ref).max()) < 1e-14
    q_id = quat_from_rotation(np.eye(3))
    assert np.array_equal(q_id, [0, 0, 0, 1.0])
    assert np.abs(rotation_from_quat([0, 0, 0, 2.0]) - np.eye(3)).max() == 0.0
