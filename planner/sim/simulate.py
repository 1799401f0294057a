"""Execute a plan on a body with mass: MuJoCo (paper section 10; DESIGN.md section 2, step 6).

The robot is the plan's own URDF, imported by MuJoCo's URDF compiler (a ``<mujoco>``
compiler extension is added to the text), saved as MJCF and completed: a free joint on the
root link, joint armature and damping, one position servo per joint whose torque saturates
at the URDF's effort limit (LittleDog: 1.7 N m hips, 0.6 N m knees), and contact settings.
The terrain comes from the plan's ``terrain_grid`` (so any plan file can be simulated):
a plane when it is level, boxes when it is piecewise constant along x (step, stairs, gap,
barrier: exact sharp edges, refined with the terrain's own sharp height when the spec can
be rebuilt), a height field otherwise (slopes, rough relief, rocks). The plan's friction
coefficient is every contact's.

Execution (this module: open loop; :mod:`planner.sim.execution`: feedback 8.3 and
precompute-then-correct 8.4) runs in cycles, one per gait step (from a touchdown to the
next): the joint set-points follow the samples linearly in time, slowed by
``time_scale`` (1: the plan's own timing), each servo given as feed-forward the torque
that holds the planned configuration on its planned feet (``SimSettings.feedforward``),
and a :class:`Monitor`
measures what the plan promised: stance feet that do not slip (motion along a leaf), no
body-terrain contact, the base where the plan puts it. :class:`SimResult` carries the
metrics and the executed motion as a ``stratawalk.plan/1`` :class:`~planner.planfile.plan.Plan`
(executed ``q``, MuJoCo foot contacts), for a replay beside the plan.

What the plan's model leaves out shows up here: a rigid sphere foot fixed to the shank
*rolls* when the shank turns, so a stance foot's centre moves by rho times the shank's
rotation (2-4 mm per body move for LittleDog) although its contact point does not slide;
open loop this accumulates (a flat 2 m walk ended 2.8 cm off, rolling and landings
together; 0.6 cm at a third of the speed). The metrics keep the
two apart: ``max_slip_m`` (the centre's travel since touchdown) and ``max_sliding_m``
(the contact point's sliding, what friction must prevent).
"""

from __future__ import annotations

import contextlib
import math
import re
import tempfile
import time as _time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.body.torques import TorqueCheck, holding_load
from planner.core import interrupts
from planner.core.errors import InputError
from planner.core.units import GRAVITY_M_S2
from planner.planfile.plan import Keyframe, Plan, Samples, TerrainGrid, loaded_feet

if TYPE_CHECKING:
    from planner.body.robot import Robot
    from planner.world.terrain import Terrain

__all__ = [
    "MUJOCO_VERSION",
    "Execution",
    "Metrics",
    "Monitor",
    "SimResult",
    "SimSettings",
    "Simulator",
    "TerrainModel",
    "Touches",
    "build_mjcf",
    "cycle_starts",
    "loaded_feet",
    "executed_plan",
    "finish_run",
    "new_run",
    "run_open_loop",
    "terrain_model",
]

MUJOCO_VERSION = "4.0.0"  # what the tests were run with (pyproject.toml pins it)
_ROBOT_GROUP = 1  # contype of robot geoms; terrain geoms have conaffinity 1 and contype 0
_Array = NDArray[np.float64]


def _mujoco():
    """The mujoco module, or an InputError saying how to install it."""
    try:
        import mujoco
    except ImportError:  # pragma: no cover - depends on the environment
        raise InputError(
            f"simulate: the mujoco package is not installed; pip install mujoco=={MUJOCO_VERSION}"
        ) from None
    return mujoco


# ------------------------------------------------------------------------------ settings
@dataclass
class SimSettings:
    """Simulation and execution settings (section 10).

    time_scale : simulated time per plan second (2 runs the plan at half speed).
    timestep_s, control_dt_s : physics step and servo set-point period.
    settle_s : standing still at the plan's first configuration before walking.
    hold_s : standing at the last set-point after the plan ends.
    kp_nm_per_rad, kv_nm_s_per_rad : servo stiffness and damping (every joint); the servo
        torque saturates at the URDF effort limit (``effort_nm`` overrides it).
    armature_kg_m2, damping_nm_s_per_rad : reflected rotor inertia and joint friction.
        None (these four): LittleDog's, scaled to the robot by dynamic similarity
        (:func:`planner.body.servo_model.servo_model`; LittleDog: 20, 0.25, 5e-4, 0.01).
    contact_timeconst_s, impratio : MuJoCo contact stiffness (solref) and friction-cone
        impedance ratio (elliptic cones; higher keeps a static foot from creeping).
    record_hz : rate of the executed samples written out.
    reach_tol_m : the final base within this (xy) of the plan's final base is "reached"
        (feedback: the COM within this of the plan's goal).
    fall_angle_deg : base roll or pitch past this is a fall (so is the body on the ground).
    tip_angle_deg : the body's up axis this far from the plan's is "tipped".
    slip_tol_m : a stance foot's contact point sliding farther than this since its
        touchdown "slipped" (its centre also moves when the sphere rolls; that is reported
        as ``max_slip_m`` but is not sliding).
    noslip_iterations : MuJoCo's no-slip post-solver (removes the creep of soft friction).
    rolling_friction_m : rolling resistance of the feet (0: a rigid sphere rolls freely).
    sliding_min_load_frac : sliding counts while the foot carries at least this fraction
        of the weight (a foot unloaded before its lift-off may drift; it is leaving anyway).
    feedforward : add to each servo the torque that holds the planned configuration still
        on its planned feet (:func:`planner.body.torques.holding_load`), as a set-point
        offset tau / kp, so the servo need not sag by tau / kp to produce it. Gains, effort
        limits and contact are unchanged: the total servo torque still saturates at the
        effort limit. Off, the servos are pure PD on the joint set-points.
    """

    time_scale: float = 1.0
    timestep_s: float = 0.001
    control_dt_s: float = 0.004
    settle_s: float = 1.0
    hold_s: float = 0.5
    kp_nm_per_rad: float | None = None
    kv_nm_s_per_rad: float | None = None
    effort_nm: tuple[float, float, float] | None = None
    armature_kg_m2: float | None = None
    damping_nm_s_per_rad: float | None = None
    contact_timeconst_s: float = 0.01
    impratio: float = 10.0
    noslip_iterations: int = 10
    rolling_friction_m: float = 0.0
    sliding_min_load_frac: float = 0.1
    record_hz: float = 25.0
    reach_tol_m: float = 0.05
    fall_angle_deg: float = 45.0
    tip_angle_deg: float = 10.0
    slip_tol_m: float = 0.01
    stop_on_fall: bool = True
    feedforward: bool = True

    def check(self) -> SimSettings:
        """Raise InputError for a non-positive scale or step; return self."""
        for name in ("time_scale", "timestep_s", "control_dt_s", "record_hz"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"simulate: {name} must be a number > 0, got {v!r}")
        if self.control_dt_s < self.timestep_s:
            raise InputError(
                f"simulate: control_dt_s ({self.control_dt_s}) must be >= timestep_s "
                f"({self.timestep_s})"
            )
        return self

    def for_robot(self, robot: Robot) -> SimSettings:
        """A copy with the unset servo values scaled to ``robot`` (:mod:`~.servo_model`)."""
        from dataclasses import replace

        from planner.body.servo_model import servo_model

        scaled = asdict(servo_model(robot))
        unset = {k: v for k, v in scaled.items() if getattr(self, k) is None}
        return replace(self, **unset) if unset else self


# ------------------------------------------------------------------------------ the model
def _urdf_to_mjcf(robot: Robot) -> tuple[str, list[str]]:
    """MuJoCo's import of the robot's URDF (:mod:`planner.sim.sim_robot`), saved as MJCF text.

    Fixed links are kept, visuals dropped. Returns (MJCF text, what was changed in the
    URDF to import it).
    """
    from planner.sim.sim_robot import sim_robot_urdf

    mujoco = _mujoco()
    urdf_path = Path(robot.urdf_path)
    prepared = sim_robot_urdf(robot)
    ext = (
        '<mujoco><compiler discardvisual="true" fusestatic="false" balanceinertia="true" '
        f'inertiafromgeom="false" strippath="false" meshdir="{urdf_path.parent}"/></mujoco>'
    )
    text, n = re.subn(r"(<robot\b[^>]*>)", lambda m: m.group(1) + ext, prepared.text, count=1)
    if n != 1:
        raise InputError(f"{urdf_path}: no <robot> element; give a URDF file")
    try:
        model = mujoco.MjModel.from_xml_string(text)
    except ValueError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else "unknown error"
        raise InputError(
            f"{urdf_path}: MuJoCo could not import the URDF ({first}); use primitive "
            "collision geometry or meshes next to the URDF"
        ) from None
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "robot.xml"
        mujoco.mj_saveLastXML(str(out), model)
        return out.read_text(encoding="utf-8"), prepared.notes


@dataclass
class TerrainModel:
    """How the terrain is given to MuJoCo: ``kind`` plane, boxes or hfield."""

    kind: str
    geoms: list[dict]  # MJCF <geom> attributes
    hfield: _Array | None = None  # (nrow, ncol) normalised elevation, rows along +y
    hfield_attrs: dict | None = None


def _profile_runs(h: _Array, max_runs: int = 64) -> list[tuple[int, int, float]] | None:
    """Runs (i0, i1, height) of a piecewise-constant 1-D profile, or None if it is not one."""
    change = np.flatnonzero(np.abs(np.diff(h)) > 1e-9)
    if len(change) + 1 > max_runs:
        return None
    edges = [0, *(change + 1).tolist(), len(h)]
    runs = [(a, b, float(h[a])) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    if any(b - a < 2 for a, b, _ in runs[1:-1]):
        return None  # one-cell plateaus are relief, not steps
    return runs


def terrain_model(grid: TerrainGrid, terrain: Terrain | None = None) -> TerrainModel:
    """MuJoCo geometry of a ``terrain_grid``: plane, boxes (sharp edges along x) or hfield.

    ``terrain`` (the plan's spec rebuilt), when given, places box edges exactly (bisection
    on its sharp height) instead of to within half a grid cell.
    """
    h = np.asarray(grid.heights, float)
    res = float(grid.resolution)
    x0, y0 = (float(v) for v in grid.origin)
    ny, nx = h.shape
    x1, y1 = x0 + (nx - 1) * res, y0 + (ny - 1) * res
    hmin, hmax = float(h.min()), float(h.max())
    far = 1.0  # boxes and planes reach this far past the grid [m]
    if hmax - hmin < 1e-9:
        size = f"{(x1 - x0) / 2 + far} {(y1 - y0) / 2 + far} 0.1"
        pos = f"{(x0 + x1) / 2} {(y0 + y1) / 2} {hmin}"
        return TerrainModel(
            "plane", [{"name": "terrain", "type": "plane", "size": size, "pos": pos}]
        )
    runs = _profile_runs(h[0]) if np.max(np.abs(h - h[0])) < 1e-9 else None
    if runs is not None:
        ym = 0.5 * (y0 + y1)
        edges = [x0 - far]
        for (_, b, ha), (_, _, hb) in zip(runs[:-1], runs[1:], strict=True):
            lo, hi = x0 + (b - 1) * res, x0 + b * res  # the sharp edge is in (lo, hi]
            if terrain is not None:
                for _ in range(40):
                    mid = 0.5 * (lo + hi)
                    z = float(terrain.height_sharp(np.array(mid), np.array(ym)))
                    lo, hi = (mid, hi) if abs(z - ha) < abs(z - hb) else (lo, mid)
            edges.append(0.5 * (lo + hi))
        edges.append(x1 + far)
        bottom = hmin - 0.2
        geoms = []
        for k, (_, _, top) in enumerate(runs):
            xa, xb = edges[k], edges[k + 1]
            geoms.append(
                {
                    "name": f"terrain_box{k}",
                    "type": "box",
                    "size": f"{(xb - xa) / 2} {(y1 - y0) / 2 + far} {(top - bottom) / 2}",
                    "pos": f"{(xa + xb) / 2} {ym} {(top + bottom) / 2}",
                }
            )
        return TerrainModel("boxes", geoms)
    elev = hmax - hmin
    data = (h - hmin) / elev
    attrs = {
        "name": "terrain",
        "nrow": str(ny),
        "ncol": str(nx),
        "size": f"{(x1 - x0) / 2} {(y1 - y0) / 2} {elev} 0.1",
    }
    geoms = [
        {
            "name": "terrain",
            "type": "hfield",
            "hfield": "terrain",
            "pos": f"{(x0 + x1) / 2} {(y0 + y1) / 2} {hmin}",
        },
        {  # a floor below, so that a robot walking off the grid lands on something
            "name": "terrain_floor",
            "type": "plane",
            "size": f"{(x1 - x0) / 2 + far} {(y1 - y0) / 2 + far} 0.1",
            "pos": f"{(x0 + x1) / 2} {(y0 + y1) / 2} {hmin - 0.1}",
        },
    ]
    return TerrainModel("hfield", geoms, data, attrs)


def build_mjcf(robot: Robot, terrain: TerrainModel, friction: float, settings: SimSettings) -> str:
    """MJCF text: the URDF's robot with a free joint, servos, and the terrain (section 10)."""
    text, _ = _urdf_to_mjcf(robot)
    root = ET.fromstring(text)
    settings = settings.for_robot(robot)
    world = root.find("worldbody")
    base = world.find("body") if world is not None else None
    if base is None:
        raise InputError(f"{robot.urdf_path}: MuJoCo found no link under the world")
    s = settings
    ET.SubElement(
        root,
        "option",
        {
            "timestep": repr(s.timestep_s),
            "integrator": "implicitfast",
            "cone": "elliptic",
            "impratio": repr(s.impratio),
            "noslip_iterations": str(s.noslip_iterations),
        },
    )
    vis = ET.SubElement(root, "visual")
    ET.SubElement(vis, "global", {"offwidth": "1280", "offheight": "720"})
    base.insert(0, ET.Element("freejoint", {"name": "root"}))
    condim = "6" if s.rolling_friction_m > 0 else "3"
    fr = f"{friction} 0.005 {s.rolling_friction_m!r}"
    for geom in root.iter("geom"):
        geom.set("contype", str(_ROBOT_GROUP))
        geom.set("conaffinity", "0")
        geom.set("condim", condim)
        geom.set("friction", fr)
        geom.set("solref", f"{s.contact_timeconst_s} 1")
    for joint in root.iter("joint"):
        joint.set("armature", repr(s.armature_kg_m2))
        joint.set("damping", repr(s.damping_nm_s_per_rad))
    for g in terrain.geoms:
        attrs = dict(g, contype="0", conaffinity=str(_ROBOT_GROUP), condim=condim, friction=fr)
        attrs["solref"] = f"{s.contact_timeconst_s} 1"
        attrs["rgba"] = "0.55 0.6 0.5 1"
        world.insert(0, ET.Element("geom", attrs))
    world.insert(0, ET.Element("light", {"pos": "0 0 3", "dir": "0 0 -1", "directional": "true"}))
    if terrain.hfield_attrs is not None:
        asset = root.find("asset")
        if asset is None:
            asset = ET.Element("asset")
            root.insert(1, asset)
        ET.SubElement(asset, "hfield", terrain.hfield_attrs)
    effort = _effort(robot, settings)
    act = ET.SubElement(root, "actuator")
    kp, kv = s.kp_nm_per_rad, s.kv_nm_s_per_rad
    for name, e in zip(robot.joint_names, effort, strict=True):
        ET.SubElement(
            act,
            "general",
            {
                "name": f"servo_{name}",
                "joint": name,
                "gaintype": "fixed",
                "biastype": "affine",
                "gainprm": repr(kp),
                "biasprm": f"0 {-kp!r} {-kv!r}",
                "forcelimited": "true",
                "forcerange": f"{-float(e)!r} {float(e)!r}",
            },
        )
    return ET.tostring(root, encoding="unicode")


def _effort(robot: Robot, settings: SimSettings) -> _Array:
    """(12,) servo torque limits [N m], robot joint order: URDF effort or the override."""
    if settings.effort_nm is not None:
        return np.tile(np.asarray(settings.effort_nm, float), 4)
    m = robot.model
    out = []
    for name in robot.joint_names:
        e = float(m.effortLimit[m.joints[m.getJointId(name)].idx_v])
        out.append(e if math.isfinite(e) and 0.0 < e < 1e6 else np.nan)
    out = np.array(out)
    if np.isnan(out).any():
        raise InputError(
            f"{robot.urdf_path}: joints without an effort limit "
            f"({', '.join(n for n, e in zip(robot.joint_names, out, strict=True) if np.isnan(e))})"
            "; add <limit effort=...> or give SimSettings.effort_nm"
        )
    return out


# ------------------------------------------------------------------------------ simulator
@dataclass
class Touches:
    """Robot-terrain contacts at one instant."""

    feet: NDArray[np.bool_]  # (4,) foot spheres touching
    body: bool  # the root link (body box) touches
    legs: bool  # a leg link other than a foot touches
    forces: _Array  # (4, 3) force of the terrain on each foot [N], world
    normals: _Array  # (4, 3) contact normal into each touching foot, world


class Simulator:
    """One robot on one terrain in MuJoCo, read and driven in Pinocchio's conventions.

    ``q`` is Pinocchio's free-flyer configuration (xyz, quaternion xyzw, 12 joints);
    set-points and joint arrays are (4, 3) or (12,) in the robot's leg order FL..HR.
    """

    def __init__(
        self,
        robot: Robot,
        grid: TerrainGrid,
        friction: float,
        terrain: Terrain | None = None,
        settings: SimSettings | None = None,
    ):
        mujoco = _mujoco()
        self.mj = mujoco
        self.robot = robot
        self.settings = (settings or SimSettings()).check().for_robot(robot)
        self.terrain = terrain
        self.terrain_model = terrain_model(grid, terrain)
        self.friction = float(friction)
        self.xml = build_mjcf(robot, self.terrain_model, self.friction, self.settings)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        if self.terrain_model.hfield is not None:
            self.model.hfield_data[:] = self.terrain_model.hfield.ravel()
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._jadr = np.array([m.joint(n).qposadr[0] for n in robot.joint_names])
        self._pin_idx = np.array([leg.q_index + k for leg in robot.legs for k in range(3)])
        self.base_body = m.body(m.joint("root").bodyid[0]).id
        terrain_names = {g["name"] for g in self.terrain_model.geoms}
        self.is_terrain = np.array([m.geom(i).name in terrain_names for i in range(m.ngeom)])
        self.foot_geoms = self._find_feet()
        self.body_geoms = np.array(
            [i for i in range(m.ngeom) if m.geom_bodyid[i] == self.base_body], dtype=int
        )
        self.effort = _effort(robot, self.settings)
        self._setpoint = np.zeros(12)
        self._holding: TorqueCheck | None = None
        self.n_sub = max(1, int(round(self.settings.control_dt_s / self.settings.timestep_s)))
        self.history: list[tuple[float, _Array, NDArray[np.bool_]]] = []
        self.history_s = 0.0

    def _find_feet(self) -> NDArray[np.int_]:
        """The sphere geom at each foot frame (compared at Pinocchio's neutral pose)."""
        import pinocchio as pin

        r, m, d = self.robot, self.model, self.data
        q = pin.neutral(r.model)
        q[2] = 1.0
        pdata = r.model.createData()
        pin.framesForwardKinematics(r.model, pdata, q)
        self.set_q(q)
        self.mj.mj_forward(m, d)
        spheres = [
            i
            for i in range(m.ngeom)
            if m.geom_type[i] == self.mj.mjtGeom.mjGEOM_SPHERE and not self.is_terrain[i]
        ]
        out = []
        for f in r.foot_frames:
            p = pdata.oMf[r.model.getFrameId(f)].translation
            dist = [np.linalg.norm(d.geom_xpos[i] - p) for i in spheres]
            if not dist or min(dist) > 2e-3:
                raise InputError(
                    f"{r.urdf_path}: no collision sphere at foot frame '{f}' in MuJoCo's import"
                )
            out.append(spheres[int(np.argmin(dist))])
        return np.array(out, dtype=int)

    # ---- state ----------------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return float(self.data.time)

    def set_q(self, q: Any, lift_m: float = 0.0) -> None:
        """Place the robot at Pinocchio configuration ``q`` (raised by ``lift_m``), at rest."""
        q = np.asarray(q, float)
        qpos = self.data.qpos
        qpos[:3] = q[:3] + [0.0, 0.0, lift_m]
        qpos[3:7] = [q[6], q[3], q[4], q[5]]
        qpos[self._jadr] = q[self._pin_idx]
        self.data.qvel[:] = 0.0
        self.set_targets(q[self._pin_idx])
        self.mj.mj_forward(self.model, self.data)

    def q(self) -> _Array:
        """Pinocchio configuration (19,) of the simulated robot."""
        qpos = self.data.qpos
        q = np.zeros(self.robot.model.nq)
        q[:3] = qpos[:3]
        q[3:7] = [qpos[4], qpos[5], qpos[6], qpos[3]]
        q[self._pin_idx] = qpos[self._jadr]
        return q

    def joints(self) -> _Array:
        """(12,) joint angles, robot order."""
        return self.data.qpos[self._jadr].copy()

    def base_rotation(self) -> _Array:
        """(3, 3) base rotation, body to world."""
        return self.data.xmat[self.base_body].reshape(3, 3).copy()

    def com_W(self) -> _Array:
        """Whole-body centre of mass [m], world."""
        return self.data.subtree_com[self.base_body].copy()

    def foot_centres_W(self) -> _Array:
        """(4, 3) foot sphere centres [m], world."""
        return self.data.geom_xpos[self.foot_geoms].copy()

    def set_targets(self, joints: Any, torque_ff_nm: Any = None) -> None:
        """Servo set-points: (12,) or (4, 3) joint angles [rad], robot order.

        ``torque_ff_nm`` (12,): feed-forward torques, applied as the set-point offset
        tau / kp (the servo's torque at the set-point is then tau; it still saturates).
        """
        self._setpoint = np.asarray(joints, float).ravel().copy()
        ctrl = self._setpoint
        if torque_ff_nm is not None:
            ctrl = ctrl + np.asarray(torque_ff_nm, float).ravel() / self.settings.kp_nm_per_rad
        self.data.ctrl[:] = ctrl

    def targets(self) -> _Array:
        """(12,) current joint set-points (without the feed-forward offset)."""
        return self._setpoint.copy()

    def holding_torques_nm(self, q: Any, contact: Any) -> _Array:
        """(N, 12) feed-forward torques for configurations q (N, 19) on contact (N, 4) feet.

        Zeros when ``settings.feedforward`` is off.
        """
        q = np.atleast_2d(np.asarray(q, float))
        if not self.settings.feedforward:
            return np.zeros((len(q), 12))
        if self._holding is None:
            self._holding = TorqueCheck(self.robot)
        c = np.atleast_2d(np.asarray(contact, bool))
        return holding_load(self._holding, q, c, self.friction, self.terrain)[1]

    def saturated(self) -> bool:
        """Whether any servo is at its torque limit."""
        return bool(np.any(np.abs(self.data.actuator_force) >= self.effort - 1e-9))

    def touches(self) -> Touches:
        """Contacts of the robot with the terrain now (forces and normals world frame)."""
        d = self.data
        out = Touches(np.zeros(4, bool), False, False, np.zeros((4, 3)), np.zeros((4, 3)))
        f6 = np.zeros(6)
        for k in range(d.ncon):
            c = d.contact[k]
            g1, g2 = int(c.geom1), int(c.geom2)
            if self.is_terrain[g1] == self.is_terrain[g2]:
                continue
            robot_geom, sign = (g2, 1.0) if self.is_terrain[g1] else (g1, -1.0)
            hit = np.flatnonzero(self.foot_geoms == robot_geom)
            if hit.size:
                i = int(hit[0])
                out.feet[i] = True
                frame = np.asarray(c.frame).reshape(3, 3)
                self.mj.mj_contactForce(self.model, d, k, f6)
                out.forces[i] += sign * (frame.T @ f6[:3])
                out.normals[i] = sign * frame[0]
            elif robot_geom in self.body_geoms:
                out.body = True
            else:
                out.legs = True
        return out

    def contact_point_velocity(self, leg: int, normal_W: _Array) -> _Array:
        """World velocity of the foot sphere's material point touching along ``normal_W``.

        Zero for a foot that rolls without sliding; the sliding velocity otherwise.
        """
        v6 = np.zeros(6)
        self.mj.mj_objectVelocity(
            self.model, self.data, self.mj.mjtObj.mjOBJ_GEOM, int(self.foot_geoms[leg]), v6, 0
        )
        r = -self.robot.foot_radius_m * np.asarray(normal_W, float)
        w = v6[:3]  # w x r, written out (np.cross costs more than the physics step)
        return v6[3:] + np.array(
            [w[1] * r[2] - w[2] * r[1], w[2] * r[0] - w[0] * r[2], w[0] * r[1] - w[1] * r[0]]
        )

    # ---- stepping -------------------------------------------------------------------------
    def tick(self) -> None:
        """Advance one control period (``n_sub`` physics steps); keep history if asked."""
        self.mj.mj_step(self.model, self.data, nstep=self.n_sub)
        if self.history_s > 0.0:
            self.history.append((self.time, self.q(), self.touches().feet))
            while self.history and self.history[0][0] < self.time - self.history_s - 0.1:
                self.history.pop(0)

    def settle(self, q0: Any, duration_s: float) -> None:
        """Start at ``q0`` (2 mm up) holding its joints, and let the robot settle."""
        self.set_q(q0, lift_m=0.002)
        q0 = np.asarray(q0, float)
        self.set_targets(q0[self._pin_idx], self.holding_torques_nm(q0, np.ones(4, bool))[0])
        end = self.time + duration_s
        while self.time < end - 1e-9:
            self.tick()


# ------------------------------------------------------------------------------ monitoring
def _up_angle_deg(Ra: _Array, Rb: _Array) -> float:
    """Angle [deg] between the body up axes of two rotations."""
    c = float(np.clip(Ra[:, 2] @ Rb[:, 2], -1.0, 1.0))
    return math.degrees(math.acos(c))


def _roll_pitch_deg(R: _Array) -> tuple[float, float]:
    """Roll and pitch (ZYX Euler) [deg]."""
    pitch = math.asin(float(np.clip(-R[2, 0], -1.0, 1.0)))
    roll = math.atan2(float(R[2, 1]), float(R[2, 2]))
    return math.degrees(roll), math.degrees(pitch)


def _quat_to_R(q_xyzw: _Array) -> _Array:
    x, y, z, w = (float(v) for v in q_xyzw)
    s = 1.0 / math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x * s, y * s, z * s, w * s
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@dataclass
class Metrics:
    """What a run measured (section 10). Lengths in metres, angles in degrees, times in s."""

    mode: str
    # no fall, and the final base within reach_tol_m (xy) of the plan's final base (feedback,
    # which plans its own way to the plan's goal: the COM within reach_tol_m of the goal)
    reached: bool = False
    final_error_m: float = math.nan  # final base vs the plan's final base, xy
    final_error_3d_m: float = math.nan
    com_to_goal_m: float = math.nan  # final whole-body COM to the plan's goal, xy
    plan_com_to_goal_m: float = math.nan  # what the plan itself promised
    max_slip_m: float = 0.0  # largest xy travel of a stance foot's centre since touchdown
    max_slip_leg: str = ""
    max_sliding_m: float = 0.0  # largest sliding of a stance foot's contact point since then
    max_sliding_leg: str = ""  # (travel minus rolling: a rigid sphere foot rolls)
    slipped: bool = False
    fell: bool = False
    fall_reason: str = ""
    fall_time_s: float = math.nan  # since the walk started (after settling)
    tipped: bool = False
    max_tilt_error_deg: float = 0.0  # body up axis vs the plan's
    max_roll_pitch_deg: float = 0.0
    body_contact: bool = False  # the body link touched the terrain
    leg_contact_s: float = 0.0  # time a leg link (not a foot) touched the terrain
    swing_touch_s: float = 0.0  # time a swing foot touched the terrain
    lost_contact_s: float = 0.0  # time a planned stance foot was off the terrain
    joint_rms_rad: float = 0.0  # set-point tracking
    joint_max_rad: float = 0.0
    saturation_frac: float = 0.0  # fraction of control ticks with a servo at its limit
    # on three planned stance legs: the largest |servo torque| / URDF effort of their joints,
    # and its largest excess over the feed-forward's (the planned commanded distribution's)
    max_three_leg_load: float = 0.0
    max_load_over_plan: float = 0.0
    cycles: int = 0
    replans: int = 0  # feedback: planning failures that cost a cycle
    ik_misses: int = 0  # correction: set-points out of reach (closest taken)
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    message: str = ""

    @property
    def ok(self) -> bool:
        """Reached, no fall, no tipping, no slip, no body contact."""
        return self.reached and not (self.fell or self.tipped or self.slipped or self.body_contact)

    def to_dict(self) -> dict:
        """JSON-ready dict (with ``ok``)."""
        d = asdict(self)
        d["ok"] = self.ok
        return d

    def summary(self) -> str:
        """A few lines for the terminal."""
        yn = {True: "yes", False: "no"}
        lines = [
            f"mode {self.mode}: {'OK' if self.ok else 'NOT OK'} - {self.message}",
            f"  reached: {yn[self.reached]}; final base {100 * self.final_error_m:.1f} cm (xy) "
            f"from the plan's final base ({100 * self.final_error_3d_m:.1f} cm 3-D); COM "
            f"{100 * self.com_to_goal_m:.1f} cm from the goal (the plan's: "
            f"{100 * self.plan_com_to_goal_m:.1f} cm)",
            f"  max stance-foot slip {1000 * self.max_slip_m:.1f} mm ({self.max_slip_leg or '-'}"
            f"), of which sliding {1000 * self.max_sliding_m:.1f} mm "
            f"({self.max_sliding_leg or '-'}; the rest is the sphere foot rolling)",
            f"  fell: {yn[self.fell]}{' (' + self.fall_reason + ')' if self.fell else ''}; "
            f"tipped: {yn[self.tipped]} (max tilt vs plan {self.max_tilt_error_deg:.1f} deg)",
            f"  body-terrain contact: {yn[self.body_contact]}; leg links on terrain "
            f"{self.leg_contact_s:.2f} s; swing foot on terrain {self.swing_touch_s:.2f} s; "
            f"stance foot off terrain {self.lost_contact_s:.2f} s",
            f"  joint tracking rms {math.degrees(self.joint_rms_rad):.2f} deg, max "
            f"{math.degrees(self.joint_max_rad):.2f} deg; servos saturated "
            f"{100 * self.saturation_frac:.1f} % of ticks; on three legs up to "
            f"{100 * self.max_three_leg_load:.0f} % of a stance joint's effort, "
            f"{100 * self.max_load_over_plan:.0f} % over the feed-forward",
            f"  {self.cycles} cycles, {self.sim_time_s:.1f} s simulated in {self.wall_time_s:.1f}"
            " s",
        ]
        return "\n".join(lines)


class Monitor:
    """Follows a run tick by tick against the reference it was asked to execute.

    The reference is a growing list of samples on the simulator's clock: set-points
    (joints), the planned base pose and the planned contact flags. A foot is a planned
    stance foot on a reference segment whose two ends both have it in contact, a planned
    swing foot when neither has; its slip is measured from where it first touches the
    terrain in that stance interval.
    """

    def __init__(self, sim: Simulator, mode: str):
        self.sim = sim
        self.settings = sim.settings
        self.metrics = Metrics(mode=mode)
        self.t0 = sim.time  # the walk starts now (after settling)
        self.t: list[float] = []
        self.q: list[_Array] = []
        self.contact: list[NDArray[np.bool_]] = []
        self.torque_ff: list[_Array] = []
        self._anchor: list[_Array | None] = [None] * 4
        self._sliding = np.zeros((4, 3))  # integral of the contact point's tangential velocity
        weight = sim.robot.total_mass_kg * GRAVITY_M_S2
        self._min_load = self.settings.sliding_min_load_frac * weight
        self._sq, self._n, self._sat = 0.0, 0, 0
        self.rec_t: list[float] = []
        self.rec_q: list[_Array] = []
        self.rec_c: list[NDArray[np.bool_]] = []
        self.keyframes: list[Keyframe] = []
        self._next_rec = -math.inf

    # ---- reference --------------------------------------------------------------------
    def extend(
        self, t: _Array, q: _Array, contact: NDArray[np.bool_], torque_ff: _Array | None = None
    ) -> None:
        """Append reference samples (simulator times, strictly after the last one).

        ``torque_ff`` (N, 12): the servos' feed-forward torques at the samples (zeros if None).
        """
        if torque_ff is None:
            torque_ff = np.zeros((len(t), 12))
        for ti, qi, ci, fi in zip(t, q, contact, torque_ff, strict=True):
            if self.t and ti <= self.t[-1] + 1e-12:
                self.q[-1], self.contact[-1] = np.asarray(qi, float), np.asarray(ci, bool)
                self.torque_ff[-1] = np.asarray(fi, float)
                continue
            self.t.append(float(ti))
            self.q.append(np.asarray(qi, float))
            self.contact.append(np.asarray(ci, bool))
            self.torque_ff.append(np.asarray(fi, float))

    def _bracket(self, t: float) -> tuple[int, int, float]:
        """Reference samples (k, k2) around simulator time ``t`` and the weight u of k2."""
        ts = self.t
        k = int(np.searchsorted(ts, t, side="right")) - 1
        if k < 0:
            return 0, 0, 0.0
        if k >= len(ts) - 1:
            return len(ts) - 1, len(ts) - 1, 0.0
        return k, k + 1, (t - ts[k]) / (ts[k + 1] - ts[k])

    def feedforward_at(self, t: float) -> _Array:
        """(12,) feed-forward torques [N m] at simulator time ``t`` (linear between samples)."""
        k, k2, u = self._bracket(t)
        return (1.0 - u) * self.torque_ff[k] + u * self.torque_ff[k2]

    def reference_at(self, t: float) -> tuple[_Array, _Array, NDArray, NDArray]:
        """(set-point joints (12,), base q (7,), planned stance (4,), planned swing (4,))."""
        k, k2, u = self._bracket(t)
        q = (1.0 - u) * self.q[k] + u * self.q[k2]
        ca, cb = self.contact[k], self.contact[k2]
        return q[self.sim._pin_idx], q[:7], ca & cb, ~ca & ~cb

    # ---- measuring --------------------------------------------------------------------
    def update(self) -> None:
        """Measure after a control tick."""
        sim, m, s = self.sim, self.metrics, self.settings
        dt = s.control_dt_s
        t = sim.time
        joints_ref, base_ref, stance, swing = self.reference_at(t)
        err = np.abs(sim.joints() - sim.targets())
        self._sq += float(np.sum(err**2)) / 12.0
        self._n += 1
        m.joint_max_rad = max(m.joint_max_rad, float(err.max()))
        self._sat += int(sim.saturated())
        if int(stance.sum()) == 3:  # the servos' load against the commanded (planned) one
            j = (3 * np.flatnonzero(stance)[:, None] + np.arange(3)).ravel()
            load = np.abs(sim.data.actuator_force[j]) / sim.effort[j]
            planned = np.abs(self.feedforward_at(t)[j]) / sim.effort[j]
            m.max_three_leg_load = max(m.max_three_leg_load, float(load.max()))
            m.max_load_over_plan = max(m.max_load_over_plan, float((load - planned).max()))
        touch = sim.touches()
        feet, body, legs = touch.feet, touch.body, touch.legs
        R = sim.base_rotation()
        m.max_tilt_error_deg = max(m.max_tilt_error_deg, _up_angle_deg(R, _quat_to_R(base_ref[3:])))
        roll, pitch = _roll_pitch_deg(R)
        m.max_roll_pitch_deg = max(m.max_roll_pitch_deg, abs(roll), abs(pitch))
        m.tipped = m.max_tilt_error_deg > s.tip_angle_deg
        if legs:
            m.leg_contact_s += dt
        if body:
            m.body_contact = True
        centres = sim.foot_centres_W()
        for i in range(4):
            if stance[i]:
                if not feet[i]:
                    m.lost_contact_s += dt
                if self._anchor[i] is None:
                    if feet[i]:
                        self._anchor[i] = centres[i, :2].copy()
                        self._sliding[i] = 0.0
                else:
                    dx, dy = centres[i, :2] - self._anchor[i]
                    slip = math.hypot(dx, dy)
                    if slip > m.max_slip_m:
                        m.max_slip_m, m.max_slip_leg = slip, self.sim.robot.legs[i].name
                    if feet[i] and touch.forces[i] @ touch.normals[i] >= self._min_load:
                        n = touch.normals[i]
                        v = sim.contact_point_velocity(i, n)
                        self._sliding[i] += dt * (v - (v @ n) * n)
                        slid = math.sqrt(float(self._sliding[i] @ self._sliding[i]))
                        if slid > m.max_sliding_m:
                            m.max_sliding_m = slid
                            m.max_sliding_leg = self.sim.robot.legs[i].name
            else:
                self._anchor[i] = None
                if swing[i] and feet[i]:
                    m.swing_touch_s += dt
        m.slipped = m.max_sliding_m > s.slip_tol_m
        if not m.fell:
            if max(abs(roll), abs(pitch)) > s.fall_angle_deg:
                m.fell, m.fall_reason = (
                    True,
                    f"base roll/pitch {max(abs(roll), abs(pitch)):.0f} deg",
                )
            elif body:
                m.fell, m.fall_reason = True, "body on the ground"
            if m.fell:
                m.fall_time_s = t - self.t0
        if t >= self._next_rec - 1e-9:
            self.record(feet)
            self._next_rec = t + 1.0 / s.record_hz

    def record(self, feet: NDArray[np.bool_] | None = None) -> None:
        """Store the current configuration and foot contacts as an executed sample."""
        if feet is None:
            feet = self.sim.touches().feet
        self.rec_t.append(self.sim.time)
        self.rec_q.append(self.sim.q())
        self.rec_c.append(np.asarray(feet, bool))

    def keyframe(self, stratum: int = 0) -> None:
        """Store the measured configuration as a keyframe (support and forces measured)."""
        from planner.body.contact import swing_point_from_centre

        sim = self.sim
        touch = sim.touches()
        feet, forces = touch.feet, touch.forces
        q = sim.q()
        c = sim.foot_centres_W()
        rho = sim.robot.foot_radius_m
        pts = swing_point_from_centre(c, rho)
        for i in np.flatnonzero(feet):
            pts[i] = c[i] - rho * touch.normals[i]
        self.keyframes.append(
            Keyframe(
                stratum=int(stratum),
                base_position=q[:3].copy(),
                base_quaternion=q[3:7] / np.linalg.norm(q[3:7]),
                joints=sim.robot.joints_from_q(q).ravel(),
                feet=pts,
                forces=forces,
                support=[int(i) + 1 for i in np.flatnonzero(feet)],
            )
        )

    def finish(self, plan: Plan, wall_s: float, sim_t0: float) -> None:
        """Final metrics against the plan's last sample and goal."""
        m, sim = self.metrics, self.sim
        self.record()
        end = plan.samples.q[-1]
        base = sim.q()[:3]
        m.final_error_m = float(np.linalg.norm(base[:2] - end[:2]))
        m.final_error_3d_m = float(np.linalg.norm(base - end[:3]))
        m.com_to_goal_m = float(np.linalg.norm(sim.com_W()[:2] - plan.goal[:2]))
        m.plan_com_to_goal_m = float(plan.outcome.get("distance_to_goal", math.nan))
        tol = self.settings.reach_tol_m
        # feedback walks to the goal itself: there, reaching is the COM at the goal (ending
        # where a partial plan ended is not reaching); open loop: the plan's final base
        if m.mode == "feedback":
            m.reached = bool(m.com_to_goal_m <= tol and not m.fell)
        else:
            m.reached = bool(m.final_error_m <= tol and not m.fell)
        m.joint_rms_rad = math.sqrt(self._sq / max(self._n, 1))
        m.saturation_frac = self._sat / max(self._n, 1)
        m.sim_time_s = sim.time - sim_t0
        m.wall_time_s = wall_s


# ------------------------------------------------------------------------------ execution
_progress: ContextVar[Callable[[Simulator], None] | None] = ContextVar(
    "stratawalk_simulation_progress", default=None
)


@contextlib.contextmanager
def reporting_progress(callback: Callable[[Simulator], None] | None) -> Iterator[None]:
    """Runs started in the block call ``callback(simulator)`` every 50 control ticks."""
    token = _progress.set(callback)
    try:
        yield
    finally:
        _progress.reset(token)


class Execution:
    """Drive a :class:`Simulator` through reference segments with a :class:`Monitor`.

    Segments are given in plan time; each starts at the scheduled end of the previous one
    and lasts ``time_scale`` times its plan duration.
    """

    def __init__(self, sim: Simulator, monitor: Monitor):
        self.sim = sim
        self.monitor = monitor
        self.clock = sim.time
        self._last_contact: NDArray[np.bool_] | None = None
        self.interrupted = False  # Ctrl-C or SIGTERM stopped the run (planner.core.interrupts)
        self.progress = _progress.get()  # called with the simulator now and then

    def interrupt(self) -> None:
        """Stop here (Ctrl-C or SIGTERM): the motion so far is kept and judged."""
        self.interrupted = True
        self.monitor.metrics.message = (
            f"interrupted at {self.sim.time:.1f} s of simulated time; the motion so far is kept"
        )

    @property
    def stopped(self) -> bool:
        """A fall ends the run (when ``stop_on_fall``)."""
        return self.monitor.metrics.fell and self.sim.settings.stop_on_fall

    def follow(self, times: Any, q: Any, contact: Any, torque_ff: Any = None) -> bool:
        """Track samples (plan times (N,), Pinocchio q (N, 19), contact (N, 4)); False on a fall.

        ``torque_ff`` (N, 12): the servos' feed-forward torques (computed when None).
        """
        times = np.asarray(times, float)
        if len(times) == 0:
            return not self.stopped
        t_sim = self.clock + self.sim.settings.time_scale * (times - times[0])
        q, contact = np.asarray(q, float), np.asarray(contact, bool)
        loaded = loaded_feet(contact, self._last_contact)
        self._last_contact = contact[-1].copy()
        if torque_ff is None or not self.sim.settings.feedforward:
            torque_ff = self.sim.holding_torques_nm(q, loaded)
        self.monitor.extend(t_sim, q, contact, np.asarray(torque_ff, float))
        end = float(t_sim[-1])
        return self._run_until(end)

    def hold(self, duration_s: float) -> bool:
        """Keep the last set-points for ``duration_s`` of simulated time."""
        return self._run_until(self.clock + duration_s)

    def _run_until(self, end: float) -> bool:
        sim, mon = self.sim, self.monitor
        half = 0.5 * sim.settings.control_dt_s
        ticks = 0
        while sim.time < end - half and not self.stopped:
            joints, _, _, _ = mon.reference_at(sim.time + half)
            sim.set_targets(joints, mon.feedforward_at(sim.time + half))
            sim.tick()
            mon.update()
            ticks += 1
            if ticks % 50 == 0:
                interrupts.check()  # Ctrl-C / SIGTERM: stop here (planner.core.interrupts)
                if self.progress is not None:
                    self.progress(sim)
        self.clock = max(self.clock, end)
        return not self.stopped


def cycle_starts(contact: NDArray[np.bool_]) -> list[int]:
    """Sample indices where a cycle (gait step) begins: 0 and every touchdown onto S0."""
    allc = np.asarray(contact, bool).all(axis=1)
    out = [0]
    out += [k for k in range(1, len(allc)) if allc[k] and not allc[k - 1]]
    return out


@dataclass
class SimResult:
    """A run: its metrics and the executed motion as a plan (stats hold metrics and settings)."""

    metrics: Metrics
    executed: Plan
    settings: SimSettings = field(repr=False)


def new_run(plan: Plan, settings: SimSettings | None, mode: str) -> tuple[Simulator, Execution]:
    """A simulator for the plan, settled at its first configuration, and an execution."""
    settings = (settings or SimSettings()).check()
    if len(plan.samples) < 2:
        raise InputError(f"{plan.source}: samples: need at least 2 samples to execute a plan")
    robot = plan.load_robot()
    try:
        terrain = plan.load_terrain()
    except InputError:
        terrain = None  # the grid is enough; edges are then placed to half a cell
    sim = Simulator(robot, plan.terrain_grid, plan.friction, terrain, settings)
    sim.settle(plan.samples.q[0], settings.settle_s)
    monitor = Monitor(sim, mode)
    return sim, Execution(sim, monitor)


def finish_run(
    plan: Plan, ex: Execution, wall0: float, t0: float, extra: dict | None = None
) -> SimResult:
    """Hold the last set-point, close the metrics, build the executed plan."""
    from planner.core.interrupts import shielded

    sim, mon = ex.sim, ex.monitor
    with shielded():  # a second Ctrl-C does not lose the run
        if not mon.t:  # nothing executed (every step failed): the settled start is held
            ex.follow(plan.samples.time[:1], plan.samples.q[:1], plan.samples.contact[:1])
        if not ex.stopped and not ex.interrupted:
            ex.hold(sim.settings.hold_s)
        mon.finish(plan, _time.perf_counter() - wall0, t0)
        m = mon.metrics
        if not m.message:
            m.message = _verdict(m)
        executed = executed_plan(plan, mon, sim.settings, extra)
    return SimResult(m, executed, sim.settings)


def _verdict(m: Metrics) -> str:
    parts = []
    if m.fell:
        parts.append(f"fell at {m.fall_time_s:.1f} s ({m.fall_reason})")
    if m.tipped:
        parts.append(f"tipped {m.max_tilt_error_deg:.0f} deg off the plan")
    if m.slipped:
        parts.append(f"{m.max_sliding_leg} slid {1000 * m.max_sliding_m:.0f} mm")
    if m.body_contact and not m.fell:
        parts.append("body touched the terrain")
    if not parts:
        parts.append("executed as planned" if m.reached else "did not reach the plan's end")
    return "; ".join(parts)


def executed_plan(plan: Plan, mon: Monitor, settings: SimSettings, extra: dict | None) -> Plan:
    """The executed motion in the plan format (same robot, terrain, grid, goal)."""
    m = mon.metrics
    t = np.array(mon.rec_t) - mon.rec_t[0]
    q = np.array(mon.rec_q)
    q[:, 3:7] /= np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)
    stats = {
        "simulation": m.to_dict(),
        "settings": asdict(settings),
        "source_plan": plan.source,
        "mujoco": MUJOCO_VERSION,
        "note": "executed motion: samples are measured (MuJoCo), keyframes are the measured "
        "configurations at each cycle start with measured contact forces; times are "
        "simulated seconds (plan time x time_scale)",
    }
    stats.update(extra or {})
    return Plan(
        robot=dict(plan.robot),
        terrain=dict(plan.terrain),
        terrain_grid=plan.terrain_grid,
        friction=plan.friction,
        start=plan.start.copy(),
        goal=plan.goal.copy(),
        keyframes=list(mon.keyframes),
        samples=Samples(t, q, np.array(mon.rec_c, bool).reshape(-1, 4)),
        outcome={
            "reached_goal": bool(m.ok and plan.outcome.get("reached_goal", False)),
            "distance_to_goal": float(m.com_to_goal_m),
            "message": f"simulated ({m.mode}): {m.message}",
        },
        stats=stats,
        source=f"{plan.source} (simulated)",
    )


def run_open_loop(
    plan: Plan, settings: SimSettings | None = None, torque_ff: _Array | None = None
) -> SimResult:
    """Execute ``plan`` open loop: joint set-points from the samples, slowed by time_scale.

    ``torque_ff`` (N, 12): feed-forward torques at the samples (e.g. an exported
    trajectory's); computed from the plan when None.
    """
    wall0 = _time.perf_counter()
    sim, ex = new_run(plan, settings, "open loop")
    t0 = sim.time
    s = plan.samples
    starts = sorted(set(cycle_starts(s.contact)) | {len(s) - 1})
    try:
        for a, b in zip(starts[:-1], starts[1:], strict=True):
            ex.monitor.keyframe(0)
            ex.monitor.metrics.cycles += 1
            ff = None if torque_ff is None else torque_ff[a : b + 1]
            if not ex.follow(s.time[a : b + 1], s.q[a : b + 1], s.contact[a : b + 1], ff):
                break
    except KeyboardInterrupt:
        ex.interrupt()
    return finish_run(plan, ex, wall0, t0)
