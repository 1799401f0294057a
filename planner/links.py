"""Leg links as capsules, and how far they are above the sharp terrain (beyond the paper).

The paper keeps the feet on the terrain and the body polyhedron P above it (section 4.4)
but says nothing of the legs between them. Near a step edge a thigh or shank can pass
through the terrain while the feet and the body are fine; MuJoCo (section 10) then finds
the leg on the terrain and the walk falls. Each leg's thigh (child link of the second
joint) and shank (child link of the knee) is modelled here as a *capsule*, a segment
swept by a sphere, in its link frame (= the frame of the joint that moves it, as URDF
defines links):

- a collision ``cylinder`` or ``capsule`` of the link: its axis and radius (the capsule
  contains the cylinder, so the test is conservative at the flat ends);
- else a collision ``box``: its longest axis, radius half the diagonal of its cross
  section;
- else (meshes or no collision geometry): the segment from the link's joint to the next
  joint (thigh) or the foot sphere centre (shank), radius ``FALLBACK_RADIUS_FRACTION`` x
  its length (a leg is rarely thicker than that).

A link's *clearance* is the distance of its capsule to the sharp terrain
(``Terrain.height_sharp`` closed by vertical faces): the distance of the axis to the
surface minus the radius. :meth:`LegLinks.clearance_fast` is the planner's cheap,
conservative bound (vertical gap under a disc of the capsule's radius, see there);
:func:`planner.validate.check_plan` measures it exactly (``leg_clearance``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

if TYPE_CHECKING:
    from planner.robot import Robot

__all__ = ["Capsule", "LegLinks", "leg_links"]

_Array = NDArray[np.float64]
FALLBACK_RADIUS_FRACTION = 0.08  # capsule radius / segment length when the URDF has no shape
LINK_NAMES = ("thigh", "shank")
_DISC_DIRECTIONS = 8  # samples on the circle of radius r in clearance_fast


@dataclass(frozen=True)
class Capsule:
    """One leg link: segment ``a_J``-``b_J`` in its joint's frame [m], swept by ``radius_m``."""

    leg: int  # 0-based, FL, FR, HL, HR
    link: str  # "thigh" or "shank"
    urdf_link: str
    joint_id: int  # Pinocchio joint whose frame the segment is given in
    a_J: _Array
    b_J: _Array
    radius_m: float
    source: str  # where the shape came from

    @property
    def length_m(self) -> float:
        """Length of the axis segment [m]."""
        return float(np.linalg.norm(self.b_J - self.a_J))


def _rpy_matrix(rpy: _Array) -> _Array:
    return np.asarray(pin.rpy.rpyToMatrix(*[float(v) for v in rpy]))


def _shape(root: ET.Element, link: str) -> tuple[_Array, _Array, float, str] | None:
    """(a, b, radius, source) of a link's first cylinder, capsule or box collision."""
    for kind in ("cylinder", "capsule", "box"):
        for el in root.findall(f"./link[@name='{link}']/collision"):
            geo = el.find(f"geometry/{kind}")
            if geo is None:
                continue
            org = el.find("origin")
            xyz = np.zeros(3)
            rot = np.eye(3)
            if org is not None:
                xyz = np.array([float(v) for v in (org.get("xyz") or "0 0 0").split()])
                rot = _rpy_matrix(np.array([float(v) for v in (org.get("rpy") or "0 0 0").split()]))
            if kind == "box":
                size = np.array([float(v) for v in geo.get("size").split()])
                ax = int(np.argmax(size))
                half = np.zeros(3)
                half[ax] = 0.5 * size[ax]
                cross = np.delete(size, ax)
                radius = 0.5 * float(np.hypot(*cross))
            else:
                half = np.array([0.0, 0.0, 0.5 * float(geo.get("length"))])
                radius = float(geo.get("radius"))
            d = rot @ half
            return xyz - d, xyz + d, radius, f"urdf collision {kind}"
    return None


def _child_link(root: ET.Element, joint_name: str) -> str:
    el = root.find(f"./joint[@name='{joint_name}']/child")
    return "" if el is None else str(el.get("link"))


class LegLinks:
    """The eight leg capsules of a robot, placed by Pinocchio's forward kinematics."""

    def __init__(self, robot: Robot, spacing_m: float = 0.002):
        from planner.robot import _parse_urdf_xml

        self.robot = robot
        self.model = robot.model
        self.data = self.model.createData()
        root = _parse_urdf_xml(robot.urdf_path)
        caps: list[Capsule] = []
        for leg in robot.legs:
            for k, link in zip((1, 2), LINK_NAMES, strict=True):
                jid = leg.joint_ids[k]
                urdf_link = _child_link(root, leg.joint_names[k])
                shape = _shape(root, urdf_link) if urdf_link else None
                if shape is None:
                    # the segment to the next joint or the foot centre, in this joint's frame
                    self._fk(pin.neutral(self.model))
                    oMi = self.data.oMi[jid]
                    if k == 1:
                        end_W = self.data.oMi[leg.joint_ids[2]].translation
                    else:
                        end_W = self.data.oMf[self.model.getFrameId(leg.foot_frame)].translation
                    b = oMi.rotation.T @ (np.asarray(end_W) - oMi.translation)
                    a = np.zeros(3)
                    r = FALLBACK_RADIUS_FRACTION * float(np.linalg.norm(b))
                    shape = (a, b, r, "joint-to-joint segment (no collision shape)")
                a, b, r, src = shape
                caps.append(Capsule(leg.index, link, urdf_link, jid, a, b, r, src))
        self.capsules = caps
        # points along each axis, spacing_m apart (ends included)
        pts, owner = [], []
        for c, cap in enumerate(caps):
            n = max(2, int(math.ceil(cap.length_m / spacing_m)) + 1)
            u = np.linspace(0.0, 1.0, n)[:, None]
            pts.append((1.0 - u) * cap.a_J + u * cap.b_J)
            owner.append(np.full(n, c))
        self.points_J = pts  # per capsule (n_c, 3)
        self.owner = np.concatenate(owner)  # (P,) capsule index of each point
        self.radius = np.array([cap.radius_m for cap in caps])[self.owner]  # (P,)

    def _fk(self, q: _Array) -> None:
        pin.forwardKinematics(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)

    def describe(self, c: int) -> str:
        """'FL shank' for capsule c."""
        from planner.robot import LEG_NAMES

        cap = self.capsules[c]
        return f"{LEG_NAMES[cap.leg]} {cap.link}"

    def axis_points_W(self, q: _Array) -> _Array:
        """(P, 3) points along every capsule axis [m], world frame, at Pinocchio ``q``."""
        self._fk(np.asarray(q, float))
        out = []
        for cap, p in zip(self.capsules, self.points_J, strict=True):
            M = self.data.oMi[cap.joint_id]
            out.append(p @ np.asarray(M.rotation).T + np.asarray(M.translation))
        return np.concatenate(out)

    def segments_W(self, q: _Array) -> tuple[_Array, _Array]:
        """(C, 3) and (C, 3): the capsule axis ends [m], world frame, at ``q``."""
        self._fk(np.asarray(q, float))
        a, b = [], []
        for cap in self.capsules:
            M = self.data.oMi[cap.joint_id]
            R, t = np.asarray(M.rotation), np.asarray(M.translation)
            a.append(R @ cap.a_J + t)
            b.append(R @ cap.b_J + t)
        return np.array(a), np.array(b)

    def clearance_fast(self, terrain, q: _Array) -> _Array:
        """(C,) lower bounds of each capsule's clearance above the sharp terrain [m].

        For every axis point: its height minus the radius minus the highest sharp terrain
        at the point and at ``_DISC_DIRECTIONS`` points on the circle of 1.05 radius
        around it (the terrain under the capsule's horizontal section). Near a riser this
        treats the face as if it were under the point: a vertical distance where the true
        one is horizontal, which can only be smaller. It misses a corner cutting less
        than ``r (1 - cos(pi / 8))`` (0.08 r) into the disc between two samples.
        """
        pts = self.axis_points_W(q)
        ang = 2.0 * np.pi * np.arange(_DISC_DIRECTIONS) / _DISC_DIRECTIONS
        ring = 1.05 * self.radius[:, None]
        xs = np.concatenate([pts[:, :1], pts[:, :1] + ring * np.cos(ang)], axis=1)
        ys = np.concatenate([pts[:, 1:2], pts[:, 1:2] + ring * np.sin(ang)], axis=1)
        h = np.asarray(terrain.height_sharp(xs, ys), dtype=float).reshape(xs.shape).max(axis=1)
        gap = pts[:, 2] - self.radius - h
        out = np.full(len(self.capsules), np.inf)
        np.minimum.at(out, self.owner, gap)
        return out


_CACHE: dict[int, LegLinks] = {}


def leg_links(robot: Robot) -> LegLinks:
    """The :class:`LegLinks` of a robot (built once per Robot object)."""
    key = id(robot)
    got = _CACHE.get(key)
    if got is None or got.robot is not robot:
        got = _CACHE[key] = LegLinks(robot)
    return got
