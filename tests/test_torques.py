"""Joint torques of a stance (planner.body.torques) against Pinocchio's RNEA and the validator."""

import numpy as np
import pinocchio as pin
import pytest

from planner.body.robot import load_robot
from planner.body.statics import equilibrating_forces
from planner.body.torques import TorqueCheck, joint_efforts_nm
from planner.planfile.plan import Plan
from planner.planfile.validate import check_plan


@pytest.fixture(scope="module")
def flat_plan(tmp_path_factory):
    from planner.planning.walk import plan_walk

    plan, report = plan_walk("littledog", "flat", goal_xy=(0.4, 0.0))
    assert report.ok
    return plan


def _rnea_torques(robot, q, forces_W, rho=0.0103, normals=None):
    """tau = g(q) - sum J^T f by RNEA with the contact forces as external joint forces.

    Contact points c - rho n (``normals`` (4, 3); None: flat ground)."""
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, q)
    fext = [pin.Force.Zero() for _ in range(model.njoints)]
    for i, frame in enumerate(robot.foot_frames):
        f = forces_W[i]
        if not np.any(f):
            continue
        fr = model.frames[model.getFrameId(frame)]
        M = data.oMi[fr.parentJoint]
        up = [0.0, 0.0, 1.0] if normals is None else normals[i]
        point = data.oMf[model.getFrameId(frame)].translation - rho * np.asarray(up)
        R = M.rotation
        fext[fr.parentJoint] += pin.Force(R.T @ f, R.T @ np.cross(point - M.translation, f))
    nv = model.nv
    return pin.rnea(model, data, q, np.zeros(nv), np.zeros(nv), fext)


def test_torques_match_rnea_and_beat_eq5(flat_plan, littledog):
    tc = TorqueCheck(littledog)
    up = np.tile([0.0, 0.0, 1.0], (4, 1))
    for k in (0, len(flat_plan.samples) // 3, len(flat_plan.samples) // 2):
        q = flat_plan.samples.q[k]
        sup = np.flatnonzero(flat_plan.samples.contact[k])
        res = tc.solve(q, sup, 0.7, up)
        assert res.feasible and res.status == "Solved"
        tau = _rnea_torques(littledog, q, res.forces_W)
        assert np.abs(tau[:6]).max() < 1e-6  # the forces balance the robot
        v = [littledog.model.joints[littledog.model.getJointId(n)].idx_v
             for n in littledog.joint_names]  # fmt: skip
        np.testing.assert_allclose(tau[v], res.torques_nm, atol=1e-6)
        effort = joint_efforts_nm(littledog)
        assert res.ratio == pytest.approx(np.max(np.abs(res.torques_nm) / effort), abs=1e-9)
        # eq. 5's particular forces are admissible, so they need at least the optimum
        model, data = littledog.model, littledog.model.createData()
        com = pin.centerOfMass(model, data, q)
        pin.framesForwardKinematics(model, data, q)
        feet = np.array([data.oMf[model.getFrameId(f)].translation for f in littledog.foot_frames])
        eq5 = equilibrating_forces(feet - [0, 0, 0.0103], com, littledog.total_mass_kg, sup)
        tau5 = _rnea_torques(littledog, q, eq5.forces)[v]
        assert np.max(np.abs(tau5) / effort) >= res.ratio - 1e-6


def test_check_rejects_torques_beyond_the_limit(flat_plan, tmp_path):
    """The same plan on a LittleDog whose knees give 0.05 N m: joint_torque names a knee."""
    assert check_plan(flat_plan).max_torque_ratio < 0.8
    dog = load_robot("littledog")
    text = dog.urdf_path.read_text().replace('effort="0.6"', 'effort="0.05"')
    weak = tmp_path / "weak_littledog.urdf"
    weak.write_text(text)
    plan = Plan.from_dict(flat_plan.to_dict(), source="edited")
    plan.robot = {**plan.robot, "urdf": str(weak)}
    report = check_plan(plan)
    torque = [v for v in report.violations if v.kind == "joint_torque"]
    assert torque and set(report.by_kind()) == {"joint_torque"}
    assert all("knee" in v.message and v.value > 1.0 for v in torque)
    assert "x its effort limit 0.05 N m" in torque[0].message
    assert report.max_torque_ratio > 1.0


def test_commanded_forces_keep_a_friction_reserve(flat_plan, littledog, monkeypatch):
    """On an 18 degree incline the least-squares forces lean along the legs onto the cones'
    edges; the commanded distribution stays in cones of the first of
    COMMANDED_FRICTION_SHARES x mu (the rest a reserve for the servos' errors) that balance
    the robot loading no joint beyond COMMANDED_TORQUE_FRACTION, else in the whole cone.
    Balance by RNEA; the cones measured on the forces."""
    import planner.body.torques as torques

    tilt = np.radians(18.0)
    n = np.tile([-np.sin(tilt), 0.0, np.cos(tilt)], (4, 1))  # uphill in +x
    tc = TorqueCheck(littledog)
    share = torques.COMMANDED_FRICTION_SHARES[0]
    assert 0.0 < share < 1.0

    efforts = joint_efforts_nm(littledog)

    def effort_cost(res):  # sum_j (tau_j / effort_j)^2
        return float(np.sum((np.ravel(res.torques_nm) / efforts) ** 2))

    def cone_ratios(res, sup):  # |f_t| / f_n per stance foot
        fn = np.einsum("ij,ij->i", res.forces_W[sup], n[sup])
        ft = np.linalg.norm(res.forces_W[sup] - fn[:, None] * n[sup], axis=1)
        assert np.all(fn > 0.0)
        return ft / fn

    for k in (0, len(flat_plan.samples) // 3, len(flat_plan.samples) // 2):
        q = flat_plan.samples.q[k]
        sup = np.flatnonzero(flat_plan.samples.contact[k])
        for mu in (0.7, 0.4):  # tan 18 deg = 0.32: 0.7 x 0.4 = 0.28 cannot hold the robot
            res = tc.solve(q, sup, mu, n, least_squares=True)
            assert res.status == "Solved"
            assert np.abs(_rnea_torques(littledog, q, res.forces_W, normals=n)[:6]).max() < 1e-6
            cap = share * mu if share * mu > np.tan(tilt) else mu
            assert cone_ratios(res, sup).max() <= cap + 1e-6
            assert cone_ratios(res, sup).max() > np.tan(tilt)  # some foot leans (not vacuous)
            if mu == 0.7:  # the reserve is kept here: a 0.8 fraction is not reached
                assert res.ratio <= torques.COMMANDED_TORQUE_FRACTION
        # without the reserve the same stance puts a foot on the whole cone's edge, and so
        # does the reserve's fallback where every share would load a joint beyond the fraction
        monkeypatch.setattr(torques, "COMMANDED_FRICTION_SHARES", ())
        edge = tc.solve(q, sup, 0.7, n, least_squares=True)
        monkeypatch.undo()
        assert cone_ratios(edge, sup).max() > share * 0.7 + 1e-3
        reserved = tc.solve(q, sup, 0.7, n, least_squares=True)
        # the reserve costs torque: the least squares sum_j (tau_j / effort_j)^2 it minimises
        # (its max, the ratio, may fall either way) is larger in the narrower cones
        assert effort_cost(reserved) > effort_cost(edge) * (1.0 + 1e-4)
        monkeypatch.setattr(torques, "COMMANDED_TORQUE_FRACTION", 0.0)  # no share admitted
        fallback = tc.solve(q, sup, 0.7, n, least_squares=True)
        monkeypatch.undo()
        np.testing.assert_allclose(fallback.forces_W, edge.forces_W, atol=1e-4)


def test_no_balance_is_infinite(littledog):
    tc = TorqueCheck(littledog)
    q = pin.neutral(littledog.model)
    q[2] = 0.2
    # three feet far to one side of the COM cannot hold it: no admissible forces at all
    res = tc.solve(q, [0, 1, 2], 0.01, np.tile([1.0, 0.0, 0.0], (4, 1)))
    assert not res.feasible and res.ratio == np.inf


def test_least_squares_torques_are_the_equality_constrained_optimum(flat_plan, littledog):
    """With wide cones, min |tau / effort|^2 subject to balance has a closed form (KKT, numpy)."""
    tc = TorqueCheck(littledog)
    up = np.tile([0.0, 0.0, 1.0], (4, 1))
    model = littledog.model
    v = [model.joints[model.getJointId(n)].idx_v for n in littledog.joint_names]
    base = [i for i in range(model.nv) if i not in v]
    for k in (0, len(flat_plan.samples) // 2):  # a four-leg and a three-leg stance
        q = flat_plan.samples.q[k]
        sup = np.flatnonzero(flat_plan.samples.contact[k])
        res = tc.solve(q, sup, 5.0, up, least_squares=True)
        tau_rnea = _rnea_torques(littledog, q, res.forces_W)
        assert np.abs(tau_rnea[:6]).max() < 1e-6  # the forces balance the robot
        np.testing.assert_allclose(tau_rnea[v], res.torques_nm, atol=1e-6)
        # reference: tau = g_a - A f, min |W tau|^2 s.t. B f = g_b, by the KKT system, with
        # W = 1 / (URDF effort) (LittleDog: 1.7 N m hips, 0.6 N m knees)
        data = model.createData()
        g = pin.computeGeneralizedGravity(model, data, q)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        cols = []
        for i in sup:
            J = pin.getFrameJacobian(
                model, data, model.getFrameId(littledog.foot_frames[i]), pin.LOCAL_WORLD_ALIGNED
            )
            d = np.array([0.0, 0.0, -littledog.foot_radius_m])
            hat = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
            cols.append((J[:3] - hat @ J[3:]).T)
        jt = np.hstack(cols)
        w = 1.0 / np.array([model.effortLimit[i] for i in v])
        a, b = jt[v], jt[base]
        wa = w[:, None] * a
        n = a.shape[1]
        kkt = np.block([[2 * wa.T @ wa, b.T], [b, np.zeros((len(base), len(base)))]])
        rhs = np.concatenate([2 * wa.T @ (w * g[v]), g[base]])
        f = np.linalg.lstsq(kkt, rhs, rcond=None)[0][:n]
        np.testing.assert_allclose(res.torques_nm, g[v] - a @ f, atol=2e-5)
        # it is a balancing distribution, so it needs at least the least achievable ratio
        assert res.ratio >= tc.solve(q, sup, 5.0, up).ratio - 1e-7


@pytest.mark.parametrize("course", ["flat", "rough2cm"])
def test_least_squares_without_active_cones_is_the_socp(flat_plan, littledog, course):
    """The closed form solve() takes where no cone is active gives the SOCP's optimum.

    Every third sample of a plan, with mu = 0.7: the same forces and torque ratio as
    Clarabel's SOCP (to its tolerance), taken for most stances; where a cone is active
    the SOCP is solved.
    """
    from planner.world.terrain import load_terrain

    terrain = load_terrain(course)
    tc = TorqueCheck(littledog)
    model, data = littledog.model, littledog.model.createData()
    closed = total = 0
    for q, contact in zip(flat_plan.samples.q[::3], flat_plan.samples.contact[::3], strict=True):
        q = q.copy()
        q[2] += float(terrain.height(q[0], q[1]))  # the same stance, on this terrain
        pin.framesForwardKinematics(model, data, q)
        centres = np.array([data.oMf[f].translation for f in tc.foot_ids])
        normals = terrain.normal(centres)
        sup = np.flatnonzero(contact)
        fast = tc.solve(q, sup, 0.7, normals, least_squares=True)
        jt = tc._contact_jacobian_T(q, list(sup), normals)
        g = pin.computeGeneralizedGravity(model, data, q)
        f = tc._least_squares_forces(jt, g)
        weight = 9.81 * littledog.total_mass_kg
        took = f is not None and tc._inside_cones(f, normals[sup], 0.7, weight)
        closed, total = closed + took, total + 1
        tc._least_squares_forces = lambda *args: None  # force the SOCP
        socp = tc.solve(q, sup, 0.7, normals, least_squares=True)
        del tc._least_squares_forces
        assert fast.status == socp.status == "Solved"
        assert fast.ratio == pytest.approx(socp.ratio, abs=1e-6)
        np.testing.assert_allclose(fast.forces_W, socp.forces_W, atol=1e-4)
        np.testing.assert_allclose(fast.torques_nm, socp.torques_nm, atol=1e-6)
    assert closed >= 0.5 * total


def test_commanded_ratio_map_carries_a_body_acceleration(flat_plan, littledog):
    """commanded_ratio_map (closed form, linear in gravity) against the SOCP and RNEA.

    A body accelerating at a with its joints held needs the generalized forces of gravity
    g - a (d'Alembert; RNEA with the base's acceleration is the reference), and the map
    gives the commanded distribution's torques for any gravity vector: the SOCP's
    (Clarabel, wide cones) solved with the model's gravity set to g - a.
    """
    tc = TorqueCheck(littledog)
    up = np.tile([0.0, 0.0, 1.0], (4, 1))
    model, data = littledog.model, littledog.model.createData()
    g0 = model.gravity.linear.copy()
    accel_W = np.array([0.4, -0.7, 0.3])  # [m/s^2]
    for k in (0, len(flat_plan.samples) // 2):  # a four-leg and a three-leg stance
        q = flat_plan.samples.q[k]
        sup = np.flatnonzero(flat_plan.samples.contact[k])
        M = tc.commanded_ratio_map(q, sup, up)
        assert np.allclose(model.gravity.linear, g0)  # the model's gravity is left as it was
        R = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
        a = np.zeros(model.nv)
        a[:3] = R.T @ accel_W  # the free flyer's acceleration, in the base frame
        dyn = pin.rnea(model, data, q, np.zeros(model.nv), a)
        try:
            model.gravity.linear = g0 - accel_W
            np.testing.assert_allclose(
                pin.computeGeneralizedGravity(model, data, q), dyn, atol=1e-9
            )
            for gravity in (g0, g0 - accel_W):
                model.gravity.linear = gravity
                res = tc.solve(q, sup, 5.0, up, least_squares=True)
                np.testing.assert_allclose(M @ gravity, res.torques_nm / tc.effort, atol=1e-5)
        finally:
            model.gravity.linear = g0


def test_symbolic_least_squares_torques_equal_the_socp(flat_plan, littledog):
    """least_squares_ratios_ca (CasADi, Theta2's torque rows) against TorqueCheck (Clarabel).

    Three-leg samples of a plan, tilted normals and turned bodies: wherever the SOCP's
    optimum lies inside the cones the two distributions agree; gravity per leg against
    Pinocchio's generalized gravity.
    """
    import casadi as ca
    from scipy.spatial.transform import Rotation

    from planner.body.kinematics import kinematics_of
    from planner.body.torques import least_squares_ratios_ca

    kin = kinematics_of(littledog)
    effort = joint_efforts_nm(littledog)
    tc = TorqueCheck(littledog)
    model, data = littledog.model, littledog.model.createData()
    v = [model.joints[model.getJointId(n)].idx_v for n in littledog.joint_names]
    pos, th = ca.SX.sym("p", 3), ca.SX.sym("th", 12)
    rot = ca.SX.sym("R", 3, 3)
    normals = [ca.SX.sym(f"n{i}", 3) for i in range(4)]
    centres = kin.feet_W_ca(pos, rot, th)
    contacts = [centres[:, i] - littledog.foot_radius_m * normals[i] for i in range(4)]
    com = pos + ca.mtimes(rot, kin.com_B_ca(th))
    gravity = ca.Function(
        "g",
        [rot, th],
        [
            ca.vertcat(*[kin.gravity_torque_ca(i, rot, th[3 * i : 3 * i + 3]) for i in range(4)])
        ],  # fmt: skip
    )
    rng = np.random.default_rng(3)
    three = np.flatnonzero(flat_plan.samples.contact.sum(axis=1) == 3)
    compared = 0
    for k in three[:: max(len(three) // 6, 1)]:
        q = flat_plan.samples.q[k].copy()
        sup = tuple(np.flatnonzero(flat_plan.samples.contact[k]))
        turn = Rotation.from_rotvec(rng.normal(0.0, 0.1, 3))
        q[3:7] = (turn * Rotation.from_quat(q[3:7])).as_quat()
        R = Rotation.from_quat(q[3:7]).as_matrix()
        ns = np.array([0.0, 0.0, 1.0]) + rng.normal(0.0, 0.1, (4, 3))
        ns /= np.linalg.norm(ns, axis=1, keepdims=True)
        np.testing.assert_allclose(
            np.array(gravity(R, q[7:])).ravel(),
            pin.computeGeneralizedGravity(model, data, q)[v],
            atol=1e-12,
        )
        ratios, forces = least_squares_ratios_ca(
            kin, rot, th, sup, contacts, normals, com, effort, littledog.total_mass_kg
        )
        f = ca.Function("f", [pos, rot, th, *normals], [ratios, *forces])
        out = [np.array(o).ravel() for o in f(q[:3], R, q[7:], *ns)]
        res = tc.solve(q, sup, 5.0, ns, least_squares=True)
        assert res.status == "Solved"
        ref = np.concatenate([res.torques_nm[3 * i : 3 * i + 3] / effort[3 * i : 3 * i + 3]
                              for i in sup])  # fmt: skip
        np.testing.assert_allclose(out[0], ref, atol=1e-5)
        np.testing.assert_allclose(np.concatenate(out[1:]), res.forces_W[list(sup)].ravel(),
                                   atol=1e-4)  # fmt: skip
        compared += 1
    assert compared >= 4
