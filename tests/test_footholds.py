"""Foothold candidates over the leg's reachable, safe region (planner.motion.footholds)."""

import numpy as np
import pytest

from planner.body.kinematics import hip_centre_B
from planner.motion.footholds import (
    BODY_SLACK_M,
    HIP_FOLLOW,
    MIN_ADVANCE_M,
    REACH_FRACTION,
    best_and_shortest,
    foothold_candidates,
)
from planner.motion.heuristics import EDGE_MARGIN_M, foothold_hazard
from planner.world.terrain import Terrain


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
        assert foothold_hazard(terrain, c, littledog.foot_radius_m, 0.7, forward_W=[1, 0, 0]) == ""
        assert c[0] >= foot[0] + MIN_ADVANCE_M - 1e-12
        assert c[2] == terrain.height(c[0], c[1])
        centre = c + littledog.foot_radius_m * terrain.normal(c).ravel()
        reach = REACH_FRACTION * littledog.reach_m[0] + BODY_SLACK_M
        assert np.linalg.norm(centre - hip) <= reach + 1e-9
    gaps = [np.linalg.norm(a[:2] - b[:2]) for i, a in enumerate(got) for b in got[i + 1 :]]
    assert min(gaps) >= 0.02 - 1e-9
    # none on the barrier, against its near face (a wall ahead) or on its far edge
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


def test_a_riser_counts_as_a_wall_ahead_of_the_foot_not_behind_it(littledog):
    """Stepping down 8 cm the foot may land 3 cm past the edge: the riser is behind it."""
    down = _terrain("step", x=0.8, height=-0.08)
    rho = littledog.foot_radius_m
    past = np.array([0.83, 0.0, -0.08])  # 3 cm beyond the edge, below it
    assert "higher" in foothold_hazard(down, past, rho, 0.7)  # no direction: refused
    assert foothold_hazard(down, past, rho, 0.7, forward_W=[1, 0, 0]) == ""
    # walking the other way the same riser is ahead of the toe: refused
    assert "higher" in foothold_hazard(down, past, rho, 0.7, forward_W=[-1, 0, 0])
    # and a toe before a step up stays refused when walking toward it
    up = _terrain("step", x=0.8, height=0.08)
    before = np.array([0.77, 0.0, 0.0])
    assert "higher" in foothold_hazard(up, before, rho, 0.7, forward_W=[1, 0, 0])
    # the edge margin itself applies in every direction
    assert "edge within" in foothold_hazard(
        down, past - [0.01, 0, 0], rho, 0.7, forward_W=[1, 0, 0]
    )


def test_the_floor_of_a_narrow_trench_is_refused_walking_either_way(littledog):
    """A 9 cm trench, 8 cm deep: its floor is a trap, not a foothold (a hind foot in a
    generated course's 7.5 cm trench could not climb out once the body had moved on)."""
    trench = _terrain("gap", x_start=0.75, width=0.09, depth=0.08)
    rho = littledog.foot_radius_m
    floor = np.array([0.795, 0.0, -0.08])  # 4.5 cm from either wall: past the wall rule
    for forward in ([1, 0, 0], [-1, 0, 0]):
        assert "trench" in foothold_hazard(trench, floor, rho, 0.7, forward_W=forward)
    # a wide trench's floor (walls 12 cm apart and more) is not a pit
    wide = _terrain("gap", x_start=0.75, width=0.16, depth=0.08)
    assert foothold_hazard(wide, np.array([0.83, 0.0, -0.08]), rho, 0.7, forward_W=[1, 0, 0]) == ""
    # nor the foot of a step down (the riser behind, flat ahead)
    down = _terrain("step", x=0.8, height=-0.08)
    assert foothold_hazard(down, np.array([0.84, 0.0, -0.08]), rho, 0.7, forward_W=[1, 0, 0]) == ""


def test_candidates_reach_back_to_the_nearest_point_past_an_edge(littledog):
    """A foot at the base of a 10 cm step: the nearest safe point on top is offered."""
    up = _terrain("step", x=0.8, height=0.1)
    body, R = np.array([0.74, 0.03, 0.18]), np.eye(3)
    foot = np.array([0.771, -0.065, 0.0])
    target = np.array([0.936, -0.037, 0.1])  # Lambda_t's, 16 cm ahead
    got = foothold_candidates(
        littledog, up, 1, target, [1, 0, 0], body, R, 0.7, not_behind_W=foot, limit=60
    )
    xs = [c[0] for c in got if c[2] > 0.05]
    assert min(xs) <= 0.8 + littledog.foot_radius_m + EDGE_MARGIN_M + 0.01
    assert max(xs) >= target[0] - 0.01
    short = best_and_shortest(got, foot, [1, 0, 0], 6)
    assert len(short) == 6 and len({id(c) for c in short}) == 6
    assert short[0] is got[0]  # the best first ...
    assert short[1][0] == pytest.approx(min(c[0] for c in got))  # ... then the shortest


def test_a_lower_candidate_lowers_the_hip_it_is_reached_from(littledog):
    """Stepping down, the body follows (HIP_FOLLOW): a foothold 8 cm lower is offered."""
    down = _terrain("step", x=0.8, height=-0.08)
    body, R = np.array([0.73, 0.025, 0.15]), np.eye(3)
    foot = np.array([0.77, 0.069, 0.0])
    target = np.array([0.852, 0.088, -0.08])
    got = foothold_candidates(
        littledog, down, 0, target, [1, 0, 0], body, R, 0.7, not_behind_W=foot, limit=8
    )
    assert got and all(c[2] == pytest.approx(-0.08, abs=1e-4) for c in got)
    hip = R @ hip_centre_B(littledog.legs[0]) + body
    reach = REACH_FRACTION * littledog.reach_m[0] + BODY_SLACK_M
    lowered = hip - [0, 0, HIP_FOLLOW * 0.08]
    centres = [c + littledog.foot_radius_m * down.normal(c).ravel() for c in got]
    assert all(np.linalg.norm(c - lowered) <= reach + 1e-9 for c in centres)
    assert any(np.linalg.norm(c - hip) > reach for c in centres)  # not from the level hip
