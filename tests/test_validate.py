"""The independent plan validator (`stratawalk check`), on real short plans."""

import io

import numpy as np
import pytest

from planner.body.kinematics import kinematics_of
from planner.body.links import LegLinks, leg_links
from planner.body.rolling import end_keyframe
from planner.motion.interpolate import interpolate_leaf, interpolate_swing
from planner.planfile.plan import Plan
from planner.planfile.validate import (
    CheckTolerances,
    check_plan,
    contact_points_from_centres,
    main_check,
    sharp_surface_distance,
)
from planner.problems import Theta2, Theta3, Theta4
from planner.world.terrain import load_terrain

N = 12  # samples per leaf
OUTCOME = {"reached_goal": True, "distance_to_goal": 0.0, "message": "test plan"}


def make_plan(dog, terrain_name, x, step_m, land_x=None):
    """Place the dog, move the COM over legs 2-4 on S0, swing leg 1 ``step_m`` ahead.

    ``land_x``: swing leg 1 to this x instead (world frame, metres).
    """
    terrain = load_terrain(terrain_name)
    z = float(terrain.height(x, 0.0)) + 0.15
    a = Theta4(dog, terrain).solve([x, 0.0, z], [1, 0, 0], [0, 0, 1]).state
    rc = a.feet_W[[1, 2, 3]].mean(axis=0) + [0.0, 0.0, 0.15]
    b = Theta2(dog, terrain, support=(1, 2, 3)).solve(a, rc, [1, 0, 0], [0, 0, 1]).state
    if land_x is not None:
        step_m = land_x - b.feet_W[0][0]
    theta3 = Theta3(dog, terrain, leg=0)  # started at the current foot, not at the target
    placed = theta3.solve(b, b.feet_W[0] + [step_m, 0.0, 0.0], x0=theta3.initial_guess(b))
    assert placed.feasible, placed.diagnosis
    c = placed.state
    move = interpolate_leaf(dog, terrain, a, b, N)  # the stance feet roll (planner.body.rolling)
    b = end_keyframe(dog, move, (1, 2, 3))
    c.feet_W[1:], c.joints_rad[1:] = b.feet_W[1:], b.joints_rad[1:]
    swing = interpolate_swing(dog, terrain, b, c, N)
    c = end_keyframe(dog, swing, (0, 1, 2, 3))
    samples = move[:-1] + [b] + swing[1:-1] + [c]
    times = list(0.05 * np.arange(len(samples)))
    return Plan.build(
        dog, terrain, terrain.friction, a.base_position_W, c.base_position_W, [a, b, c],
        samples, times, OUTCOME,
    )  # fmt: skip


@pytest.fixture(scope="module")
def flat_plan(littledog):
    return make_plan(littledog, "flat", 0.3, 0.04)


def edited(plan):
    """A deep copy of a plan to tamper with."""
    return Plan.from_dict(plan.to_dict(), source="edited")


def kinds_at(report, kind):
    """Sample/keyframe labels of the violations of one kind."""
    return {v.where for v in report.violations if v.kind == kind}


def wall_into(terrain: dict, low, radius_m: float, thickness_m: float) -> dict:
    """A plan's terrain spec made a wall centred below ``low`` (a link axis point of radius
    ``radius_m``), its top 3 mm into the link, only on the left (y > low_y - 3 cm)."""
    return {
        **terrain,
        "kind": "barrier",
        "x": float(low[0]) - 0.5 * thickness_m,
        "thickness": thickness_m,
        "height": float(low[2]) - radius_m + 0.003,
        "opening": [-1.0, float(low[1]) - 0.03],
    }


SWING = range(N, 2 * N - 2)  # samples with leg 1 in the air
MID_SWING = N + N // 2


def test_flat_plan_passes(flat_plan, tmp_path):
    report = check_plan(flat_plan)
    assert report.ok, report.summary() + "\n" + "\n".join(map(str, report.violations))
    assert report.n_samples == 2 * N - 1 and report.n_keyframes == 3
    assert report.min_body_clearance_m > 0.05
    assert report.min_balance_margin_N > 0.0 and report.max_slip_m < 1e-7  # rolling, no sliding
    assert not flat_plan.samples.contact[list(SWING), 0].any()
    # through the file and the CLI entry point
    path = flat_plan.save(tmp_path / "plan.json")
    out = io.StringIO()
    assert main_check(path, out=out) == 0
    assert "OK" in out.getvalue().splitlines()[-1]


def test_step_plan_near_the_edge_passes(littledog):
    # leg 1 lands ~8 mm before the 5 cm step, on the smoothed ramp: smooth vs sharp terrain
    plan = make_plan(littledog, "step5cm", 0.66, None, land_x=0.792)
    assert 0.78 < plan.keyframes[2].feet[0][0] < 0.8
    report = check_plan(plan)
    assert report.ok, "\n".join(map(str, report.violations))


def test_sliding_stance_feet_fail(flat_plan):
    plan = edited(flat_plan)
    plan.samples.q[5:8, 0] += 0.005  # body 5 mm ahead, same joints: all four feet slide
    report = check_plan(plan)
    assert kinds_at(report, "stance_slip") == {"sample 5", "sample 8"}
    slips = [v for v in report.violations if v.kind == "stance_slip"]
    assert len(slips) == 8 and {v.leg for v in slips} == {1, 2, 3, 4}
    assert all(v.value == pytest.approx(0.005, abs=1e-7) for v in slips)
    msgs = [str(v) for v in slips]
    assert (
        "sample 5: stance_slip: leg 2 (FR) slid 5 mm while in contact (centre travel minus "
        "rolling; limit 0.001 mm)" in msgs
    )


def test_com_outside_three_feet_fails_balance(flat_plan):
    plan = edited(flat_plan)
    k = N - 1  # end of the S0 leaf: COM over the centroid of legs 2, 3, 4
    plan.samples.contact[k] = [True, True, True, False]  # HR not carrying: COM off FL-FR-HL
    report = check_plan(plan)
    assert kinds_at(report, "balance") == {f"sample {k}"}
    assert report.by_kind() == {"balance": 1}
    v = report.violations[0]
    assert v.value < 0.0 and "legs 1, 2, 3" in v.message


def test_joint_beyond_limits_fails(flat_plan, littledog):
    plan = edited(flat_plan)
    k = MID_SWING
    leg = littledog.legs[0]  # the swing leg: nothing else moves
    plan.samples.q[k, leg.q_index + 2] = leg.upper_rad[2] + 0.05
    report = check_plan(plan)
    viols = [v for v in report.violations if v.kind == "joint_limits"]
    assert [(v.where, v.leg) for v in viols] == [(f"sample {k}", 1)]
    assert viols[0].value == pytest.approx(0.05)


def test_two_feet_down_fails(flat_plan):
    plan = edited(flat_plan)
    plan.samples.contact[3] = [True, False, True, False]
    report = check_plan(plan)
    assert kinds_at(report, "contact_count") == {"sample 3"}
    assert "only 2 feet in contact (legs 1, 3)" in str(report.violations[0])


def test_swing_foot_in_the_ground_fails(flat_plan, littledog):
    plan = edited(flat_plan)
    k = MID_SWING
    q = plan.samples.q[k]
    state = plan.sample_states()[k]
    centres = plan.foot_centres_W()[k]
    centres[0, 2] = littledog.foot_radius_m - 0.004  # sphere 4 mm into the flat ground
    ik = kinematics_of(littledog).ik(
        state.base_position_W, state.base_rotation_W, centres, state.joints_rad
    )
    assert ik[0].reachable
    leg = littledog.legs[0]
    q[leg.q_index : leg.q_index + 3] = ik[0].joints_rad
    report = check_plan(plan)
    viols = [v for v in report.violations if v.kind == "swing_clearance"]
    at = [v for v in viols if "between" not in v.message]
    assert [(v.where, v.leg) for v in at] == [(f"sample {k}", 1)]
    assert at[0].value == pytest.approx(0.004, abs=2e-5)
    # the executor's lines into that sample and out of it dip as well, no deeper
    assert all(v.value <= 0.004 + 2e-5 for v in viols)
    assert report.min_swing_clearance_m == pytest.approx(-0.004, abs=2e-5)


def test_shank_in_a_step_edge_fails(flat_plan, littledog):
    """A 6 mm thick wall whose top is 3 mm above the bottom of the swinging shank."""
    assert check_plan(flat_plan).min_leg_clearance_m > 0.0
    plan = edited(flat_plan)
    k = MID_SWING
    links = LegLinks(littledog)
    c = next(i for i, cap in enumerate(links.capsules) if cap.leg == 0 and cap.link == "shank")
    a, b = (s[c] for s in links.segments_W(plan.samples.q[k]))
    low = a if a[2] < b[2] else b  # the capsule's lowest point is below this axis end
    r = links.capsules[c].radius_m
    plan.terrain = wall_into(plan.terrain, low, r, 0.006)
    report = check_plan(plan)
    legs = [v for v in report.violations if v.kind == "leg_clearance"]
    at_k = [v for v in legs if v.where == f"sample {k}" and v.leg == 1]
    assert at_k, "\n".join(map(str, legs))
    assert at_k[0].value == pytest.approx(-0.003, abs=3e-4)
    assert "leg 1 (FL) shank (FL_lower) reaches 3" in at_k[0].message
    assert report.min_leg_clearance_m < -0.003 + 3e-4  # later samples swing through the wall


def test_keyframe_feet_must_match_fk(flat_plan):
    plan = edited(flat_plan)
    plan.keyframes[1].feet[2, 1] += 0.001
    report = check_plan(plan)
    fk = [(v.where, v.leg) for v in report.violations if v.kind == "keyframe_fk"]
    assert fk == [("keyframe 1", 3)]
    assert report.by_kind().keys() <= {"keyframe_fk", "keyframe_forces"}  # moments moved


def test_keyframe_forces_must_balance(flat_plan):
    plan = edited(flat_plan)
    plan.keyframes[1].forces[1, 2] += 0.5
    report = check_plan(plan)
    assert kinds_at(report, "keyframe_forces") == {"keyframe 1"}


def test_body_in_the_ground_fails(flat_plan):
    plan = edited(flat_plan)
    plan.samples.q[4, 2] -= 0.2  # body 20 cm down (and feet with it)
    report = check_plan(plan)
    assert "sample 4" in kinds_at(report, "body_clearance")
    assert report.min_body_clearance_m < 0.0


def test_main_check_reports_and_fails(flat_plan, tmp_path):
    plan = edited(flat_plan)
    plan.samples.contact[3] = [True, False, True, False]
    path = plan.save(tmp_path / "bad.json")
    out = io.StringIO()
    assert main_check(path, out=out) == 1
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("sample 3: contact_count: only 2 feet")
    assert "FAILED" in lines[-1] and "contact_count 1" in lines[-1]
    (tmp_path / "junk.json").write_text("{")
    err = io.StringIO()
    assert main_check(tmp_path / "junk.json", out=out, err=err) == 2
    assert "not JSON (line 1, column 2)" in err.getvalue()
    assert len(err.getvalue().strip().splitlines()) == 1


def test_tolerances_are_configurable(flat_plan):
    plan = edited(flat_plan)
    plan.samples.q[5, 0] += 1e-5  # a 0.01 mm slip
    assert not check_plan(plan).ok
    assert check_plan(plan, CheckTolerances(slip_m=1e-4, on_terrain_m=1e-4)).ok


def test_sharp_surface_distance_sees_step_faces():
    terrain = load_terrain("step5cm")  # riser at x = 0.8, 5 cm high
    pts = np.array(
        [
            [0.795, 0.0, 0.02],  # 5 mm in front of the riser, halfway up it
            [0.70, 0.0, 0.01],  # 1 cm above the lower floor
            [0.797, 0.0, 0.053],  # off the top corner: sqrt(3^2 + 3^2) mm
            [0.81, 0.0, 0.04],  # inside the step, 1 cm below its top
        ]
    )
    d = sharp_surface_distance(terrain, pts, 0.012)
    np.testing.assert_allclose(d, [0.005, 0.01, np.hypot(0.003, 0.003), -0.01], atol=2e-5)


def test_contact_points_from_either_convention():
    terrain = load_terrain("slope10")
    rho = 0.0103
    r = np.array([[1.5, 0.1, float(terrain.height(1.5, 0.1))]])
    from planner.body.contact import contact_from_foot_centre, foot_centre_from_contact

    c = foot_centre_from_contact(terrain, r, rho)
    contacts, miss = contact_points_from_centres(terrain, c, rho)
    np.testing.assert_allclose(contacts, r, atol=1e-9)
    assert miss[0] < 1e-9
    np.testing.assert_allclose(contact_from_foot_centre(terrain, c, rho), r, atol=1e-9)


def _knee_flipped_mid_swing(flat_plan, littledog):
    """A copy of the plan whose FL swing sample after MID_SWING has the same foot point on
    the other knee branch: (plan, MID_SWING, q of MID_SWING)."""
    plan = edited(flat_plan)
    k = MID_SWING
    q = plan.samples.q[k].copy()
    kin = kinematics_of(littledog)
    th = q[7:10]
    other = kin.ik_leg(0, kin.foot_B(0, th), knee=-kin.knee_direction(0, th))
    assert other.reachable and float(np.max(np.abs(other.joints_rad - th))) > 1.0
    plan.samples.q[k + 1] = q
    plan.samples.q[k + 1, 7:10] = other.joints_rad  # the same foot point, the other knee
    return plan, k, q


def test_a_knee_flipping_between_two_clear_samples_through_a_wall_fails(flat_plan, littledog):
    """The executor interpolates joints linearly: a knee flipped between two samples sweeps
    its shank lower than either sample. A wall under the sweep's lowest point (3 mm into
    the shank there, clear of both samples) is a leg_clearance violation between the
    samples, for check and for the planner's own path check."""
    import pinocchio as pin

    from planner.body.state import State
    from planner.motion.interpolate import between_q
    from planner.planning.soft import SoftPlanner
    from planner.world.terrain import Terrain

    plan, k, q = _knee_flipped_mid_swing(flat_plan, littledog)
    links = LegLinks(littledog)
    fl = np.array([links.capsules[c].leg == 0 for c in links.owner])
    mid = links.axis_points_W(between_q(q, plan.samples.q[k + 1], 0.5))[fl]
    low = mid[np.argmin(mid[:, 2])]
    r = max(cap.radius_m for cap in links.capsules if cap.leg == 0)
    plan.terrain = wall_into(plan.terrain, low, r, 0.02)
    report = check_plan(plan)
    between = [v for v in report.violations if "between it and" in v.message]
    assert between and between[0].where == f"sample {k}" and between[0].leg == 1, report
    assert not [v for v in report.violations if v.kind == "leg_clearance" and v.where in
                (f"sample {k}", f"sample {k + 1}") and "between" not in v.message]  # fmt: skip
    # the planner's path check sees it too
    terrain = Terrain.from_spec(plan.terrain)
    planner = SoftPlanner(littledog, terrain)
    states = []
    for qq in (q, plan.samples.q[k + 1]):
        R = pin.Quaternion(qq[6], qq[3], qq[4], qq[5]).toRotationMatrix()
        feet = np.zeros((4, 3))
        states.append(State(qq[:3].copy(), R, feet, qq[7:].reshape(4, 3).copy(), 1, (1, 2, 3)))
    links = leg_links(littledog)
    ends = [q, plan.samples.q[k + 1]]
    bares = links.path_margins(terrain, ends, [[0], [0]], scales=(0.0,))[0]
    why = planner._between_samples(states, ends, links, bares)
    assert "FL" in why and "between samples 0 and 1" in why, why
    fl_moves = np.abs(states[1].joints_rad[0] - states[0].joints_rad[0]).max()
    assert f"its joints move {fl_moves:.2f} rad there" in why, why  # the FL's own motion


def test_a_sweep_names_the_motion_of_the_leg_whose_link_it_is():
    """A link swept through the terrain by a small motion of its own leg while another leg
    flips: the message says both, not the other's flip as the link's leg's."""
    from planner.planning.path_checks import _moves

    jumps = np.array([0.06, 0.0, 2.57, 0.0])  # FL a little, HL 2.57 rad
    assert _moves(jumps, 0) == "its joints move 0.06 rad there, HL's 2.57 rad"
    assert _moves(jumps, 2) == "its joints move 2.57 rad there"


def test_a_swing_foot_swept_through_the_ground_between_two_samples_fails(flat_plan, littledog):
    """The foot sphere as the leg links above: a knee flipped between two clear samples
    sweeps the foot lower than either; a block under the sweep's lowest foot centre (3 mm
    into the sphere, clear of both samples) is a swing_clearance violation between the
    samples, for check and for the planner's path check. (A 12 cm trench's plan passed
    check so and fell in MuJoCo: the foot struck the trench's floor between two samples.)"""
    import pinocchio as pin

    from planner.body.state import State
    from planner.motion.interpolate import between_q
    from planner.planning.soft import SoftPlanner
    from planner.world.terrain import Terrain

    plan, k, q = _knee_flipped_mid_swing(flat_plan, littledog)
    kin = kinematics_of(littledog)

    def foot_W(qq):
        R = pin.Quaternion(qq[6], qq[3], qq[4], qq[5]).toRotationMatrix()
        return R @ kin.foot_B(0, qq[7:10]) + qq[:3]

    sweep = [foot_W(between_q(q, plan.samples.q[k + 1], u)) for u in np.linspace(0, 1, 41)]
    low = min(sweep, key=lambda c: c[2])
    rho = littledog.foot_radius_m
    assert foot_W(q)[2] - low[2] > 0.01  # the sweep dips well below the samples' foot
    plan.terrain = wall_into(plan.terrain, low, rho, 0.02)
    report = check_plan(plan)
    swept = [v for v in report.violations if v.kind == "swing_clearance"]
    assert swept and swept[0].where == f"sample {k}" and swept[0].leg == 1, report
    assert "between it and" in swept[0].message
    assert swept[0].value == pytest.approx(0.003, abs=5e-4)
    # the planner's path check sees it too
    terrain = Terrain.from_spec(plan.terrain)
    planner = SoftPlanner(littledog, terrain)
    states = []
    for qq in (q, plan.samples.q[k + 1]):
        R = pin.Quaternion(qq[6], qq[3], qq[4], qq[5]).toRotationMatrix()
        states.append(State(qq[:3].copy(), R, np.zeros((4, 3)), qq[7:].reshape(4, 3).copy(), 1,
                            (1, 2, 3)))  # fmt: skip
    links = leg_links(littledog)
    ends = [q, plan.samples.q[k + 1]]
    bares = links.path_margins(terrain, ends, [[0], [0]], scales=(0.0,))[0]
    why = planner._between_samples(states, ends, links, bares)  # the links clear: the foot
    assert "FL foot passes" in why and "between samples 0 and 1" in why, why
