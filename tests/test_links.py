"""Leg capsules against the sharp terrain (planner.body.links), checked against the validator."""

import numpy as np
import pytest

from planner.body.links import (
    KEYFRAME_ANGLE_RAD,
    KEYFRAME_MARGIN_M,
    WITNESS_GRID_M,
    _nearest_on_terrain,
    leg_links,
)
from planner.planfile.validate import sharp_surface_distance
from planner.world.terrain import Terrain


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


@pytest.mark.parametrize("legs", [[0], [1, 3], [0, 1, 2, 3]])
def test_path_margin_of_some_legs_is_theirs_and_leaves_the_others(littledog, rng, legs):
    """``legs``: those legs' capsules get the margins of the full call, near an edge too
    (the Euclidean fallback), the others +inf."""
    terrain = _course("step", x=0.8, height=0.1)
    links = leg_links(littledog)
    near = 0
    for _ in range(10):
        joints = littledog.theta_nor + rng.normal(scale=0.3, size=(4, 3))
        q = littledog.q_from(np.array([0.72, 0.0, rng.uniform(0.08, 0.2)]), [0, 0, 0, 1], joints)
        full = links.path_margin(terrain, q, swing_legs=[1])
        some = links.path_margin(terrain, q, swing_legs=[1], legs=legs)
        mine = np.array([cap.leg in legs for cap in links.capsules])
        np.testing.assert_array_equal(some[mine], full[mine])
        assert np.all(np.isinf(some[~mine]))
        near += int(np.any(full[mine] < 0.0))
    assert near > 0  # some capsule within its margin: the Euclidean fallback ran


def test_path_margins_of_a_path_are_each_configurations_own(littledog, rng):
    """One batched call over a path (issue 16) gives every configuration the margins of
    its own call, with its own swing legs and scale, near an edge too (witnesses)."""
    terrain = _course("barrier", x=0.8, height=0.075, thickness=0.03)
    links = leg_links(littledog)
    qs, swings = [], []
    for _ in range(12):
        joints = littledog.theta_nor + rng.normal(scale=0.3, size=(4, 3))
        base = np.array([rng.uniform(0.7, 0.9), rng.uniform(-0.05, 0.05), rng.uniform(0.1, 0.2)])
        qs.append(littledog.q_from(base, [0, 0, 0, 1], joints))
        swings.append(list(rng.choice(4, size=rng.integers(0, 2), replace=False)))
    short, bare = links.path_margins(terrain, qs, swings, scales=(1.0, 0.0))
    for k, (q, sw) in enumerate(zip(qs, swings, strict=True)):
        np.testing.assert_allclose(short[k], links.path_margin(terrain, q, sw), atol=1e-15)
        np.testing.assert_allclose(
            bare[k], links.path_margin(terrain, q, sw, scale=0.0), atol=1e-15
        )
        # against the exact distance (validator, 0.5 mm grid): a link through the terrain
        # has a negative margin, one with a positive margin is not through it
        exact = sharp_surface_distance(terrain, links.axis_points_W(q), 0.05, step_m=5e-4)
        clear = np.array([(exact - links.radius)[links.owner == c].min() for c in range(8)])
        assert np.all(bare[k][clear < -1e-3] < 0.0)
        assert np.all(clear[bare[k] > 1e-3] > -1e-3)
    assert np.any(short < 0.0) and np.any(short > 0.0)  # witnesses ran, and clear links


def test_the_shank_end_inside_the_foot_sphere_is_cut(rng):
    """What is cut lies inside the foot sphere; the new end's ball touches it from inside."""
    from planner.body.links import _outside_sphere

    cuts = 0
    for _ in range(300):
        c = rng.normal(size=3) * 0.01
        rho, r = rng.uniform(0.01, 0.03), rng.uniform(0.002, 0.03)
        a, b = rng.normal(size=3) * 0.1, c + rng.normal(size=3) * 0.01
        a2, b2 = _outside_sphere(a, b, r, c, rho)
        np.testing.assert_allclose(a2, a)  # only the end at the foot moves here
        inside_b = np.linalg.norm(b - c) + r <= rho
        if np.linalg.norm(b2 - b) > 1e-12:
            cuts += 1
            t = np.linspace(0.0, 1.0, 50)[:, None]
            cut = b2 + t * (b - b2)  # the removed part of the axis
            assert np.all(np.linalg.norm(cut - c, axis=1) + r <= rho + 1e-9)
            assert np.linalg.norm(b2 - c) + r == pytest.approx(rho)
            assert np.dot(b2 - a, b - a) > 0  # cut back along the segment, not past a
        else:  # kept: the end's ball is not inside the foot sphere (or the whole link is)
            assert not inside_b or np.linalg.norm(a - c) + r <= rho
    assert cuts > 20


def test_littledog_shanks_are_not_cut_and_hyq_shanks_are(littledog):
    """LittleDog's shank cylinder stops short of its foot; HyQ's reaches the foot centre."""
    from planner.body.robot import load_robot

    ld = {c.link: c.length_m for c in leg_links(littledog).capsules if c.leg == 0}
    assert ld["shank"] == pytest.approx(0.0917, abs=5e-4)
    hyq = load_robot("hyq")
    shank = next(c for c in leg_links(hyq).capsules if c.leg == 0 and c.link == "shank")
    foot = hyq.legs[0]
    # the capsule's end ball now touches the foot sphere from inside
    import pinocchio as pin

    d = hyq.model.createData()
    pin.framesForwardKinematics(hyq.model, d, pin.neutral(hyq.model))
    M = d.oMi[shank.joint_id]
    centre = d.oMf[hyq.model.getFrameId(foot.foot_frame)].translation
    end_W = min((M.rotation @ e + M.translation for e in (shank.a_J, shank.b_J)),
                key=lambda p: np.linalg.norm(p - centre))  # fmt: skip
    assert np.linalg.norm(end_W - centre) + shank.radius_m == pytest.approx(hyq.foot_radius_m)


def test_sphere_penetration_agrees_with_the_exact_distance(rng):
    """Foot spheres against a riser: the sampled overlap vs the validator's exact distance."""
    from planner.body.contact import sphere_penetration_m

    step = _course("step", x=0.8, height=0.17)
    rho = 0.031
    assert sphere_penetration_m(step, [[0.5, 0.0, rho]], rho)[0] == pytest.approx(0.0, abs=1e-9)
    for _ in range(40):
        d = rng.uniform(0.0, 0.05)  # sphere centre this far before the riser
        z = rng.uniform(rho, 0.1)
        c = np.array([[0.8 - d, rng.uniform(-0.2, 0.2), z]])
        cut = sphere_penetration_m(step, c, rho)[0]
        exact = rho - sharp_surface_distance(step, c, rho + 1e-3, 1e-4)[0]  # Euclidean depth
        if exact > 0.1 * rho:  # into the riser (beyond the ring's sampling): seen, not less
            assert cut >= exact - 1e-6
        elif exact < -1e-3:  # clear by a millimetre: no overlap at any sample
            assert cut <= 0.0
