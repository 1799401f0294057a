"""See the walk: a plan replayed in meshcat, live or as one self-contained HTML file.

DESIGN.md section 2, step 6. :func:`build_scene` turns a ``stratawalk.plan/1`` plan into
meshcat commands and one animation (``meshcat.animation.Animation``, played with the
viewer's own play / pause / reset / time controls):

- the robot from its URDF geometry (a Pinocchio geometry model: the visual one, primitives
  for LittleDog and meshes for example-robot-data robots, or the collision one), posed by
  the samples' ``q``, its trunk see-through so that the COM inside it shows;
- the terrain as a mesh built from the plan's ``terrain_grid`` alone (coloured by height,
  with 10 cm grid lines draped on it);
- each foot marked by a sphere: dark blue while it stands (stratum S0 or another leg's
  S_i), orange while it swings (paper section 4.3);
- the support polygon of the feet on the ground, the whole-body COM and its ground
  projection (green inside the feasible COM region, red outside);
- the contact forces of eqs. 3-5 as arrows, length in proportion to newtons, coloured by
  their friction-cone margin (:func:`planner.plots.cone_margin`: green along the normal,
  yellow half-way, red on or outside the cone, inequalities (d)-(e) of 7.3);
- the base path and the COM path, and the current stratum as a label over the robot.

:func:`scene_html` writes the scene as one HTML file that embeds meshcat's viewer script
and every command, so it opens without a server or a network; it starts playing on load
and adds a small bar with play / pause, a time slider and the current stratum.
:class:`ReplayServer` serves it live: a meshcat server in a subprocess, bound to the
loopback interface only unless ``allow_remote`` (it has no authentication).
"""

from __future__ import annotations

import argparse
import base64
import functools
import html
import ipaddress
import json
import math
import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.errors import InputError, PlannerError
from planner.plots import PlanSeries, plan_series

if TYPE_CHECKING:
    import meshcat
    from meshcat.animation import Animation

    from planner.plan import Plan

__all__ = [
    "DEFAULT_HOST",
    "GEOMETRIES",
    "ReplayServer",
    "Scene",
    "add_replay_parser",
    "build_scene",
    "check_host",
    "notebook_html",
    "scene_html",
    "write_html",
]

DEFAULT_HOST = "127.0.0.1"
STANCE_RGB = (0.10, 0.20, 0.60)  # a foot on the ground
SWING_RGB = (1.00, 0.55, 0.00)  # a foot in the air
COM_RGB = (0.85, 0.10, 0.75)
SUPPORT_RGB = (0.15, 0.35, 0.95)
STRATUM_TEXT = (
    "S0: four feet down",
    "S1: FL in the air",
    "S2: FR in the air",
    "S3: HL in the air",
    "S4: HR in the air",
)
GEOMETRIES = ("visual", "collision")
MAX_TERRAIN_VERTICES = 40_000  # the terrain mesh is subsampled to at most this many
_Array = NDArray[np.float64]


# ------------------------------------------------------------------------------ recording
def _meshcat():
    """Import meshcat (quiet about its pyzmq deprecation warning) and return it."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import meshcat
        import meshcat.animation
        import meshcat.geometry
    return meshcat


class Scene:
    """meshcat commands recorded in order (a stand-in for meshcat's ``ViewerWindow``).

    ``meshcat.Visualizer(window=scene)`` draws into it; :meth:`html` and
    :meth:`push` replay the commands into a static page or a live server.
    """

    def __init__(self) -> None:
        self.commands: list[tuple[str, str, bytes]] = []  # (type, path, msgpack)
        self.info: dict[str, Any] = {}

    def send(self, command: Any) -> None:
        """Record one meshcat command (anything with ``lower()``)."""
        import umsgpack

        data = command.lower()
        self.commands.append((str(data["type"]), str(data.get("path", "")), umsgpack.packb(data)))

    def visualizer(self) -> meshcat.Visualizer:
        """A meshcat visualizer that draws into this recording."""
        return _meshcat().Visualizer(window=self)

    def push(self, zmq_url: str, timeout_s: float = 10.0) -> None:
        """Send every command to a running meshcat server's ZeroMQ socket."""
        import zmq

        ctx = zmq.Context.instance()
        sock = ctx.socket(zmq.REQ)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.RCVTIMEO, int(timeout_s * 1000))
        sock.connect(zmq_url)
        try:
            for kind, path, packed in self.commands:
                sock.send_multipart([kind.encode(), path.encode(), packed])
                sock.recv()
        except zmq.Again:
            raise PlannerError(
                f"replay: the meshcat server at {zmq_url} did not answer within {timeout_s:g} s"
            ) from None
        finally:
            sock.close()

    def html(self, autoplay: bool = True, title: str = "stratawalk replay") -> str:
        """One self-contained HTML page: meshcat's viewer script plus every command."""
        return scene_html(self, autoplay=autoplay, title=title)


# ------------------------------------------------------------------------------ geometry
@functools.cache
def _geometry() -> SimpleNamespace:
    """Geometry the meshcat viewer knows but meshcat-python lacks (imported on first use)."""
    mg = _meshcat().geometry

    class ZCylinder(mg.Cylinder):
        """Cylinder along +z from z = 0 to z = height (three.js cylinders run along y)."""

        def intrinsic_transform(self) -> _Array:
            t = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])
            t[2, 3] = self.height / 2.0
            return t.T  # meshcat sends this matrix as it is, and three.js reads column-major

    class Plane(mg.Geometry):
        """three.js PlaneGeometry (in the object's xy plane, facing +z)."""

        def __init__(self, width: float, height: float):
            super().__init__()
            self.width, self.height = width, height

        def lower(self, object_data: Any) -> dict:
            return {"uuid": self.uuid, "type": "PlaneGeometry", "width": self.width,
                    "height": self.height, "widthSegments": 1, "heightSegments": 1}  # fmt: skip

    class TextTexture(mg.Texture):
        """meshcat's ``_text`` texture: text drawn on a 256 x 256 canvas by the viewer."""

        def __init__(self, text: str, font_size: int = 40, font_face: str = "sans-serif"):
            super().__init__()
            self.text, self.font_size, self.font_face = text, font_size, font_face

        def lower(self, object_data: Any) -> dict:
            return {"uuid": self.uuid, "type": "_text", "text": self.text,
                    "font_size": self.font_size, "font_face": self.font_face}  # fmt: skip

    return SimpleNamespace(mg=mg, ZCylinder=ZCylinder, Plane=Plane, TextTexture=TextTexture)


def _hex(rgb: tuple[float, float, float] | NDArray) -> int:
    r, g, b = (int(round(255 * float(np.clip(c, 0.0, 1.0)))) for c in rgb[:3])
    return (r << 16) | (g << 8) | b


def _phong(rgb, opacity: float = 1.0):
    return _geometry().mg.MeshPhongMaterial(color=_hex(rgb), opacity=opacity)


def _rotation_z_to(v: _Array) -> _Array:
    """Rotation matrix taking +z to the direction of ``v`` (identity for v ~ 0)."""
    n = np.linalg.norm(v)
    if n < 1e-12:
        return np.eye(3)
    d = v / n
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.dot(z, d))
    axis = np.cross(z, d)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * kx + (1 - c) * kx @ kx


def _quat_xyzw(r: _Array) -> list[float]:
    from planner.lie import quat_from_rotation

    return [float(v) for v in quat_from_rotation(r)]


def _nice_scale(x: float) -> float:
    """Round ``x`` > 0 to 1, 2 or 5 times a power of ten."""
    e = math.floor(math.log10(x))
    m = x / 10**e
    return (1 if m < 1.5 else 2 if m < 3.5 else 5 if m < 7.5 else 10) * 10**e


def _grid_height(plan: Plan, xy: _Array) -> _Array:
    """Terrain height [m] at points (..., 2) from ``terrain_grid`` (bilinear, clamped)."""
    g = plan.terrain_grid
    h = g.heights
    ny, nx = h.shape
    u = np.clip((xy[..., 0] - g.origin[0]) / g.resolution, 0, nx - 1)
    v = np.clip((xy[..., 1] - g.origin[1]) / g.resolution, 0, ny - 1)
    i0 = np.minimum(np.floor(u).astype(int), max(nx - 2, 0))
    j0 = np.minimum(np.floor(v).astype(int), max(ny - 2, 0))
    i1, j1 = np.minimum(i0 + 1, nx - 1), np.minimum(j0 + 1, ny - 1)
    a, b = u - i0, v - j0
    return (
        (1 - a) * (1 - b) * h[j0, i0] + a * (1 - b) * h[j0, i1]
        + (1 - a) * b * h[j1, i0] + a * b * h[j1, i1]
    )  # fmt: skip


# ------------------------------------------------------------------------------ the scene
@dataclass
class _Tracks:
    """The animation being built: clip fps = speed, so a frame number is plan time [s]."""

    anim: Animation
    vis: meshcat.Visualizer
    times: _Array

    def at(self, k: int):
        return self.anim.at_frame(self.vis, float(self.times[k]))

    def steps(self, path: str, values: NDArray[np.bool_]) -> None:
        """A visibility track with keys where ``values`` change."""
        keep = np.concatenate([[True], values[1:] != values[:-1]])
        keep[-1] = True  # every clip spans the whole walk, or it loops out of step
        for k in np.flatnonzero(keep):
            self.at(int(k))[path].set_property("visible", "boolean", bool(values[k]))


def _terrain(plan: Plan, root: meshcat.Visualizer) -> None:
    """Terrain mesh from ``terrain_grid`` plus draped 10 cm grid lines."""
    from matplotlib import colormaps

    geo = _geometry()
    mg = geo.mg
    grid = plan.terrain_grid
    h = grid.heights
    ny, nx = h.shape
    step = max(1, math.ceil(math.sqrt(nx * ny / MAX_TERRAIN_VERTICES)))
    rows = np.unique(np.r_[np.arange(0, ny, step), ny - 1])
    cols = np.unique(np.r_[np.arange(0, nx, step), nx - 1])
    hs = h[np.ix_(rows, cols)]
    xs = grid.origin[0] + grid.resolution * cols
    ys = grid.origin[1] + grid.resolution * rows
    gx, gy = np.meshgrid(xs, ys)
    verts = np.stack([gx, gy, hs], axis=-1).reshape(-1, 3)
    m, n = hs.shape
    idx = np.arange(m * n).reshape(m, n)
    v00, v01, v10, v11 = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    faces = np.concatenate(
        [np.stack([v00, v01, v11], -1).reshape(-1, 3), np.stack([v00, v11, v10], -1).reshape(-1, 3)]
    )
    lo, hi = float(hs.min()), float(hs.max())
    if hi - lo < 1e-4:
        colours = np.tile([0.72, 0.76, 0.68], (len(verts), 1))
    else:
        colours = colormaps["gist_earth"](0.25 + 0.6 * (verts[:, 2] - lo) / (hi - lo))[:, :3]
    root["terrain/surface"].set_object(
        mg.TriangularMeshGeometry(verts, faces, color=colours),
        mg.MeshLambertMaterial(vertexColors=True),
    )
    # grid lines every 10 cm, 1 mm above the surface, sampled every grid cell
    segs = []
    x0, x1, y0, y1 = xs[0], xs[-1], ys[0], ys[-1]
    for x in np.arange(math.ceil(x0 * 10) / 10, x1 + 1e-9, 0.1):
        yy = np.linspace(y0, y1, max(2, len(ys)))
        segs.append(np.stack([np.full_like(yy, x), yy], -1))
    for y in np.arange(math.ceil(y0 * 10) / 10, y1 + 1e-9, 0.1):
        xx = np.linspace(x0, x1, max(2, len(xs)))
        segs.append(np.stack([xx, np.full_like(xx, y)], -1))
    pts = []
    for s in segs:
        p = np.concatenate([s, _grid_height(plan, s)[:, None] + 0.001], axis=1)
        pts.append(np.repeat(p, 2, axis=0)[1:-1])  # polyline -> segment pairs
    if pts:
        root["terrain/grid"].set_object(
            mg.LineSegments(
                mg.PointsGeometry(np.concatenate(pts).T.astype(np.float32)),
                mg.LineBasicMaterial(color=0x404040, opacity=0.35, transparent=True),
            )
        )


def _robot(plan: Plan, root: meshcat.Visualizer, tr: _Tracks, geometry: str) -> None:
    """The robot's URDF geometry (a Pinocchio geometry model) posed by every sample's q."""
    import warnings

    import pinocchio as pin
    from pinocchio.visualize import MeshcatVisualizer

    from planner.robot import erd_robots_dir

    robot = plan.load_robot()
    dirs = [str(Path(robot.urdf_path).parent)]
    try:
        dirs.append(str(erd_robots_dir().parents[1]))
    except PlannerError:
        pass
    kind = pin.GeometryType.VISUAL if geometry == "visual" else pin.GeometryType.COLLISION
    visual = pin.buildGeomFromUrdf(robot.model, str(robot.urdf_path), kind, package_dirs=dirs)
    viz = MeshcatVisualizer(robot.model, visual, visual)
    viz.viewer = root
    viz.viewerRootNodeName = "robot"
    viz.viewerVisualGroupName = viz.viewerCollisionGroupName = "robot"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for obj in visual.geometryObjects:  # the trunk see-through: the COM is inside it
            trunk = obj.parentJoint == 1
            rgba = [*np.asarray(obj.meshColor)[:3], 0.45] if trunk else None
            viz.loadViewerGeometryObject(obj, kind, rgba)
    model, data, gdata = robot.model, robot.model.createData(), pin.GeometryData(visual)
    for k, q in enumerate(plan.samples.q):
        pin.forwardKinematics(model, data, q)
        pin.updateGeometryPlacements(model, data, visual, gdata)
        frame = tr.at(k)
        for i, obj in enumerate(visual.geometryObjects):
            t = gdata.oMg[i].homogeneous
            if k == 0:  # the static transform carries the mesh scale; tracks pose only
                root[f"robot/{obj.name}"].set_transform(t @ np.diag([*obj.meshScale, 1.0]))
            frame[f"robot/{obj.name}"].set_transform(t)


def _feet(plan: Plan, s: PlanSeries, root: meshcat.Visualizer, tr: _Tracks) -> None:
    """A sphere around each foot: stance colour on the ground, swing colour in the air."""
    from planner.robot import LEG_NAMES

    geo = _geometry()
    mg = geo.mg
    rho = float(plan.robot["foot_radius"])
    centres = s.feet_W + rho * np.where(s.contact[..., None], s.normals_W, [0.0, 0.0, 1.0])
    for leg, name in enumerate(LEG_NAMES):
        root[f"feet/{name}/stance"].set_object(mg.Sphere(1.3 * rho), _phong(STANCE_RGB))
        root[f"feet/{name}/swing"].set_object(mg.Sphere(1.3 * rho), _phong(SWING_RGB))
        for k in range(len(s)):
            tr.at(k)[f"feet/{name}"].set_property(
                "position", "vector3", [float(v) for v in centres[k, leg]]
            )
        tr.steps(f"feet/{name}/stance", s.contact[:, leg])
        tr.steps(f"feet/{name}/swing", ~s.contact[:, leg])


def _support(s: PlanSeries, root: meshcat.Visualizer, tr: _Tracks) -> None:
    """The polygon of the feet on the ground, one object per stance (shown while it lasts)."""
    geo = _geometry()
    mg = geo.mg
    # a stance lasts while the contact flags do (its feet roll by millimetres meanwhile,
    # planner.rolling: the polygon of its first sample stands for it)
    key = [s.contact[k].tobytes() for k in range(len(s))]
    starts = [0] + [k for k in range(1, len(s)) if key[k] != key[k - 1]]
    stops = starts[1:] + [len(s)]
    for i, (a, b) in enumerate(zip(starts, stops, strict=True)):
        p = s.feet_W[a][s.contact[a]] + [0.0, 0.0, 0.003]
        if len(p) < 3:
            continue
        c = p.mean(axis=0)
        p = p[np.argsort(np.arctan2(p[:, 1] - c[1], p[:, 0] - c[0]))]
        verts = np.vstack([c, p])
        faces = np.array([[0, 1 + j, 1 + (j + 1) % len(p)] for j in range(len(p))])
        node = root[f"support/{i}"]
        node["fill"].set_object(
            mg.TriangularMeshGeometry(verts, faces),
            mg.MeshBasicMaterial(color=_hex(SUPPORT_RGB), opacity=0.25, transparent=True),
        )
        node["edge"].set_object(
            mg.LineLoop(
                mg.PointsGeometry(p.T.astype(np.float32)),
                mg.LineBasicMaterial(color=_hex(SUPPORT_RGB)),
            )
        )
        shown = np.zeros(len(s), dtype=bool)
        shown[a:b] = True
        tr.steps(f"support/{i}", shown)


def _com(plan: Plan, s: PlanSeries, root: meshcat.Visualizer, tr: _Tracks, h: float) -> None:
    """COM sphere, its ground projection (disc + drop line), and the COM path (sizes ~ h)."""
    geo = _geometry()
    mg = geo.mg
    ground = _grid_height(plan, s.com_W[:, :2])
    r = max(0.01, 0.07 * h)
    root["com/ball"].set_object(mg.Sphere(r), _phong(COM_RGB))
    root["com/foot/disc"].set_object(geo.ZCylinder(0.002, r), _phong(COM_RGB, 0.9))
    root["com/drop/line"].set_object(geo.ZCylinder(1.0, 0.12 * r), _phong(COM_RGB, 0.6))
    inside = np.nan_to_num(s.com_margin_m, nan=-1.0) > 0.0
    for k in range(len(s)):
        f = tr.at(k)
        f["com/ball"].set_property("position", "vector3", [float(v) for v in s.com_W[k]])
        p = [float(s.com_W[k, 0]), float(s.com_W[k, 1]), float(ground[k]) + 0.001]
        f["com/foot"].set_property("position", "vector3", p)
        f["com/drop"].set_property("position", "vector3", p)
        f["com/drop"].set_property(
            "scale", "vector3", [1.0, 1.0, max(float(s.com_W[k, 2] - ground[k]), 1e-3)]
        )
        rgb = (0.1, 0.75, 0.2) if inside[k] else (0.9, 0.1, 0.1)
        f["com/foot/disc/<object>"].set_property("material.color", "color", list(rgb))
    path = np.concatenate([s.com_W[:, :2], ground[:, None] + 0.002], axis=1)
    root["paths/com_ground"].set_object(
        mg.Line(mg.PointsGeometry(path.T.astype(np.float32)),
                mg.LineBasicMaterial(color=_hex(COM_RGB)))
    )  # fmt: skip
    root["paths/base"].set_object(
        mg.Line(mg.PointsGeometry(s.base_W.T.astype(np.float32)),
                mg.LineBasicMaterial(color=0x111111))
    )  # fmt: skip


def _forces(
    s: PlanSeries, root: meshcat.Visualizer, tr: _Tracks, m_per_N: float, head: float
) -> None:
    """Contact-force arrows at the contact points, coloured by friction-cone margin.

    An arrow is ``m_per_N`` metres per newton long, its head ``head`` metres of that.
    """
    from matplotlib import colormaps

    from planner.robot import LEG_NAMES

    geo = _geometry()
    cmap = colormaps["RdYlGn"]
    mag = np.linalg.norm(s.forces_W, axis=-1)
    for leg, name in enumerate(LEG_NAMES):
        node = f"forces/{name}"
        green = _phong((0.2, 0.7, 0.2))
        root[f"{node}/shaft"].set_object(geo.ZCylinder(1.0, 0.2 * head), green)
        root[f"{node}/head"].set_object(
            geo.ZCylinder(head, radiusTop=0.0, radiusBottom=0.6 * head), green
        )
        shown = s.contact[:, leg] & (mag[:, leg] > 1e-9)
        tr.steps(node, shown)
        for k in range(len(s)):
            f = tr.at(k)
            length = float(mag[k, leg]) * m_per_N
            shaft = max(length - head, 1e-4)
            f[node].set_property("position", "vector3", [float(v) for v in s.feet_W[k, leg]])
            f[node].set_property("quaternion", "quaternion",
                                 _quat_xyzw(_rotation_z_to(s.forces_W[k, leg])))  # fmt: skip
            f[f"{node}/shaft"].set_property("scale", "vector3", [1.0, 1.0, shaft])
            f[f"{node}/head"].set_property("position", "vector3", [0.0, 0.0, shaft])
            m = s.cone_margin[k, leg]
            rgb = [float(c) for c in cmap(float(np.clip(m, 0.0, 1.0)) if np.isfinite(m) else 0.0)]
            rgb = rgb[:3]
            f[f"{node}/shaft/<object>"].set_property("material.color", "color", rgb)
            f[f"{node}/head/<object>"].set_property("material.color", "color", rgb)


def _stratum_label(s: PlanSeries, root: meshcat.Visualizer, tr: _Tracks, h: float) -> None:
    """The current stratum as text floating over the robot (one label per stratum)."""
    geo = _geometry()
    mg = geo.mg
    rot = np.eye(4)
    rot[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # the plane faces -y, text up +z
    for st in range(5):
        obj = mg.Mesh(
            geo.Plane(1.5 * h, 1.5 * h),
            mg.MeshBasicMaterial(map=geo.TextTexture(STRATUM_TEXT[st]), transparent=True),
        )
        root[f"stratum/S{st}"].set_object(obj)
        root[f"stratum/S{st}"].set_transform(rot)
        tr.steps(f"stratum/S{st}", s.stratum == st)
    for k in range(len(s)):
        p = s.base_W[k] + [0.0, 0.0, 0.75 * h]
        tr.at(k)["stratum"].set_property("position", "vector3", [float(v) for v in p])


def build_scene(
    plan: Plan,
    series: PlanSeries | None = None,
    speed: float = 4.0,
    loop: bool = True,
    geometry: str = "visual",
    follow: bool = True,
) -> Scene:
    """Record the meshcat scene and animation of ``plan`` (see the module docstring).

    ``speed`` plays the walk that many times faster than its sample times (a quasi-static
    walk is slow); the viewer's ``timeScale`` control changes it further. ``geometry``
    draws the robot's URDF ``visual`` geometry (meshes for most robots) or its lighter
    ``collision`` geometry (often primitives; Collada meshes can weigh tens of MB).
    ``follow``: the view follows the body (the world is animated under a fixed camera, so
    the robot keeps its size on a long walk); False frames the whole walk once.
    """
    if not (speed > 0 and math.isfinite(speed)):
        raise InputError(f"--speed: expected a number > 0, got {speed}")
    if geometry not in GEOMETRIES:
        raise InputError(f"--geometry: expected one of {', '.join(GEOMETRIES)}, got {geometry!r}")
    s = plan_series(plan) if series is None else series
    scene = Scene()
    vis = scene.visualizer()
    vis["/Grid"].set_property("visible", False)
    vis["/Axes"].set_property("visible", False)
    vis["/Background"].set_property("visible", False)
    root = vis["stratawalk"]
    lo = np.minimum(s.base_W.min(axis=0), s.feet_W.reshape(-1, 3).min(axis=0))
    hi = np.maximum(s.base_W.max(axis=0), s.feet_W.reshape(-1, 3).max(axis=0))
    ground = float(s.feet_W[0, :, 2].min())
    height = max(float(np.mean(s.base_W[:, 2])) - ground, 0.05)  # the robot's size, roughly
    centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, ground + 0.6 * height])
    shift = np.eye(4)
    shift[:3, 3] = -centre
    root.set_transform(shift)
    span = float(max(hi[0] - lo[0], hi[1] - lo[1], 0.3))
    if follow:
        span = min(span, 0.3 + 4.0 * height)  # a window around the robot, not the whole walk
    d = 0.25 + 1.2 * height + 0.45 * span  # the camera's distance scales with the robot and walk
    vis["/Cameras/default/rotated/<object>"].set_property("position", [0.35 * d, 0.55 * d, d])

    anim = _meshcat().animation.Animation(default_framerate=speed)
    tr = _Tracks(anim, root, s.time)
    if follow:  # the world moves so that the base (xy) stays where the view centre is
        for k in range(len(s)):
            p = [-float(s.base_W[k, 0]), -float(s.base_W[k, 1]), -float(centre[2])]
            tr.at(k).set_property("position", "vector3", p)
    mag = np.linalg.norm(s.forces_W, axis=-1)
    fmax = float(np.max(mag)) if np.max(mag) > 0 else 1.0
    m_per_N = _nice_scale(0.7 * height / fmax)  # the longest arrow ~ 0.7 standing heights

    _terrain(plan, root)
    _robot(plan, root, tr, geometry)
    _feet(plan, s, root, tr)
    _support(s, root, tr)
    head = 0.075 * height
    _com(plan, s, root, tr, height)
    _forces(s, root, tr, m_per_N, head)
    _stratum_label(s, root, tr, height)
    vis.set_animation(anim, play=True, repetitions=1_000_000 if loop else 1)
    scene.info = {
        "robot": plan.robot["name"],
        "terrain": plan.terrain.get("name", plan.terrain.get("kind", "")),
        "speed": speed,
        "follow": bool(follow),
        "m_per_N": m_per_N,
        "arrow_head_m": head,
        "time": [round(float(t), 4) for t in s.time],
        "stratum": [int(v) for v in s.stratum],
        "margin_N": [None if not np.isfinite(v) else round(float(v), 3) for v in s.margin_N],
        "outcome": plan.outcome.get("message", ""),
    }
    return scene


# ------------------------------------------------------------------------------ HTML
def _viewer_js() -> str:
    """The viewer script of meshcat (three.js and all), to inline into a page."""
    js = Path(_meshcat().__file__).parent / "viewer" / "dist" / "main.min.js"
    return js.read_text(encoding="utf-8")


_OVERLAY = """
<div id="sw-bar">
  <button id="sw-play" title="play / pause">&#10074;&#10074;</button>
  <input id="sw-time" type="range" min="0" max="1000" value="0" step="1">
  <span id="sw-clock"></span> <b id="sw-stratum"></b> <span id="sw-margin"></span>
</div>
<div id="sw-legend">__LEGEND__</div>
<style>
 #sw-bar{position:fixed;left:0;right:0;bottom:0;padding:6px 10px;background:rgba(255,255,255,.85);
   font:13px sans-serif;display:flex;gap:10px;align-items:center}
 #sw-time{flex:1} #sw-play{width:44px}
 #sw-legend{position:fixed;left:8px;top:8px;padding:6px 8px;background:rgba(255,255,255,.8);
   font:12px sans-serif;line-height:1.5;border-radius:4px}
 .sw-dot{display:inline-block;width:10px;height:10px;border-radius:5px;margin-right:4px}
</style>
<script>
(function(){
 const info = __INFO__;
 const names = ["S0 four feet down","S1 FL up","S2 FR up","S3 HL up","S4 HR up"];
 const anim = viewer.animator, play = document.getElementById("sw-play");
 const slider = document.getElementById("sw-time"), t = info.time, T = t[t.length-1];
 const el = (id) => document.getElementById(id);
 function planTime(){
   return anim.actions.length ? (anim.actions[0].time * info.speed) % (T + 1e-9) : 0;
 }
 function index(x){
   let lo = 0, hi = t.length - 1;
   while (lo < hi) { const m = (lo + hi + 1) >> 1; if (t[m] <= x) lo = m; else hi = m - 1; }
   return lo;
 }
 function show(){
   const x = planTime(), k = index(x), m = info.margin_N[k];
   el("sw-clock").textContent = "t = " + x.toFixed(1) + " / " + T.toFixed(1) + " s";
   el("sw-stratum").textContent = names[info.stratum[k]];
   el("sw-margin").textContent = m === null ? "" : "force margin " + m.toFixed(2) + " N";
   if (anim.playing) slider.value = Math.round(1000 * x / T);
   play.innerHTML = anim.playing ? "&#10074;&#10074;" : "&#9654;";
 }
 play.onclick = function(){ if (anim.playing) anim.pause(); else anim.play(); show(); };
 slider.oninput = function(){
   anim.pause(); anim.seek(slider.value / 1000 * T / info.speed); show();
 };
 if (!info.autoplay) anim.pause();
 (function tick(){ show(); requestAnimationFrame(tick); })();
})();
</script>
"""


def scene_html(scene: Scene, autoplay: bool = True, title: str = "stratawalk replay") -> str:
    """A self-contained HTML page of ``scene`` (no server, no network).

    meshcat's viewer script is inlined and the recorded commands are embedded as base64
    msgpack and applied in order when the page loads; the animation plays on load unless
    ``autoplay`` is false. A bar at the bottom gives play / pause, a time slider, the
    current stratum and the force margin.
    """
    cmds = ",\n".join(
        '"' + base64.b64encode(packed).decode("ascii") + '"' for _, _, packed in scene.commands
    )
    info = dict(scene.info, autoplay=bool(autoplay))
    legend = (
        f"<b>{html.escape(str(info.get('robot', '')))}</b> on "
        f"{html.escape(str(info.get('terrain', '')))} &middot; playback x{info.get('speed', 1):g}"
        f"<br><span class='sw-dot' style='background:#{_hex(STANCE_RGB):06x}'></span>foot on the"
        f" ground <span class='sw-dot' style='background:#{_hex(SWING_RGB):06x}'></span>foot in "
        f"the air<br><span class='sw-dot' style='background:#{_hex(SUPPORT_RGB):06x}'></span>"
        f"support polygon <span class='sw-dot' style='background:#{_hex(COM_RGB):06x}'></span>"
        f"COM (disc: green inside its feasible region)<br>force arrows: 1 cm = "
        f"{0.01 / info.get('m_per_N', 0.01):.3g} N, colour = friction-cone margin "
        f"(<span style='color:#1a9850'>along the normal</span> &rarr; "
        f"<span style='color:#d73027'>on the cone</span>)"
    )
    overlay = _OVERLAY.replace("__INFO__", json.dumps(info).replace("</", "<\\/")).replace(
        "__LEGEND__", legend
    )
    js = _viewer_js().replace("</script", "<\\/script")
    return f"""<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{margin:0}} #meshcat-pane{{width:100vw;height:100vh;overflow:hidden}}</style>
</head>
<body>
<div id="meshcat-pane"></div>
<script>
{js}
</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
(function(){{
 const commands = [
{cmds}
 ];
 for (const c of commands) {{
   const s = atob(c), bytes = new Uint8Array(s.length);
   for (let i = 0; i < s.length; i++) bytes[i] = s.charCodeAt(i);
   viewer.handle_command_bytearray(bytes);
 }}
}})();
</script>
{overlay}
</body>
</html>
"""


def write_html(
    plan: Plan | str | Path,
    path: str | Path,
    speed: float = 4.0,
    autoplay: bool = True,
    geometry: str = "visual",
) -> Path:
    """Write the replay of ``plan`` (a Plan or a plan file) as one self-contained HTML file."""
    from planner.plan import Plan

    plan = plan if isinstance(plan, Plan) else Plan.load(plan)
    scene = build_scene(plan, speed=speed, geometry=geometry)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(scene.html(autoplay=autoplay, title=f"stratawalk: {plan.source}"), "utf-8")
    return out


def notebook_html(scene: Scene | Plan, height: int = 480, speed: float = 4.0):
    """The replay inline in a notebook: an ``<iframe srcdoc>`` of :func:`scene_html`.

    ``scene`` is a :class:`Scene` from :func:`build_scene` or a plan to build one from.
    """
    from IPython.display import HTML

    if not isinstance(scene, Scene):
        scene = build_scene(scene, speed=speed)
    doc = scene.html().replace("&", "&amp;").replace('"', "&quot;")
    style = f"width:100%;height:{int(height)}px;border:none"
    return HTML(f'<div><iframe srcdoc="{doc}" style="{style}"></iframe></div>')


# ------------------------------------------------------------------------------ live server
def check_host(host: str, allow_remote: bool = False) -> str:
    """The address to bind: ``host`` if it is loopback, or anything if ``allow_remote``.

    The meshcat server has no authentication: anyone who reaches it sees the scene, so it
    serves only this machine unless asked. ``localhost`` becomes ``127.0.0.1``.

    Raises
    ------
    InputError
        A non-loopback host without ``allow_remote``.

    """
    host = str(host).strip()
    if host == "localhost":
        return DEFAULT_HOST
    try:
        loopback = ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = False
    if loopback or allow_remote:
        return host
    raise InputError(
        f"--host {host}: not a loopback address; the replay server has no authentication, "
        f"so it listens on {DEFAULT_HOST} only unless you also pass --allow-remote"
    )


def _serve(host: str, port: int | None) -> None:
    """Run a meshcat server (subprocess body): web on ``host``, ZeroMQ on loopback only."""
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    class Bridge(ZMQWebSocketBridge):
        def make_app(self):
            app = super().make_app()
            listen = app.listen

            def listen_on_host(p, **kw):
                return listen(p, address=self.host, **kw)

            app.listen = listen_on_host
            return app

        def setup_zmq(self, url):
            return super().setup_zmq(re.sub(r"^tcp://.*:(\d+)$", r"tcp://127.0.0.1:\1", url))

    bridge = Bridge(host=host, port=port)
    shown = f"[{host}]" if ":" in host else host
    bridge.web_url = f"http://{shown}:{bridge.fileserver_port}/static/"
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    bridge.run()


class ReplayServer:
    """A meshcat server in a subprocess, on loopback unless ``allow_remote``.

    Use as a context manager or call :meth:`start` / :meth:`stop`; :meth:`show` sends a
    :class:`Scene`. ``url`` is the page to open in a browser.
    """

    def __init__(
        self, host: str = DEFAULT_HOST, port: int | None = None, allow_remote: bool = False
    ):
        self.host = check_host(host, allow_remote)
        self.port = port
        self.proc: subprocess.Popen | None = None
        self.url = ""
        self.zmq_url = ""

    def start(self, timeout_s: float = 30.0) -> ReplayServer:
        """Start the server and wait for its URLs."""
        cmd = [sys.executable, "-u", "-m", "planner.replay", "--serve", "--host", self.host]
        if self.port is not None:
            cmd += ["--port", str(int(self.port))]
        self.proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
            start_new_session=True,
        )  # fmt: skip
        lines: list[str] = []

        def read() -> None:
            for line in self.proc.stdout:
                lines.append(line.strip())
                if line.startswith("web_url="):
                    return

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        reader.join(timeout_s)
        urls = dict(line.split("=", 1) for line in lines if "=" in line)
        if "web_url" not in urls or "zmq_url" not in urls:
            self.stop()
            raise PlannerError(
                f"replay: the meshcat server did not start on {self.host} within {timeout_s:g} s"
                f" (output: {' | '.join(lines)[:200]!r}); is the port free?"
            )
        self.url, self.zmq_url = urls["web_url"], urls["zmq_url"]
        return self

    def show(self, scene: Scene) -> None:
        """Send a recorded scene to the server (browsers connected now or later see it)."""
        scene.push(self.zmq_url)

    def stop(self) -> None:
        """Stop the server process (the one this object started)."""
        if self.proc is not None and self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5)
        if self.proc is not None and self.proc.stdout:
            self.proc.stdout.close()
        self.proc = None

    def __enter__(self) -> ReplayServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


# ------------------------------------------------------------------------------ command
def add_replay_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``replay plan.json [--html OUT] [--host H] [--port P] [--allow-remote] ...``."""
    p = subparsers.add_parser(
        "replay", help="play a plan in meshcat (browser), or write it as one HTML file"
    )
    p.add_argument("plan", help="plan.json written by `stratawalk plan`")
    p.add_argument("--html", help="write a self-contained HTML replay here instead of serving")
    p.add_argument("--host", default=DEFAULT_HOST, help="address to serve on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="web port (default: first free >= 7000)")
    p.add_argument(
        "--allow-remote", action="store_true", help="allow a non-loopback --host (no auth!)"
    )
    p.add_argument("--speed", type=float, default=4.0, help="playback speed-up (default 4)")
    p.add_argument(
        "--geometry", choices=GEOMETRIES, default="visual", help="robot geometry of the URDF"
    )
    p.add_argument(
        "--seconds", type=float, default=None, help="stop serving after this long (default: Ctrl-C)"
    )
    p.add_argument("--open", action="store_true", help="open the page in a web browser")
    p.add_argument(
        "--fixed-camera",
        action="store_true",
        help="frame the whole walk once (default: the view follows the body)",
    )
    p.set_defaults(func=cmd_replay)
    return p


def cmd_replay(args) -> int:
    """Run ``stratawalk replay``: write the HTML file, or serve the walk until Ctrl-C."""
    from planner.plan import Plan

    host = None if args.html else check_host(args.host, args.allow_remote)
    plan = Plan.load(args.plan)
    if args.html:
        path = write_html(plan, args.html, speed=args.speed, geometry=args.geometry)
        print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB; open it in a browser)")
        return 0
    scene = build_scene(
        plan, speed=args.speed, geometry=args.geometry, follow=not args.fixed_camera
    )
    with ReplayServer(host, args.port, allow_remote=args.allow_remote) as server:
        server.show(scene)
        print(f"replay of {args.plan}: open {server.url}", flush=True)
        print("(play / pause / time: Open Controls > Animations; Ctrl-C to stop)", flush=True)
        if args.open:
            import webbrowser

            webbrowser.open(server.url, new=2)
        try:
            if args.seconds is None:
                while True:
                    time.sleep(3600)
            else:
                time.sleep(max(0.0, args.seconds))
        except KeyboardInterrupt:
            print("\nstopped", flush=True)
    return 0


def _main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="python -m planner.replay", description=__doc__)
    p.add_argument("--serve", action="store_true", required=True)
    p.add_argument("--host", default=DEFAULT_HOST)
    p.add_argument("--port", type=int, default=None)
    a = p.parse_args(argv)
    _serve(a.host, a.port)


if __name__ == "__main__":
    _main()
