"""Every robot of the list in MuJoCo (issue 14): importable URDFs, the planner's feet, servos."""

import xml.etree.ElementTree as ET
from dataclasses import replace

import numpy as np
import pytest

from planner.body.robot import load_robot, robot_names
from planner.body.servo_model import LITTLEDOG_SERVOS, servo_model
from planner.planfile.plan import TerrainGrid
from planner.sim.sim_robot import _fix_inertia, _resolve_package, sim_robot_urdf
from planner.sim.simulate import Simulator


def _flat_grid() -> TerrainGrid:
    return TerrainGrid(np.array([-1.0, -1.0]), 0.05, np.zeros((41, 41)))


@pytest.mark.parametrize("name", robot_names())
def test_every_robot_simulates_on_the_planners_feet(name):
    """MuJoCo imports the robot; each foot is a sphere of the planner's radius at its frame."""
    import pinocchio as pin

    robot = load_robot(name)
    sim = Simulator(robot, _flat_grid(), 0.7)
    m = sim.model
    # (MuJoCo's saved MJCF keeps about 7 significant digits)
    np.testing.assert_allclose(m.geom_size[sim.foot_geoms, 0], robot.foot_radius_m, rtol=1e-6)
    q = pin.neutral(robot.model)
    q[2] = 1.0
    sim.set_q(q)
    d = robot.model.createData()
    pin.framesForwardKinematics(robot.model, d, q)
    for leg, geom in zip(robot.legs, sim.foot_geoms, strict=True):
        p = d.oMf[robot.model.getFrameId(leg.foot_frame)].translation
        np.testing.assert_allclose(sim.data.geom_xpos[geom], p, atol=1e-6)
    # MuJoCo's mass is the URDF's (inertias were mended, not masses)
    assert float(m.body_mass.sum()) == pytest.approx(robot.total_mass_kg, rel=1e-5)
    # the servos are LittleDog's scaled to the robot
    kp = servo_model(robot).kp_nm_per_rad
    np.testing.assert_allclose(m.actuator_gainprm[:, 0], kp, rtol=1e-12)


def test_littledogs_servos_are_the_reference_and_scale_by_similarity(littledog):
    s = servo_model(littledog)
    for key in ("kp_nm_per_rad", "kv_nm_s_per_rad", "armature_kg_m2", "damping_nm_s_per_rad"):
        assert getattr(s, key) == pytest.approx(getattr(LITTLEDOG_SERVOS, key), rel=1e-6)
    heavy = servo_model(replace(littledog, total_mass_kg=2 * littledog.total_mass_kg))
    long = servo_model(replace(littledog, reach_m=4 * littledog.reach_m))
    assert heavy.kp_nm_per_rad == pytest.approx(2 * s.kp_nm_per_rad)
    assert long.kp_nm_per_rad == pytest.approx(4 * s.kp_nm_per_rad)  # M g L
    assert long.kv_nm_s_per_rad == pytest.approx(8 * s.kv_nm_s_per_rad)  # M L sqrt(g L)
    assert long.armature_kg_m2 == pytest.approx(16 * s.armature_kg_m2)  # M L^2


def test_an_indefinite_inertia_is_mended_and_a_good_one_kept():
    bad = ET.fromstring(
        '<link name="l"><inertial><mass value="0.5"/><inertia ixx="1e-4" ixy="2e-4" ixz="0" '
        'iyy="1e-4" iyz="0" izz="3e-4"/></inertial></link>'
    )
    note = _fix_inertia(bad)
    assert "'l'" in note
    i = bad.find("inertial/inertia").attrib
    matrix = np.array(
        [
            [float(i["ixx"]), float(i["ixy"]), float(i["ixz"])],
            [float(i["ixy"]), float(i["iyy"]), float(i["iyz"])],
            [float(i["ixz"]), float(i["iyz"]), float(i["izz"])],
        ]
    )
    w = np.linalg.eigvalsh(matrix)
    assert w.min() > 0.0
    np.testing.assert_allclose(sorted(w)[1:], [3e-4, 3e-4], rtol=1e-9)  # the positive ones stay
    good = ET.fromstring(
        '<link name="g"><inertial><mass value="0.5"/><inertia ixx="1e-4" ixy="0" ixz="0" '
        'iyy="2e-4" iyz="0" izz="2.5e-4"/></inertial></link>'
    )
    before = ET.tostring(good)
    assert _fix_inertia(good) == "" and ET.tostring(good) == before


def test_package_paths_resolve_against_the_urdfs_ancestors(tmp_path):
    mesh = tmp_path / "share" / "robots" / "dog_description" / "meshes" / "foot.stl"
    mesh.parent.mkdir(parents=True)
    mesh.write_text("solid x\nendsolid x\n")
    urdf = tmp_path / "share" / "robots" / "dog_description" / "urdf" / "dog.urdf"
    urdf.parent.mkdir(parents=True)
    got = _resolve_package("package://some-pkg/robots/dog_description/meshes/foot.stl", urdf)
    assert got == str(mesh)
    assert _resolve_package("package://x/none.stl", urdf) == "package://x/none.stl"
    assert _resolve_package("meshes/foot.stl", urdf) == "meshes/foot.stl"


def test_unreadable_meshes_become_the_planners_primitives():
    """HyQ's collision meshes are COLLADA: body box on the trunk, capsules on the thighs."""
    notes = sim_robot_urdf(load_robot("hyq")).notes
    assert any("'trunk'" in n and "body box" in n for n in notes)
    assert sum("thigh capsule" in n for n in notes) == 4


def test_another_robot_walks_with_feedback_and_arrives_over_the_goal():
    """A1 (13.7 kg, 37 cm legs) on flat with feedback (8.3) in MuJoCo: its steps are 13 cm,
    so the walk ends with the arrival move from the measured state (COM over the goal)."""
    from planner.planning.walk import plan_walk
    from planner.sim.execution import simulate_plan
    from planner.world.terrain import Terrain

    flat = Terrain.from_spec({"name": "flat", "kind": "flat", "friction": 0.7, "length": 2.0})
    plan, report = plan_walk("a1", flat, (0.6, 0.0), (0.25, 0.0))
    assert plan.outcome["reached_goal"] and report.ok, plan.outcome["message"]
    res = simulate_plan(plan, "feedback")
    m = res.metrics
    assert m.reached and not m.fell and not m.body_contact, m.message
    assert m.com_to_goal_m < 0.03
    assert res.executed.stats["feedback"]["arrivals"] >= 1


def test_timing_scales_with_the_leg_unless_given(littledog):
    """LittleDog keeps its time law's numbers; ANYmal (s = 3.58) gets speeds and times
    x sqrt(s) and the same accelerations (the same Froude number); a given value wins."""
    from planner.body.robot_scale import length_scale
    from planner.planning.local import (
        BODY_ACCEL_M_S2,
        BODY_SPEED_M_S,
        SWING_TIME_S,
        LocalSettings,
    )
    from planner.planning.soft import SoftPlanner
    from planner.world.terrain import load_terrain

    flat = load_terrain("flat")
    ld = SoftPlanner(littledog, flat).settings
    assert (ld.body_speed_m_s, ld.body_accel_m_s2, ld.swing_time_s) == (
        BODY_SPEED_M_S,
        BODY_ACCEL_M_S2,
        SWING_TIME_S,
    )
    anymal = load_robot("anymal")
    k = length_scale(anymal) ** 0.5
    st = SoftPlanner(anymal, flat).settings
    assert st.body_speed_m_s == pytest.approx(BODY_SPEED_M_S * k)
    assert st.swing_time_s == pytest.approx(SWING_TIME_S * k)
    assert st.body_accel_m_s2 == BODY_ACCEL_M_S2
    given = SoftPlanner(anymal, flat, settings=LocalSettings(swing_time_s=0.8)).settings
    assert given.swing_time_s == 0.8
    assert given.body_speed_m_s == pytest.approx(BODY_SPEED_M_S * k)
