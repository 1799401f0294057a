"""The replay scene: a plan drawn as meshcat commands and one animation (DESIGN.md 2, step 6).

:func:`build_scene` records, into a :class:`Scene`:

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
  their friction-cone margin (:func:`planner.replay.plots.cone_margin`: green along the normal,
  yellow half-way, red on or outside the cone, inequalities (d)-(e) of 7.3);
- the base path and the COM path, and the current stratum as a label over the robot;
- optionally a second motion of the same robot on the same clock, see-through (``compare``:
  e.g. the plan under its MuJoCo execution from ``stratawalk simulate --out``), with its base
  path, so that where the body left the plan shows.

The animation is :class:`planner.replay.tracks.Tracks`: one float32 track per property over
the samples, played by the viewer's own play / pause / reset / time controls.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.core.errors import InputError, PlannerError
from planner.replay.plots import PlanSeries, plan_series
from planner.replay.tracks import SetAnimation, Tracks

if TYPE_CHECKING:
    import meshcat

    from planner.planfile.plan import Plan

__all__ = ["GEOMETRIES", "Scene", "build_scene", "STANCE_RGB", "SWING_RGB", "COM_RGB"]

STANCE_RGB = (0.10, 0.20, 0.60)  # a foot on the ground
SWING_RGB = (1.00, 0.55, 0.00)  # a foot in the air
COM_RGB = (0.85, 0.10, 0.75)
SUPPORT_RGB = (0.15, 0.35, 0.95)
COMPARE_RGBA = (0.55, 0.60, 0.70, 0.35)  # the compared motion: see-through grey-blue
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
        import meshcat.geometry
    return meshcat


class Scene:
    """meshcat commands recorded in order (a stand-in for meshcat's ``ViewerWindow``).

    ``meshcat.Visualizer(window=scene)`` draws into it; :meth:`push` sends the commands to
    a live server, :func:`planner.replay.page.scene_html` makes a static page of them.
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

    class HeightMesh(mg.TriangularMeshGeometry):
        """A triangle mesh in fewer bytes than meshcat's own.

        16-bit indices when it has under 65,536 vertices, and 8-bit vertex colours (three.js
        normalises them), where meshcat sends 32-bit ones.
        """

        def lower(self, object_data: Any) -> dict:
            import umsgpack

            data = super().lower(object_data)
            if len(self.vertices) < 65_536:
                faces = np.ascontiguousarray(self.faces, dtype="<u2")
                data["data"]["index"] = {"itemSize": 3, "type": "Uint16Array",
                                         "array": umsgpack.Ext(0x14, faces.tobytes())}  # fmt: skip
            if self.color is not None:
                rgb = np.clip(np.rint(255 * np.asarray(self.color)), 0, 255).astype(np.uint8)
                data["data"]["attributes"]["color"] = {
                    "itemSize": 3, "type": "Uint8Array", "normalized": True,
                    "array": umsgpack.Ext(0x12, np.ascontiguousarray(rgb).tobytes()),
                }  # fmt: skip
            return data

    return SimpleNamespace(
        mg=mg, ZCylinder=ZCylinder, Plane=Plane, TextTexture=TextTexture, HeightMesh=HeightMesh
    )


def _hex(rgb: tuple[float, float, float] | NDArray) -> int:
    r, g, b = (int(round(255 * float(np.clip(c, 0.0, 1.0)))) for c in rgb[:3])
    return (r << 16) | (g << 8) | b


def _phong(rgb, opacity: float = 1.0):
    return _geometry().mg.MeshPhongMaterial(color=_hex(rgb), opacity=opacity)


def _rotations_z_to(v: _Array) -> _Array:
    """Rotation matrices (n, 3, 3) taking +z to the directions of ``v`` (n, 3).

    The identity for v ~ 0, a half turn about x for v along -z.
    """
    v = np.asarray(v, float)
    n = np.linalg.norm(v, axis=-1)
    d = np.where(n[:, None] > 1e-12, v / np.maximum(n, 1e-300)[:, None], [0.0, 0.0, 1.0])
    c = d[:, 2]
    axis = np.stack([-d[:, 1], d[:, 0], np.zeros_like(c)], axis=-1)  # z x d
    s = np.linalg.norm(axis, axis=-1)
    k = np.where(s[:, None] > 1e-12, axis / np.maximum(s, 1e-300)[:, None], 0.0)
    kx = np.zeros((len(v), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    kx -= kx.transpose(0, 2, 1)
    r = np.eye(3) + s[:, None, None] * kx + (1 - c)[:, None, None] * kx @ kx
    flip = (s <= 1e-12) & (c < 0)
    r[flip] = np.diag([1.0, -1.0, -1.0])
    return r


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
        geo.HeightMesh(verts, faces, color=colours),
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


def _robot(
    plan: Plan,
    root: meshcat.Visualizer,
    tr: Tracks,
    geometry: str,
    name: str = "robot",
    rgba: tuple[float, float, float, float] | None = None,
) -> None:
    """The robot's URDF geometry (a Pinocchio geometry model) posed by every sample's q.

    Drawn under ``root[name]``; ``rgba`` paints every part (else the URDF's colours, the
    trunk see-through).
    """
    import warnings

    import pinocchio as pin
    from pinocchio.visualize import MeshcatVisualizer

    from planner.body.robot import erd_robots_dir

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
    viz.viewerRootNodeName = name
    viz.viewerVisualGroupName = viz.viewerCollisionGroupName = name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for obj in visual.geometryObjects:  # the trunk see-through: the COM is inside it
            colour = rgba
            if colour is None and obj.parentJoint == 1:
                colour = (*np.asarray(obj.meshColor)[:3], 0.45)
            viz.loadViewerGeometryObject(obj, kind, None if colour is None else list(colour))
    model, data, gdata = robot.model, robot.model.createData(), pin.GeometryData(visual)
    q = plan.samples.q
    placements = np.empty((len(visual.geometryObjects), len(q), 4, 4))
    for k in range(len(q)):
        pin.forwardKinematics(model, data, q[k])
        pin.updateGeometryPlacements(model, data, visual, gdata)
        for i in range(len(visual.geometryObjects)):
            placements[i, k] = gdata.oMg[i].homogeneous
    for i, obj in enumerate(visual.geometryObjects):
        # the static transform carries the mesh scale; the tracks pose only
        root[f"{name}/{obj.name}"].set_transform(placements[i, 0] @ np.diag([*obj.meshScale, 1]))
        tr.transform(f"{name}/{obj.name}", placements[i], times=plan.samples.time)


def _feet(plan: Plan, s: PlanSeries, root: meshcat.Visualizer, tr: Tracks) -> None:
    """A sphere around each foot: stance colour on the ground, swing colour in the air."""
    from planner.body.robot import LEG_NAMES

    mg = _geometry().mg
    rho = float(plan.robot["foot_radius"])
    centres = s.feet_W + rho * np.where(s.contact[..., None], s.normals_W, [0.0, 0.0, 1.0])
    for leg, name in enumerate(LEG_NAMES):
        root[f"feet/{name}/stance"].set_object(mg.Sphere(1.3 * rho), _phong(STANCE_RGB))
        root[f"feet/{name}/swing"].set_object(mg.Sphere(1.3 * rho), _phong(SWING_RGB))
        tr.set(f"feet/{name}", "position", "vector3", centres[:, leg])
        tr.visible(f"feet/{name}/stance", s.contact[:, leg])
        tr.visible(f"feet/{name}/swing", ~s.contact[:, leg])


def _support(s: PlanSeries, root: meshcat.Visualizer, tr: Tracks) -> None:
    """The polygon of the feet on the ground, one object per stance (shown while it lasts)."""
    mg = _geometry().mg
    # a stance lasts while the contact flags do (its feet roll by millimetres meanwhile,
    # planner.body.rolling: the polygon of its first sample stands for it)
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
        tr.visible(f"support/{i}", shown)


def _com(plan: Plan, s: PlanSeries, root: meshcat.Visualizer, tr: Tracks, h: float) -> None:
    """COM sphere, its ground projection (disc + drop line), and the COM path (sizes ~ h)."""
    geo = _geometry()
    mg = geo.mg
    ground = _grid_height(plan, s.com_W[:, :2])
    r = max(0.01, 0.07 * h)
    root["com/ball"].set_object(mg.Sphere(r), _phong(COM_RGB))
    root["com/foot/disc"].set_object(geo.ZCylinder(0.002, r), _phong(COM_RGB, 0.9))
    root["com/drop/line"].set_object(geo.ZCylinder(1.0, 0.12 * r), _phong(COM_RGB, 0.6))
    inside = np.nan_to_num(s.com_margin_m, nan=-1.0) > 0.0
    foot = np.stack([s.com_W[:, 0], s.com_W[:, 1], ground + 0.001], axis=1)
    tr.set("com/ball", "position", "vector3", s.com_W)
    tr.set("com/foot", "position", "vector3", foot)
    tr.set("com/drop", "position", "vector3", foot)
    drop = np.maximum(s.com_W[:, 2] - ground, 1e-3)
    tr.set("com/drop", "scale", "vector3", np.stack([np.ones_like(drop)] * 2 + [drop], axis=1))
    rgb = np.where(inside[:, None], [0.1, 0.75, 0.2], [0.9, 0.1, 0.1])
    tr.set("com/foot/disc/<object>", "material.color", "color", rgb)
    path = np.concatenate([s.com_W[:, :2], ground[:, None] + 0.002], axis=1)
    root["paths/com_ground"].set_object(
        mg.Line(mg.PointsGeometry(path.T.astype(np.float32)),
                mg.LineBasicMaterial(color=_hex(COM_RGB)))
    )  # fmt: skip
    root["paths/base"].set_object(
        mg.Line(mg.PointsGeometry(s.base_W.T.astype(np.float32)),
                mg.LineBasicMaterial(color=0x111111))
    )  # fmt: skip


def _forces(s: PlanSeries, root: meshcat.Visualizer, tr: Tracks, m_per_N: float, head: float):
    """Contact-force arrows at the contact points, coloured by friction-cone margin.

    An arrow is ``m_per_N`` metres per newton long, its head ``head`` metres of that.
    """
    from matplotlib import colormaps

    from planner.body.robot import LEG_NAMES
    from planner.core.lie import quat_from_rotation

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
        tr.visible(node, s.contact[:, leg] & (mag[:, leg] > 1e-9))
        shaft = np.maximum(mag[:, leg] * m_per_N - head, 1e-4)
        quats = [quat_from_rotation(r) for r in _rotations_z_to(s.forces_W[:, leg])]
        tr.set(node, "position", "vector3", s.feet_W[:, leg])
        tr.set(node, "quaternion", "quaternion", quats)
        ones = np.ones_like(shaft)
        tr.set(f"{node}/shaft", "scale", "vector3", np.stack([ones, ones, shaft], axis=1))
        tr.set(f"{node}/head", "position", "vector3", np.stack([0 * ones, 0 * ones, shaft], 1))
        m = s.cone_margin[:, leg]
        rgb = cmap(np.where(np.isfinite(m), np.clip(np.nan_to_num(m), 0.0, 1.0), 0.0))[:, :3]
        tr.set(f"{node}/shaft/<object>", "material.color", "color", rgb)
        tr.set(f"{node}/head/<object>", "material.color", "color", rgb)


def _stratum_label(s: PlanSeries, root: meshcat.Visualizer, tr: Tracks, h: float) -> None:
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
        tr.visible(f"stratum/S{st}", s.stratum == st)
    tr.set("stratum", "position", "vector3", s.base_W + [0.0, 0.0, 0.75 * h])


def _compared(other: Plan, plan: Plan, root: meshcat.Visualizer, tr: Tracks, geometry: str):
    """``other`` (same robot) see-through on the same clock, with its base path."""
    if other.robot.get("name") != plan.robot.get("name"):
        raise InputError(
            f"--compare {other.source}: robot {other.robot.get('name')!r}, but the replayed plan"
            f" has {plan.robot.get('name')!r}; compare two motions of the same robot"
        )
    _robot(other, root, tr, geometry, name="compare", rgba=COMPARE_RGBA)
    base = other.samples.q[:, :3]  # the free-flyer's position: the base path
    root["paths/compare_base"].set_object(
        _geometry().mg.Line(_geometry().mg.PointsGeometry(base.T.astype(np.float32)),
                            _geometry().mg.LineBasicMaterial(color=_hex(COMPARE_RGBA[:3])))
    )  # fmt: skip


def build_scene(
    plan: Plan,
    series: PlanSeries | None = None,
    speed: float = 4.0,
    loop: bool = True,
    geometry: str = "visual",
    follow: bool = True,
    compare: Plan | None = None,
) -> Scene:
    """Record the meshcat scene and animation of ``plan`` (see the module docstring).

    ``speed`` plays the walk that many times faster than its sample times (a quasi-static
    walk is slow); the viewer's ``timeScale`` control changes it further. ``geometry``
    draws the robot's URDF ``visual`` geometry (meshes for most robots) or its lighter
    ``collision`` geometry (often primitives; Collada meshes can weigh tens of MB).
    ``follow``: the view follows the body (the world is animated under a fixed camera, so
    the robot keeps its size on a long walk); False frames the whole walk once.
    ``compare``: a second motion of the same robot (e.g. ``simulate --out``) drawn
    see-through on the same clock.
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

    end = float(s.time[-1]) if compare is None else max(s.time[-1], compare.samples.time[-1])
    tr = Tracks(root.path.lower(), np.asarray(s.time, float), fps=speed, end=end)
    if follow:  # the world moves so that the base (xy) stays where the view centre is
        world = np.stack([-s.base_W[:, 0], -s.base_W[:, 1], np.full(len(s), -centre[2])], 1)
        tr.set("", "position", "vector3", world)
    mag = np.linalg.norm(s.forces_W, axis=-1)
    fmax = float(np.max(mag)) if np.max(mag) > 0 else 1.0
    m_per_N = _nice_scale(0.7 * height / fmax)  # the longest arrow ~ 0.7 standing heights

    _terrain(plan, root)
    _robot(plan, root, tr, geometry)
    if compare is not None:
        _compared(compare, plan, root, tr, geometry)
    _feet(plan, s, root, tr)
    _support(s, root, tr)
    head = 0.075 * height
    _com(plan, s, root, tr, height)
    _forces(s, root, tr, m_per_N, head)
    _stratum_label(s, root, tr, height)
    scene.send(SetAnimation(tr, play=True, repetitions=1_000_000 if loop else 1))
    scene.info = {
        "robot": plan.robot["name"],
        "terrain": plan.terrain.get("name", plan.terrain.get("kind", "")),
        "speed": speed,
        "follow": bool(follow),
        "compare": None if compare is None else str(compare.source),
        "m_per_N": m_per_N,
        "arrow_head_m": head,
        "time": [round(float(t), 4) for t in s.time],
        "end": round(end, 4),
        "stratum": [int(v) for v in s.stratum],
        "margin_N": [None if not np.isfinite(v) else round(float(v), 3) for v in s.margin_N],
        "outcome": plan.outcome.get("message", ""),
    }
    return scene
