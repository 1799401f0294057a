"""The time law of planned paths (planner.motion.time_law): against closed-form motion profiles and
the caps, and the plan's samples against the URDF's joint speed limits."""

import math

import numpy as np
import pytest

from planner.motion.time_law import (
    JOINT_SPEED_FRACTION,
    LANDING_FRACTION,
    body_profile,
    rest_to_rest_durations_s,
    swing_durations_s,
)


def _node_speeds(lengths, dt):
    """Node speeds implied by constant acceleration in each interval, from rest."""
    v = [0.0]
    for ell, t in zip(lengths, dt, strict=True):
        v.append(2.0 * ell / t - v[-1])
    return np.array(v)


@pytest.mark.parametrize(
    ("d", "vmax", "a"), [(0.5, 0.1, 0.5), (0.03, 0.2, 0.6), (1.0, 0.3, 2.0), (0.06, 0.04, 0.6)]
)
def test_a_finely_sampled_straight_move_takes_the_trapezoid_time(d, vmax, a):
    """Accelerate at a to vmax (or half way), cruise, brake: T = d / v + v / a, with the
    peak v = min(vmax, sqrt(a d)); a fine sampling converges to it."""
    k = 1000
    dt = rest_to_rest_durations_s(np.full(k, d / k), np.full(k, vmax), a)
    v = min(vmax, math.sqrt(a * d))
    assert dt.sum() == pytest.approx(d / v + v / a, rel=2e-3)


def test_one_interval_is_a_bang_bang_move_or_its_cap():
    assert rest_to_rest_durations_s(np.array([0.04]), np.array([1.0]), 1.0)[0] == pytest.approx(
        2.0 * math.sqrt(0.04)
    )
    assert rest_to_rest_durations_s(np.array([0.04]), np.array([0.01]), 1.0)[0] == pytest.approx(
        4.0
    )


def test_no_interval_passes_its_cap_nor_the_acceleration_bound(rng):
    """Random lengths and caps: the mean speed of each interval is within its cap, the node
    speeds start and end at rest and change by at most the bound."""
    for _ in range(50):
        k = int(rng.integers(2, 30))
        ell = rng.uniform(0.001, 0.05, k)
        cap = rng.uniform(0.02, 0.5, k)
        a = float(rng.uniform(0.2, 5.0))
        dt = rest_to_rest_durations_s(ell, cap, a)
        assert np.all(ell / dt <= cap * (1 + 1e-9))
        v = _node_speeds(ell, dt)
        assert abs(v[-1]) < 1e-9 * max(1.0, v.max())
        assert np.all(v >= -1e-9)
        assert np.all(np.abs(np.diff(v**2)) <= 2.0 * a * ell * (1 + 1e-9) + 1e-12)


def test_a_longer_allowance_never_slows_a_path(rng):
    """Raising the caps or the acceleration bound can only shorten the path."""
    ell = rng.uniform(0.001, 0.05, 12)
    cap = rng.uniform(0.02, 0.5, 12)
    base = rest_to_rest_durations_s(ell, cap, 1.0).sum()
    assert rest_to_rest_durations_s(ell, 2 * cap, 1.0).sum() <= base + 1e-12
    assert rest_to_rest_durations_s(ell, cap, 2.0).sum() <= base + 1e-12


def test_body_move_respects_the_joint_limits_and_counts_a_turn():
    """A pure turn still takes time (its hips travel arm x angle), and the joint caps bind
    when the joints move fast for little base travel."""
    R = [np.eye(3)]
    for ang in np.linspace(0.05, 0.2, 4):
        c, s = math.cos(ang), math.sin(ang)
        R.append(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))
    p = np.zeros((5, 3))
    th = np.zeros((5, 12))
    dt, _ = body_profile(p, R, th, speed_m_s=0.1, accel_m_s2=1.0, arm_m=0.1, vmax_rad_s=None)
    assert dt.sum() > 0.1 * 0.2 / 0.1  # at least the hips' travel at the peak speed
    th[:, 0] = np.linspace(0.0, 1.0, 5)  # 0.25 rad per interval
    vmax = np.full(12, 7.0)
    dt, _ = body_profile(p, R, th, speed_m_s=0.1, accel_m_s2=1.0, arm_m=0.1, vmax_rad_s=vmax)
    assert np.all(0.25 / dt <= JOINT_SPEED_FRACTION * 7.0 * (1 + 1e-9))


def test_a_swing_lands_at_its_landing_speed_and_lasts_its_least():
    """The landing third of the intervals stays within the landing cap; a swing the law
    makes shorter than ``least_s`` is stretched to it."""
    foot = np.column_stack([np.linspace(0.0, 0.12, 13), np.zeros(13), np.zeros(13)])
    th = np.zeros((13, 12))
    kw = dict(foot_speed_m_s=0.5, landing_speed_m_s=0.1, foot_accel_m_s2=6.0, vmax_rad_s=None)
    dt = swing_durations_s(foot, th, least_s=0.0, **kw)
    speeds = 0.01 / dt
    n_land = round(12 * LANDING_FRACTION)
    assert np.all(speeds[-n_land:] <= 0.1 + 1e-9)
    assert speeds[:-n_land].max() > 0.1  # the rest is faster
    stretched = swing_durations_s(foot, th, least_s=10.0, **kw)
    assert stretched.sum() == pytest.approx(10.0)
    np.testing.assert_allclose(stretched / dt, 10.0 / dt.sum())


def test_a_planned_walk_keeps_its_joints_and_body_within_the_law(short_flat_walk, littledog):
    """Every sample interval of a plan: joints within JOINT_SPEED_FRACTION of the URDF's
    limits, the base within its peak speed in body moves and in the swings that overlap
    their body moves' ends (planner.planning.overlap); the plan records the law's settings."""
    _, plan, _ = short_flat_walk
    t, q, contact = plan.samples.time, plan.samples.q, plan.samples.contact
    settings = plan.stats["settings"]
    dt = np.diff(t)
    assert np.all(dt > 0)
    vmax = np.asarray(littledog.model.velocityLimit, float)[-12:]
    joint_ratio = (np.abs(np.diff(q[:, 7:], axis=0)) / dt[:, None] / vmax).max()
    assert joint_ratio <= JOINT_SPEED_FRACTION * (1 + 1e-9)
    base_speed = np.linalg.norm(np.diff(q[:, :3], axis=0), axis=1) / dt
    in_swing = ~contact[:-1].all(axis=1) | ~contact[1:].all(axis=1)
    assert in_swing.any() and (~in_swing).any()
    assert base_speed.max() <= settings["body_speed_m_s"] * (1 + 1e-9)
    assert settings["swing_overlap"] > 0 and base_speed[in_swing].max() > 0.0
    assert settings["body_accel_m_s2"] > 0


@pytest.mark.parametrize("overlap", [0.0, 1.0])
def test_the_executor_times_a_step_as_the_planner_does(littledog, overlap):
    """Feedback (8.3) follows a step at the times the walk records for it, its swing
    overlapping the body move's end or not (planner.planning.overlap)."""
    from planner.motion.trajectory import Trajectory
    from planner.planning.local import LocalSettings, Walk
    from planner.planning.soft import SoftPlanner
    from planner.world.terrain import load_terrain

    terrain = load_terrain("flat")
    planner = SoftPlanner(littledog, terrain, settings=LocalSettings(swing_overlap=overlap))
    tau = Trajectory.straight((0.2, 0.0), (0.6, 0.0), terrain, planner.com_height_m())
    state = planner.initial_state((0.2, 0.0), tau)
    step = planner.step(state, 2, tau, planner.stride_m())
    assert step.ok, step.diagnosis
    walk = Walk(planner, state)
    walk.add(step)
    states, times = planner.step_samples(step)
    np.testing.assert_allclose(walk.times, times)
    assert len(walk.samples) == len(states)
    for a, b in zip(walk.samples[1:], states[1:], strict=True):
        np.testing.assert_array_equal(a.joints_rad, b.joints_rad)
    if overlap:
        assert step.overlap is not None and 0 < step.overlap.lift < len(step.body_path) - 1
        assert len(states) == step.overlap.lift + len(step.swing_path)
    else:
        assert step.overlap is None
        assert len(states) == len(step.body_path) + len(step.swing_path) - 1


def test_the_carried_acceleration_is_the_largest_that_keeps_the_margin():
    """Against a concave margin with a known root: the cap when it holds there, else the
    bisection's lower end within cap / 2^iters of the root, never above it."""
    from planner.motion.time_law import carried_accel_m_s2

    def margin(a):
        return 5.0 - 4.0 * a * a  # >= 1 up to a = 1

    assert carried_accel_m_s2(margin, 0.8, 1.0) == 0.8
    got = carried_accel_m_s2(margin, 1.5, 1.0, iters=10)
    assert 1.0 - 1.5 / 2**10 <= got <= 1.0


def test_a_body_move_on_a_slope_accelerates_only_as_its_feet_can_carry(littledog, monkeypatch):
    """On a 20 degree slope with mu 0.45 the stance has little friction to spare: with a
    3 m/s^2 cap the law lowers some intervals' accelerations (the move takes longer than
    at the cap), and every interval's
    acceleration (from the sample times, constant in each interval) leaves the margin the
    law asks, checked directly with eq. 4 under gravity g - a u (static_feasibility)."""
    from dataclasses import replace

    from planner.body.statics import static_feasibility
    from planner.motion.time_law import CARRIED_SHARE
    from planner.motion.trajectory import Trajectory
    from planner.planning.soft import SoftPlanner
    from planner.world.terrain import Terrain

    slope = Terrain.from_spec(
        {
            "name": "s",
            "friction": 0.45,
            "x_min": -0.5,
            "length": 2.0,
            "kind": "slope",
            "angle_deg": 20.0,
        }  # fmt: skip
    )
    planner = SoftPlanner(littledog, slope)
    tau = Trajectory.straight((0.0, 0.0), (0.5, 0.0), slope, planner.com_height_m())
    state = planner.initial_state((0.0, 0.0), tau)
    for fraction in (1.0, 0.8, 0.6):  # a body move onto three feet (the stride's swing-ready
        # pose is out of reach from some), the law's subject
        step = planner.step(state, 2, tau, fraction * planner.stride_m())
        if step.moved is not None:
            break
    assert step.moved is not None, step.diagnosis
    path = step.body_path
    planner.settings = replace(planner.settings, body_speed_m_s=1.0, body_accel_m_s2=3.0)
    t = np.concatenate([[0.0], planner.body_offsets_s(path)])
    p = np.array([s.base_position_W for s in path])
    ell = np.linalg.norm(np.diff(p, axis=0), axis=1)
    v = [0.0]
    for length, dt in zip(ell, np.diff(t), strict=True):
        v.append(2.0 * length / dt - v[-1])
    v = np.array(v)
    acc = (v[1:] ** 2 - v[:-1] ** 2) / (2.0 * ell)
    assert np.abs(acc).max() <= 3.0 * (1 + 1e-6)
    m = littledog.total_mass_kg
    com = np.array([planner.check.com_W(s) for s in path])
    g = np.array([0.0, 0.0, -9.81])
    need = planner.settings.balance_margin_frac * m * 9.81
    for k, a in enumerate(acc):
        u = (com[k + 1] - com[k]) / np.linalg.norm(com[k + 1] - com[k])
        for j in (k, k + 1):
            s = path[j]

            def marg(grav, s=s, j=j):
                return static_feasibility(
                    s.feet_W, com[j], m, np.flatnonzero(s.in_contact), planner.mu,
                    slope.normal(s.feet_W), grav, with_com_margin=False,
                ).margin_N  # fmt: skip

            floor = max(need, CARRIED_SHARE * marg(g))
            assert marg(g - a * u) >= floor - 1e-6
    # the check binds: without it (every interval at the cap) the move is quicker
    monkeypatch.setattr("planner.motion.time_law.carried_accel_m_s2", lambda margin, cap, need: cap)
    assert planner.body_offsets_s(path)[-1] < t[-1] - 1e-3


def test_feedback_replans_with_the_settings_the_plan_was_made_with():
    """A plan made with a gentler time law and another gait is walked with them (8.3)."""
    from planner.planning.local import LocalSettings
    from planner.planning.walk import plan_walk
    from planner.sim.feedback import _planned_settings

    settings = LocalSettings(body_accel_m_s2=0.2, swing_time_s=0.7, gait=(0, 3, 1, 2))
    plan, report = plan_walk("littledog", "flat", (0.3, 0.0), (0.2, 0.0), settings=settings)
    assert report.ok
    st = _planned_settings(plan)
    assert (st.body_accel_m_s2, st.swing_time_s, tuple(st.gait)) == (0.2, 0.7, (0, 3, 1, 2))
    assert st.step_m == pytest.approx(plan.stats["settings"]["step_m"])


def test_a_move_braking_toward_an_edge_keeps_the_zero_moment_point_inside(littledog):
    """An arrival move on four feet to a COM 25 mm inside the support polygon's front edge,
    at a 1.5 m/s^2 cap: braking, the law slows down (it tipped the robot over that edge in
    MuJoCo at the cap), and at every sample the zero-moment point, computed here by hand
    (COM - h a / g on flat ground), stays inside by the floor the law asks."""
    from dataclasses import replace

    from planner.body.stability import PATH_BALANCE_MARGIN_M, polygon_margin_m
    from planner.motion.time_law import CARRIED_SHARE
    from planner.motion.trajectory import Trajectory
    from planner.planning.soft import SoftPlanner
    from planner.world.terrain import load_terrain

    flat = load_terrain("flat")
    planner = SoftPlanner(littledog, flat)
    planner.settings = replace(planner.settings, body_accel_m_s2=1.5)
    tau = Trajectory.straight((0.3, 0.0), (1.3, 0.0), flat, planner.com_height_m())
    state = planner.initial_state((0.3, 0.0), tau)
    front = float(state.feet_W[:2, 0].min())  # the front feet's edge
    moved = planner.arrival(state, (front - 0.005, 0.0), tau, nearest=True)
    assert moved is not None
    _, path = moved
    t = np.concatenate([[0.0], planner.body_offsets_s(path)])
    com = np.array([planner.check.com_W(s) for s in path])
    ell = np.linalg.norm(np.diff(com, axis=0), axis=1)
    v = [0.0]
    for length, dt in zip(ell, np.diff(t), strict=True):
        v.append(2.0 * length / dt - v[-1])
    v = np.array(v)
    acc = (v[1:] ** 2 - v[:-1] ** 2) / (2.0 * np.maximum(ell, 1e-12))
    assert acc.min() > -1.5 * (1 - 1e-3)  # braking below the cap somewhere
    feet = path[-1].feet_W
    for k, a in enumerate(acc):
        u = (com[k + 1] - com[k]) / max(np.linalg.norm(com[k + 1] - com[k]), 1e-12)
        for j in (k, k + 1):
            h = com[j][2] - feet[:, 2].mean()
            rest = polygon_margin_m(feet, com[j])
            floor = min(rest, max(CARRIED_SHARE * rest, PATH_BALANCE_MARGIN_M))
            zmp = com[j] - h * a * u / 9.81
            assert polygon_margin_m(feet, zmp) >= floor - 2e-4, (k, j)


def test_a_body_move_over_an_edge_goes_no_faster_than_its_clearance_allows(littledog):
    """The same body path over flat ground and with a barrier under its belly whose top
    is 9 mm below the body's lowest point: over the barrier the move takes longer, and in
    every interval the base's mean speed is at most the clearance beyond BODY_CLEARANCE_M
    over BODY_LAG_S (the clearance measured here on a 1 mm grid of the body box's bottom
    face); over flat ground the clearance is ample and the law is the plain one."""
    from planner.motion.time_law import BODY_LAG_S
    from planner.motion.trajectory import Trajectory
    from planner.planning.path_checks import BODY_CLEARANCE_M
    from planner.planning.soft import SoftPlanner
    from planner.world.terrain import Terrain, load_terrain

    flat = load_terrain("flat")
    planner = SoftPlanner(littledog, flat)
    tau = Trajectory.straight((0.2, 0.0), (0.6, 0.0), flat, planner.com_height_m())
    state = planner.initial_state((0.2, 0.0), tau)
    for fraction in (1.0, 0.8, 0.6):  # a body move onto three feet (the stride's swing-ready
        # pose is out of reach from some), the law's subject
        step = planner.step(state, 2, tau, fraction * planner.stride_m())
        if step.moved is not None:
            break
    assert step.moved is not None, step.diagnosis
    path = step.body_path
    lo, hi = littledog.body_box_B
    gx, gy = np.meshgrid(
        np.arange(lo[0], hi[0] + 1e-9, 0.001), np.arange(lo[1], hi[1] + 1e-9, 0.001)
    )
    bottom_B = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, lo[2])])
    bottoms = [bottom_B @ s.base_rotation_W.T + s.base_position_W for s in path]
    mid = path[len(path) // 2].base_position_W
    top = min(float(b[:, 2].min()) for b in bottoms) - 0.009
    barrier = Terrain.from_spec(
        {
            "name": "b",
            "friction": 0.7,
            "x_min": -0.5,
            "length": 2.0,
            "kind": "barrier",
            "x": float(mid[0]) - 0.015,
            "height": top,
            "thickness": 0.03,
        }  # fmt: skip
    )
    t_flat = planner.body_offsets_s(path)
    over = SoftPlanner(littledog, barrier)
    t_over = over.body_offsets_s(path)
    assert t_over[-1] > 1.2 * t_flat[-1]
    gaps = np.array(
        [float((b[:, 2] - barrier.height_sharp(b[:, 0], b[:, 1])).min()) for b in bottoms]
    )
    assert 0.0085 < gaps.min() < 0.0095
    p = np.array([s.base_position_W for s in path])
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(np.concatenate([[0.0], t_over]))
    allowed = (np.minimum(gaps[:-1], gaps[1:]) - BODY_CLEARANCE_M) / BODY_LAG_S
    assert np.all(speed <= allowed * (1 + 1e-6) + 1e-6)
    flat_gaps = np.array([float(b[:, 2].min()) for b in bottoms])
    assert flat_gaps.min() > BODY_CLEARANCE_M + BODY_LAG_S * planner.settings.body_speed_m_s
