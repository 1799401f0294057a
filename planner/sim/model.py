"""The MuJoCo model of a plan: its robot, its terrain, its servos (paper section 10).

The robot is the plan's own URDF, imported by MuJoCo's URDF compiler (a ``<mujoco>``
compiler extension is added to the text), saved as MJCF and completed: a free joint on the
root link, joint armature and damping, one position servo per joint whose torque saturates
at the URDF's effort limit (LittleDog: 1.7 N m hips, 0.6 N m knees), and contact settings.
The terrain comes from the plan's ``terrain_grid`` (so any plan file can be simulated):
a plane when it is level, boxes when it is piecewise constant along x (step, stairs, gap,
barrier: exact sharp edges, refined with the terrain's own sharp height when the spec can
be rebuilt), a height field otherwise (slopes, rough relief, rocks). The plan's friction
coefficient is every contact's. :class:`SimSettings` holds the simulation's and the
execution's settings.
"""

from __future__ import annotations

import math
import re
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.core.errors import InputError

if TYPE_CHECKING:
    from planner.body.robot import Robot
    from planner.planfile.plan import TerrainGrid
    from planner.world.terrain import Terrain

__all__ = ["MUJOCO_VERSION", "SimSettings", "TerrainModel", "build_mjcf", "terrain_model"]

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
