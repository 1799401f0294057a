"""Leg capsules against the sharp terrain (planner.links), checked against the validator."""

import numpy as np
import pytest

from planner.links import (
    KEYFRAME_ANGLE_RAD,
    KEYFRAME_MARGIN_M,
    WITNESS_GRID_M,
    _nearest_on_terrain,
    leg_links,
)
from planner.terrain import Terrain
from planner.validate import sharp_surface_distance


def _course(kind, **spec):
    return Terrain.from_spec(
        {"name": kind, "friction": 0.7, "x_min": -0.5, "length": 2.0, "kind": kind, **spec}
    )


COURSES = [
    _course("step", x=0.8, height=0.1),
    _course("step", x=0.8, height=-0.08),
    _course("barrier", x=0.8, height=0.075, thickness=0.03),
    _course("gap", x_start=0.8, width=0.06, depth=0.1),
]


@pytest.mark.parametrize("terrain", COURSES, ids=lambda t: t.name)
def test_witness_distance_matches_the_exact_distance(terrain, rng):
    """The witness cloud's distance is the exact one (validator, 1 mm grid) to ~1 mm."""
    worst, n = 0.0, 0
    for _ in range(80):
        a = np.array([0.8 + rng.uniform(-0.03, 0.05), rng.uniform(-0.1, 0.1), 0.0])
        a[2] = rng.uniform(-0.06, 0.14)
        b = a + rng.normal(size=3) * 0.04
        pts = a + np.linspace(0.0, 1.0, 201)[:, None] * (b - a)
        exact = float(sharp_surface_distance(terrain, pts, 0.03, step_m=1e-3).min())
        w = _nearest_on_terrain(terrain, a, b, 0.03)
        if exact <= 0.0:  # through the terrain: the witness says so
            assert w is not None and w.distance_m <= 1e-3
            continue
        if w is None:
            assert exact > 0.03 - 1e-3
            continue
        n += 1
        worst = max(worst, abs(w.distance_m - exact))
        np.testing.assert_allclose(np.linalg.norm(w.normal_W), 1.0)
        on_axis = a + w.u * (b - a)
        assert np.linalg.norm(on_axis - w.point_W) == pytest.approx(w.distance_m, abs=1e-12)
    assert n > 15
    assert worst <= 0.6 * WITNESS_GRID_M, worst


def test_path_margin_and_witnesses_flag_a_shank_at_an_edge(littledog):
    """Lower the robot until a shank touches a step edge: both tests see it."""
    terrain = _course("step", x=0.8, height=0.1)
    links = leg_links(littledog)
    joints = littledog.theta_nor.copy()
    rows = []
    for z in np.linspace(0.30, 0.05, 126):
        q = littledog.q_from(np.array([0.72, 0.0, z]), [0, 0, 0, 1], joints)
        rows.append((z, links.path_margin(terrain, q), links.witnesses(terrain, q)))
    # far above: nothing near; lower: some capsule comes within its margin
    assert all(m > 0 for m in rows[0][1]) and all(w is None for w in rows[0][2])
    z_fail, margin, wit = next(r for r in rows if r[1].min() < 0.0)
    c = int(np.argmin(margin))
    assert wit[c] is not None and wit[c].clearance_m < wit[c].need_m
    assert links.capsules[c].leg in (0, 1)  # a front leg meets the step first
    q = littledog.q_from(np.array([0.72, 0.0, z_fail]), [0, 0, 0, 1], joints)
    exact = sharp_surface_distance(terrain, links.axis_points_W(q), 0.05, step_m=5e-4)
    clear = (exact - links.radius)[links.owner == c].min()
    assert clear < KEYFRAME_MARGIN_M + KEYFRAME_ANGLE_RAD * 0.2  # near, by the exact measure
