"""The two-beat crawl's body targets (issue 16, planner.motion.heuristics.two_beat_xy_W).

Checked against independent references: the Chebyshev centre against a dense grid of the
support margins, the walk against the validator (``check``), the paper's centroid targets
(same walk, more body moves) and MuJoCo.
"""

import numpy as np
import pytest

from planner.body.stability import (
    BALANCE_MARGIN_M,
    polygon_margin_m,
    support_margin_m,
    tip_margin_m,
    triangle_inradius_m,
)
from planner.body.state import State
from planner.motion.heuristics import chebyshev_centre_xy, two_beat_xy_W
from planner.planning.local import LocalSettings
from planner.planning.walk import plan_walk


def _grid_best(triangles, lo, hi, n=201):
    """(point, margin) of the best grid point: the least margin over ``triangles``.

    The margin is concave (a least of affine functions): the coarse pass lands within a
    coarse cell of the optimum's basin, the fine pass resolves it to a fraction of a mm."""
    xs, ys = np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n)
    best, at = -np.inf, None
    for x in xs:
        for y in ys[::8]:  # coarse pass
            m = min(support_margin_m(t, [x, y, 0.0]) for t in triangles)
            if m > best:
                best, at = m, (x, y)
    # fine pass around the coarse optimum
    step = (hi[1] - lo[1]) / (n - 1) * 8
    for x in np.linspace(at[0] - step, at[0] + step, 81):
        for y in np.linspace(at[1] - step, at[1] + step, 81):
            m = min(support_margin_m(t, [x, y, 0.0]) for t in triangles)
            if m > best:
                best, at = m, (x, y)
    return np.array(at), best


def test_chebyshev_centre_of_one_triangle_is_its_incentre():
    tri = np.array([[0.0, 0.0, 0.0], [0.2, 0.01, 0.0], [0.05, 0.15, 0.0]])
    xy, r = chebyshev_centre_xy([tri])
    assert r == pytest.approx(triangle_inradius_m(tri), abs=1e-9)
    assert support_margin_m(tri, [*xy, 0.0]) == pytest.approx(r, abs=1e-9)


def test_chebyshev_centre_of_two_triangles_against_a_grid(rng):
    """Random pairs of overlapping triangles: the LP's margin is the grid's best, to the
    grid's resolution, and its point has that margin in both triangles."""
    for _ in range(5):
        a = rng.uniform(-0.1, 0.1, (3, 3)) * [1, 1, 0] + [[0, 0, 0], [0.25, 0, 0], [0.1, 0.2, 0]]
        b = a + rng.uniform(-0.04, 0.04, (3, 3)) * [1, 1, 0]
        xy, r = chebyshev_centre_xy([a, b])
        lo = np.minimum(a.min(axis=0), b.min(axis=0))[:2]
        hi = np.maximum(a.max(axis=0), b.max(axis=0))[:2]
        _, best = _grid_best([a, b], lo, hi)
        assert min(support_margin_m(t, [*xy, 0.0]) for t in (a, b)) == pytest.approx(r, abs=1e-9)
        assert best - 1e-9 <= r <= best + 1e-3


def test_disjoint_triangles_have_a_negative_radius():
    a = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    _, r = chebyshev_centre_xy([a, a + [0.5, 0.0, 0.0]])
    assert r < 0.0


def _stance():
    """A crawl stance: FL, FR, HL, HR feet around the origin (world frame, flat ground)."""
    s = State.__new__(State)
    s.feet_W = np.array([[0.11, 0.07, 0.0], [0.1, -0.07, 0.0], [-0.1, 0.07, 0.0],
                         [-0.11, -0.07, 0.0]])  # fmt: skip
    return s


def test_two_beat_stays_where_the_com_has_the_margin_already():
    s = _stance()
    com = np.array([0.0, -0.04, 0.15])  # deep inside FR, HL, HR's triangle (FL swings)
    assert support_margin_m(s.feet_W[[1, 2, 3]], com) > 0.03
    assert np.allclose(two_beat_xy_W(s, 0, 3, None, com, 0.03), com[:2])


def test_two_beat_moves_into_both_supports():
    """HL (2) swings next, then FL (0): the target is deepest in both FL-FR-HR and, with
    HL on its new foothold, FR-HL'-HR; the paper's target needs no such point."""
    s = _stance()
    com = np.array([0.0, 0.0, 0.15])  # on the FL-HR diagonal: no margin for HL's swing
    target = np.array([-0.03, 0.07, 0.0])  # HL's next foothold, a 7 cm stride
    xy = two_beat_xy_W(s, 2, 0, target, com, 0.02)
    assert xy is not None
    after = s.feet_W.copy()
    after[2] = target
    p = np.array([*xy, 0.0])
    m_now = support_margin_m(s.feet_W[[0, 1, 3]], p)
    m_next = support_margin_m(after[[1, 2, 3]], p)
    assert min(m_now, m_next) >= 0.02
    assert m_now == pytest.approx(m_next, abs=1e-6)  # the LP balances the two
    # no target known (the plain Theta2): the paper's Lambda_c
    assert two_beat_xy_W(s, 2, 0, None, com, 0.02) is None
    # a margin the two triangles cannot give: the paper's Lambda_c
    assert two_beat_xy_W(s, 2, 0, target, com, 0.2) is None


def test_tip_margin_is_the_com_margin_at_rest_and_shifts_with_acceleration():
    s = _stance()
    com = np.array([0.02, 0.01, 0.15])
    g = np.array([0.0, 0.0, -9.81])
    assert tip_margin_m(s.feet_W, com, g) == pytest.approx(polygon_margin_m(s.feet_W, com))
    a = np.array([1.5, 0.0, 0.0])  # braking backward = accelerating forward: ZMP back
    zmp = com - 0.15 * a / 9.81
    assert tip_margin_m(s.feet_W, com, g - a) == pytest.approx(polygon_margin_m(s.feet_W, zmp))


GOAL_XY = (0.7, 0.0)  # the walks: 0.5 m on flat, 14-15 steps


@pytest.fixture(scope="module")
def walks():
    """The same 0.5 m flat walk with the paper's centroid targets and the two-beat's."""
    out = {}
    for target in ("centroid", "two_beat"):
        settings = LocalSettings(com_target=target, body_samples=16, swing_samples=24)
        plan, report = plan_walk("littledog", "flat", GOAL_XY, (0.2, 0.0), "soft", settings)
        assert plan.outcome["reached_goal"] and report.ok, report.summary()
        out[target] = plan
    return out


def _travel(plan) -> tuple[float, float]:
    """(path length, backward travel) of the base in xy [m]."""
    d = np.diff(plan.samples.q[:, :2], axis=0)
    return float(np.linalg.norm(d, axis=1).sum()), float(-d[:, 0][d[:, 0] < 0.0].sum())


def test_two_beat_walk_sways_less_and_walks_faster(walks):
    """The paper's centroid targets sway the body back before each front swing (13 cm of
    backward travel in the 0.5 m walk, measured); the two-beat's hardly at all, with a
    shorter body path and walk."""
    (path_c, back_c), (path_t, back_t) = _travel(walks["centroid"]), _travel(walks["two_beat"])
    assert back_t < 0.05 * back_c and back_c > 0.1, (back_c, back_t)
    assert path_t < 0.8 * path_c, (path_c, path_t)
    assert walks["two_beat"].samples.time[-1] < walks["centroid"].samples.time[-1]


def test_two_beat_keyframes_keep_the_balance_margin(walks, littledog):
    """Every three-leg keyframe: the COM (Pinocchio's, independent of the planner's) at
    least BALANCE_MARGIN_M inside the support triangle."""
    import pinocchio as pin

    model = littledog.model
    data = model.createData()
    for kf in walks["two_beat"].keyframes:
        if kf.stratum == 0:
            continue
        support = [i for i in range(4) if i != kf.stratum - 1]
        q = littledog.q_from(kf.base_position, kf.base_quaternion, kf.joints.reshape(4, 3))
        com = pin.centerOfMass(model, data, q)
        assert support_margin_m(kf.feet[support], com) >= BALANCE_MARGIN_M - 1e-4


def test_two_beat_walk_holds_up_in_mujoco(walks):
    from planner.sim.simulate import run_open_loop

    m = run_open_loop(walks["two_beat"]).metrics
    assert m.reached and m.final_error_m < 0.03, m.summary()
    assert not m.fell and not m.tipped, m.summary()


def test_theta2_hold_checks_the_start_itself(walks):
    """Theta2.hold at a three-leg keyframe of the walk (the body already there): feasible,
    the same pose and joints; at a four-feet keyframe whose COM lies on a diagonal of the
    stance: the balance margin is what it misses."""
    from planner.body.robot import load_robot
    from planner.motion.heuristics import reference_directions
    from planner.motion.trajectory import Trajectory
    from planner.planning.soft import SoftPlanner
    from planner.world.terrain import load_terrain

    robot, terrain = load_robot("littledog"), load_terrain("flat")
    planner = SoftPlanner(robot, terrain)
    tau = Trajectory.straight((0.2, 0.0), GOAL_XY, terrain, planner.com_height_m())
    kfs = walks["two_beat"].keyframes
    k = next(i for i in range(1, len(kfs)) if kfs[i].stratum != 0 and kfs[i - 1].stratum == 0)
    moved = kfs[k - 1].to_state()  # the body-move end, on four feet, before leg k swings
    leg = kfs[k].stratum - 1
    support = tuple(i for i in range(4) if i != leg)
    com = planner.check.com_W(moved)
    u_f, u_n = reference_directions(tau, terrain, com)
    held = planner.theta2(support).hold(moved, com, u_f, u_n)
    assert held.feasible, held.diagnosis
    assert np.allclose(held.state.base_position_W, moved.base_position_W)
    assert np.allclose(held.state.joints_rad, moved.joints_rad)
    start = kfs[0].to_state()  # standing square: the COM on the diagonal of FL-HR
    com0 = planner.check.com_W(start)
    miss = planner.theta2((0, 1, 3)).hold(start, com0, u_f, u_n)
    assert not miss.feasible and miss.violations["balance_margin"] > 0.01


def test_long_strides_only_over_level_ground(littledog):
    """``level_stride``: the long stride on flat ground; the default for the front legs
    about to cross step5cm's 5 cm step (at x = 0.8 m); on rough2cm both, and where long,
    the ground along the foot's track (every mm) within 5 mm of the feet's plane."""
    from planner.motion.heuristics import support_plane_W
    from planner.motion.trajectory import Trajectory
    from planner.planning.soft import SoftPlanner
    from planner.world.terrain import load_terrain

    long = 0.67 * float(np.min(littledog.reach_m))

    def strides(name, x, legs):
        terrain = load_terrain(name)
        planner = SoftPlanner(littledog, terrain, settings=LocalSettings(level_stride=0.67))
        tau = Trajectory.straight((x, 0.0), (x + 1.0, 0.0), terrain, planner.com_height_m())
        state = planner.initial_state((x, 0.0), tau)
        return (
            planner,
            terrain,
            state,
            tau,
            {leg: planner.stride_at(state, leg, tau) for leg in legs},
        )

    _, _, _, _, got = strides("flat", 0.3, range(4))
    assert all(v == pytest.approx(long) for v in got.values())
    planner, _, _, _, got = strides("step5cm", 0.68, (0, 1))
    assert all(v == pytest.approx(planner.stride_m()) for v in got.values())
    seen = set()
    for x in np.arange(0.3, 1.6, 0.1):
        planner, terrain, state, tau, got = strides("rough2cm", float(x), range(4))
        for leg, stride in got.items():
            is_long = stride == pytest.approx(long)
            seen.add(is_long)
            if is_long:
                grad, c = support_plane_W(state.feet_W)
                a = state.feet_W[leg, :2]
                b = planner.stride_target(state, leg, tau, long)[:2]
                pts = a + np.linspace(0.0, 1.0, 300)[:, None] * (b - a)
                z = np.asarray(terrain.height_sharp(pts[:, 0], pts[:, 1]), float)
                assert np.abs(z - c[2] - (pts - c[:2]) @ grad).max() <= 0.005 + 1e-9
    assert seen == {True, False}
    flat = load_terrain("flat")
    plain = SoftPlanner(littledog, flat)
    tau = Trajectory.straight((0.3, 0.0), (1.3, 0.0), flat, plain.com_height_m())
    assert plain.stride_at(plain.initial_state((0.3, 0.0), tau), 0, tau) == plain.stride_m()


def test_fast_settings_apply_over_level_ground_only(littledog):
    """Where the ground under the feet is not level (step5cm's step between the front and
    hind feet) the two-beat target is Lambda_c's, the body accelerates at the default
    bound, swings are the default's height and both have the default's samples; on flat
    ground the two-beat's and the level settings."""
    from dataclasses import replace

    from planner.motion.trajectory import Trajectory
    from planner.planning.soft import SoftPlanner
    from planner.world.terrain import load_terrain

    fast = LocalSettings(
        com_target="two_beat", level_body_accel_m_s2=1.5, level_clearance_m=0.02,
        level_body_samples=16, level_swing_samples=24,
    )  # fmt: skip
    for name, x, level in (("flat", 0.3, True), ("step5cm", 0.75, False)):
        terrain = load_terrain(name)
        planner = SoftPlanner(littledog, terrain, settings=fast)
        paper = SoftPlanner(littledog, terrain)
        tau = Trajectory.straight((x, 0.0), (x + 1.0, 0.0), terrain, planner.com_height_m())
        state = planner.initial_state((x, 0.0), tau)
        assert planner.level_under(state) is level
        target = np.array([x - 0.03, 0.07, 0.0])  # HL's next foothold
        target[2] = float(terrain.height(target[0], target[1]))
        got = planner.body_target(state, 2, swing_target_W=target, tau=tau)
        want = paper.body_target(state, 2, swing_target_W=target, tau=tau)
        assert bool(np.linalg.norm(got[:2] - want[:2]) > 1e-3) is level
        step = paper.step(state, 2, tau, paper.stride_m())
        assert step.ok, step.diagnosis
        path = step.body_path
        planner.settings = replace(planner.settings, body_accel_m_s2=0.5)
        quick, slow = planner.body_offsets_s(path)[-1], paper.body_offsets_s(path)[-1]
        assert (quick < 0.8 * slow) if level else quick == pytest.approx(slow)
        clear = planner.swing_clearance_m(step.moved, 2, step.end.feet_W[2])
        assert clear == (0.02 if level else pytest.approx(0.029981, abs=1e-6))
        assert planner.body_samples_at(state) == (16 if level else 8)
        assert planner.swing_samples_at(step.moved, 2, step.end.feet_W[2]) == (24 if level else 12)
