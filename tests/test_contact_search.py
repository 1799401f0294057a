"""The contact-sequence search (planner.motion.contact_search): its certificates checked
against the support triangle and the legs' reach computed independently, and the search on
the stance where the greedy queue left a hind leg below a 10 cm step."""

import numpy as np
import pytest

from planner.body.kinematics import hip_point_B, kinematics_of
from planner.body.stability import support_margin_m
from planner.motion.contact_search import (
    ContactSearch,
    SearchSettings,
    certify_step,
    stance_rotation_W,
)
from planner.motion.heuristics import nominal_height_m
from planner.world.terrain import load_terrain

X = np.array([1.0, 0.0, 0.0])


def _stance(robot, x=0.5):
    """LittleDog's feet at theta_nor under a level body at (x, 0), on flat ground."""
    kin = kinematics_of(robot)
    feet = kin.feet_B(robot.theta_nor) + np.array([x, 0.0, nominal_height_m(robot)])
    feet[:, 2] = 0.0
    return feet


def _check_certificate(robot, feet, leg, new, cert, settings, R=None):
    """The certificate's body pose, judged with the stability module, the hips and the IK."""
    R = cert.rotation_W if R is None else R
    kin = kinematics_of(robot)
    rho = robot.foot_radius_m
    stay = np.delete(feet, leg, axis=0)
    shares = [settings.stance_reach_share] * 4 + [settings.swing_reach_share]
    joints = np.zeros((4, 3))
    for k, ((j, c), share) in enumerate(zip([*enumerate(feet), (leg, new)], shares, strict=True)):
        hip = R @ hip_point_B(robot.legs[j]) + cert.body_W
        assert np.linalg.norm(c + rho * R[:, 2] - hip) <= share * robot.reach_m[j] + 1e-6
        # the legs reach their feet within their joint limits there (an independent IK)
        ik = kin.ik_leg(j, R.T @ (c + rho * R[:, 2] - cert.body_W), closest=False)
        assert ik.reachable
        joints[j] = ik.joints_rad
        if k == 3 or k == 4:  # lift-off, then touch-down: the COM at those joints
            com = R @ kin.com_B(joints) + cert.body_W
            assert support_margin_m(stay, com) >= settings.balance_margin_m - 1e-6


def test_a_nominal_step_on_flat_ground_is_certified(littledog):
    settings = SearchSettings()
    feet = _stance(littledog)
    for leg in range(4):
        new = feet[leg] + [0.04, 0.0, 0.0]
        R = stance_rotation_W(feet, X)
        cert = certify_step(littledog, feet, leg, new, R, 0.1, settings)
        assert cert.ok and cert.margin_m >= 0.0, cert
        _check_certificate(littledog, feet, leg, new, cert, settings, R)


def test_out_of_reach_sliver_and_low_body_are_refused(littledog):
    settings = SearchSettings()
    feet = _stance(littledog)
    R = stance_rotation_W(feet, X)
    far = feet[0] + [0.3, 0.0, 0.0]  # beyond the leg's reach from any body keeping the others
    assert not certify_step(littledog, feet, 0, far, R, 0.1, settings).ok
    sliver = feet.copy()
    sliver[3] = sliver[1] + [0.005, 0.0, 0.0]  # HR beside FR: HL's triangle is a sliver
    cert = certify_step(littledog, sliver, 2, sliver[2] + [0.03, 0, 0], R, 0.1, settings)
    assert not cert.ok and cert.margin_m < 0.0
    # the body cannot be raised above the legs' reach
    assert not certify_step(littledog, feet, 0, feet[0] + [0.03, 0, 0], R, 0.3, settings).ok


@pytest.fixture(scope="module")
def step_search(littledog):
    terrain = load_terrain("step10cm")
    box_lo = float(littledog.body_box_B[0][2])

    def z_floor(feet):
        c = feet.mean(axis=0)
        X_, Y_ = np.meshgrid(np.linspace(c[0] - 0.15, c[0] + 0.15, 13), np.linspace(-0.08, 0.08, 5))
        return float(np.max(terrain.height_sharp(X_, Y_))) + 0.02 - box_lo

    return ContactSearch(littledog, terrain, 0.7, lambda p: X, z_floor)


# stances of a recursive walk up step10cm (the riser at x = 0.8 m) that stalled: after
# HR stepped up beside FR, HL's triangle (FL, FR, HR) is a sliver and HL stayed below
BEFORE = np.array([[0.8416, 0.0638, 0.1], [0.8409, -0.0688, 0.1], [0.7554, 0.0654, 0.0],
                   [0.7467, -0.0651, 0.0]])  # fmt: skip
STALLED = np.array([[0.9669, 0.0681, 0.1], [0.8455, -0.0637, 0.1], [0.7602, 0.0688, 0.0],
                    [0.8347, -0.0668, 0.1]])  # fmt: skip


def test_the_stalled_stance_has_no_certificate_for_the_hind_leg(step_search):
    for leg in (0, 2):  # HL and FL cannot lift there; FR and HR can
        assert not step_search.certify(STALLED, leg, STALLED[leg] + [0.03, 0, 0]).ok
    for leg in (1, 3):
        assert step_search.certify(STALLED, leg, STALLED[leg] + [0.02, 0, 0]).ok


def test_the_search_takes_the_hind_leg_up_and_theta_realises_it(step_search, littledog):
    """From the stance before the stall, the search's first step takes HL onto the step;
    the Theta problems (the soft planner's step: Theta2 landing-ready, the swing, Theta3)
    make that step from there."""
    from planner.body.state import State
    from planner.motion.trajectory import Trajectory
    from planner.planning.soft import SoftPlanner

    body = np.array([0.81, -0.03, 0.1955])
    steps = step_search.search(BEFORE, body, [2, 0, 3, 1, 2], 0.063)
    assert steps and steps[0][0] == 2
    feet = BEFORE.copy()
    for leg, foothold, cert in steps:
        assert cert.ok
        _check_certificate(littledog, feet, leg, foothold, cert, step_search.settings)
        feet[leg] = foothold
    leg, first, _ = steps[0]
    assert first[0] > 0.8 and first[2] > 0.099  # HL on the step's top
    planner = SoftPlanner(littledog, step_search.terrain)
    tau = Trajectory.straight([0.2, 0.0], [2.2, 0.0], planner.terrain, planner.com_height_m())
    R = stance_rotation_W(BEFORE, X)
    kin = kinematics_of(littledog)
    rho = littledog.foot_radius_m
    joints = [kin.ik_leg(i, R.T @ (BEFORE[i] + R[:, 2] * rho - body)).joints_rad for i in range(4)]
    made = planner.step(State(body, R, BEFORE, joints), leg, tau, 0.063, target_W=first,
                        try_others=False)  # fmt: skip
    assert made.ok, made.diagnosis
    # a step the Theta problems could not realise is not proposed again
    step_search.mark_failed(BEFORE, leg, first)
    again = step_search.search(BEFORE, body, [2, 0, 3, 1, 2], 0.063)
    assert again and np.linalg.norm(again[0][1] - first) > 1e-9


def test_a_proposal_is_kept_where_the_cycle_after_it_is_certified(littledog):
    flat = load_terrain("flat")
    box_lo = float(littledog.body_box_B[0][2])
    search = ContactSearch(littledog, flat, 0.7, lambda p: X, lambda feet: 0.02 - box_lo)
    feet = _stance(littledog)
    body = np.array([0.5, 0.0, nominal_height_m(littledog)])
    proposal = feet[2] + [0.05, 0.0, 0.0]
    steps = search.search(feet, body, [2, 0, 3, 1], 0.063, first_W=proposal)
    assert [leg for leg, _, _ in steps] == [2, 0, 3, 1]
    np.testing.assert_array_equal(steps[0][1], proposal)
    # a proposal beyond the leg's reach is replaced by a certified foothold
    far = feet[2] + [0.4, 0.0, 0.0]
    steps = search.search(feet, body, [2, 0, 3, 1], 0.063, first_W=far)
    assert steps and np.linalg.norm(steps[0][1] - far) > 0.1 and steps[0][2].ok
    assert search.stats["certificates"] <= 2 * search.settings.budget


def test_the_search_keeps_lambda_t_where_the_cycle_is_certified():
    """On flat ground every Lambda_t foothold is certified: the walk is Lambda_t's, to the
    bit, and the search ran at every step."""
    import json

    from planner.planning.local import LocalSettings
    from planner.planning.walk import plan_walk

    plans = {}
    for footholds in ("lambda_t", "search"):
        plan, report = plan_walk(
            "littledog", "flat", (0.45, 0.0), (0.2, 0.0), "soft", LocalSettings(footholds=footholds)
        )
        assert report.ok and plan.outcome["reached_goal"]
        plans[footholds] = plan
    assert json.dumps(plans["search"].to_dict()["samples"]) == json.dumps(
        plans["lambda_t"].to_dict()["samples"]
    )
    stats = plans["search"].stats["contact_search"]
    assert stats["searches"] >= plans["search"].stats["steps"] > 0
    assert stats["found"] == stats["searches"]
    # every searched step was made by the Theta problems (the certificates' record)
    assert stats["realised"] == plans["search"].stats["steps"] and stats["unrealised"] == 0
    assert plans["search"].stats["settings"]["footholds"] == "search"


def test_the_certificates_reach_is_theta2s():
    """A certificate looser than the problem it certifies passes steps Theta2 cannot make."""
    from planner.problems import theta2

    s = SearchSettings()
    assert s.stance_reach_share == theta2.STANCE_REACH_FRACTION
    assert s.swing_reach_share == theta2.SWING_REACH_FRACTION


def test_leg_check_refuses_joint_limits_a_sinking_com_and_links_in_the_terrain(
    littledog, step_search
):
    """leg_check against independent judgments: the IK's joint limits, the stability
    module's margin with the COM at the IK's joints, and the links' distance to the
    terrain's nearest point (their witnesses)."""
    from planner.body.links import leg_links
    from planner.core.lie import quat_from_rotation
    from planner.motion.contact_search import leg_check, leg_joints

    feet = _stance(littledog)
    flat = load_terrain("flat")
    new = feet[0] + [0.04, 0.0, 0.0]
    R = stance_rotation_W(feet, X)
    cert = certify_step(littledog, feet, 0, new, R, 0.1, SearchSettings(), flat)
    assert cert.ok and leg_check(littledog, feet, 0, new, R, cert.body_W, 0.025, flat) == ""
    kin = kinematics_of(littledog)
    rho = littledog.foot_radius_m
    # a foot straight under the hip at a tenth of the leg: no in-limit knee folds that far
    hip = R @ hip_point_B(littledog.legs[0]) + cert.body_W
    close = hip - [0.0, 0.0, 0.1 * littledog.reach_m[0] + rho]
    assert "cannot reach its new foothold" in leg_check(
        littledog, feet, 0, close, R, cert.body_W, 0.025, flat
    )
    assert not kin.ik_leg(0, R.T @ (close + [0, 0, rho] - cert.body_W), closest=False).reachable
    # the body 4 cm towards FL: the COM leaves the triangle of FR, HL, HR
    moved = cert.body_W + [0.04, 0.04, 0.0]
    why = leg_check(littledog, feet, 0, new, R, moved, 0.025, flat)
    poses = leg_joints(littledog, feet, 0, new, R, moved)
    com = R @ kin.com_B(poses[0]) + moved
    assert "balance margin" in why and support_margin_m(np.delete(feet, 0, 0), com) < 0.025
    # the body 4 cm lower: the knees of the three support legs carry it beyond the
    # commanded share of their effort (the torque check of the planner's paths)
    from planner.body.margins import COMMANDED_TORQUE_FRACTION
    from planner.body.torques import TorqueCheck

    low = cert.body_W - [0.0, 0.0, 0.04]
    assert leg_check(littledog, feet, 0, new, R, low, 0.025, flat) == ""  # no mu: no torques
    why = leg_check(littledog, feet, 0, new, R, low, 0.025, flat, 0.7)
    q = littledog.q_from(low, quat_from_rotation(R), leg_joints(littledog, feet, 0, new, R, low)[0])
    ratio = TorqueCheck(littledog).solve(q, [1, 2, 3], 0.7, np.tile([0, 0, 1.0], (4, 1)),
                                         least_squares=True).ratio  # fmt: skip
    assert "support joint" in why and ratio > COMMANDED_TORQUE_FRACTION
    # HL 4 cm before a 10 cm riser, its knee forward, the body over the step: the shank
    # is inside the riser (the witness: the terrain's nearest point to the capsule's axis)
    after = STALLED.copy()
    after[1] += [0.02, 0.0, 0.0]
    R = stance_rotation_W(after, X)
    body = np.array([0.8445, 0.0193, 0.1868])
    why = leg_check(littledog, STALLED, 1, after[1], R, body, 0.025, step_search.terrain)
    assert why == "HL shank inside its margin from the terrain"
    links = leg_links(littledog)
    th = leg_joints(littledog, STALLED, 1, after[1], R, body)[0]
    q = littledog.q_from(body, quat_from_rotation(R), th)
    hl_shank = next(c for c, cap in enumerate(links.capsules) if links.describe(c) == "HL shank")
    assert links.witnesses(step_search.terrain, q)[hl_shank].clearance_m < 0.0


def test_the_walk_follows_the_sequence_it_found(littledog):
    """After a step of the sequence found, the next search tries that sequence's next
    foothold right after the step's own proposal: where the proposal is not certified,
    the sequence goes on as found, not as a new search would begin it."""
    flat = load_terrain("flat")
    box_lo = float(littledog.body_box_B[0][2])
    search = ContactSearch(littledog, flat, 0.7, lambda p: X, lambda feet: 0.02 - box_lo)
    feet = _stance(littledog)
    body = np.array([0.5, 0.0, nominal_height_m(littledog)])
    steps = search.search(feet, body, [2, 0, 3, 1, 2], 0.063)
    assert len(steps) == 5
    after = feet.copy()
    after[2] = steps[0][1]
    # the sequence's next foothold: not the one a new search would take first
    planned = steps[1][1] + [-0.012, 0.008, 0.0]
    search.sequence = (feet, [steps[0], (0, planned, steps[1][2]), *steps[2:]])
    far = after[0] + [0.4, 0.0, 0.0]  # out of reach: never certified
    again = search.search(after, steps[0][2].body_W, [0, 3, 1, 2, 0], 0.063, first_W=far)
    np.testing.assert_array_equal(again[0][1], planned)
    # from a stance the sequence did not lead to, a new search's first foothold
    search.sequence = (feet + [0.05, 0.0, 0.0], [steps[0], (0, planned, steps[1][2])])
    other = search.search(after, steps[0][2].body_W, [0, 3, 1, 2, 0], 0.063, first_W=far)
    np.testing.assert_array_equal(other[0][1], steps[1][1])


def test_a_body_move_aims_for_a_given_com(littledog):
    """Theta2 with the COM target of a certificate (the searched step's fallback): the
    body ends nearer that target than Lambda_c's move does."""
    from planner.motion.trajectory import Trajectory
    from planner.planning.soft import SoftPlanner

    planner = SoftPlanner(littledog, load_terrain("flat"))
    tau = Trajectory.straight([0.2, 0.0], [1.0, 0.0], planner.terrain, planner.com_height_m())
    state = planner.initial_state([0.2, 0.0], tau)
    leg = 2
    target = np.asarray(state.feet_W[leg]) + [0.05, 0.0, 0.0]
    plain, _ = planner.body_move(state, leg, tau, target)
    com_plain = planner.check.com_W(plain.state)
    aim = com_plain + [-0.015, -0.01, 0.0]
    aimed, _ = planner.body_move(state, leg, tau, target, com_target_W=aim)
    assert plain.feasible and aimed.feasible
    com_aimed = planner.check.com_W(aimed.state)
    assert np.linalg.norm(com_aimed - aim) < np.linalg.norm(com_plain - aim) - 0.005
