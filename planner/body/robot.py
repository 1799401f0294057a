"""Quadruped robot model loaded from a URDF with Pinocchio (DESIGN.md section 2, step 1).

Pinocchio's model is the single source of truth: leg chains, joint placements and axes,
limits and inertias are read from it and from the URDF's collision geometry. A robot is
accepted when its free-flyer root carries exactly four leg chains of three revolute joints
each; anything else is refused with an error that says what was found.

``load_robot("littledog")`` loads ``models/littledog/littledog.urdf``; the quadrupeds of
the example-robot-data wheel (solo12, anymal, anymal_b, hyq, go1, go2, a1, b1, laikago)
load by name from its share folder.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pinocchio as pin

from planner.body.kinematics import finalize_robot
from planner.body.robot_model import Leg, Robot
from planner.core.errors import RobotModelError
from planner.core.legs import LEG_NAMES  # noqa: F401  (re-exported: planner.body.robot.LEG_NAMES)

MODELS_DIR = Path(__file__).resolve().parents[2] / "models"
# a foot without a collision sphere in the URDF (a mesh, or none) gets a sphere of this
# share of its shank (knee to foot point): the sphere feet of littledog, go1, a1, b1,
# laikago and anymal measure 0.086-0.11 of their shanks (hyq 0.063)
FOOT_RADIUS_FRACTION = 0.1

# example-robot-data ships URDFs under <prefix>/share/example-robot-data/robots (no loader).
_ERD_ROBOTS = {
    "solo12": "solo_description/robots/solo12.urdf",
    "anymal": "anymal_c_simple_description/urdf/anymal.urdf",
    "anymal_b": "anymal_b_simple_description/robots/anymal.urdf",
    "hyq": "hyq_description/robots/hyq_no_sensors.urdf",
    "go1": "go1_description/urdf/go1.urdf",
    "go2": "go2_description/urdf/go2.urdf",
    "a1": "a1_description/urdf/a1.urdf",
    "b1": "b1_description/urdf/b1.urdf",
    "laikago": "laikago_description/urdf/laikago.urdf",
}


def erd_robots_dir() -> Path:
    """Folder where the example-robot-data wheel installs its robot descriptions."""
    candidates = [Path(sys.prefix) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"]
    candidates += [
        Path(p) / "cmeel.prefix" / "share" / "example-robot-data" / "robots" for p in sys.path if p
    ]
    for c in candidates:
        if c.is_dir():
            return c
    raise RobotModelError(
        "example-robot-data: its share folder was not found; install it (pip install "
        "example-robot-data) or give a URDF path"
    )


def robot_names() -> list[str]:
    """Names that :func:`load_robot` accepts."""
    return ["littledog", *sorted(_ERD_ROBOTS)]


def resolve_urdf(name_or_path: str | Path) -> tuple[str, Path]:
    """Return (robot name, URDF path) for a known name or a path to a URDF file."""
    key = str(name_or_path)
    if key == "littledog":
        return "littledog", MODELS_DIR / "littledog" / "littledog.urdf"
    if key in _ERD_ROBOTS:
        return key, erd_robots_dir() / _ERD_ROBOTS[key]
    path = Path(key)
    if path.suffix.lower() != ".urdf" and not path.exists():
        raise RobotModelError(
            f"{key}: not a known robot name (known: {', '.join(robot_names())}) "
            "and not a URDF file; give one of the names or a path to a .urdf file"
        )
    return path.stem, path


def _fail(path: Path, what: str) -> RobotModelError:
    return RobotModelError(f"{path}: {what}")


def _parse_urdf_xml(path: Path) -> ET.Element:
    try:
        return ET.parse(path).getroot()
    except OSError as exc:
        raise _fail(path, f"cannot read it ({exc.strerror}); give an existing URDF") from None
    except ET.ParseError as exc:
        raise _fail(path, f"malformed URDF XML ({exc}); fix the XML") from None


def _build_model(path: Path) -> pin.Model:
    if path.is_dir():
        inside = sorted(p.name for p in path.glob("*.urdf"))[:3]
        raise _fail(
            path,
            "is a folder, not a URDF file; give the path of the .urdf file"
            + (f" (in it: {', '.join(inside)})" if inside else ""),
        )
    if not path.is_file():
        raise _fail(path, "file not found; give an existing URDF path or a known robot name")
    root = _parse_urdf_xml(path)
    if root.tag != "robot":
        raise _fail(path, f"root element is <{root.tag}>, a URDF needs <robot>")
    _check_link_masses(path, root)
    with _c_stderr() as said:  # urdfdom writes its complaints straight to fd 2
        try:
            return pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
        except (RuntimeError, ValueError) as exc:
            msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    why = next((ln.split("Error:", 1)[1].strip() for ln in said if "Error:" in ln), None)
    raise _fail(path, f"Pinocchio could not read it: {why or msg}")


@contextlib.contextmanager
def _c_stderr() -> Iterator[list[str]]:
    """Capture what C/C++ code writes to file descriptor 2 in the block (its lines)."""
    lines: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            lines += tmp.read().decode("utf-8", "replace").splitlines()


def _numbers(path: Path, where: str, text: object, n: int) -> np.ndarray:
    """``n`` finite numbers from a URDF attribute; one-line error naming ``where``."""
    try:
        values = [float(v) for v in str(text).split()]
    except ValueError:
        values = []
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise _fail(path, f"{where}={str(text)!r}: expected {n} finite number(s)")
    return np.array(values)


def _link_geometry(
    root: ET.Element, link: str, path: Path = Path("<urdf>")
) -> list[tuple[str, dict, np.ndarray]]:
    """Collision geometries of a URDF link: (kind, attributes, origin xyz)."""
    out = []
    for el in root.findall(f"./link[@name='{link}']/collision"):
        geo = el.find("geometry")
        if geo is None or len(geo) == 0:
            continue
        org = el.find("origin")
        xyz = np.zeros(3)
        if org is not None and org.get("xyz"):
            xyz = _numbers(path, f"link {link!r}: collision <origin xyz", org.get("xyz"), 3)
        out.append((geo[0].tag, dict(geo[0].attrib), xyz))
    return out


def _find_legs(path: Path, model: pin.Model) -> list[list[int]]:
    """Chains of joint ids from the root's children to the leaves."""
    children: dict[int, list[int]] = {}
    for j in range(2, model.njoints):
        children.setdefault(model.parents[j], []).append(j)
    chains = []
    for start in children.get(1, []):
        chain = [start]
        while len(children.get(chain[-1], [])) == 1:
            chain.append(children[chain[-1]][0])
        if len(children.get(chain[-1], [])) > 1:
            raise _fail(path, f"joint '{model.names[chain[-1]]}' branches; legs must be chains")
        chains.append(chain)
    desc = ", ".join(f"{model.names[c[0]]}: {len(c)} joints" for c in chains)
    if len(chains) != 4:
        raise _fail(
            path,
            f"found {len(chains)} leg chains from the root ({desc}); "
            "stratawalk plans for quadrupeds with exactly 4 legs of 3 revolute joints",
        )
    for c in chains:
        kinds = [model.joints[j].shortname() for j in c]
        if len(c) != 3 or not all("JointModelR" in k and "Unbounded" not in k for k in kinds):
            raise _fail(
                path,
                f"leg starting at '{model.names[c[0]]}' has joints {kinds}; "
                "each leg needs exactly 3 revolute joints",
            )
    return chains


def _foot_frame(path: Path, model: pin.Model, data: pin.Data, knee_id: int) -> int:
    """Return the frame below the knee farthest from it (preferring names with "foot")."""
    candidates = [
        i
        for i, f in enumerate(model.frames)
        if f.parentJoint == knee_id and f.type in (pin.FrameType.BODY, pin.FrameType.FIXED_JOINT)
    ]
    named = [i for i in candidates if "foot" in model.frames[i].name.lower()]
    pool = named or candidates
    if not pool:
        raise _fail(path, f"no frame below joint '{model.names[knee_id]}' to use as the foot")
    knee = data.oMi[knee_id].translation
    dist = [np.linalg.norm(data.oMf[i].translation - knee) for i in pool]
    best = max(dist)
    # several frames at the same point (fixed joint + child link): prefer the BODY frame
    same = [i for i, d in zip(pool, dist, strict=True) if abs(d - best) < 1e-9]
    same.sort(key=lambda i: model.frames[i].type != pin.FrameType.BODY)
    return same[0]


def _check_link_masses(path: Path, root) -> None:
    """Refuse a link mass that is negative or not a finite number.

    Checked before Pinocchio, whose URDF parser would print its own multi-line complaint
    or take the number.
    """
    for link in root.iter("link"):
        for mass in link.iter("mass"):
            try:
                value = float(mass.get("value", "nan"))
            except ValueError:
                value = math.nan
            if not (math.isfinite(value) and value >= 0.0):
                raise _fail(
                    path,
                    f"link {link.get('name')!r}: <mass value={mass.get('value')!r}>; "
                    "give a finite mass >= 0 in kg",
                )


def _check_mass_and_limits(path: Path, model: pin.Model) -> None:
    """Refuse a robot of no mass, or a joint whose lower limit is not below its upper."""
    total = float(sum(inert.mass for inert in model.inertias))
    if not total > 0.0:
        raise _fail(path, f"total mass {total:g} kg; give the links their <mass value> in kg")
    for i in range(2, model.njoints):  # joint 1 is the free-flyer
        j = model.joints[i]
        if j.nq != 1:
            continue
        lo, hi = model.lowerPositionLimit[j.idx_q], model.upperPositionLimit[j.idx_q]
        if not lo < hi:
            raise _fail(
                path,
                f"joint {model.names[i]!r}: <limit lower={lo:g} upper={hi:g}>; the lower limit "
                "must be below the upper (swapped?)",
            )


def _foot_sphere(
    root: ET.Element, model: pin.Model, frame_id: int, path: Path
) -> tuple[np.ndarray, float] | None:
    """(centre in the frame [m], radius [m]) of the foot link's largest collision sphere."""
    frame = model.frames[frame_id]
    best = None
    for link in {frame.name, model.frames[frame.parentFrame].name}:
        for kind, attrib, xyz in _link_geometry(root, link, path):
            if kind == "sphere":
                where = f"link {link!r}: <sphere radius"
                r = float(_numbers(path, where, attrib.get("radius"), 1)[0])
                if best is None or r > best[1]:
                    best = (np.asarray(xyz, float), r)
    return best


def _add_sphere_frame(model: pin.Model, frame_name: str, offset: np.ndarray) -> str:
    """Add an operational frame at ``offset`` [m] in frame ``frame_name``; return its name."""
    parent_id = model.getFrameId(frame_name)
    parent = model.frames[parent_id]
    name = f"{frame_name}_sphere_centre"
    if not model.existFrame(name):
        placement = parent.placement * pin.SE3(np.eye(3), np.asarray(offset, float))
        model.addFrame(
            pin.Frame(name, parent.parentJoint, parent_id, placement, pin.FrameType.OP_FRAME)
        )
    return name


def load_robot(name_or_path: str | Path, foot_radius_m: float | None = None) -> Robot:
    """Load a quadruped by name (``littledog``, ``solo12``, ...) or from a URDF path.

    Raises :class:`RobotModelError` (one line naming the file and the problem) for a
    missing file, malformed XML, or a robot that is not 4 legs x 3 revolute joints.
    """
    name, path = resolve_urdf(name_or_path)
    model = _build_model(path)
    root = _parse_urdf_xml(path)
    _check_mass_and_limits(path, model)
    data = model.createData()
    q0 = pin.neutral(model)
    pin.forwardKinematics(model, data, q0)
    pin.updateFramePlacements(model, data)

    legs = _legs_of(path, model, data)
    radius, foot_source = _foot_spheres(path, root, model, q0, legs, foot_radius_m)
    box, source = _body_box(path, root, model, legs)

    inertia = model.inertias[1]
    robot = Robot(
        name=name,
        urdf_path=path,
        model=model,
        legs=legs,
        foot_radius_m=float(radius),
        foot_radius_source=foot_source,
        body_box_B=box,
        body_box_source=source,
        total_mass_kg=float(sum(inert.mass for inert in model.inertias)),
        body_mass_kg=float(inertia.mass),
        body_com_B=np.asarray(inertia.lever).copy(),
    )
    finalize_robot(robot)
    return robot


def _legs_of(path: Path, model: pin.Model, data: pin.Data) -> list[Leg]:
    """The four legs (3 revolute joints each) at the neutral configuration, in leg order.

    Axes, joint points and feet in the body frame; one hip per quadrant (front/hind x
    left/right) names each leg.
    """
    chains = _find_legs(path, model)
    legs: list[Leg] = []
    for chain in chains:
        axes = []
        for j in chain:
            jm = model.joints[j]
            local = {"X": [1, 0, 0], "Y": [0, 1, 0], "Z": [0, 0, 1]}.get(jm.shortname()[-1])
            if local is None:  # revolute unaligned
                local = np.asarray(jm.extract().axis).ravel()
            axes.append(data.oMi[j].rotation @ np.asarray(local, float))
        foot_id = _foot_frame(path, model, data, chain[2])
        hip = data.oMi[chain[0]].translation
        legs.append(
            Leg(
                name="",
                index=-1,
                joint_names=tuple(model.names[j] for j in chain),
                joint_ids=tuple(chain),
                q_index=model.joints[chain[0]].idx_q,
                axes_B=np.array(axes),
                points_B=np.array([data.oMi[j].translation.copy() for j in chain]),
                foot_B0=data.oMf[foot_id].translation.copy(),
                foot_frame=model.frames[foot_id].name,
                lower_rad=model.lowerPositionLimit[[model.joints[j].idx_q for j in chain]].copy(),
                upper_rad=model.upperPositionLimit[[model.joints[j].idx_q for j in chain]].copy(),
                is_front=bool(hip[0] > 0),
                is_left=bool(hip[1] > 0),
            )
        )
    order = {(True, True): 0, (True, False): 1, (False, True): 2, (False, False): 3}
    slots = [order[(leg.is_front, leg.is_left)] for leg in legs]
    if sorted(slots) != [0, 1, 2, 3]:
        found = ", ".join(
            f"{leg.joint_names[0]} at {np.round(leg.points_B[0], 3).tolist()}" for leg in legs
        )
        raise _fail(path, f"hips are not one per quadrant (front/hind x left/right): {found}")
    for leg, slot in zip(legs, slots, strict=True):
        leg.index, leg.name = slot, LEG_NAMES[slot]
    legs.sort(key=lambda leg: leg.index)
    return legs


def _foot_spheres(
    path: Path,
    root: ET.Element,
    model: pin.Model,
    q0: np.ndarray,
    legs: list[Leg],
    foot_radius_m: float | None,
) -> tuple[float, str]:
    """The foot radius [m] and its source; each leg's foot moved to its sphere's centre."""
    # foot spheres: a sphere collision on the foot's link, its centre the foot point
    # (a frame is added where the sphere sits off the link's origin); none: a derived radius
    spheres = [_foot_sphere(root, model, model.getFrameId(leg.foot_frame), path) for leg in legs]
    radius, foot_source = foot_radius_m, "given"
    if any(sp is not None for sp in spheres):
        for leg, sp in zip(legs, spheres, strict=True):
            if sp is not None and np.linalg.norm(sp[0]) > 1e-6:
                leg.foot_frame = _add_sphere_frame(model, leg.foot_frame, sp[0])
        if radius is None:
            radius = max(sp[1] for sp in spheres if sp is not None)
            foot_source = "urdf collision sphere"
    data = model.createData()
    pin.forwardKinematics(model, data, q0)
    pin.updateFramePlacements(model, data)
    for leg in legs:
        leg.foot_B0 = data.oMf[model.getFrameId(leg.foot_frame)].translation.copy()
    if radius is None:
        shank_m = min(float(np.linalg.norm(leg.foot_B0 - leg.points_B[2])) for leg in legs)
        radius = FOOT_RADIUS_FRACTION * shank_m
        foot_source = f"{FOOT_RADIUS_FRACTION:g} x the shank length (no sphere foot in the URDF)"
    return radius, foot_source


def _body_box(
    path: Path, root: ET.Element, model: pin.Model, legs: list[Leg]
) -> tuple[np.ndarray, str]:
    """The body box P (paper, section 4.2): [min, max] corners in the body frame, its source.

    The root link's collision boxes, else a box around the hips.
    """
    root_link = model.frames[2].name if len(model.frames) > 2 else ""
    root_link = next(
        (f.name for f in model.frames if f.parentJoint == 1 and f.type == pin.FrameType.BODY),
        root_link,
    )
    boxes = [
        (attrib, xyz)
        for kind, attrib, xyz in _link_geometry(root, root_link, path)
        if kind == "box"
    ]
    if boxes:
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for attrib, xyz in boxes:
            size = _numbers(path, f"link {root_link!r}: <box size", attrib.get("size"), 3)
            lo, hi = np.minimum(lo, xyz - size / 2), np.maximum(hi, xyz + size / 2)
        box, source = np.array([lo, hi]), f"collision box of link '{root_link}'"
    else:
        hips = np.array([leg.points_B[0] for leg in legs])
        lo = hips.min(axis=0) - [0.05, 0.02, 0.05]
        hi = hips.max(axis=0) + [0.05, 0.02, 0.05]
        box = np.array([lo, hi])
        source = "estimated from the hip positions (no collision box on the root link)"
    return box, source
