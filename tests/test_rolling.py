"""Rolling sphere feet (planner.body.rolling): against Pinocchio, the validator and MuJoCo."""

import numpy as np
import pinocchio as pin
import pytest

from planner.body.rolling import end_keyframe, rolling_displacement, sliding
from planner.motion.interpolate import interpolate_leaf
from planner.planfile.plan import Plan
from planner.planfile.validate import check_plan
from planner.problems import Theta2, Theta4
from planner.sim.simulate import SimSettings, run_open_loop
from planner.world.terrain import load_terrain

OUTCOME = {"reached_goal": True, "distance_to_goal": 0.0, "message": "test"}


def _body_move(dog, terrain_name, x=0.4, rolling=True, n=12):
    """Theta4 stance, then Theta2 onto legs 2-4: the leaf between them."""
    terrain = load_terrain(terrain_name)
    z = float(terrain.height(x, 0.0)) + 0.15
    a = Theta4(dog, terrain).solve([x, 0.0, z], [1, 0, 0], [0, 0, 1]).state
    rc = a.feet_W[[1, 2, 3]].mean(axis=0) + [0.0, 0.0, 0.15]
    b = Theta2(dog, terrain, support=(1, 2, 3)).solve(a, rc, [1, 0, 0], [0, 0, 1]).state
    return terrain, a, b, interpolate_leaf(dog, terrain, a, b, n, rolling=rolling)


def _pinocchio_feet(dog, states):
    """(N, 4, 3) foot centres and (N, 4, 3, 3) foot frame rotations by Pinocchio."""
    model, data = dog.model, dog.model.createData()
    ids = [model.getFrameId(f) for f in dog.foot_frames]
    c, R = [], []
    for s in states:
        q = dog.q_from(s.base_position_W, s.base_quaternion_xyzw, s.joints_rad)
        pin.framesForwardKinematics(model, data, q)
        c.append([data.oMf[i].translation.copy() for i in ids])
        R.append([data.oMf[i].rotation.copy() for i in ids])
    return np.array(c), np.array(R)


def test_leg_rotations_turn_as_pinocchio_s_feet(littledog):
    """leg_rotations_W (Rodrigues per joint) turns each shank as Pinocchio's foot frame."""
    from planner.body.kinematics import kinematics_of
    from planner.body.rolling import leg_rotations_W

    kin = kinematics_of(littledog)
    model, data = littledog.model, littledog.model.createData()
    ids = [model.getFrameId(f) for f in littledog.foot_frames]
    rng = np.random.default_rng(3)
    rots, pins = [], []
    for _ in range(2):
        R = pin.exp3(rng.normal(size=3))
        joints = rng.uniform(-1.0, 1.0, (4, 3))
        rots.append(leg_rotations_W(kin, R, joints))
        q = littledog.q_from(np.zeros(3), pin.Quaternion(R).coeffs(), joints)
        pin.framesForwardKinematics(model, data, q)
        pins.append(np.array([data.oMf[i].rotation.copy() for i in ids]))
    for i in range(4):  # relative rotations: the shank's constant zero-pose frame cancels
        np.testing.assert_allclose(rots[1][i] @ rots[0][i].T, pins[1][i] @ pins[0][i].T, atol=1e-12)


@pytest.mark.parametrize("terrain_name", ["flat", "slope10", "rough2cm"])
def test_stance_feet_roll_without_sliding(littledog, terrain_name):
    terrain, a, b, path = _body_move(littledog, terrain_name, x=1.2)
    c, R = _pinocchio_feet(littledog, path)
    rho = littledog.foot_radius_m
    travel = np.linalg.norm(c[-1] - c[0], axis=1)
    assert travel.max() > 1e-3  # the body move turns the shanks: the feet roll mm
    for k in range(len(path) - 1):
        n = terrain.normal(path[k].feet_W)
        assert sliding(c[k], c[k + 1], R[k], R[k + 1], n, rho).max() < 1e-8
        # the centre moved by the rolling rho w x n, and rests on the terrain
        roll = rolling_displacement(R[k], R[k + 1], n, rho)
        assert np.abs((c[k + 1] - c[k]) - roll).max() < 1e-6
    assert np.abs(terrain.f_T(path[-1].feet_W)).max() < 1e-6  # the contact fit (contact.py)
    # the paper's leaf (fixed contact points) slides by the same millimetres
    fixed = interpolate_leaf(littledog, terrain, a, b, len(path), rolling=False)
    cf, Rf = _pinocchio_feet(littledog, fixed)
    slid = sum(
        sliding(cf[k], cf[k + 1], Rf[k], Rf[k + 1], terrain.normal(fixed[k].feet_W), rho)
        for k in range(len(fixed) - 1)
    )
    assert slid.max() > 0.5 * travel.max()


def _plan(dog, terrain, path):
    """A plan of the body move, its end a keyframe with the rolled feet."""
    end = end_keyframe(dog, path, (1, 2, 3))
    samples = path[:-1] + [end]
    return Plan.build(
        dog, terrain, terrain.friction, path[0].base_position_W, end.base_position_W,
        [path[0], end], samples, list(0.25 * np.arange(len(samples))), OUTCOME,
    )  # fmt: skip


def test_check_accepts_rolling_and_rejects_fixed_centres(littledog):
    terrain, a, b, path = _body_move(littledog, "flat")
    report = check_plan(_plan(littledog, terrain, path))
    assert report.ok, "\n".join(map(str, report.violations))
    assert report.max_slip_m < 1e-8
    fixed = interpolate_leaf(littledog, terrain, a, b, len(path), rolling=False)
    kinds = check_plan(_plan(littledog, terrain, fixed)).by_kind()
    assert kinds.get("stance_slip", 0) > 0


def test_mujoco_feet_roll_as_planned(littledog):
    """Executed open loop, the rolled plan ends where planned; the fixed-centre one does not."""
    terrain, a, b, path = _body_move(littledog, "flat", n=16)
    fixed = interpolate_leaf(littledog, terrain, a, b, len(path), rolling=False)
    settings = SimSettings(time_scale=1.0, settle_s=0.5, hold_s=0.3)
    err = {}
    for name, p in (("rolling", path), ("fixed", fixed)):
        plan = _plan(littledog, terrain, p)
        m = run_open_loop(plan, settings).metrics
        assert not m.fell and m.max_sliding_m < 1e-3, m.summary()
        err[name] = m.final_error_3d_m
    # the servos track to a degree or so; the rolling model removes the systematic part
    assert err["rolling"] < 0.6 * err["fixed"], err


def test_rolled_centres_in_casadi_are_pinocchios_log_with_exact_derivatives(littledog):
    """Theta2's rolling (c + rho w x n) against rolled_centres_W (w by Pinocchio's log3),
    its Jacobian against central differences, both at and away from zero rotation."""
    import casadi as ca

    from planner.body.kinematics import kinematics_of
    from planner.body.rolling import leg_rotations_W, rolled_centres_W, rolled_centres_W_ca

    kin = kinematics_of(littledog)
    rng = np.random.default_rng(5)
    R0, j0 = pin.exp3(rng.normal(size=3)), littledog.theta_nor.copy()
    shanks = leg_rotations_W(kin, R0, j0)
    c0 = rng.normal(size=(4, 3))
    n = rng.normal(size=(4, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    th = ca.SX.sym("th", 12)
    expr = rolled_centres_W_ca(kin, ca.DM(R0), th, ca.DM(c0.T), ca.DM(n.T),
                               ca.DM(np.column_stack([R.T.ravel() for R in shanks])))  # fmt: skip
    f = ca.Function("f", [th], [ca.vec(expr)])
    jac = ca.Function("J", [th], [ca.jacobian(ca.vec(expr), th)])
    for joints in (j0, j0 + rng.normal(scale=0.4, size=(4, 3))):
        want = rolled_centres_W(kin, R0, joints, c0, shanks, n)
        np.testing.assert_allclose(np.array(f(joints.ravel())).reshape(4, 3), want, atol=1e-12)
        J = np.array(jac(joints.ravel()))
        h, fd = 1e-6, np.zeros_like(J)
        for k in range(12):
            e = np.zeros(12)
            e[k] = h
            fd[:, k] = (np.array(f(joints.ravel() + e)) - np.array(f(joints.ravel() - e))).ravel()
        np.testing.assert_allclose(J, fd / (2 * h), atol=1e-8)
    np.testing.assert_allclose(np.array(f(j0.ravel())).reshape(4, 3), c0, atol=1e-15)


@pytest.mark.parametrize("terrain_name", ["flat", "rough2cm"])
def test_theta2_poses_the_legs_where_the_path_rolls_the_feet(littledog, terrain_name):
    """Theta2 solves for the centres its stance spheres roll to: the interpolated path
    (rolling, the validator's model) ends within 0.1 mm of them, where the paper's fixed
    contacts (``rolling_feet`` off) end millimetres off."""
    from planner.problems.options import ThetaOptions

    terrain = load_terrain(terrain_name)
    z = float(terrain.height(1.2, 0.0)) + 0.15
    a = Theta4(littledog, terrain).solve([1.2, 0.0, z], [1, 0, 0], [0, 0, 1]).state
    rc = a.feet_W[[1, 2, 3]].mean(axis=0) + [0.0, 0.0, 0.15]
    misses = {}
    for rolling in (True, False):
        opts = ThetaOptions(rolling_feet=rolling)
        sol = Theta2(littledog, terrain, support=(1, 2, 3), options=opts).solve(
            a, rc, [1, 0, 0], [0, 0, 1]
        )
        assert sol.feasible, sol.diagnosis
        path = interpolate_leaf(littledog, terrain, a, sol.state, 12)
        (c0, end, posed), _ = _pinocchio_feet(littledog, [a, path[-1], sol.state])
        assert np.abs(end - c0).max() > 2e-3  # the feet rolled millimetres
        misses[rolling] = float(np.linalg.norm(end - posed, axis=1).max())
    assert misses[True] < 1e-4 and misses[False] > 2e-3, misses
