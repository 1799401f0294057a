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


def _check_certificate(robot, feet, leg, new, cert, settings):
    """The certificate's body position, judged with the stability module and the hips."""
    R = stance_rotation_W(np.vstack([np.delete(feet, leg, 0), new]), X)
    com = R @ kinematics_of(robot).com_B(robot.theta_nor) + cert.body_W
    stay = np.delete(feet, leg, axis=0)
    assert support_margin_m(stay, com) >= settings.balance_margin_m - 1e-6
    rho = robot.foot_radius_m
    for j, c in [*enumerate(feet), (leg, new)]:
        hip = R @ hip_point_B(robot.legs[j]) + cert.body_W
        assert np.linalg.norm(c + rho * R[:, 2] - hip) <= (
            settings.reach_share * robot.reach_m[j] + 1e-6
        )


def test_a_nominal_step_on_flat_ground_is_certified(littledog):
    settings = SearchSettings()
    feet = _stance(littledog)
    for leg in range(4):
        new = feet[leg] + [0.04, 0.0, 0.0]
        R = stance_rotation_W(feet, X)
        cert = certify_step(littledog, feet, leg, new, R, 0.1, settings)
        assert cert.ok and cert.margin_m >= 0.0, cert
        _check_certificate(littledog, feet, leg, new, cert, settings)


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


def test_the_search_takes_both_hind_legs_up_within_a_cycle(step_search, littledog):
    steps = step_search.search(BEFORE, np.array([0.81, -0.03, 0.1955]), [2, 0, 3, 1], 0.063)
    assert [leg for leg, _, _ in steps] == [2, 0, 3, 1]
    feet = BEFORE.copy()
    for leg, foothold, cert in steps:
        assert cert.ok
        _check_certificate(littledog, feet, leg, foothold, cert, step_search.settings)
        feet[leg] = foothold
    assert np.all(feet[:, 0] > 0.8) and np.all(feet[:, 2] > 0.099)  # all four on the step
    # a step the Theta problems could not realise is not proposed again
    leg, first, _ = steps[0]
    step_search.mark_failed(BEFORE, leg, first)
    again = step_search.search(BEFORE, np.array([0.81, -0.03, 0.1955]), [2, 0, 3, 1], 0.063)
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
    assert plans["search"].stats["settings"]["footholds"] == "search"
