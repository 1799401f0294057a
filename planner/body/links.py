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
:func:`planner.planfile.validate.check_plan` measures it exactly (``leg_clearance``).
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
    from planner.body.robot import Robot

__all__ = ["Capsule", "LegLinks", "Witness", "disc_clearance", "leg_links"]

_Array = NDArray[np.float64]
FALLBACK_RADIUS_FRACTION = 0.08  # capsule radius / segment length when the URDF has no shape
LINK_NAMES = ("thigh", "shank")
_DISC_DIRECTIONS = 8  # samples on the circle of radius r in clearance_fast
# Margins (beyond the paper) for what execution meets. A leg's links move against the
# terrain by its joint tracking error turning the leg about where it is held: a stance
# leg about its foot (pinned on the terrain), a swinging leg about its hip (its links
# near the foot move with the foot, which has the swing path's clearance). A point at
# distance d from that anchor moves by ~ d x error, plus a constant for the body's own
# position error. Chosen poses (Theta) keep KEYFRAME_*, every path sample PATH_*.
KEYFRAME_MARGIN_M, KEYFRAME_ANGLE_RAD = 0.002, 0.05  # 3 degrees: 5 mm at a 10 cm knee
PATH_MARGIN_M, PATH_ANGLE_RAD = 0.001, 0.025
WITNESS_SEARCH_M = 0.02  # capsules farther than this from the terrain get no constraint [m]
WITNESS_GRID_M = 0.002  # grid of the terrain cloud a witness is picked from [m]


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


def _outside_sphere(a: _Array, b: _Array, r: float, centre: _Array, rho: float):
    """Segment a-b without its end that sweeps a radius-``r`` ball inside the ``rho`` sphere.

    A point p of the axis whose ball lies within the foot sphere (|p - centre| <= rho - r)
    cannot meet the terrain unless the foot does, which its contact checks already cover;
    such an end is cut back to where the ball touches the sphere from inside. Unchanged
    when the link is as thick as the foot or both ends are inside.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    inner = rho - r
    if inner <= 0.0:
        return a, b
    d = b - a
    length = float(np.linalg.norm(d))
    if length == 0.0:
        return a, b
    u = d / length
    w = a - np.asarray(centre, float)
    # |a + s u - centre| = inner: s^2 + 2 (w.u) s + |w|^2 - inner^2 = 0
    bq, cq = float(w @ u), float(w @ w) - inner**2
    disc = bq * bq - cq
    if disc <= 0.0:
        return a, b  # the axis misses the inner ball
    s0, s1 = -bq - math.sqrt(disc), -bq + math.sqrt(disc)
    a_in, b_in = s0 <= 0.0 <= s1, s0 <= length <= s1
    if a_in and b_in:
        return a, b
    if b_in:
        return a, a + max(s0, 0.0) * u
    if a_in:
        return a + min(s1, length) * u, b
    return a, b


def _child_link(root: ET.Element, joint_name: str) -> str:
    el = root.find(f"./joint[@name='{joint_name}']/child")
    return "" if el is None else str(el.get("link"))


class LegLinks:
    """The eight leg capsules of a robot, placed by Pinocchio's forward kinematics."""

    def __init__(self, robot: Robot, spacing_m: float = 0.002):
        from planner.body.robot import _parse_urdf_xml

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
                if k == 2:  # the shank's end inside the foot sphere is the foot's
                    self._fk(pin.neutral(self.model))
                    oMi = self.data.oMi[jid]
                    foot_W = self.data.oMf[self.model.getFrameId(leg.foot_frame)].translation
                    foot_J = oMi.rotation.T @ (np.asarray(foot_W) - oMi.translation)
                    a, b = _outside_sphere(a, b, r, foot_J, robot.foot_radius_m)
                caps.append(Capsule(leg.index, link, urdf_link, jid, a, b, r, src))
        self.capsules = caps
        # each capsule's ends in body frame at zero joint angles (the root joint at identity)
        self._fk(pin.neutral(self.model))
        self.ends_B0 = []
        for cap in caps:
            M = self.data.oMi[cap.joint_id]
            R, t = np.asarray(M.rotation), np.asarray(M.translation)
            self.ends_B0.append((R @ cap.a_J + t, R @ cap.b_J + t))
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
        # for path_margins: all points in their joints' frames, each point's leg, where
        # each capsule's points start, and the frames placed by forward kinematics
        self._pts_J = np.concatenate(pts)  # (P, 3)
        self._point_legs = np.array([cap.leg for cap in caps])[self.owner]  # (P,)
        self._cap_starts = np.flatnonzero(np.r_[True, self.owner[1:] != self.owner[:-1]])
        self._ends_J = (np.array([c.a_J for c in caps]), np.array([c.b_J for c in caps]))
        self._joint_ids = [cap.joint_id for cap in caps]
        self._foot_ids = [self.model.getFrameId(leg.foot_frame) for leg in robot.legs]
        self._hip_ids = [leg.joint_ids[0] for leg in robot.legs]

    def _fk(self, q: _Array) -> None:
        pin.forwardKinematics(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)

    def describe(self, c: int) -> str:
        """'FL shank' for capsule c."""
        from planner.body.robot import LEG_NAMES

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

    def ends_B_ca(self, c: int, theta):
        """Symbolic body-frame ends (a, b) of capsule ``c`` for its leg's 3 joint angles.

        The product of exponentials (eq. 2) up to the capsule's joint, as for the foot.
        """
        from planner.body.kinematics import twist_apply_ca

        cap = self.capsules[c]
        leg = self.robot.legs[cap.leg]
        upto = list(leg.joint_ids).index(cap.joint_id) + 1
        a0, b0 = self.ends_B0[c]
        return twist_apply_ca(leg, theta, a0, upto), twist_apply_ca(leg, theta, b0, upto)

    def witnesses(
        self,
        terrain,
        q: _Array,
        capsules=None,
        swing_legs=(),
        search_m: float = WITNESS_SEARCH_M,
    ) -> list[Witness | None]:
        """Per capsule: the sharp-terrain point nearest its axis, or None beyond ``search_m``.

        The sharp surface near the capsule is sampled as a cloud: the tops of a
        ``WITNESS_GRID_M`` grid of ``Terrain.height_sharp`` around the axis, plus points
        every ``WITNESS_GRID_M`` on the vertical faces between neighbouring nodes whose
        heights jump, at the mid-point between them (the corner of a step is within half a
        grid step of a cloud point). The witness's normal points from it to the axis; the
        Theta problems hold the capsule on that side of the plane through the witness
        (:meth:`planner.problems.base.ThetaProblem.constrain_leg_links`) at least
        ``Witness.need_m`` (``KEYFRAME_*`` margins; ``swing_legs`` are held at the hip).
        """
        fast = self.clearance_fast(terrain, q)  # also places the links (forward kinematics)
        a_W, b_W = self._segments()
        which = range(len(self.capsules)) if capsules is None else capsules
        out: list[Witness | None] = [None] * len(self.capsules)
        for c in which:
            if fast[c] > search_m:
                continue
            cap = self.capsules[c]
            w = _nearest_on_terrain(terrain, a_W[c], b_W[c], search_m + cap.radius_m)
            if w is not None:
                w.clearance_m = w.distance_m - cap.radius_m
                p = a_W[c] + w.u * (b_W[c] - a_W[c])
                d = float(self._anchor_distance(p, cap.leg, swing_legs))
                w.need_m = KEYFRAME_MARGIN_M + KEYFRAME_ANGLE_RAD * d
            out[c] = w
        return out

    def _anchor_distance(self, points_W: _Array, legs, swing_legs=()) -> _Array:
        """Distance of points to where their leg is held (last forward kinematics)."""
        feet = np.array([self.data.oMf[f].translation for f in self._foot_ids])
        hips = np.array([self.data.oMi[j].translation for j in self._hip_ids])
        return _anchor_distance_m(points_W, legs, swing_legs, feet, hips)

    def _segments(self) -> tuple[_Array, _Array]:
        a, b = [], []
        for cap in self.capsules:
            M = self.data.oMi[cap.joint_id]
            R, t = np.asarray(M.rotation), np.asarray(M.translation)
            a.append(R @ cap.a_J + t)
            b.append(R @ cap.b_J + t)
        return np.array(a), np.array(b)

    def silhouette_m(self, leg: int, joints_rad, grid_m: float, length_m: float) -> _Array:
        """Lowest height of ``leg``'s links over the ground ahead of its foot, at a posture.

        ``joints_rad`` (3,) the leg's joints, the body level. Element k: over the
        horizontal distance ``k grid_m`` ahead of the foot centre (body x, up to
        ``length_m``), the lowest point of the leg's capsules less the keyframe margin
        (``KEYFRAME_MARGIN_M`` + ``KEYFRAME_ANGLE_RAD`` x its distance to the foot), in metres
        above the foot's contact point on level ground; inf where no link is. Terrain ahead
        higher than this meets the links.
        """
        th = np.array(self.robot.theta_nor, float)
        th[leg] = np.asarray(joints_rad, float)
        self._fk(self.robot.q_from(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), th))
        foot = np.asarray(self.data.oMf[self._foot_ids[leg]].translation, float)
        ds = grid_m * np.arange(int(np.ceil(length_m / grid_m)) + 1)
        low = np.full(len(ds), np.inf)
        for cap in self.capsules:
            if cap.leg != leg:
                continue
            M = self.data.oMi[cap.joint_id]
            a = np.asarray(M.rotation) @ cap.a_J + np.asarray(M.translation)
            b = np.asarray(M.rotation) @ cap.b_J + np.asarray(M.translation)
            k = max(2, int(np.ceil(np.linalg.norm(b - a) / (0.25 * grid_m))) + 1)
            pts = a + np.linspace(0.0, 1.0, k)[:, None] * (b - a)
            need = KEYFRAME_MARGIN_M + KEYFRAME_ANGLE_RAD * np.linalg.norm(pts - foot, axis=1)
            z = pts[:, 2] - foot[2] + self.robot.foot_radius_m - cap.radius_m - need
            band = (cap.radius_m + need)[:, None]  # a section's width, with its margin
            over = np.abs(ds[None, :] - (pts[:, 0] - foot[0])[:, None]) <= band
            low = np.minimum(low, np.where(over, z[:, None], np.inf).min(axis=0))
        low[0] = np.inf  # under the foot itself: the foot's own edge rules
        return low

    def path_margin(
        self, terrain, q: _Array, swing_legs=(), scale: float = 1.0, legs=None
    ) -> _Array:
        """(C,) least of (clearance bound - path margin) over each capsule's points [m].

        ``scale`` multiplies the margin (0: the clearance bound itself). ``legs``: only
        these legs' capsules are measured (the others get +inf); None: all.

        Negative: some point of the capsule is nearer the terrain than the path margin
        (``PATH_MARGIN_M`` + ``PATH_ANGLE_RAD`` x its distance to the leg's anchor): by
        the conservative bound of :meth:`clearance_fast`, and where that fails, by the
        Euclidean distance to the nearest terrain point (:meth:`witnesses`' cloud, ~1 mm).
        """
        return self.path_margins(terrain, [q], [swing_legs], (scale,), legs)[0][0]

    def path_margins(self, terrain, qs, swing_legs, scales=(1.0,), legs=None) -> list[_Array]:
        """:meth:`path_margin` at every configuration of a path: one (N, C) array per scale.

        ``qs`` (N,) Pinocchio configurations, ``swing_legs`` (N,) the legs in the air at
        each: one terrain query for the whole path (a query per sample costs thousands of
        small terrain calls a plan), each witness searched once for all scales.
        """
        n, n_caps, n_pts = len(qs), len(self.capsules), len(self._pts_J)
        point_legs, starts, (a_J, b_J) = self._point_legs, self._cap_starts, self._ends_J
        pts = np.empty((n, n_pts, 3))
        seg_a, seg_b = np.empty((n, n_caps, 3)), np.empty((n, n_caps, 3))
        feet, hips = np.empty((n, 4, 3)), np.empty((n, 4, 3))
        for k, q in enumerate(qs):
            self._fk(np.asarray(q, float))
            R = np.array([self.data.oMi[j].rotation for j in self._joint_ids])  # (C, 3, 3)
            t = np.array([self.data.oMi[j].translation for j in self._joint_ids])
            pts[k] = np.einsum("pij,pj->pi", R[self.owner], self._pts_J) + t[self.owner]
            seg_a[k] = np.einsum("cij,cj->ci", R, a_J) + t
            seg_b[k] = np.einsum("cij,cj->ci", R, b_J) + t
            feet[k] = [self.data.oMf[f].translation for f in self._foot_ids]
            hips[k] = [self.data.oMi[j].translation for j in self._hip_ids]
        radius = np.broadcast_to(self.radius, (n, n_pts))
        gap = np.full((n, n_pts), np.inf)
        sel = np.ones(n_pts, bool) if legs is None else np.isin(point_legs, list(legs))
        gap[:, sel] = disc_clearance(
            terrain, pts[:, sel].reshape(-1, 3), radius[:, sel].reshape(-1)
        ).reshape(n, -1)
        anchor = np.array(
            [_anchor_distance_m(pts[k], point_legs, swing_legs[k], feet[k], hips[k])
             for k in range(n)]
        )  # fmt: skip
        witness: dict[tuple[int, int], tuple[Witness | None, float]] = {}
        outs = []
        for scale in scales:
            out = np.full((n, n_caps), np.inf)
            need = scale * (PATH_MARGIN_M + PATH_ANGLE_RAD * anchor)
            out[:, self.owner[starts]] = np.minimum.reduceat(gap - need, starts, axis=1)
            for k, c in zip(*np.nonzero(out < 0.0), strict=True):  # the witness decides
                if (k, c) not in witness:
                    cap = self.capsules[c]
                    a, b = seg_a[k, c], seg_b[k, c]
                    w = _nearest_on_terrain(terrain, a, b, cap.radius_m + WITNESS_SEARCH_M)
                    d = 0.0
                    if w is not None:
                        p = a + w.u * (b - a)
                        d = float(_anchor_distance_m(p, cap.leg, swing_legs[k], feet[k], hips[k]))
                    witness[k, c] = (w, d)
                w, d = witness[k, c]
                need_w = scale * (PATH_MARGIN_M + PATH_ANGLE_RAD * d)
                out[k, c] = (
                    np.inf if w is None else w.distance_m - self.capsules[c].radius_m - need_w
                )
            outs.append(out)
        return outs

    def clearance_fast(self, terrain, q: _Array) -> _Array:
        """(C,) lower bounds of each capsule's clearance above the sharp terrain [m].

        For every axis point: its height minus the radius minus the highest sharp terrain
        at the point and at ``_DISC_DIRECTIONS`` points on the circle of 1.05 radius
        around it (the terrain under the capsule's horizontal section). Near a riser this
        treats the face as if it were under the point: a vertical distance where the true
        one is horizontal, which can only be smaller. It misses a corner cutting less
        than ``r (1 - cos(pi / 8))`` (0.08 r) into the disc between two samples.
        """
        gap = self._gaps(terrain, q)
        out = np.full(len(self.capsules), np.inf)
        np.minimum.at(out, self.owner, gap)
        return out

    def point_clearances(self, terrain, q: _Array) -> tuple[_Array, _Array]:
        """Clearance bounds of every axis point (P,) and the points (P, 3) [m], world frame.

        As :meth:`clearance_fast`, per point; ``owner`` names each point's capsule.
        """
        gap = self._gaps(terrain, q)
        return gap, self._points_W

    def _gaps(self, terrain, q: _Array) -> _Array:
        """(P,) clearance bound of every axis point (see :meth:`clearance_fast`)."""
        pts = self._points_W = self.axis_points_W(q)
        return disc_clearance(terrain, pts, self.radius)


def _anchor_distance_m(points_W, legs, swing_legs, feet_W: _Array, hips_W: _Array) -> _Array:
    """Distance [m] of points to where their leg (``legs``, per point) is held.

    A stance leg is held at its foot; a swinging leg at its hip, and its links near the
    foot move with the foot, which keeps the swing path's own clearance: the nearer of hip
    and foot. ``feet_W``, ``hips_W`` (4, 3): the legs' foot and hip positions.
    """
    points, legs = np.asarray(points_W, float), np.asarray(legs, int)
    d = np.linalg.norm(points - feet_W[legs], axis=-1)
    swing = np.isin(legs, list(swing_legs))
    if np.any(swing):
        d = np.where(swing, np.minimum(d, np.linalg.norm(points - hips_W[legs], axis=-1)), d)
    return d


def disc_clearance(terrain, points_W: _Array, radius_m) -> _Array:
    """(P,) cheap, conservative clearance of spheres or capsule sections at ``points_W``.

    Each point's height minus ``radius_m`` minus the highest sharp terrain under a disc of
    1.05 ``radius_m`` around it (the point and ``_DISC_DIRECTIONS`` on the circle); see
    :meth:`LegLinks.clearance_fast`.
    """
    pts = np.asarray(points_W, float)
    r = np.broadcast_to(np.asarray(radius_m, float), (len(pts),))
    ang = 2.0 * np.pi * np.arange(_DISC_DIRECTIONS) / _DISC_DIRECTIONS
    h = np.empty(len(pts))
    for radius in np.unique(r):  # the disc's offsets, one set per radius
        at = r == radius
        ox = np.concatenate([[0.0], 1.05 * radius * np.cos(ang)])
        oy = np.concatenate([[0.0], 1.05 * radius * np.sin(ang)])
        h[at] = terrain.height_sharp_offsets(pts[at, 0], pts[at, 1], ox, oy).max(axis=1)
    return pts[:, 2] - r - h


@dataclass
class Witness:
    """The terrain point nearest a capsule axis: ``u`` along the axis (0 at a, 1 at b)."""

    u: float
    point_W: _Array  # on the sharp terrain [m]
    normal_W: _Array  # unit, from the terrain point toward the axis
    distance_m: float  # axis to terrain; under it: minus the depth, normal e_z
    clearance_m: float = 0.0  # distance minus the capsule radius
    need_m: float = 0.0  # the clearance asked of this point (margin model, module top)


def _nearest_on_terrain(terrain, a: _Array, b: _Array, reach_m: float) -> Witness | None:
    """Nearest cloud point of the sharp terrain to segment a-b within ``reach_m``."""
    g = WITNESS_GRID_M
    lo = np.minimum(a, b)[:2] - reach_m
    hi = np.maximum(a, b)[:2] + reach_m
    xs = np.arange(lo[0], hi[0] + g, g)
    ys = np.arange(lo[1], hi[1] + g, g)
    X, Y = np.meshgrid(xs, ys)  # [iy, ix]
    H = terrain.height_sharp_offsets(xs, np.full(len(xs), ys[0]), 0.0, ys - ys[0]).T
    clouds = [np.stack([X, Y, H], axis=-1).reshape(-1, 3)]
    for axis in (0, 1):  # faces between neighbours along x, then y
        h0 = H[:, :-1] if axis == 1 else H[:-1, :]
        h1 = H[:, 1:] if axis == 1 else H[1:, :]
        x0 = X[:, :-1] if axis == 1 else X[:-1, :]
        x1 = X[:, 1:] if axis == 1 else X[1:, :]
        y0 = Y[:, :-1] if axis == 1 else Y[:-1, :]
        y1 = Y[:, 1:] if axis == 1 else Y[1:, :]
        jump = np.abs(h1 - h0) > 2 * g
        if not np.any(jump):
            continue
        lo_h, hi_h = np.minimum(h0, h1)[jump], np.maximum(h0, h1)[jump]
        mx, my = 0.5 * (x0 + x1)[jump], 0.5 * (y0 + y1)[jump]
        n = int(np.ceil(float(np.max(hi_h - lo_h)) / g)) + 1
        t = np.linspace(0.0, 1.0, n)
        zs = lo_h[:, None] + (hi_h - lo_h)[:, None] * t[None, :]
        face = np.stack([np.repeat(mx, n), np.repeat(my, n), zs.ravel()], axis=1)
        clouds.append(face)
    # an axis that enters the terrain: the deepest of its points, pushed straight up
    s = np.linspace(0.0, 1.0, max(2, int(np.ceil(np.linalg.norm(b - a) / g)) + 1))
    axis = a + s[:, None] * (b - a)
    gap = axis[:, 2] - np.asarray(terrain.height_sharp(axis[:, 0], axis[:, 1]), float)
    if float(gap.min()) < 0.0:
        k = int(np.argmin(gap))
        top = np.array([axis[k, 0], axis[k, 1], axis[k, 2] - gap[k]])
        return Witness(float(s[k]), top, np.array([0.0, 0.0, 1.0]), float(gap[k]))
    cloud = np.concatenate(clouds)
    ab = b - a
    L2 = max(float(ab @ ab), 1e-18)
    u = np.clip(((cloud - a) @ ab) / L2, 0.0, 1.0)
    foot = a + u[:, None] * ab
    d = np.linalg.norm(foot - cloud, axis=1)
    k = int(np.argmin(d))
    if d[k] > reach_m:
        return None
    p, w = foot[k], cloud[k]
    return Witness(float(u[k]), w, (p - w) / max(float(d[k]), 1e-12), float(d[k]))


_CACHE: dict[int, LegLinks] = {}


def leg_links(robot: Robot) -> LegLinks:
    """The :class:`LegLinks` of a robot (built once per Robot object)."""
    key = id(robot)
    got = _CACHE.get(key)
    if got is None or got.robot is not robot:
        got = _CACHE[key] = LegLinks(robot)
    return got
