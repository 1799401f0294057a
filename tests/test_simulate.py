import json

import numpy as np
import pytest

from planner.cli.main import main
from planner.motion.footholds import MIN_ADVANCE_M
from planner.planfile.plan import Plan, Samples
from planner.planning.walk import plan_walk
from planner.sim.correction import run_corrected, shift_body
from planner.sim.feedback import plan_step_cycles, planned_steps, run_feedback
from planner.sim.measure import Measurement, SimulatedMocap
from planner.sim.simulate import (
    SimSettings,
    Simulator,
    cycle_starts,
    loaded_feet,
    run_open_loop,
    terrain_model,
)
from planner.world.terrain import load_terrain


@pytest.fixture(scope="module")
def short_plan():
    """0.35 m on flat: 12 gait steps, 23 s of plan."""
    plan, report = plan_walk("littledog", "flat", goal_xy=(0.55, 0.0))
    assert plan.outcome["reached_goal"] and report.ok
    return plan


@pytest.fixture(scope="module")
def open_loop(short_plan):
    return run_open_loop(short_plan)


def first_cycles(plan: Plan, n: int) -> Plan:
    """The plan cut after its first n cycles (gait steps)."""
    end = cycle_starts(plan.samples.contact)[n] + 1
    out = Plan.from_dict(plan.to_dict(), source=plan.source)
    s = plan.samples
    out.samples = Samples(s.time[:end].copy(), s.q[:end].copy(), s.contact[:end].copy())
    return out


def test_terrain_becomes_plane_boxes_or_height_field():
    def model(name):
        t = load_terrain(name)
        origin, res, h = t.height_grid(0.0, 1.5, -0.3, 0.3, 0.005)
        from planner.planfile.plan import TerrainGrid

        return terrain_model(TerrainGrid(np.array(origin), res, h), t)

    assert model("flat").kind == "plane"
    step = model("step5cm")
    assert step.kind == "boxes" and len(step.geoms) == 2
    # the edge is placed exactly (x = 0.8), not to within half a grid cell
    lower = step.geoms[0]
    x_c, half = float(lower["pos"].split()[0]), float(lower["size"].split()[0])
    assert x_c + half == pytest.approx(0.8, abs=1e-6)
    assert float(step.geoms[1]["pos"].split()[2]) + float(step.geoms[1]["size"].split()[2]) == (
        pytest.approx(0.05)
    )
    assert model("rough2cm").kind == "hfield"
    assert model("slope10").kind == "hfield"


def test_standing_robot_carries_its_weight_without_creeping(short_plan):
    plan = short_plan
    sim = Simulator(plan.load_robot(), plan.terrain_grid, plan.friction, plan.load_terrain())
    sim.settle(plan.samples.q[0], 1.0)
    feet0 = sim.foot_centres_W()
    for _ in range(int(2.0 / sim.settings.control_dt_s)):
        sim.tick()
    touch = sim.touches()
    assert touch.feet.all() and not touch.body and not touch.legs
    weight = plan.load_robot().total_mass_kg * 9.81
    assert touch.forces[:, 2].sum() == pytest.approx(weight, rel=0.03)
    assert np.abs(sim.foot_centres_W() - feet0).max() < 2e-4  # no soft-contact creep
    # the servos hold the planned pose to a few millimetres
    assert np.linalg.norm(sim.q()[:3] - plan.samples.q[0, :3]) < 0.005
    assert np.abs(sim.joints() - sim.targets()).max() < np.radians(3)


def test_feedforward_removes_the_servo_sag(short_plan):
    """Standing, PD servos sag by tau / kp; a feed-forward of the forces they settle into
    (uniform stiffness: least sum tau^2) removes most of it. (The executor commands the
    effort-weighted distribution, which a four-leg stand settles away from: its use is on
    three legs, planner.body.torques.)"""
    from planner.body.torques import TorqueCheck

    plan = short_plan
    q0 = plan.samples.q[0]
    sag = {}
    for ff in (False, True):
        sim = Simulator(
            plan.load_robot(), plan.terrain_grid, plan.friction, plan.load_terrain(),
            SimSettings(feedforward=ff),
        )  # fmt: skip
        sim._holding = TorqueCheck(sim.robot)
        sim._holding.weights[:] = 1.0  # unweighted: the stiffness distribution
        sim.settle(q0, 1.0)
        sag[ff] = np.abs(sim.joints() - q0[sim._pin_idx]).max()
        tau = sim.holding_torques_nm(q0, np.ones(4, bool))[0]
        assert np.any(tau != 0.0) == ff
    # a hip pitch carries ~0.5 N m: ~1.4 degrees of sag at kp = 20 N m/rad
    assert sag[False] > np.radians(0.5)
    assert sag[True] < 0.3 * sag[False], sag


def test_feet_unload_before_lift_off_and_load_after_touch_down():
    c = np.ones((6, 4), bool)
    c[2:4, 1] = False  # FR lifts after sample 1 and lands at sample 4
    out = loaded_feet(c)
    assert out[:, [0, 2, 3]].all()
    assert out[:, 1].tolist() == [True, False, False, False, False, True]
    # a segment that starts at a touch-down sample knows the sample before it
    before = np.array([True, False, True, True])
    assert loaded_feet(c[4:], before)[:, 1].tolist() == [False, True]


def test_open_loop_short_flat_walk_reaches_without_falling(short_plan, open_loop):
    m = open_loop.metrics
    n = len(short_plan.samples)
    assert m.reached and m.final_error_m < 0.05, m.summary()
    assert not m.fell and not m.tipped and not m.body_contact, m.summary()
    assert m.max_sliding_m < 0.01 and m.max_tilt_error_deg < 5.0, m.summary()
    assert m.ok and m.cycles == len(set(cycle_starts(short_plan.samples.contact)) - {n - 1})
    assert m.saturation_frac < 0.05  # the 0.6 N m knees are enough for this walk


def test_three_leg_servo_loads_are_measured_against_statics(short_plan, open_loop):
    """On three legs the servos carry at least what statics needs: the largest load the run
    reports is no less than the least achievable ratio (any admissible forces, Clarabel) at
    the plan's three-leg samples, and no more than the effort limit; the excess over the
    feed-forward is part of it."""
    from planner.body.torques import TorqueCheck

    m = open_loop.metrics
    tc = TorqueCheck(short_plan.load_robot())
    s = short_plan.samples
    three = [k for k in range(len(s)) if s.contact[k].sum() == 3]
    up = np.tile([0.0, 0.0, 1.0], (4, 1))
    least = max(tc.solve(s.q[k], np.flatnonzero(s.contact[k]), 0.7, up).ratio for k in three)
    assert 0.2 < least < 1.0
    assert 0.95 * least <= m.max_three_leg_load <= 1.0 + 1e-9, m.summary()
    assert 0.0 < m.max_load_over_plan < m.max_three_leg_load, m.summary()
    assert "on three legs up to" in m.summary()


def test_executed_motion_is_a_plan_file(open_loop, tmp_path):
    path = open_loop.executed.save(tmp_path / "sim.json")
    back = Plan.load(path)
    s = back.samples
    assert s.q.shape[1] == 19 and len(s) > 100
    assert s.time[-1] == pytest.approx(open_loop.metrics.sim_time_s, abs=0.1)
    assert s.contact.all(axis=1).mean() > 0.3 and (s.contact.sum(axis=1) >= 3).mean() > 0.95
    assert len(back.keyframes) == open_loop.metrics.cycles
    assert back.stats["simulation"]["mode"] == "open loop"
    kf = back.keyframes[0]
    assert kf.forces[:, 2].sum() == pytest.approx(3.004 * 9.81, rel=0.05)


def test_body_moved_outside_its_support_tips_the_robot(short_plan):
    # 5 cm to the left: when a left leg lifts, the COM is outside the other three feet
    bad = shift_body(first_cycles(short_plan, 3), [0.0, 0.05, 0.0])
    m = run_open_loop(bad).metrics
    assert not m.ok
    assert m.tipped and m.max_tilt_error_deg > 15.0, m.summary()
    assert m.fell or m.swing_touch_s > 0.0 or m.slipped, m.summary()
    assert "tipped" in m.message or "fell" in m.message


def test_precompute_then_correct_tracks_the_plan_end(short_plan, open_loop):
    res = run_corrected(short_plan)
    m = res.metrics
    assert m.ok and m.ik_misses == 0, m.summary()
    # both end within a centimetre: the plan's rolling feet are what MuJoCo does
    assert m.final_error_m < 0.01 and open_loop.metrics.final_error_m < 0.01


def test_feedback_replans_from_noisy_late_measurements(short_plan):
    # six cycles of re-planning from mocap with 1 mm / 0.1 deg noise and 20 ms latency
    res = run_feedback(
        short_plan,
        max_cycles=6,
        position_noise_m=0.001,
        angle_noise_rad=0.002,
        latency_s=0.02,
        seed=1,
    )
    m = res.metrics
    assert m.cycles == 6 and res.executed.stats["feedback"]["steps"] >= 5, m.summary()
    assert not (m.fell or m.tipped or m.slipped or m.body_contact), m.summary()
    assert m.com_to_goal_m < 0.35 - 0.1  # the COM came at least 10 cm closer to the goal
    assert "max_cycles" in m.message


def test_mocap_noise_and_latency(short_plan):
    plan = first_cycles(short_plan, 1)
    sim = Simulator(plan.load_robot(), plan.terrain_grid, plan.friction)
    sim.settle(plan.samples.q[0], 0.2)
    mocap = SimulatedMocap(sim, position_noise_m=0.002, latency_s=0.05, seed=3)
    for _ in range(50):
        sim.tick()
    meas = mocap.measure()
    assert isinstance(meas, Measurement) and meas.contact.all()
    assert sim.time - meas.time_s == pytest.approx(0.05, abs=sim.settings.control_dt_s)
    assert 0 < np.linalg.norm(meas.q[:3] - sim.q()[:3]) < 0.02
    with pytest.raises(ValueError, match="latency_s"):
        SimulatedMocap(sim, latency_s=-1.0)


def test_cli_simulate_writes_the_executed_motion(short_plan, tmp_path, capsys):
    src = first_cycles(short_plan, 2).save(tmp_path / "plan.json")
    out = tmp_path / "sim.json"
    rc = main(["simulate", str(src), "--time-scale", "3", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "mode open loop: OK" in text and "max stance-foot slip" in text
    sim = json.loads(out.read_text())
    assert sim["format"] == "stratawalk.plan/1"
    assert sim["stats"]["settings"]["time_scale"] == 3.0


@pytest.mark.parametrize(
    "content, expect",
    [("hello, not a plan\n", "not JSON"), ('{"a": 1}', "format")],
)
def test_cli_simulate_bad_input_is_one_line_error(tmp_path, capsys, content, expect):
    bad = tmp_path / "bad.json"
    bad.write_text(content)
    assert main(["simulate", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "bad.json" in err and expect in err


def test_settings_are_checked():
    with pytest.raises(ValueError, match="time_scale"):
        SimSettings(time_scale=0.0).check()


def test_feedback_backs_off_instead_of_giving_up(short_plan, monkeypatch):
    """Every full-stride step fails from the measured state: half steps carry the walk on."""
    from planner.planning.local import LocalPlanner

    real = LocalPlanner.step
    tried = []

    def step(self, state, leg, tau, step_m, shrink=None, target_W=None, try_others=True, **kw):
        tried.append(step_m)
        if step_m > 0.6 * self.stride_m():  # the plan's footholds too (a full stride)
            out = real(self, state, leg, tau, step_m, shrink, target_W, try_others, **kw)
            out.ok, out.moved, out.end, out.phase = False, None, None, "body_move"
            out.diagnosis = "refused by the test"
            return out
        return real(self, state, leg, tau, step_m, shrink, target_W, try_others, **kw)

    monkeypatch.setattr(LocalPlanner, "step", step)
    res = run_feedback(short_plan, max_cycles=4, correct_plan_steps=False)
    m = res.metrics
    assert m.replans == 0 and res.executed.stats["feedback"]["steps"] == 4, m.summary()
    assert not (m.fell or m.tipped), m.summary()
    full = max(tried)
    assert any(abs(s - 0.5 * full) < 1e-12 for s in tried)  # the first back-off: half a stride


def test_planned_steps_are_the_plans_swings_and_landings(short_plan):
    steps = planned_steps(short_plan)
    swings = [kf for kf in short_plan.keyframes if kf.stratum != 0]
    assert len(steps) == len(swings) == short_plan.stats["steps"]
    assert [leg for leg, _ in steps[:4]] == [2, 0, 3, 1]  # the crawl: HL, FL, HR, FR
    for (leg, foot), kf in zip(steps, swings, strict=True):
        assert kf.stratum == leg + 1 and leg + 1 not in kf.support
        moved = np.linalg.norm(foot[:2] - kf.feet[leg][:2])  # the swing keyframe: lifted
        # forward (a stride, or a shorter step: at least min_step_fraction of it), grounded
        assert MIN_ADVANCE_M < moved < 0.12 and abs(foot[2]) < 1e-3


def test_plan_step_cycles_hold_each_planned_swing(short_plan):
    """Step j's samples run from step j-1's touchdown to its own, lifting only its leg."""
    steps, cycles = planned_steps(short_plan), plan_step_cycles(short_plan)
    assert cycles is not None and len(cycles) == len(steps)
    c = short_plan.samples.contact
    assert cycles[0][0] == 0
    for (a, b), (a2, _), (leg, _) in zip(cycles, cycles[1:] + [(None, None)], steps, strict=True):
        assert c[a].all() and c[b].all() and (a2 is None or a2 == b)
        lifted = np.flatnonzero(~c[a : b + 1].all(axis=0))
        assert list(lifted) == [leg]


def refuse_steps(monkeypatch, phase: str, plans_foothold_only: bool) -> None:
    """Every step planned anew fails in ``phase`` (only those onto a given foothold, the
    plan's, with ``plans_foothold_only``), nothing moved."""
    from planner.planning.local import LocalPlanner

    real = LocalPlanner.step

    def step(self, state, leg, tau, step_m, shrink=None, target_W=None, try_others=True, **kw):
        out = real(self, state, leg, tau, step_m, shrink, target_W, try_others, **kw)
        if target_W is not None or not plans_foothold_only:
            out.ok, out.moved, out.end, out.phase = False, None, None, phase
            out.diagnosis = "refused by the test"
        return out

    monkeypatch.setattr(LocalPlanner, "step", step)


def test_feedback_falls_back_on_the_plans_step_corrected(short_plan, monkeypatch):
    """No body move from the measured state reaches the plan's foothold: the plan's own step,
    corrected from the measurement (8.4), carries the walk on, landing on that foothold;
    where the corrected step keeps less than 25 mm of balance margin (short_plan's second
    step lifts with 24 mm) it is refused and the step is planned anew."""
    refuse_steps(monkeypatch, "body_move", plans_foothold_only=True)
    res = run_feedback(short_plan, max_cycles=4, plan_steps_first=False)
    m, fb = res.metrics, res.executed.stats["feedback"]
    assert fb["steps"] == 4 and m.ik_misses == 0, m.summary()
    corrected = [f["cycle"] - 1 for f in fb["planner_failures"] if "corrected" in f["why"]]
    assert fb["plan_steps_corrected"] == len(corrected) == 3 and 1 not in corrected
    assert not (m.fell or m.tipped), m.summary()
    kfs = res.executed.keyframes  # measured at the start of each cycle
    for k in corrected[:2]:
        leg, foot = planned_steps(short_plan)[k]
        landed = kfs[k + 1].feet[leg]
        assert np.linalg.norm(landed[:2] - foot[:2]) < 0.015, (k, landed, foot)


def test_feedback_takes_the_plans_step_at_the_path_margin_when_nothing_else_steps(
    short_plan, monkeypatch
):
    """No step planned anew at all (every foothold refused): rather than a failed cycle
    that leaves the plan, the plan's own step, corrected (8.4), is held to the 20 mm the
    plan's path samples keep; short_plan's second step (24 mm, under the fallback's usual
    25 mm) runs so, landing on the plan's foothold."""
    refuse_steps(monkeypatch, "foot_placement", plans_foothold_only=False)
    res = run_feedback(short_plan, max_cycles=4, plan_steps_first=False)
    m, fb = res.metrics, res.executed.stats["feedback"]
    assert fb["steps"] == fb["plan_steps_corrected"] == 4, fb
    assert not (m.fell or m.tipped), m.summary()
    last_resort = [f["cycle"] for f in fb["planner_failures"] if "20 mm" in f["why"]]
    assert last_resort == [2], fb["planner_failures"]
    kfs = res.executed.keyframes
    for k, (leg, foot) in enumerate(planned_steps(short_plan)[:3]):
        assert np.linalg.norm(kfs[k + 1].feet[leg][:2] - foot[:2]) < 0.015, k


def test_feedback_follows_the_plans_footholds(short_plan):
    """From the measured state, each step is re-planned onto the plan's own foothold."""
    res = run_feedback(short_plan, max_cycles=4, plan_steps_first=False)
    fb = res.executed.stats["feedback"]
    assert fb["plan_steps_followed"] == 4 and fb["plan_steps"] == len(planned_steps(short_plan))
    kfs = res.executed.keyframes  # measured at the start of each cycle
    for k, (leg, foot) in enumerate(planned_steps(short_plan)[:3]):
        landed = kfs[k + 1].feet[leg]
        assert np.linalg.norm(landed[:2] - foot[:2]) < 0.015, (k, landed, foot)


def test_feedback_executes_the_plans_own_steps_corrected_first(short_plan, monkeypatch):
    """With plan_steps_first each plan step is the plan's own, corrected from the measurement (8.4),
    where the corrected step passes its gates (short_plan's second step lifts with 24 mm of
    balance margin, under the 25 mm asked: planned anew onto the plan's foothold); with no
    gate passing (a balance margin of 1 m asked) every step is planned anew."""
    import planner.body.stability

    res = run_feedback(short_plan, max_cycles=4, plan_steps_first=True)
    m, fb = res.metrics, res.executed.stats["feedback"]
    assert fb["steps"] == 4 and not (m.fell or m.tipped), m.summary()
    assert fb["plan_steps_corrected"] == 3 and fb["plan_steps_followed"] == 1, fb
    kfs = res.executed.keyframes  # measured at the start of each cycle
    for k, (leg, foot) in enumerate(planned_steps(short_plan)[:3]):
        landed = kfs[k + 1].feet[leg]
        assert np.linalg.norm(landed[:2] - foot[:2]) < 0.015, (k, landed, foot)
    monkeypatch.setattr(planner.body.stability, "BALANCE_MARGIN_M", 1.0)
    res = run_feedback(short_plan, max_cycles=2, plan_steps_first=True)
    fb = res.executed.stats["feedback"]
    assert fb["plan_steps_corrected"] == 0 and fb["plan_steps_followed"] == 2, fb


@pytest.mark.parametrize("gate", ["balance", "links", "path"])
def test_a_corrected_plan_step_that_fails_a_gate_is_not_executed(short_plan, monkeypatch, gate):
    """The fallback refuses a corrected step whose COM nears a support edge, whose leg links
    dip into the terrain, or that fails the check of a path planned anew: nothing is executed
    and the caller goes on replanning."""
    import planner.body.links
    import planner.body.stability
    from planner.planning.local import LocalPlanner
    from planner.planning.soft import SoftPlanner
    from planner.sim.correction import _follow_corrected
    from planner.sim.simulate import new_run

    robot, terrain = short_plan.load_robot(), short_plan.load_terrain()
    local = SoftPlanner(robot, terrain, mu=short_plan.friction)
    checked = []
    real_problem = LocalPlanner.path_problem

    def counted(self, path):
        checked.append(len(path))
        return real_problem(self, path)

    monkeypatch.setattr(LocalPlanner, "path_problem", counted)
    if gate == "balance":  # no support triangle holds the COM 1 m inside it
        monkeypatch.setattr(planner.body.stability, "BALANCE_MARGIN_M", 1.0)
    elif gate == "path":  # e.g. a joint past its torque margin on the corrected samples
        monkeypatch.setattr(LocalPlanner, "path_problem", lambda self, path: "torque")
    else:  # after the first sample every link 1 m inside the terrain
        real = planner.body.links.LegLinks.path_margin
        calls = []

        def deeper(self, terrain, q, swing_legs=(), scale=1.0):
            calls.append(1)
            return real(self, terrain, q, swing_legs, scale) - 1.0 * (len(calls) > 1)

        monkeypatch.setattr(planner.body.links.LegLinks, "path_margin", deeper)
    sim, ex = new_run(short_plan, None, "feedback")
    a, b = plan_step_cycles(short_plan)[0]
    t0 = sim.time
    refused = []
    got = _follow_corrected(
        ex, SimulatedMocap(sim).measure(), robot, terrain, short_plan.samples,
        short_plan.foot_centres_W(), a, b, sim, local, refused,
    )  # fmt: skip
    assert got is None and sim.time == t0
    words = {"balance": "inside its support", "links": "deeper", "path": "torque"}
    assert len(refused) == 1 and words[gate] in refused[0], refused
    monkeypatch.undo()  # without the violation the same step runs, checked as a planned path
    monkeypatch.setattr(LocalPlanner, "path_problem", counted)
    assert _follow_corrected(
        ex, SimulatedMocap(sim).measure(), robot, terrain, short_plan.samples,
        short_plan.foot_centres_W(), a, b, sim, local,
    ) is True and sim.time > t0  # fmt: skip
    assert checked and checked[-1] in (b - a + 1, b - a + 2)  # with a hold sample or not


def test_a_corrected_step_brings_the_body_back_at_the_planners_body_speed(short_plan, monkeypatch):
    """A body measured 5 cm off the plan against its feet (8.4) is brought back over a
    four-feet hold no shorter than the body-move time law's rest-to-rest time for 5 cm,
    not in the plan's own four-feet phase (barrier75mm's body, 2.8 cm off, was pulled back
    in 0.2 s and the robot tipped and fell); measured on the plan, no hold is added."""
    import planner.body.stability
    from planner.body.kinematics import hip_point_B
    from planner.planning.local import BODY_ACCEL_M_S2
    from planner.sim.correction import (
        _correction_time_s,
        _follow_corrected,
        _four_feet_span_s,
        shift_body,
    )
    from planner.sim.simulate import new_run

    robot, terrain, s = short_plan.load_robot(), short_plan.load_terrain(), short_plan.samples
    zero = np.zeros(3)
    assert _correction_time_s(robot, zero, zero) < 1e-3
    off = 0.05
    need = _correction_time_s(robot, np.array([off, 0.0, 0.0]), zero)
    assert need == pytest.approx(2.0 * np.sqrt(off / BODY_ACCEL_M_S2))  # below the speed cap
    lever = max(np.linalg.norm(hip_point_B(leg)) for leg in robot.legs)  # a turn at the hips
    turn = _correction_time_s(robot, zero, np.array([0.0, 0.0, 0.3]))
    assert turn == pytest.approx(2.0 * np.sqrt(0.3 * lever / BODY_ACCEL_M_S2))
    a, b = plan_step_cycles(short_plan)[1]
    times = s.time[a : b + 1]
    span = _four_feet_span_s(times, s.contact[a : b + 1])
    assert 0.0 < span < need
    sim, ex = new_run(short_plan, None, "feedback")
    followed = []
    monkeypatch.setattr(ex, "follow", lambda t, q, contact: followed.append((t, q)) or True)
    monkeypatch.setattr(planner.body.stability, "BALANCE_MARGIN_M", -1.0)  # timing only here
    shifted = shift_body(short_plan, [off, 0.0, 0.0])  # the same feet, the body 5 cm ahead
    centres = short_plan.foot_centres_W()
    for q_meas, hold in ((shifted.samples.q[a], need - span), (s.q[a], 0.0)):
        meas = Measurement(0.0, q_meas.copy(), np.ones(4, bool))
        assert _follow_corrected(ex, meas, robot, terrain, s, centres, a, b, sim) is True
        t, q = followed[-1]
        assert t[-1] - t[0] == pytest.approx(times[-1] - times[0] + hold, abs=1e-9)
        assert len(t) == len(times) + (hold > 0.0)
        np.testing.assert_allclose(q[0, :3], q_meas[:3], atol=1e-6)  # from the measured body
        np.testing.assert_allclose(q[-1, :3], s.q[b, :3], atol=2e-3)  # to the plan's


def test_a_correction_keeps_a_leg_on_the_plans_other_knee(short_plan):
    """8.4 of a plan where a leg stands on its other knee branch (as the planner lands a
    leg beside an edge): measured exactly at the plan's first sample, the correction
    reproduces the plan's joints; with the leg's default branch it had flipped the knee
    (barrier75mm: the FR shank 33 mm into the barrier)."""
    from planner.body.kinematics import kinematics_of
    from planner.core.lie import rotation_from_quat
    from planner.sim.correction import correct_cycle

    robot, s = short_plan.load_robot(), short_plan.samples
    kin = kinematics_of(robot)
    a, b = plan_step_cycles(short_plan)[1]
    q_plan, contact = s.q[a : b + 1].copy(), s.contact[a : b + 1]
    centres = short_plan.foot_centres_W()[a : b + 1]
    flipped = []
    for leg in range(4):  # a leg whose other branch stays within its limits all along
        other = -robot.legs[leg].knee_direction
        q_leg = q_plan.copy()
        for k, qk in enumerate(q_plan):  # the leg on its other branch, the same foot centres
            R, joints = rotation_from_quat(qk[3:7]), robot.joints_from_q(qk)
            res = kin.ik_leg(leg, R.T @ (centres[k, leg] - qk[:3]), joints[leg], knee=other)
            if not res.reachable or res.knee_flipped:
                break
            joints[leg] = res.joints_rad
            q_leg[k] = robot.q_from(qk[:3], qk[3:7], joints)
        else:
            flipped.append(leg)
            q_plan = q_leg
            break
    assert flipped, "no leg can stand on its other knee here"
    meas = Measurement(0.0, q_plan[0].copy(), np.ones(4, bool))
    q, misses = correct_cycle(robot, q_plan, contact, centres, meas, s.time[a : b + 1])
    assert misses == 0
    np.testing.assert_allclose(q[:, 7:], q_plan[:, 7:], atol=1e-6)


def test_feedback_replans_the_rest_when_the_plans_steps_fail(short_plan, monkeypatch):
    """Every step fails from the measured state until the rest of the walk is planned anew
    from it (8.3): the walk then follows the new plan's steps onto its footholds."""
    import planner.sim.feedback as feedback
    from planner.planning.local import LocalPlanner

    real_step, real_replan = LocalPlanner.step, feedback.replan_rest
    made = []

    def step(self, *args, **kw):
        out = real_step(self, *args, **kw)
        if not made:  # refused until the re-plan
            out.ok, out.moved, out.end, out.phase = False, None, None, "body_move"
            out.diagnosis = "refused by the test"
        return out

    def replan(*args):
        made.append(1)
        new = real_replan(*args)
        made.append(new)
        return new

    monkeypatch.setattr(LocalPlanner, "step", step)
    monkeypatch.setattr(feedback, "replan_rest", replan)
    res = run_feedback(short_plan, max_cycles=8, correct_plan_steps=False)
    m, fb = res.metrics, res.executed.stats["feedback"]
    new = made[1]
    assert new is not None and fb["replans"] == [len(planned_steps(new))] and fb["replans"][0] > 4
    assert fb["steps"] == 6 and fb["plan_steps_followed"] == 6, m.summary()
    assert not (m.fell or m.tipped), m.summary()
    kfs = res.executed.keyframes  # measured at the start of each cycle
    for k, (leg, foot) in enumerate(planned_steps(new)[:5]):  # onto the new plan's footholds
        landed = kfs[k + 1].feet[leg]
        assert np.linalg.norm(landed[:2] - foot[:2]) < 0.015, (k, landed, foot)


def test_feedback_replans_again_once_the_plans_steps_were_left(short_plan, monkeypatch):
    """The first re-plan stops short (None): the plan's steps are left and the gait queue
    steps; when its steps fail too, the rest is planned anew once more (REPLANS = 2; the
    second was never used: barrier9cm's recursive plan stalled 127 cm short so) and the
    walk follows that plan's steps."""
    import planner.sim.feedback as feedback
    from planner.planning.local import LocalPlanner

    real_step, real_replan = LocalPlanner.step, feedback.replan_rest
    made = []

    def step(self, *args, **kw):
        out = real_step(self, *args, **kw)
        if len(made) < 2:  # refused until the second re-plan
            out.ok, out.moved, out.end, out.phase = False, None, None, "body_move"
            out.diagnosis = "refused by the test"
        return out

    def replan(*args):
        made.append(None)  # (the re-plan's own steps are not refused)
        if len(made) == 2:
            made[-1] = real_replan(*args)
        return made[-1]

    monkeypatch.setattr(LocalPlanner, "step", step)
    monkeypatch.setattr(feedback, "replan_rest", replan)
    res = run_feedback(short_plan, max_cycles=6, correct_plan_steps=False)
    m, fb = res.metrics, res.executed.stats["feedback"]
    assert len(made) == 2 and made[1] is not None, made
    assert fb["replans"] == [0, len(planned_steps(made[1]))], fb
    assert fb["steps"] == 3 and fb["plan_steps_followed"] == 3, fb  # cycles 4-6
    assert not (m.fell or m.tipped), m.summary()


def test_a_replan_is_followed_only_when_it_reaches_the_goal(short_plan, monkeypatch):
    """replan_rest plans from a given state to the goal; where the soft planner stops short
    the recursive one is asked; a re-plan that stops short (its own dead end) is not
    returned, so feedback does not walk into it. From the plan's state after its fourth
    step, as feedback re-plans mid-walk: the rest of the walk, some six steps."""
    from planner.motion.trajectory import Trajectory
    from planner.planning.local import LocalPlanner
    from planner.planning.soft import SoftPlanner
    from planner.sim.feedback import _planned_settings, replan_rest

    robot, terrain = short_plan.load_robot(), short_plan.load_terrain()
    st = _planned_settings(short_plan)
    kfs = short_plan.keyframes
    landed = [k for k in range(1, len(kfs)) if kfs[k].stratum == 0 and kfs[k - 1].stratum != 0]
    start = short_plan.keyframe_states()[landed[3]]
    goal = short_plan.goal[:2]
    tau = Trajectory.straight(short_plan.start[:2], goal, terrain, 0.15)
    new = replan_rest(robot, terrain, short_plan.friction, st, start, goal, tau)
    assert new is not None and new.outcome["reached_goal"] and len(planned_steps(new)) > 4
    np.testing.assert_allclose(new.keyframes[0].base_position, start.base_position_W)
    real = LocalPlanner.plan
    asked = []

    def short(self, *args, **kw):
        res = real(self, *args, **kw)
        asked.append(self.name)
        res.reached_goal = res.reached_goal and self.name not in stalls
        return res

    monkeypatch.setattr(LocalPlanner, "plan", short)
    assert "plan" not in SoftPlanner.__dict__  # (both planners run LocalPlanner.plan)
    stalls = {"soft"}
    new = replan_rest(robot, terrain, short_plan.friction, st, start, goal, tau)
    assert asked == ["soft", "recursive"] and new is not None and new.outcome["reached_goal"]
    stalls = {"soft", "recursive"}
    assert replan_rest(robot, terrain, short_plan.friction, st, start, goal, tau) is None


def test_planned_body_poses_are_the_plans_at_each_step(short_plan):
    """Each step's body pose is one the plan passes in that step (the swing keyframe's),
    with every foot on the ground where that step starts (the Theta2 hint of feedback)."""
    from planner.sim.feedback import planned_body_poses

    steps, poses = planned_steps(short_plan), planned_body_poses(short_plan)
    cycles, s = plan_step_cycles(short_plan), short_plan.samples
    centres = short_plan.foot_centres_W()
    rho = short_plan.load_robot().foot_radius_m
    assert len(poses) == len(steps)
    for (leg, _), pose, (a, b) in zip(steps, poses, cycles, strict=True):
        assert pose.stratum == leg + 1  # a sample of the step has the pose's base
        d = np.linalg.norm(s.q[a : b + 1, :3] - pose.base_position_W, axis=1)
        assert d.min() < 1e-9
        # the feet: contact points under the step's first sample's sphere centres
        np.testing.assert_allclose(pose.feet_W[:, :2], centres[a, :, :2], atol=0.01)
        np.testing.assert_allclose(pose.feet_W[:, 2], centres[a, :, 2] - rho, atol=0.005)


def test_a_correction_turns_the_body_from_its_measured_attitude(short_plan):
    """8.4 from a body yawed 12 degrees and 8 mm off the plan's (feet where planned): the
    corrected base starts at the measured pose, reaches the plan's when the first leg
    lifts, and the stance feet stay on their measured centres throughout."""
    from planner.core.lie import quat_from_rotation, rotation_from_quat, rotation_from_vector
    from planner.sim.correction import correct_cycle
    from planner.sim.measure import _foot_centres

    robot, s = short_plan.load_robot(), short_plan.samples
    a, b = plan_step_cycles(short_plan)[1]
    q_plan, contact = s.q[a : b + 1], s.contact[a : b + 1]
    centres = short_plan.foot_centres_W()[a : b + 1]
    # the measured robot: the plan's first sample, base turned about its own centre
    R = rotation_from_vector([0.0, 0.0, np.radians(12.0)]) @ rotation_from_quat(q_plan[0, 3:7])
    p = q_plan[0, :3] + np.array([0.0, 0.008, 0.0])
    from planner.body.kinematics import kinematics_of

    kin = kinematics_of(robot)
    ik = [kin.ik_leg(i, R.T @ (centres[0, i] - p)) for i in range(4)]
    assert all(r.reachable for r in ik)
    meas_q = robot.q_from(p, quat_from_rotation(R), np.array([r.joints_rad for r in ik]))
    meas = Measurement(0.0, meas_q, np.ones(4, bool))
    q, misses = correct_cycle(robot, q_plan, contact, centres, meas, s.time[a : b + 1])
    assert misses == 0
    np.testing.assert_allclose(q[0, :3], p, atol=1e-9)
    assert np.degrees(np.arccos(np.clip(abs(q[0, 3:7] @ meas_q[3:7]), 0, 1))) * 2 < 1e-3
    lift = int(np.flatnonzero(~contact.all(axis=1))[0])
    np.testing.assert_allclose(q[lift - 1 :, 3:7], q_plan[lift - 1 :, 3:7], atol=1e-12)
    for k in range(lift):  # the corrected joints keep the stance feet where they stand
        np.testing.assert_allclose(_foot_centres(robot, q[k]), centres[k], atol=1e-6)


def test_a_correction_moves_the_body_toward_a_foot_out_of_reach(short_plan, monkeypatch):
    """8.4 from a stance foot measured behind the plan's (FR, in the cycle where HR swings),
    the least offset of 30-60 mm for which the plan's body, shifted by the feet's mean
    offset, leaves FR out of reach (barrier9cm's recursive plan, HR stretched: refused, the
    walk left the plan and stalled). The corrected body moves toward it by one offset (at
    most REACH_SHIFT_M), taken on over the four-feet phase from the measured pose, and FK of
    the corrected joints puts the stance feet on their measured centres plus the plan's
    rolling."""
    import planner.sim.correction as correction
    from planner.body.kinematics import kinematics_of
    from planner.core.lie import rotation_from_quat
    from planner.sim.correction import REACH_SHIFT_M, correct_cycle
    from planner.sim.measure import _foot_centres

    robot, s = short_plan.load_robot(), short_plan.samples
    kin = kinematics_of(robot)
    cycles = plan_step_cycles(short_plan)
    (a, b), leg = cycles[2], 1
    q_plan, contact = s.q[a : b + 1], s.contact[a : b + 1]
    assert contact[:, leg].all() and not contact[:, 3].all()  # FR stands while HR swings
    centres = short_plan.foot_centres_W()[a : b + 1]
    R0, times = rotation_from_quat(q_plan[0, 3:7]), s.time[a : b + 1]
    for offset_m in np.arange(0.030, 0.0601, 0.002):
        joints = robot.joints_from_q(q_plan[0]).copy()
        ik = kin.ik_leg(leg, R0.T @ (centres[0, leg] - [offset_m, 0.0, 0.0] - q_plan[0, :3]))
        assert ik.reachable  # the measured robot stands so
        joints[leg] = ik.joints_rad
        meas_q = robot.q_from(q_plan[0, :3], q_plan[0, 3:7], joints)
        meas = Measurement(0.0, meas_q, np.ones(4, bool))
        monkeypatch.setattr(correction, "REACH_SHIFT_M", 0.0)
        q_plain, plain_misses = correct_cycle(robot, q_plan, contact, centres, meas, times)
        monkeypatch.undo()
        if plain_misses > 0:
            break
    assert plain_misses > 0, "no offset up to 60 mm leaves FR out of reach"
    q, misses = correct_cycle(robot, q_plan, contact, centres, meas, times)
    assert misses == 0, (offset_m, plain_misses, misses)
    shift = q[:, :3] - q_plain[:, :3]
    np.testing.assert_allclose(shift[0], 0.0, atol=1e-12)  # starts at the measured base
    lift = int(np.flatnonzero(~contact.all(axis=1))[0])
    np.testing.assert_allclose(shift[lift - 1 :] - shift[-1], 0.0, atol=1e-12)  # then one offset
    assert 0.0 < np.linalg.norm(shift[-1]) <= REACH_SHIFT_M + 1e-12
    c_meas = _foot_centres(robot, meas.q)
    for k in range(len(q)):
        got = _foot_centres(robot, q[k])
        for i in np.flatnonzero(contact.all(axis=0)):  # the legs that stand all cycle
            want = centres[k, i] + c_meas[i] - centres[0, i]
            np.testing.assert_allclose(got[i], want, atol=1e-6, err_msg=f"sample {k} leg {i}")


def test_a_corrected_swing_keeps_the_plans_joints_where_ik_leaves_them(short_plan, monkeypatch):
    """8.4 re-solves a swing sample by IK; where IK answers with another solution than the
    plan's (step10cm's recursive plan: the HR knee 66 degrees off, the foot on the step's
    edge, a fall) the swing leg keeps the plan's joints; small corrections are IK's."""
    from planner.body.kinematics import kinematics_of
    from planner.sim.correction import SWING_JUMP_RAD, correct_cycle

    robot, s = short_plan.load_robot(), short_plan.samples
    a, b = plan_step_cycles(short_plan)[1]
    q_plan, contact = s.q[a : b + 1], s.contact[a : b + 1]
    centres = short_plan.foot_centres_W()[a : b + 1]
    meas_q = q_plan[0].copy()
    meas_q[0] += 0.004  # the measured body 4 mm ahead: every sample is corrected a little
    meas = Measurement(0.0, meas_q, np.ones(4, bool))
    leg = int(np.flatnonzero(~contact.all(axis=0))[0])  # the leg that swings in the cycle
    air = np.flatnonzero(~contact[:, leg])[1:-1]
    q, misses = correct_cycle(robot, q_plan, contact, centres, meas, s.time[a : b + 1])
    plan_j = np.array([robot.joints_from_q(qk)[leg] for qk in q_plan])
    got_j = np.array([robot.joints_from_q(qk)[leg] for qk in q])
    assert misses == 0 and 0.0 < np.abs(got_j[air] - plan_j[air]).max() < SWING_JUMP_RAD
    kin = kinematics_of(robot)
    real = kin.ik_leg

    def other_solution(i, target, *args, **kw):  # a knee wrapped by 1 rad mid-swing
        res = real(i, target, *args, **kw)
        if i == leg:
            res.joints_rad = res.joints_rad + np.array([0.0, 0.0, 1.0])
        return res

    monkeypatch.setattr(kin, "ik_leg", other_solution)
    q, _ = correct_cycle(robot, q_plan, contact, centres, meas, s.time[a : b + 1])
    got_j = np.array([robot.joints_from_q(qk)[leg] for qk in q])
    np.testing.assert_array_equal(got_j[air], plan_j[air])


def test_a_feedback_run_that_executes_nothing_ends_standing(short_plan, monkeypatch):
    """No step succeeds from the measured state and the plan's steps are not corrected:
    the run stops stuck, judged on the settled start it held (it raised an IndexError from
    the monitor's empty reference), and says so in one line."""
    import planner.sim.feedback as feedback
    from planner.planning.local import LocalPlanner

    real = LocalPlanner.step

    def step(self, *args, **kw):
        out = real(self, *args, **kw)
        out.ok, out.moved, out.end, out.phase = False, None, None, "foot_placement"
        out.diagnosis = "refused by the test"
        return out

    monkeypatch.setattr(LocalPlanner, "step", step)
    monkeypatch.setattr(feedback, "replan_rest", lambda *a: None)
    res = run_feedback(short_plan, max_cycles=4, correct_plan_steps=False)
    m, fb = res.metrics, res.executed.stats["feedback"]
    assert fb["steps"] == 0 and not (m.fell or m.tipped), m.summary()
    assert not m.reached and "stopped after 4 cycles" in m.message, m.message
    assert len(res.executed.samples) >= 2  # the held start, recorded
