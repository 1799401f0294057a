"""Foothold candidates over the leg's reachable, safe region (planner.footholds)."""

import numpy as np

from planner.footholds import BODY_SLACK_M, MIN_ADVANCE_M, REACH_FRACTION, foothold_candidates
from planner.heuristics import foothold_hazard
from planner.kinematics import hip_centre_B
from planner.terrain import Terrain


def _terrain(kind, **spec):
    return Terrain.from_spec(
        {"name": kind, "friction": 0.7, "x_min": -0.5, "length": 2.0, "kind": kind, **spec}
    )


def test_candidates_are_safe_reachable_ahead_and_spread(littledog):
    terrain = _terrain("barrier", x=0.8, height=0.075, thickness=0.03)
    body, R = np.array([0.72, 0.0, 0.15]), np.eye(3)
    foot = np.array([0.757, 0.069, 0.0])
    target = np.array([0.82, 0.069, 0.075])  # on the barrier: not a foothold
    got = foothold_candidates(
        littledog, terrain, 0, target, [1, 0, 0], body, R, 0.7, not_behind_W=foot, limit=8
    )
    assert 3 <= len(got) <= 8
    hip = R @ hip_centre_B(littledog.legs[0]) + body
    for c in got:
        assert foothold_hazard(terrain, c, littledog.foot_radius_m, 0.7) == ""
        assert c[0] >= foot[0] + MIN_ADVANCE_M - 1e-12
        assert c[2] == terrain.height(c[0], c[1])
        centre = c + littledog.foot_radius_m * terrain.normal(c).ravel()
        reach = REACH_FRACTION * littledog.reach_m[0] + BODY_SLACK_M
        assert np.linalg.norm(centre - hip) <= reach + 1e-9
    gaps = [np.linalg.norm(a[:2] - b[:2]) for i, a in enumerate(got) for b in got[i + 1 :]]
    assert min(gaps) >= 0.02 - 1e-9
    # none on the barrier or against its faces (the wall radius keeps feet off them)
    assert all(c[0] < 0.77 or c[0] > 0.85 for c in got)
    assert any(c[0] > 0.85 for c in got)  # and the far side is offered


def test_on_open_ground_the_target_comes_first(littledog):
    terrain = _terrain("flat")
    body, R = np.array([0.5, 0.0, 0.15]), np.eye(3)
    target = np.array([0.66, 0.07, 0.0])
    got = foothold_candidates(littledog, terrain, 0, target, [1, 0, 0], body, R, 0.7)
    np.testing.assert_allclose(got[0], target, atol=1e-12)
    # the next best are the nearest along the stride (shorter before sideways)
    assert abs(got[1][1] - target[1]) < 1e-9 or abs(got[1][0] - target[0]) < 1e-9
