"""Foothold candidates over the leg's reachable, safe region (planner.motion.footholds)."""

import numpy as np
import pytest

from planner.body.kinematics import hip_centre_B, kinematics_of
from planner.motion.footholds import (
    BODY_SLACK_M,
    HIP_FOLLOW,
    MIN_ADVANCE_M,
    REACH_FRACTION,
    best_and_shortest,
    foothold_candidates,
)
from planner.motion.heuristics import (
    EDGE_MARGIN_M,
    STEP_FRACTION_OF_REACH,
    foothold_hazard,
    leg_room,
    safe_foothold,
)
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


def _leaning_pose(robot, leg):
    """theta_nor with ``leg``'s foot half a stride behind its nominal place (Newton IK)."""
    kin = kinematics_of(robot)
    th = np.array(robot.theta_nor, float)
    target = kin.foot_B(leg, th[leg]) - [0.5 * STEP_FRACTION_OF_REACH * robot.reach_m[leg], 0, 0]
    th[leg] = kin.ik_leg_near(leg, target, th[leg]).joints_rad
    assert np.allclose(kin.foot_B(leg, th[leg]), target, atol=1e-9)
    return th, target


def test_a_foothold_keeps_the_room_of_its_leg_links_before_a_riser(littledog):
    """A riser ahead of a foot that would reach into the leg's links as the body moves on
    refuses the foothold (LittleDog's hind knees point ahead of their feet).
    Reference: the links' capsules placed by Pinocchio at the leaning stance, their exact
    distance to the riser (where it is nearer than the ground) by the validator's surface
    distance; no foothold is
    allowed whose links would come within the keyframe margin of the riser, and a riser
    the links clear by 5 mm more does not refuse it (the room is conservative by at most
    a capsule radius)."""
    import pinocchio as pin

    from planner.body.links import KEYFRAME_ANGLE_RAD, KEYFRAME_MARGIN_M, leg_links
    from planner.planfile.validate_surface import sharp_surface_distance

    rho, links = littledog.foot_radius_m, leg_links(littledog)
    data = littledog.model.createData()
    flat = _terrain("flat")
    checked = {True: 0, False: 0}  # refused where the links meet it, allowed where clear
    for leg in (0, 2):  # a front leg (knee behind the foot) and a hind one
        th, foot_B = _leaning_pose(littledog, leg)
        caps = [c for c in links.capsules if c.leg == leg]
        room = leg_room(littledog, leg)
        for d in np.arange(0.045, 0.095, 0.01):
            for h in np.arange(0.02, 0.13, 0.015):
                edge = 0.8
                foot_W = np.array([edge - d, foot_B[1], rho])
                q = littledog.q_from(foot_W - foot_B, np.array([0.0, 0.0, 0.0, 1.0]), th)
                pin.forwardKinematics(littledog.model, data, q)
                up = _terrain("step", x=edge, height=float(h))
                slack = np.inf
                for c in caps:
                    M = data.oMi[c.joint_id]
                    a, b = M.rotation @ c.a_J + M.translation, M.rotation @ c.b_J + M.translation
                    pts = a + np.linspace(0, 1, 40)[:, None] * (b - a)
                    need = KEYFRAME_MARGIN_M + KEYFRAME_ANGLE_RAD * np.linalg.norm(
                        pts - foot_W, axis=1
                    )
                    dist = sharp_surface_distance(up, pts, 0.05)
                    riser = dist < sharp_surface_distance(flat, pts, 0.05) - 1e-6  # not ground
                    if np.any(riser):
                        slack = min(slack, float(np.min((dist - c.radius_m - need)[riser])))
                contact = [edge - d, foot_B[1], 0.0]
                why = foothold_hazard(up, contact, rho, 0.7, forward_W=[1, 0, 0], room=room)
                if slack < -0.001:
                    assert why, (leg, d, h, slack)
                    checked[True] += 1
                elif slack > 0.005 + max(c.radius_m for c in caps):
                    assert why == "", (leg, d, h, slack, why)
                    checked[False] += 1
    assert min(checked.values()) >= 5, checked
    # LittleDog's front knees point back: beyond the toe's room only a riser as tall as
    # the hip meets the front leg's links
    assert leg_room(littledog, 0).height_at(np.arange(0.042, 0.09, 0.003)).min() > 0.1
    # walking away from the riser, or with it beside the foot, the room does not apply
    up = _terrain("step", x=0.8, height=0.05)
    hind = leg_room(littledog, 3)
    before = np.array([0.756, -0.066, 0.0])
    assert "room" in foothold_hazard(up, before, rho, 0.7, forward_W=[1, 0, 0], room=hind)
    assert foothold_hazard(up, before, rho, 0.7, forward_W=[1, 0, 0]) == ""  # the toe alone
    assert foothold_hazard(up, before, rho, 0.7, forward_W=[0, 1, 0], room=hind) == ""
    # a thin barrier is crossed whole (the knee branch flips there): no room before it
    barrier = _terrain("barrier", x=0.8, height=0.075, thickness=0.03)
    for x in (0.71, 0.756):
        foot = np.array([x, -0.066, 0.0])
        assert foothold_hazard(barrier, foot, rho, 0.7, forward_W=[1, 0, 0], room=hind) == ""
    # Lambda_t's target in the riser's room goes to the top, not before it
    got, why = safe_foothold(up, [0.794, -0.066, 0.0], [1, 0, 0], rho, room=hind)
    assert why == "" and got[0] > 0.8 and got[2] == pytest.approx(0.05, abs=1e-4)
    got, why = safe_foothold(up, [0.794, -0.066, 0.0], [1, 0, 0], rho)
    assert why == "" and got[0] < 0.8  # (the toe's room alone: before it)


@pytest.mark.parametrize("height", [0.05, 0.1])
def test_a_target_in_the_leg_room_crosses_the_riser_and_one_at_the_toe_goes_nearest(
    littledog, height
):
    """safe_foothold with a hind leg's room, a riser at x = 0.8 m: a target the toe's rule
    accepts but the room refuses is moved onto the riser's top (within the shift allowed);
    a target the toe's rule refuses goes to the nearest safe point (none nearer is safe);
    every point returned is a foothold the room accepts, and the room changes nothing far
    from the riser."""
    rho, hind = littledog.foot_radius_m, leg_room(littledog, 3)
    up = _terrain("step", x=0.8, height=height)
    fwd = [1, 0, 0]

    def safe(x, room):
        got, why = safe_foothold(up, [x, -0.066, 0.0], fwd, rho, room=room, max_shift_m=0.09)
        assert why == ""
        assert foothold_hazard(up, got, rho, 0.7, forward_W=fwd, room=hind) == ""
        return got

    only_room = 0.8 - 0.045  # past the toe's 4 cm, inside the room (5.8 cm for 5 cm)
    assert foothold_hazard(up, [only_room, -0.066, 0.0], rho, 0.7, forward_W=fwd) == ""
    assert "room" in foothold_hazard(up, [only_room, -0.066, 0.0], rho, 0.7, forward_W=fwd,
                                     room=hind)  # fmt: skip
    got = safe(only_room, hind)
    assert got[0] > 0.8 and got[2] == pytest.approx(height, abs=1e-4)
    at_toe = 0.77  # 3 cm before the riser: the toe's rule refuses it
    got = safe(at_toe, hind)
    shift = abs(got[0] - at_toe)
    for d in np.arange(0.0, shift - 0.011, 0.01):  # nothing nearer is safe
        for x in (at_toe - d, at_toe + d):
            z = float(up.height(x, -0.066))
            assert foothold_hazard(up, [x, -0.066, z], rho, 0.7, forward_W=fwd, room=hind)
    far = [0.5, -0.066, 0.0]
    assert np.allclose(safe(far[0], hind), far) and np.allclose(safe(far[0], None), far)


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
