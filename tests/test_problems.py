"""Theta1-Theta4 (sections 7.2-7.5) on named reference stances, checked independently."""

import numpy as np
import pytest

from planner.body import statics
from planner.body.robot import load_robot
from planner.problems import Theta1, Theta2, Theta3, Theta4, ThetaOptions
from planner.problems.base import FEASIBILITY_TOL
from planner.world.terrain import load_terrain

# (terrain, body x [m]): flat ground, a 10 degree slope, straddling a 5 cm step
STANCES = [("flat", 0.3), ("slope10", 1.0), ("step5cm", None)]


@pytest.fixture(scope="module")
def dog():
    return load_robot("littledog")


def _step_x(terrain):
    """x of the step edge: where the sharp height first exceeds half the rise."""
    xs = np.linspace(0, 2.5, 2501)
    h = terrain.height_sharp(xs, np.zeros_like(xs))
    return float(xs[np.argmax(h > 0.5 * h.max())])


def _directions(terrain, x):
    p = np.array([x, 0.0, float(terrain.height(np.array(x), np.array(0.0)))])
    n = terrain.smoothed_normal(p, 0.1)
    u_f = np.array([1.0, 0.0, 0.0])
    u_f = u_f - (u_f @ n) * n
    return u_f / np.linalg.norm(u_f), n


def _placed(dog, name, x):
    terrain = load_terrain(name)
    if x is None:  # body centred on the step edge: front feet up, hind feet down
        x = _step_x(terrain)
    u_f, u_n = _directions(terrain, x)
    z = float(terrain.height(np.array(x), np.array(0.0))) + 0.15
    sol = Theta4(dog, terrain).solve([x, 0.0, z], u_f, u_n)
    return terrain, sol, u_f, u_n


@pytest.mark.parametrize("name,x", STANCES)
def test_theta4_places_the_robot(dog, name, x):
    terrain, sol, _, _ = _placed(dog, name, x)
    assert sol.feasible, sol.diagnosis
    assert sol.max_violation() < FEASIBILITY_TOL
    # independently: feet on the terrain, forces of eq. 5 balance and lie in the cones
    assert np.abs(terrain.f_T(sol.state.feet_W)).max() < 1e-6
    assert statics.forces_in_friction_cones(
        sol.state.forces_W, terrain_mu(terrain), (0, 1, 2, 3), terrain.normal(sol.state.feet_W)
    )


def terrain_mu(terrain):
    return float(terrain.spec.get("friction", 0.7))


@pytest.mark.parametrize("rolling", [False, True])
@pytest.mark.parametrize("name,x", STANCES)
def test_theta2_moves_com_over_three_feet(dog, name, x, rolling):
    terrain, placed, u_f, u_n = _placed(dog, name, x)
    start = placed.state
    support = (1, 2, 3)  # FL about to swing
    problem = Theta2(dog, terrain, support=support, options=ThetaOptions(rolling_feet=rolling))
    rc = start.feet_W[list(support)].mean(axis=0) + 0.15 * u_n
    sol = problem.solve(start, rc, u_f, u_n)
    assert sol.feasible, sol.diagnosis
    assert sol.max_violation() < FEASIBILITY_TOL
    np.testing.assert_array_equal(sol.state.feet_W, start.feet_W)  # same leaf of S0
    # forces of the S^-1 formulation equal the statics module's eq. 5 on the contacts: the
    # start's, or with rolling feet those the spheres rolled to, FK of the solved joints
    # (Pinocchio's frames, not the rolling model) less a radius along the start's normals
    com = problem.check.com_W(sol.state)
    contacts = start.feet_W
    if problem.rolls_feet:
        n = terrain.normal(start.feet_W)
        contacts = problem.check.foot_centres_W(sol.state) - dog.foot_radius_m * n
        assert 1e-4 < np.abs(contacts[list(support)] - start.feet_W[list(support)]).max() < 0.02
    ref = statics.equilibrating_forces(contacts, com, dog.total_mass_kg, support)
    np.testing.assert_allclose(sol.state.forces_W, ref.forces, atol=1e-9)
    # objective no worse than the (feasible) start's
    p = problem.params(start, rc, u_f, u_n)
    x0 = problem.initial_guess(start, p)
    assert sol.objective <= problem.objective_at(x0, p) + 1e-9
    # the weighted log objective ranks like the paper's product
    prod = np.prod(
        [v**w for (k, v), w in zip(sol.objective_terms.items(), _weights(problem), strict=True)]
    )
    assert -np.log(prod) == pytest.approx(sol.objective, abs=1e-6)


def _weights(problem):
    return [w for _, w, _ in problem._terms]


@pytest.mark.parametrize("name,x", STANCES)
def test_theta1_hits_the_com_target(dog, name, x):
    terrain, placed, u_f, u_n = _placed(dog, name, x)
    start = placed.state
    support = (0, 1, 2, 3)
    problem = Theta1(dog, terrain, support=support)
    com0 = problem.check.com_W(start)
    rc = com0 + 0.01 * u_f  # 1 cm ahead on the trajectory
    sol = problem.solve(start, rc, u_f, u_n)
    assert sol.feasible, sol.diagnosis
    assert np.linalg.norm(problem.check.com_W(sol.state) - rc) < 1e-6


@pytest.mark.parametrize("name,x", STANCES)
def test_theta1_with_a_height_band_pins_the_com_over_the_target(dog, name, x):
    """Beyond eq. 7 (the hard planner's Theta1): the COM's horizontal position is r_c*'s,
    its height anywhere within the band; a target 6 cm above the stance's COM is out of
    the legs' comfort pinned in 3-D and reached within a 10 cm band, on three feet with the
    eq. 5 forces in their cones and the COM inside the triangle by the balance margin."""
    terrain, placed, u_f, u_n = _placed(dog, name, x)
    start = placed.state
    support = (1, 2, 3)
    com0 = Theta1(dog, terrain, support=support).check.com_W(start)
    # over the support triangle's incentre, 6 cm above the start's COM height
    tri = start.feet_W[list(support)]
    side = np.array([np.linalg.norm(tri[(i + 1) % 3] - tri[(i + 2) % 3]) for i in range(3)])
    inc = (side[:, None] * tri).sum(axis=0) / side.sum()
    rc = np.array([inc[0], inc[1], com0[2] + 0.06])
    band = Theta1(dog, terrain, support=support, height_band_m=0.10)
    sol = band.solve(start, rc, u_f, u_n)
    assert sol.feasible, sol.diagnosis
    com = band.check.com_W(sol.state)
    assert np.linalg.norm(com[:2] - rc[:2]) < 1e-6
    assert abs(com[2] - rc[2]) <= 0.10 + 1e-6 and com[2] < rc[2] - 1e-3  # it sank
    mu = terrain_mu(terrain)
    assert statics.forces_in_friction_cones(
        sol.state.forces_W, mu, support, terrain.normal(sol.state.feet_W)
    )
    from planner.body.stability import support_margin_m

    assert support_margin_m(tri, com) >= band.options.balance_margin_m - 1e-6
    pinned = Theta1(dog, terrain, support=support).solve(start, rc, u_f, u_n)
    assert not pinned.feasible and "com" in pinned.violations


@pytest.mark.parametrize("name,x", STANCES)
def test_theta3_places_a_foot(dog, name, x):
    terrain, placed, u_f, u_n = _placed(dog, name, x)
    start = placed.state
    for leg in range(4):
        problem = Theta3(dog, terrain, leg=leg)
        target = start.feet_W[leg] + 0.04 * u_f
        sol = problem.solve(start, target)
        assert sol.feasible, sol.diagnosis
        foot = sol.state.feet_W[leg]
        assert abs(float(terrain.f_T(foot))) < 1e-6
        # other legs untouched
        others = [i for i in range(4) if i != leg]
        np.testing.assert_array_equal(sol.state.feet_W[others], start.feet_W[others])
        p = problem.pack_params(
            {
                "p": start.base_position_W,
                "R": start.base_rotation_W.T.ravel(),
                "target_W": target,
                "target_radius_m": [1e3],
            }
        )
        assert sol.objective <= problem.objective_at(problem.initial_guess(start), p) + 1e-9
        # a hard target radius (beyond the paper) is met or reported
        on = np.array([*target[:2], float(terrain.height(target[0], target[1]))])
        tight = problem.solve(start, on, target_radius_m=0.005)
        assert tight.feasible, tight.diagnosis
        assert np.linalg.norm(tight.state.feet_W[leg] - on) <= 0.005 + 1e-9
        far = problem.solve(start, start.feet_W[leg] + 0.3 * u_f, target_radius_m=0.005)
        assert not far.feasible and "target_radius" in far.diagnosis


def test_unreachable_foothold_is_reported(dog):
    terrain, placed, u_f, u_n = _placed(dog, "flat", 0.3)
    start = placed.state.copy()
    start.feet_W[0] += [0.25, 0.0, 0.0]  # FL foothold 25 cm ahead: out of reach
    sol = Theta2(dog, terrain, support=(1, 2, 3)).solve(
        start, placed.state.base_position_W, u_f, u_n
    )
    assert not sol.feasible
    assert "contact" in sol.diagnosis and "reach" in sol.diagnosis


def test_com_outside_support_is_reported(dog):
    terrain, placed, u_f, u_n = _placed(dog, "flat", 0.3)
    start = placed.state
    rc = start.base_position_W + [0.3, 0.0, 0.0]  # far ahead of the front feet
    sol = Theta1(dog, terrain, support=(0, 1, 2, 3)).solve(start, rc, u_f, u_n)
    assert not sol.feasible and sol.status == "Infeasible_Forces"
    assert "cannot be held" in sol.diagnosis
    # and the soft version cannot keep a 3-foot stance whose COM lies outside
    opts = ThetaOptions(weights=(1, 1, 1, 2, 0.5))
    sol2 = Theta2(dog, terrain, support=(1, 2, 3), options=opts).solve(start, rc, u_f, u_n)
    assert sol2.feasible  # soft persuasion stays inside and only approaches rc
    com = Theta2(dog, terrain, support=(1, 2, 3)).check.com_W(sol2.state)
    assert np.linalg.norm(com - rc) > 0.1


def test_clearance_constraint_generation_over_a_barrier(littledog):
    """Theta2 lowers the body onto a 7.5 cm barrier under the belly, between the corners.

    The NLP holds the bottom corners and 8 picked points of P; the independent check holds
    all 58. Even when the first round is given the *highest* points (the barrier then
    ignored, the body sinks onto it), the next round picks the violated ones and the
    final configuration clears the barrier everywhere.
    """
    from planner.problems import base

    terrain = load_terrain("barrier75mm")
    start = Theta4(littledog, terrain).solve([0.815, 0.0, 0.17], [1, 0, 0], [0, 0, 1]).state
    rc = Theta2(littledog, terrain).check.com_W(start) - [0.0, 0.0, 0.05]  # pull it down

    natural = Theta2(littledog, terrain)
    sol = natural.solve(start, rc, [1, 0, 0], [0, 0, 1])
    assert sol.feasible, sol.diagnosis
    assert natural.check.clearance(sol.state) == 0.0
    pts_W = littledog.body_clearance_points_B @ sol.state.base_rotation_W.T
    pts_W += sol.state.base_position_W
    lowest = float(np.min(terrain.f_T(pts_W)))
    assert lowest == pytest.approx(natural.options.clearance_m, abs=1e-6)  # resting on it
    assert start.base_position_W[2] - sol.state.base_position_W[2] > 0.02

    forced = Theta2(littledog, terrain)
    rounds = []
    pick = forced._lowest_points_B

    def highest_first(state):
        rounds.append(state)
        if len(rounds) > 1:
            return pick(state)
        pts = forced._candidates_B
        f = terrain.f_T(pts @ state.base_rotation_W.T + state.base_position_W)
        return pts[np.argsort(-f)[: base.CLEARANCE_ACTIVE_POINTS]]

    forced._lowest_points_B = highest_first
    again = forced.solve(start, rc, [1, 0, 0], [0, 0, 1])
    assert len(rounds) >= 2
    assert again.feasible, again.diagnosis
    np.testing.assert_allclose(again.state.base_position_W, sol.state.base_position_W, atol=1e-5)


def _exact_link_clearance(dog, terrain, state):
    """Per capsule: least exact distance of its axis to the sharp terrain minus its radius."""
    from planner.body.links import leg_links
    from planner.planfile.validate import sharp_surface_distance

    links = leg_links(dog)
    q = dog.q_from(state.base_position_W, state.base_quaternion_xyzw, state.joints_rad)
    d = sharp_surface_distance(terrain, links.axis_points_W(q), 0.05, step_m=5e-4) - links.radius
    return np.array([d[links.owner == c].min() for c in range(len(links.capsules))])


@pytest.mark.parametrize("name,x", STANCES)
def test_theta2_keeps_leg_links_off_the_terrain(dog, name, x):
    """Every thigh and shank keeps its keyframe margin, measured exactly (to the ~1 mm
    of the witness cloud); the NLP's rows are the witness distances at the start."""
    from planner.body.links import leg_links
    from planner.problems.base import WITNESS_SLACK_M

    terrain, placed, u_f, u_n = _placed(dog, name, x)
    start = placed.state
    problem = Theta2(dog, terrain, support=(1, 2, 3))
    rc = start.feet_W[[1, 2, 3]].mean(axis=0) + 0.15 * u_n
    # rows at the start with the start's witnesses: n.(axis point - w) - need
    _, wit = problem.check.leg_clearance(start, range(4))
    assert any(w is not None for w in wit)  # the shanks' feet ends are near the ground
    p = problem.params(start, rc, u_f, u_n)
    p[problem._p_slices["leg_clearance_witnesses"]] = problem._link_witness_params(wit)
    x0 = problem.initial_guess(start, p)
    x0[problem._x_slices["p"]] = start.base_position_W  # the start pose itself
    x0[problem._x_slices["theta"]] = start.joints_rad.ravel()
    from planner.core.lie import coords_from_pose

    x0[problem._x_slices["phi"]] = coords_from_pose(start.pose)[3:]
    g = np.array(problem._g_fun(x0, p)).ravel()[problem._g_slices["leg_clearance"]]
    links = leg_links(dog)
    for row, c in zip(g, problem._link_blocks["leg_clearance"][1], strict=True):
        w = wit[c]
        if w is None:
            assert row == pytest.approx(1.0)  # inactive
        else:
            want = w.clearance_m - w.need_m - WITNESS_SLACK_M
            assert row == pytest.approx(want, abs=1e-9), links.describe(c)
    sol = problem.solve(start, rc, u_f, u_n)
    assert sol.feasible, sol.diagnosis
    exact = _exact_link_clearance(dog, terrain, sol.state)
    _, wit = problem.check.leg_clearance(sol.state, range(4))
    for c, w in enumerate(wit):
        need = 0.0 if w is None else w.need_m
        assert exact[c] >= need - 1.2e-3, (links.describe(c), exact[c], need)


def test_theta2_tilt_stays_within_max_tilt_of_u_n(dog):
    """A weak orientation weight and a COM target low and to the side roll the body 11
    degrees; ``max_tilt_rad`` bounds the angle between its z axis and u_n."""
    terrain, placed, _, _ = _placed(dog, "flat", 0.3)
    start = placed.state
    rc = start.feet_W[[1, 2, 3]].mean(axis=0) + [0.0, -0.06, 0.09]
    tilts = {}
    for deg in (3.0, 80.0):
        opts = ThetaOptions(weights=(50, 1, 1, 2, 0.5), max_tilt_rad=np.radians(deg))
        sol = Theta2(dog, terrain, support=(1, 2, 3), options=opts).solve(
            start, rc, [1, 0, 0], [0, 0, 1]
        )
        assert sol.feasible, sol.diagnosis
        tilts[deg] = np.degrees(np.arccos(sol.state.base_rotation_W[2, 2]))
    assert tilts[80.0] > 8.0  # free, it rolls
    assert tilts[3.0] <= 3.0 + 1e-4  # bounded


def test_touchdown_joints_keep_off_their_limits(dog):
    """Theta3 keeps the touch-down joints LANDING_LIMIT_MARGIN_RAD inside the URDF limits
    where it can, so the swing can lift the foot off along the normal again (its pre-pose)."""
    from planner.body.kinematics import kinematics_of
    from planner.problems.base import LANDING_LIMIT_MARGIN_RAD, landing_bounds_rad

    terrain, placed, _, _ = _placed(dog, "flat", 0.3)
    start, leg = placed.state, 1  # FR, pulled far outward: the hip roll would hit its stop
    sol = Theta3(dog, terrain, leg=leg).solve(start, start.feet_W[leg] + [0.0, -0.1, 0.0])
    assert sol.feasible, sol.diagnosis
    lo, hi = landing_bounds_rad(dog, leg)
    np.testing.assert_allclose(lo, dog.lower_rad[leg] + LANDING_LIMIT_MARGIN_RAD)
    th = sol.state.joints_rad[leg]
    assert np.all(th >= lo - 1e-9) and np.all(th <= hi + 1e-9)
    assert th[0] == pytest.approx(lo[0], abs=1e-3)  # the bound is what holds it
    # the sphere centre 1 cm up from the touch-down is reachable (same knee branch)
    kin = kinematics_of(dog)
    up_B = kin.foot_B(leg, th) + sol.state.base_rotation_W.T @ [0.0, 0.0, 0.01]
    ik = kin.ik_leg(leg, up_B, reference_rad=th, knee=kin.knee_direction(leg, th))
    assert ik.reachable and not ik.knee_flipped


def test_touchdown_uses_the_margin_only_where_nothing_else_lands(dog):
    """A foothold reachable only with the hip roll past the margin (the target radius
    holds the foot within 2.08 cm of a point 10 cm outward: 2.17 cm within the margin,
    1.99 cm without) is still found, within the URDF limits."""
    from planner.problems.base import landing_bounds_rad

    terrain, placed, _, _ = _placed(dog, "flat", 0.3)
    start, leg = placed.state, 1
    target = start.feet_W[leg] + [0.0, -0.1, 0.0]
    sol = Theta3(dog, terrain, leg=leg).solve(start, target, target_radius_m=0.0208)
    assert sol.feasible, sol.diagnosis
    th = sol.state.joints_rad[leg]
    lo, _ = landing_bounds_rad(dog, leg)
    assert th[0] < lo[0] - 1e-3  # past the margin: the margin alone finds nothing
    assert np.all(th >= dog.lower_rad[leg] - 1e-9) and np.all(th <= dog.upper_rad[leg] + 1e-9)
    assert np.linalg.norm(sol.state.feet_W[leg] - target) <= 0.0208 + 1e-6


def test_theta2_retry_starts_turned_to_the_reference_directions(dog):
    """Theta2's second start (after an infeasible first solve): the body turned to
    (u_f, u_n), its COM moved toward r_c*, the legs on the same foot centres (the leaf)."""
    from planner.core.lie import pose_from_coords
    from planner.motion.heuristics import frame_from_directions

    terrain, placed, u_f, _ = _placed(dog, "step5cm", None)
    start = placed.state
    problem = Theta2(dog, terrain, support=(1, 2, 3))
    pitch = np.radians(15.0)
    u_n = np.array([-np.sin(pitch), 0.0, np.cos(pitch)])
    rc = problem.check.com_W(start) + [0.02, 0.0, 0.01]
    p = problem.params(start, rc, u_f, u_n)
    x0 = problem.initial_guess(start, p, turned=True)
    T = pose_from_coords(np.concatenate([problem.x_block(x0, "p"), problem.x_block(x0, "phi")]))
    np.testing.assert_allclose(T[:3, :3], frame_from_directions(u_f, u_n), atol=1e-9)
    joints = problem.x_block(x0, "theta").reshape(4, 3)
    feet = problem.kin.feet_W(T[:3, 3], T[:3, :3], joints)
    centres = p[problem._p_slices["centres_W"]].reshape(4, 3)
    np.testing.assert_allclose(feet, centres, atol=1e-8)
    sol = problem.solve(start, rc, u_f, u_n)
    assert sol.feasible, sol.diagnosis


def test_theta2_keeps_the_commanded_torques_within_the_fraction(dog):
    """On three legs straddling a step, Theta2 loads a hip pitch to 57 % of its effort; asked
    for at most 40 %, it finds a pose that the independent check (Clarabel) confirms."""
    from dataclasses import replace

    from planner.body.torques import TorqueCheck

    terrain, placed, u_f, u_n = _placed(dog, "step5cm", None)
    start, support = placed.state, (1, 2, 3)
    rc = start.feet_W[list(support)].mean(axis=0) + 0.15 * u_n
    tc = TorqueCheck(dog)

    def ratio(state):
        q = dog.q_from(state.base_position_W, state.base_quaternion_xyzw, state.joints_rad)
        normals = terrain.normal(state.feet_W)
        return tc.solve(q, support, terrain_mu(terrain), normals, least_squares=True).ratio

    loose = Theta2(dog, terrain, support=support, options=ThetaOptions(torque_fraction=None))
    sol = loose.solve(start, rc, u_f, u_n)
    assert sol.feasible and ratio(sol.state) > 0.5
    tight = Theta2(dog, terrain, support=support,
                   options=replace(ThetaOptions(), torque_fraction=0.4))  # fmt: skip
    sol = tight.solve(start, rc, u_f, u_n)
    assert sol.feasible, sol.diagnosis
    assert ratio(sol.state) <= 0.4 + 1e-4
    assert tight._torque_problem is not None  # solved with the torque rows


def test_theta2_stiffens_a_three_leg_stance_when_asked(dog):
    """Straddling a step, Theta2's three-leg pose has some sway stiffness on the servos;
    asked for 1.2 times it, the cuts find a pose that the independent Hessian confirms."""
    from dataclasses import replace

    from planner.body.stiffness import sway_stiffness_of
    from planner.body.torques import TorqueCheck

    terrain, placed, u_f, u_n = _placed(dog, "step5cm", None)
    start, support = placed.state, (1, 2, 3)
    rc = start.feet_W[list(support)].mean(axis=0) + 0.15 * u_n
    sway, tc = sway_stiffness_of(dog), TorqueCheck(dog)

    def stiffness(state):
        q = dog.q_from(state.base_position_W, state.base_quaternion_xyzw, state.joints_rad)
        normals = terrain.normal(state.feet_W)
        tau = tc.solve(q, support, terrain_mu(terrain), normals, least_squares=True).torques_nm
        R = state.base_rotation_W
        return sway.stance(state.base_position_W, R, state.joints_rad, support, tau).least

    loose = Theta2(dog, terrain, support=support, options=ThetaOptions(sway_stiffness=None))
    sol = loose.solve(start, rc, u_f, u_n)
    assert sol.feasible
    have = stiffness(sol.state)
    assert have > sway.minimum_n_per_m  # the default bound holds here already
    want = 1.2 * have / sway.bound_n_per_m(1.0)
    tight = Theta2(dog, terrain, support=support,
                   options=replace(ThetaOptions(), sway_stiffness=want))  # fmt: skip
    sol = tight.solve(start, rc, u_f, u_n)
    assert sol.feasible, sol.diagnosis
    assert stiffness(sol.state) >= sway.bound_n_per_m(want)
    assert tight._sway_problem is not None  # solved with the sway rows
    # a feasible pose below the aim is made stiffer where a stiffer one exists
    aiming = Theta2(dog, terrain, support=support,
                    options=replace(ThetaOptions(), sway_stiffness_aim=want))  # fmt: skip
    sol = aiming.solve(start, rc, u_f, u_n)
    assert sol.feasible, sol.diagnosis
    assert stiffness(sol.state) >= sway.bound_n_per_m(want)


def test_theta2_on_a_support_narrower_than_the_balance_margin_solves_nothing(dog, monkeypatch):
    """HL's foot under the body, 3 cm right of the centre line: the triangle FR-HL-HR
    has an inradius below the 25 mm balance margin, so no COM, hence no body pose, keeps
    it. Theta2 says so without IPOPT; IPOPT, asked anyway, finds no pose either, and its
    best keeps no more margin than the inradius."""
    from planner.body.stability import support_margin_m, triangle_inradius_m

    terrain, placed, u_f, u_n = _placed(dog, "flat", 0.3)
    start, support = placed.state.copy(), (1, 2, 3)
    start.feet_W = np.array(start.feet_W, float)
    start.feet_W[2, 1] = -0.03 + placed.state.base_position_W[1]
    room = triangle_inradius_m(start.feet_W[list(support)])
    problem = Theta2(dog, terrain, support=support)
    margin = problem.options.balance_margin_m
    assert 0.0 < room < margin
    rc = start.feet_W[list(support)].mean(axis=0) + 0.15 * u_n
    solves = []
    real = problem.solve_packed
    monkeypatch.setattr(problem, "solve_packed", lambda *a: solves.append(a) or real(*a))
    sol = problem.solve(start, rc, u_f, u_n)
    assert not solves and not sol.feasible and sol.status == "support_too_small"
    assert "'balance_margin'" in sol.diagnosis and "inradius" in sol.diagnosis
    from planner.core.failures import FailureKind

    assert sol.failure == (FailureKind.BALANCE_MARGIN,)  # the kind the planners branch on
    assert sol.violations == {"balance_margin": pytest.approx(margin - room)}
    # the reference: IPOPT from the start
    p = problem.params(start, rc, u_f, u_n)
    ipopt = real(p, problem.initial_guess(start, p))
    assert not ipopt.feasible
    have = support_margin_m(ipopt.state.feet_W[list(support)], problem.check.com_W(ipopt.state))
    assert have <= room + 1e-9


def _can_lift(problem, state, leg, terrain):
    """Independently (Paden-Kahan IK): can ``leg`` lift its sphere ``lift_m`` up the normal?"""
    from planner.body.contact import foot_centre_from_contact
    from planner.problems.base import landing_bounds_rad

    c = foot_centre_from_contact(terrain, state.feet_W[leg], problem.robot.foot_radius_m)
    up = c + problem.lift_m * terrain.normal(state.feet_W[leg])
    th = state.joints_rad[leg]
    ik = problem.kin.ik_leg(
        leg,
        state.base_rotation_W.T @ (up - state.base_position_W),
        reference_rad=th,
        knee=problem.kin.knee_direction(leg, th),
    )
    lo, hi = landing_bounds_rad(problem.robot, leg)
    inside = np.all(ik.joints_rad >= lo - 1e-9) and np.all(ik.joints_rad <= hi + 1e-9)
    return bool(ik.reachable and not ik.knee_flipped and inside)


def test_lift_ready_body_move_leaves_the_swing_leg_room_to_lift(dog):
    """A low body folds a hind leg to its knee limit: lift-ready keeps it able to lift off."""
    terrain, placed, u_f, u_n = _placed(dog, "flat", 0.3)
    start, leg = placed.state, 2  # HL swings next
    support = tuple(i for i in range(4) if i != leg)
    target = start.feet_W[leg] + np.array([0.05, 0.0, 0.0])
    rc = start.feet_W[list(support)].mean(axis=0) + 0.07 * u_n  # below the legs' room
    solved = {}
    for lift in (False, True):
        problem = Theta2(
            dog, terrain, support=support, options=ThetaOptions(lift_ready=lift), landing=True
        )
        sol = problem.solve(start, rc, u_f, u_n, target)
        assert sol.feasible, sol.diagnosis
        solved[lift] = (problem, sol)
    problem, sol = solved[False]
    assert not _can_lift(problem, sol.state, leg, terrain)  # the case bites without it
    problem, sol = solved[True]
    assert _can_lift(problem, sol.state, leg, terrain)
    # the lift joints Theta2 proved put the sphere there (Pinocchio's frames)
    lifted = sol.state.copy()
    lifted.joints_rad = sol.state.joints_rad.copy()
    lifted.joints_rad[leg] = problem.x_block(sol.x, "theta_lift")
    n = terrain.normal(start.feet_W[leg])
    want = problem.check.foot_centres_W(start)[leg] + problem.lift_m * n
    np.testing.assert_allclose(problem.check.foot_centres_W(lifted)[leg], want, atol=1e-6)
