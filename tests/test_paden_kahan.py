import math

import numpy as np
import pytest

from planner.body.paden_kahan import subproblem1, subproblem2, subproblem3

N_CASES = 10_000
TWO_PI = 2.0 * math.pi


def _rot(w, th):
    """Rodrigues rotation about unit w (independent of planner.core.lie on purpose)."""
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return np.eye(3) + math.sin(th) * K + (1.0 - math.cos(th)) * (K @ K)


def _apply(w, r, th, p):
    return r + _rot(w, th) @ (p - r)


def _apply_many(W, R, TH, P):
    """Vectorised exp(xi theta) p for rows of W (axes), R, P and angles TH."""
    u = P - R
    c, s = np.cos(TH)[:, None], np.sin(TH)[:, None]
    wu = np.sum(W * u, axis=1, keepdims=True)
    return R + c * u + s * np.cross(W, u) + (1.0 - c) * wu * W


def _angle_dist_many(a, b):
    d = np.mod(a - b, TWO_PI)
    return np.minimum(d, TWO_PI - d)


def _unit_rows(rng, n):
    x = rng.normal(size=(n, 3))
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def _angle_dist(a, b):
    d = (a - b) % TWO_PI
    return min(d, TWO_PI - d)


def test_subproblem1_random():
    rng = np.random.default_rng(1)
    W = _unit_rows(rng, N_CASES)
    Rp = rng.uniform(-1, 1, (N_CASES, 3))
    P = rng.uniform(-1, 1, (N_CASES, 3))
    TH = rng.uniform(-math.pi, math.pi, N_CASES)
    Q = _apply_many(W, Rp, TH, P)
    sols = [subproblem1(*args) for args in zip(W, Rp, P, Q, strict=True)]
    assert all(s is not None for s in sols)
    S = np.array(sols)
    assert np.all((S >= -math.pi) & (S < math.pi))
    assert np.abs(_apply_many(W, Rp, S, P) - Q).max() < 1e-10
    # the angle is only well defined when p is away from the axis
    ok = np.linalg.norm(np.cross(W, P - Rp), axis=1) > 1e-3
    assert _angle_dist_many(S, TH)[ok].max() < 1e-9


def test_subproblem1_unreachable_and_on_axis():
    w, r = np.array([0.0, 0.0, 1.0]), np.zeros(3)
    assert subproblem1(w, r, [1, 0, 0], [0, 2, 0]) is None  # different radius
    assert subproblem1(w, r, [1, 0, 0], [0, 1, 0.5]) is None  # different height
    assert subproblem1(w, r, [0, 0, 1], [0, 0, 1]) == 0.0  # on the axis
    assert subproblem1(w, r, [1, 0, 0], [0, 1, 0]) == pytest.approx(math.pi / 2)


def test_subproblem2_random():
    rng = np.random.default_rng(2)
    W1 = _unit_rows(rng, N_CASES)
    W2 = _unit_rows(rng, N_CASES)
    Rp = rng.uniform(-1, 1, (N_CASES, 3))
    P = rng.uniform(-1, 1, (N_CASES, 3))
    TH = rng.uniform(-math.pi, math.pi, (N_CASES, 2))
    C = _apply_many(W2, Rp, TH[:, 1], P)  # intermediate point exp(xi2 t2) p
    Q = _apply_many(W1, Rp, TH[:, 0], C)
    sols = [subproblem2(*args) for args in zip(W1, W2, Rp, P, Q, strict=True)]
    counts = np.array([len(s) for s in sols])
    assert counts.min() >= 1 and counts.max() <= 2
    assert np.all(counts == 2)  # generic: always two solutions
    # evaluate both returned solutions (repeat the first one if there is only one)
    S = np.array([[s[0], s[-1]] for s in sols])  # (N, 2 solutions, 2 angles)
    res = np.empty((N_CASES, 2))
    for k in range(2):
        qk = _apply_many(W1, Rp, S[:, k, 0], _apply_many(W2, Rp, S[:, k, 1], P))
        res[:, k] = np.abs(qk - Q).max(axis=1)
    assert res.min(axis=1).max() < 1e-10  # one solution reproduces q
    assert res.max() < 1e-9  # every solution satisfies the equation
    # the true pair is among the solutions when well conditioned: p away from
    # axis 2, intermediate point away from axis 1, axes not nearly parallel
    ok = (
        (np.linalg.norm(np.cross(W2, P - Rp), axis=1) > 1e-2)
        & (np.linalg.norm(np.cross(W1, C - Rp), axis=1) > 1e-2)
        & (np.linalg.norm(np.cross(W1, W2), axis=1) > 1e-2)
    )
    assert ok.sum() > 0.9 * N_CASES
    d = np.maximum(
        _angle_dist_many(S[:, :, 0], TH[:, None, 0]), _angle_dist_many(S[:, :, 1], TH[:, None, 1])
    ).min(axis=1)
    assert d[ok].max() < 1e-7


def test_subproblem2_unreachable_tangent_parallel():
    r = np.array([0.1, -0.2, 0.3])
    ez, ex = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    p = r + np.array([0.3, 0.4, 0.5])
    assert subproblem2(ez, ex, r, p, r + 1.5 * (p - r)) == []  # |q - r| != |p - r|
    # |q - r| == |p - r| but the two circles do not meet: p on axis 2 stays put,
    # and axis-1 rotation cannot change the z component
    assert subproblem2(ez, ex, r, r + ex, r + ez) == []
    # tangent: circles touch at one point -> one solution, within tolerance
    p_t = r + np.array([0.0, 1.0, 0.0])  # about x: circle in the y-z plane
    q_t = r + np.array([0.0, 0.0, 1.0 + 5e-10])
    sols = subproblem2(ez, ex, r, p_t, q_t)
    assert len(sols) == 1
    with pytest.raises(ValueError, match="parallel"):
        subproblem2(ez, -ez, r, p, p)


def test_subproblem3_random():
    rng = np.random.default_rng(3)
    W = _unit_rows(rng, N_CASES)
    Rp = rng.uniform(-1, 1, (N_CASES, 3))
    P = rng.uniform(-1, 1, (N_CASES, 3))
    Q = rng.uniform(-1, 1, (N_CASES, 3))
    TH = rng.uniform(-math.pi, math.pi, N_CASES)
    PT = _apply_many(W, Rp, TH, P)
    D = np.linalg.norm(PT - Q, axis=1)
    sols = [subproblem3(*args) for args in zip(W, Rp, P, Q, D, strict=True)]
    counts = np.array([len(s) for s in sols])
    assert counts.min() >= 1 and counts.max() <= 2
    assert np.all(counts == 2)  # generic: always two solutions
    S = np.array([[s[0], s[-1]] for s in sols])
    res = np.empty((N_CASES, 2))
    pos = np.empty((N_CASES, 2))
    for k in range(2):
        pk = _apply_many(W, Rp, S[:, k], P)
        res[:, k] = np.abs(np.linalg.norm(pk - Q, axis=1) - D)
        pos[:, k] = np.abs(pk - PT).max(axis=1)
    assert pos.min(axis=1).max() < 1e-10  # one solution reproduces the rotated point
    assert res.max() < 1e-9  # every solution satisfies the distance equation
    # the true angle is among the solutions where d(dist)/d(theta) is not small
    v = Q - Rp
    vp = v - np.sum(W * v, axis=1, keepdims=True) * W
    ptp = PT - Rp
    ddist = np.abs(np.sum(W * np.cross(ptp, vp), axis=1)) / D
    ok = ddist > 1e-2
    assert ok.sum() > 0.9 * N_CASES
    assert _angle_dist_many(S, TH[:, None]).min(axis=1)[ok].max() < 1e-8


def test_subproblem3_unreachable_and_tangent():
    w, r = np.array([0.0, 0.0, 1.0]), np.zeros(3)
    p, q = np.array([1.0, 0.0, 0.0]), np.array([2.0, 0.0, 1.0])
    dmin, dmax = math.sqrt(1 + 1), math.sqrt(9 + 1)
    assert subproblem3(w, r, p, q, dmax + 1e-3) == []
    assert subproblem3(w, r, p, q, dmin - 1e-3) == []
    assert subproblem3(w, r, p, q, 0.5) == []  # shorter than the axial offset
    for delta, expect in ((dmax, -math.pi), (dmax + 5e-10, -math.pi), (dmin, 0.0)):
        sols = subproblem3(w, r, p, q, delta)
        assert len(sols) == 1 and sols[0] == pytest.approx(expect, abs=1e-12)
    sols = subproblem3(w, r, p, q, dmin - 5e-10)
    assert len(sols) == 1 and abs(sols[0]) < 1e-12
    # p on the axis: distance independent of theta
    assert subproblem3(w, r, [0, 0, 0.5], q, math.hypot(2.0, 0.5)) == [0.0]
    assert subproblem3(w, r, [0, 0, 0.5], q, 3.0) == []
    two = subproblem3(w, r, p, q, math.sqrt(5 + 1))  # |pt - q|^2 = 5 - 4 cos -> cos = 0
    assert sorted(two) == pytest.approx([-math.pi / 2, math.pi / 2])
