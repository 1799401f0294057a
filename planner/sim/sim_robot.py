"""The robot's URDF made importable by MuJoCo, with the planner's feet (section 10).

Any 4-leg URDF that Pinocchio loads should simulate. MuJoCo's URDF compiler is stricter
than Pinocchio's parser, and the planner's model of the feet must be the body's. Before
the import, the URDF text is changed in four ways, each recorded in :attr:`SimRobot.notes`:

- **Inertias.** MuJoCo refuses an inertia matrix that is not positive definite (go1, b1,
  go2 and the ANYmals ship links whose inertia has a zero or negative eigenvalue); such
  eigenvalues are raised to mass x ``MIN_GYRATION_M``^2 (a 1 mm radius of gyration), the
  principal axes kept. Masses, centres of mass and every positive definite inertia are
  unchanged (MuJoCo's ``balanceinertia`` still mends the triangle inequality).
- **Mesh paths.** ``package://NAME/rest`` is resolved against the URDF's folder and its
  ancestors (example-robot-data's layout), as ROS would.
- **Meshes MuJoCo cannot read** (COLLADA ``.dae``: HyQ) become the planner's primitives:
  the body box on the first body link that has one, the leg capsules (:mod:`planner.body.links`)
  on thigh and shank links; other links lose that collision shape (named in the notes).
- **Feet.** A foot without a collision sphere in the URDF (go2, Solo12: meshes) gets the
  planner's sphere (:attr:`Robot.foot_radius_m`, centred on the foot frame) in place of
  its link's collision shapes, so MuJoCo's feet are the ones the plan stands on.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from planner.core.errors import InputError

if TYPE_CHECKING:
    from planner.body.robot import Robot

__all__ = ["MESH_SUFFIXES", "SimRobot", "sim_robot_urdf"]

MESH_SUFFIXES = (".stl", ".obj", ".msh")  # mesh files MuJoCo reads
MIN_GYRATION_M = 1e-3  # least radius of gyration of a link given an indefinite inertia [m]
_INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
_INERTIA_INDEX = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


@dataclass
class SimRobot:
    """URDF text for MuJoCo and what was changed to get it."""

    text: str
    notes: list[str] = field(default_factory=list)


def _resolve_package(filename: str, urdf_path: Path) -> str:
    """An absolute path for ``package://...`` (the first ancestor that holds it), else as is."""
    if not filename.startswith("package://"):
        return filename
    parts = Path(filename[len("package://") :]).parts
    for base in [urdf_path.parent, *urdf_path.parents]:
        for k in range(len(parts)):
            cand = base.joinpath(*parts[k:])
            if cand.is_file():
                return str(cand)
    return filename


def _fix_inertia(link: ET.Element) -> str:
    """Make ``link``'s inertia positive definite (module doc); '' or what was done."""
    inertia = link.find("inertial/inertia")
    mass_el = link.find("inertial/mass")
    if inertia is None or mass_el is None:
        return ""
    try:
        mass = float(mass_el.get("value", "0"))
        v = {k: float(inertia.get(k, "0")) for k in _INERTIA_KEYS}
    except ValueError:
        return ""
    if not mass > 0.0:
        return ""
    matrix = np.array(
        [
            [v["ixx"], v["ixy"], v["ixz"]],
            [v["ixy"], v["iyy"], v["iyz"]],
            [v["ixz"], v["iyz"], v["izz"]],
        ]
    )
    w, vec = np.linalg.eigh(matrix)
    if w.min() > 0.0:
        return ""
    fixed = np.maximum(w, mass * MIN_GYRATION_M**2)
    out = vec @ np.diag(fixed) @ vec.T
    for key, (i, j) in zip(_INERTIA_KEYS, _INERTIA_INDEX, strict=True):
        inertia.set(key, repr(float(out[i, j])))
    return (
        f"link {link.get('name')!r}: inertia eigenvalues {np.round(w, 9).tolist()} raised to "
        f"{np.round(fixed, 9).tolist()} kg m^2 (MuJoCo needs a positive definite inertia)"
    )


def _collision(origin_xyz, origin_rpy, tag: str, attrib: dict[str, str]) -> ET.Element:
    col = ET.Element("collision")
    ET.SubElement(
        col,
        "origin",
        {"xyz": " ".join(repr(float(v)) for v in origin_xyz),
         "rpy": " ".join(repr(float(v)) for v in origin_rpy)},
    )  # fmt: skip
    geo = ET.SubElement(col, "geometry")
    ET.SubElement(geo, tag, attrib)
    return col


def _capsule_collision(a: np.ndarray, b: np.ndarray, radius: float) -> ET.Element:
    """A URDF cylinder from ``a`` to ``b`` (link frame) of ``radius`` (MuJoCo: a cylinder)."""
    d = np.asarray(b, float) - np.asarray(a, float)
    length = float(np.linalg.norm(d))
    z = d / max(length, 1e-12)
    pitch = math.atan2(math.hypot(z[0], z[1]), z[2])
    yaw = math.atan2(z[1], z[0])
    centre = 0.5 * (np.asarray(a, float) + np.asarray(b, float))
    return _collision(
        centre, (0.0, pitch, yaw), "cylinder", {"radius": repr(radius), "length": repr(length)}
    )


def sim_robot_urdf(robot: Robot) -> SimRobot:
    """``robot``'s URDF text, changed as the module doc says, for MuJoCo's URDF compiler."""
    from planner.body.links import leg_links

    path = Path(robot.urdf_path)
    try:
        root = ET.fromstring(path.read_text(encoding="utf-8"))
    except (OSError, ET.ParseError) as exc:
        raise InputError(f"{path}: cannot read the robot's URDF ({exc})") from None
    notes: list[str] = []
    links = {el.get("name"): el for el in root.findall("link")}
    for link in links.values():
        note = _fix_inertia(link)
        if note:
            notes.append(note)
    # the planner's primitives for links whose mesh MuJoCo cannot read
    import pinocchio as pin

    # links fixed to the root joint (the body) and their placement in the body frame
    body_links = {
        f.name: f.placement
        for f in robot.model.frames
        if f.parentJoint == 1 and f.type == pin.FrameType.BODY
    }
    box_done = False
    capsules = {cap.urdf_link: cap for cap in leg_links(robot).capsules if cap.urdf_link}
    for name, link in links.items():
        for col in list(link.findall("collision")):
            mesh = col.find("geometry/mesh")
            if mesh is None:
                continue
            filename = _resolve_package(mesh.get("filename", ""), path)
            mesh.set("filename", filename)
            readable = Path(filename).suffix.lower() in MESH_SUFFIXES and Path(filename).is_file()
            if readable:
                continue
            link.remove(col)
            why = Path(filename).name + ("" if Path(filename).is_file() else " (file not found)")
            if name in body_links and not box_done:
                lo, hi = robot.body_box_B
                M = body_links[name]  # the link in the body frame
                R = np.asarray(M.rotation)
                centre = R.T @ (0.5 * (lo + hi) - np.asarray(M.translation))
                rpy = np.asarray(pin.rpy.matrixToRpy(R.T))
                link.append(
                    _collision(centre, rpy, "box",
                               {"size": " ".join(repr(float(v)) for v in hi - lo)})
                )  # fmt: skip
                box_done = True
                notes.append(f"link {name!r}: mesh {why} -> the planner's body box")
            elif name in capsules and not any(
                c.get("_stratawalk") for c in link.findall("collision")
            ):
                cap = capsules[name]
                col2 = _capsule_collision(cap.a_J, cap.b_J, cap.radius_m)
                col2.set("_stratawalk", "1")
                link.append(col2)
                notes.append(f"link {name!r}: mesh {why} -> the planner's {cap.link} capsule")
            else:
                notes.append(f"link {name!r}: mesh {why} dropped (MuJoCo cannot read it)")
    for col in root.iter("collision"):
        col.attrib.pop("_stratawalk", None)
    for mesh in root.iter("mesh"):  # visuals are discarded; their paths are resolved too
        mesh.set("filename", _resolve_package(mesh.get("filename", ""), path))
    # the planner's sphere feet where the URDF has none
    if robot.foot_radius_source != "urdf collision sphere":
        for leg in robot.legs:
            link = links.get(leg.foot_frame)
            if link is None:
                raise InputError(
                    f"{path}: foot frame '{leg.foot_frame}' is not a link; give the foot a "
                    "collision sphere in the URDF"
                )
            for col in list(link.findall("collision")):
                link.remove(col)
            link.append(
                _collision((0, 0, 0), (0, 0, 0), "sphere", {"radius": repr(robot.foot_radius_m)})
            )
        notes.append(
            f"feet: spheres of {1000 * robot.foot_radius_m:.1f} mm at the foot frames "
            f"({robot.foot_radius_source})"
        )
    return SimRobot(ET.tostring(root, encoding="unicode"), notes)
