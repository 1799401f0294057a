"""Trajectory tau, R_tau(lambda) with lambda the arc length (sections 4.6, 8.2, 9 eq. 15)."""

import numpy as np
import pytest
from scipy.integrate import quad

from planner.core.errors import InputError
from planner.motion.trajectory import Trajectory

H_M = 0.15  # body height above the terrain used below [m]


class _Heights:
    """Test double of planner.world.terrain.Terrain, heights only."""

    def __init__(self, fn):
        self._fn = fn

    def height(self, x, y):
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        return self._fn(x, y)

    height_sharp = height


FLAT = _Heights(lambda x, y: np.zeros_like(x))
# a 4 cm wide, 10 cm deep trench across x in [0.50, 0.54]
TRENCH = _Heights(lambda x, y: np.where((x > 0.50) & (x < 0.54), -0.10, 0.0))
STEP = _Heights(lambda x, y: np.where(x >= 0.5, 0.05, 0.0))


def _fd_tangent(tau, lam, h=1e-6):
    return (tau.point(lam + h) - tau.point(lam - h)) / (2 * h)


@pytest.fixture
def wiggly_spline():
    pts = [[0, 0, 0.15], [0.4, 0.2, 0.16], [0.9, -0.1, 0.2], [1.5, 0.3, 0.18], [2.0, 0.0, 0.15]]
    return Trajectory.spline(pts), np.array(pts, float)


def test_polyline_lambda_is_arc_length():
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.5], [0.2, 1.3, 0.5]])
    tau = Trajectory.polyline(pts)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert tau.length_m == pytest.approx(seg.sum(), abs=1e-15)
    np.testing.assert_allclose(tau.point(np.cumsum(np.r_[0, seg])), pts, atol=1e-15)
    lam = np.linspace(0, tau.length_m, 5001)
    p = tau.point(lam)
    # straight pieces: chord == parameter step except across a vertex
    chords = np.linalg.norm(np.diff(p, axis=0), axis=1)
    assert np.sum(np.abs(chords - np.diff(lam)) > 1e-12) <= 2  # the 2 interior vertices
    assert np.sum(chords) == pytest.approx(tau.length_m, abs=1e-3)
    # the point a quarter of the way along segment 2
    np.testing.assert_allclose(tau.point(1 + 0.25 * seg[1]), [1, 0.25, 0.125], atol=1e-15)


def test_spline_lambda_is_arc_length_and_interpolates(wiggly_spline):
    tau, pts = wiggly_spline
    lam = np.linspace(0, tau.length_m, 20001)
    p = tau.point(lam)
    chords = np.linalg.norm(np.diff(p, axis=0), axis=1)
    # equal parameter steps give equal chords, and they add up to the length
    np.testing.assert_allclose(chords, np.diff(lam), rtol=1e-6)
    assert np.sum(chords) == pytest.approx(tau.length_m, rel=1e-7)
    np.testing.assert_allclose(tau.point([0, tau.length_m]), pts[[0, -1]], atol=1e-12)
    for w in pts[1:-1]:
        lam_w = tau.closest_lambda(w)
        np.testing.assert_allclose(tau.point(lam_w), w, atol=1e-7)


def test_tangent_unit_and_matches_finite_differences(wiggly_spline):
    tau_s, _ = wiggly_spline
    tau_p = Trajectory.polyline([[0, 0, 0], [1, 0, 0.2], [1.3, 0.8, 0.2]])
    tau_sine = Trajectory.sine_series(tau_p, [[0.0, 0.1, 0.02], [0.03, -0.05, 0.0]])
    for tau, lams in (
        (tau_s, np.linspace(0.01, tau_s.length_m - 0.01, 17)),
        (tau_p, [0.3, 0.9, 1.2, 1.5]),  # away from the vertex at lambda = |(1, 0, 0.2)|
        (tau_sine, [0.2, 0.5, 0.8, 1.4, 1.7]),
    ):
        for lam in lams:
            t = tau.tangent(lam)
            assert np.linalg.norm(t) == pytest.approx(1.0, abs=1e-12)
            np.testing.assert_allclose(t, _fd_tangent(tau, lam), atol=1e-6)
    # vectorised call agrees with scalar calls
    lams = np.array([0.1, 0.5, 0.9])
    np.testing.assert_allclose(tau_s.tangent(lams), [tau_s.tangent(x) for x in lams], atol=1e-15)


def test_closest_lambda_known_geometry():
    tau = Trajectory.polyline([[0, 0, 0], [1, 0, 0], [1, 1, 0.5]])
    seg2 = np.sqrt(1 + 0.25)
    assert tau.closest_lambda([0.3, 0.2, 9.0]) == pytest.approx(0.3, abs=1e-15)
    assert tau.closest_lambda([1.2, 0.5, 0.0]) == pytest.approx(1 + 0.5 * seg2, abs=1e-14)
    assert tau.closest_lambda([-1.0, -1.0, 0.0]) == 0.0
    assert tau.closest_lambda([3.0, 4.0, 0.0]) == pytest.approx(tau.length_m, abs=1e-14)
    got = tau.closest_lambda(np.array([[0.3, 0.2, 0], [1.2, 0.5, 0]]))
    np.testing.assert_allclose(got, [0.3, 1 + 0.5 * seg2], atol=1e-14)
    # restricting the search
    assert tau.closest_lambda([0.9, 0.05, 0], within=(1.2, 2.0)) == pytest.approx(1.2)


def test_closest_lambda_on_a_curve_is_the_orthogonal_projection(wiggly_spline, rng):
    tau, _ = wiggly_spline
    lam_dense = np.linspace(0, tau.length_m, 4001)
    xy_dense = tau.point(lam_dense)[:, :2]
    for q in rng.uniform([0.2, -0.3, 0], [1.8, 0.4, 1], size=(10, 3)):
        lam = tau.closest_lambda(q)
        d_best = np.linalg.norm(tau.point(lam)[:2] - q[:2])
        assert d_best <= np.min(np.linalg.norm(xy_dense - q[:2], axis=1)) + 1e-12
        if 0 < lam < tau.length_m:  # interior minimum: the xy residual is normal to the path
            r = tau.point(lam)[:2] - q[:2]
            t = tau.tangent(lam)[:2]
            assert abs(r @ t) < 1e-7


def test_sine_series_endpoints_shape_and_length():
    tau0 = Trajectory.polyline([[0, 0, 0.15], [2, 0, 0.15]])
    amp = 0.2
    tau = Trajectory.sine_series(tau0, [[0.0, amp, 0.0]])
    np.testing.assert_array_equal(tau.point(0.0), tau0.point(0.0))
    np.testing.assert_allclose(tau.point(tau.length_m), tau0.point(tau0.length_m), atol=1e-15)
    lam = np.linspace(0, tau.length_m, 301)
    p = tau.point(lam)
    np.testing.assert_allclose(p[:, 1], amp * np.sin(np.pi * p[:, 0] / 2), atol=1e-12)
    np.testing.assert_allclose(p[:, 2], 0.15, atol=1e-15)
    exact, _ = quad(lambda x: np.sqrt(1 + (amp * np.pi / 2 * np.cos(np.pi * x / 2)) ** 2), 0, 2)
    assert tau.length_m == pytest.approx(exact, abs=1e-10)
    # several harmonics on a bent tau0: still tau0's endpoints
    bent = Trajectory.polyline([[0, 0, 0], [1, 0.5, 0.1], [2, 0, 0]])
    tau2 = Trajectory.sine_series(bent, np.array([[0.1, -0.2, 0.05], [0.0, 0.1, 0], [0.02, 0, 0]]))
    np.testing.assert_allclose(tau2.start_W, bent.start_W, atol=1e-15)
    np.testing.assert_allclose(tau2.end_W, bent.end_W, atol=1e-15)


def test_straight_follows_the_ground_without_dipping():
    flat = Trajectory.straight([0, 0], [1.0, 0.5, 7.0], FLAT, H_M)
    assert flat.length_m == pytest.approx(np.hypot(1.0, 0.5), abs=1e-12)
    np.testing.assert_allclose(flat.waypoints_W[:, 2], H_M, atol=1e-15)
    np.testing.assert_allclose(flat.end_W, [1.0, 0.5, H_M], atol=1e-15)
    # a trench narrower than the footprint is bridged
    tr = Trajectory.straight([0, 0], [1, 0], TRENCH, H_M, footprint_radius_m=0.1)
    np.testing.assert_allclose(tr.waypoints_W[:, 2], H_M, atol=1e-15)
    # a step becomes a ramp that never gets closer than H_M to the ground under it
    st = Trajectory.straight([0, 0], [1, 0], STEP, H_M, footprint_radius_m=0.1)
    w = st.waypoints_W
    assert np.all(w[:, 2] >= STEP.height(w[:, 0], w[:, 1]) + H_M - 1e-12)
    assert np.all(np.diff(w[:, 2]) >= -1e-15)  # monotone ramp
    assert np.max(np.diff(w[:, 2])) < 0.05 / 3  # spread over several samples
    np.testing.assert_allclose(w[[0, -1], 2], [H_M, H_M + 0.05], atol=1e-15)


@pytest.mark.parametrize(
    "bad, match",
    [
        ([[0, 0, 0]], "at least 2"),
        ([[0, 0, 0], [0, 0, 0]], "at least 2"),
        ([[0, 0, 0], [1, np.nan, 0]], "NaN"),
        ([[0, 0], [1, 1]], r"\(N, 3\)"),
    ],
)
def test_invalid_waypoints_raise_input_error(bad, match):
    for make in (Trajectory.polyline, Trajectory.spline):
        with pytest.raises(InputError, match=match):
            make(bad)


def test_invalid_sine_coefficients_and_straight_inputs():
    tau0 = Trajectory.polyline([[0, 0, 0], [1, 0, 0]])
    with pytest.raises(InputError, match=r"\(P, 3\)"):
        Trajectory.sine_series(tau0, [[1.0, 2.0]])
    with pytest.raises(InputError, match="NaN"):
        Trajectory.sine_series(tau0, [[np.nan, 0, 0]])
    with pytest.raises(InputError, match="same x, y"):
        Trajectory.straight([0, 0], [0, 0, 1], FLAT, H_M)
    with pytest.raises(InputError, match="goal_W"):
        Trajectory.straight([0, 0], [np.nan, 0], FLAT, H_M)


@pytest.mark.parametrize("name", ["flat", "step5cm", "gap6cm", "slope10"])
def test_straight_on_the_real_terrains(name):
    terrain = pytest.importorskip("planner.world.terrain").load_terrain(name)
    tau = Trajectory.straight([0.0, 0.0], [2.0, 0.0], terrain, H_M, footprint_radius_m=0.1)
    w = tau.waypoints_W
    # never closer than H_M to the (sharp) ground under it
    assert np.all(w[:, 2] >= terrain.height_sharp(w[:, 0], w[:, 1]) + H_M - 1e-9)
    if name in ("flat", "gap6cm"):  # the 6 cm trench is bridged by the 20 cm footprint
        np.testing.assert_allclose(w[:, 2], H_M, atol=1e-12)
    lam = np.linspace(0, tau.length_m, 2001)
    assert np.all(np.linalg.norm(tau.tangent(lam), axis=1) == pytest.approx(1.0, abs=1e-12))
