"""``stratawalk check plan.json``: an independent validator of a plan file.

Judges a ``stratawalk.plan/1`` plan (DESIGN.md section 3) with numpy, Pinocchio and the
exact statics SOCP only; none of the solver's CasADi graphs is used. The robot is rebuilt
from ``robot.urdf`` (or ``robot.name``) and the terrain from its spec.

Checks (``Violation.kind``), at every sample unless marked keyframe:

``robot_mismatch``
    The URDF's joint names, foot frames or foot radius differ from the file's.
``empty_plan``, ``time_order``, ``out_of_range``, ``plan_structure``
    A plan no robot could execute (:mod:`planner.planfile.loader`: fewer than two samples,
    sample times that do not increase, absurd numbers, a degenerate terrain grid), which
    every other command refuses; the other checks are then skipped. ``empty_plan`` also:
    no keyframe.
``keyframe_fk`` (keyframes)
    Pinocchio's foot sphere centre vs the stored foot: ``r + rho n(r)`` for a foot in
    contact (the smaller of that mismatch and ``|c - rho n - r|`` with n taken under the
    centre, the two contact-point conventions of :mod:`planner.body.contact`, equal on planar
    ground), ``r + rho e_z`` for a swing foot; tolerance 1e-6 m.
``contact_count``
    Fewer than three feet in contact (paper section 4.3: quasi-static walking).
``joint_limits`` (samples and keyframes)
    A joint beyond the URDF limits by more than 1e-9 rad (section 7.2 c).
``stance_slip``
    A foot in contact at two consecutive samples that *slides* by more than 1e-6 m: the
    tangential part of its sphere centre's travel (FK) minus the rolling rho w x n of the
    sphere turned by w with the shank (foot frame rotations by Pinocchio; n the normal at
    the first sample's contact). A rigid sphere foot that does not slide rolls
    (:mod:`planner.body.rolling`; the simulator's sliding metric is the same quantity).
``foot_on_terrain`` (samples and keyframes)
    A foot not resting on the *smooth* terrain the planner saw, by more than 1e-4 m
    (section 4.4): ``|f_T(r)|`` of a stored contact point; for a sample, the miss of the
    contact point r on the surface with ``r + rho n(r)`` = the FK sphere centre
    (:func:`contact_points_from_centres`).
``foot_off_sharp_surface``
    A contact point farther from the *sharp* terrain than the smoothing width (+1 mm):
    the solver stands on ``Terrain.height``, which near an edge departs from the real
    surface by up to half the jump over about the smoothing width, so this looser check
    bounds how much of that a plan uses.
``body_clearance``
    A point of the body box P (its vertices and a ``body_grid_m`` grid on its
    downward-facing faces, which form its lower envelope) below the sharp terrain.
``swing_clearance``
    A swing foot's sphere centre closer to the sharp terrain than ``rho - 1e-4 m`` (the
    sphere penetrates the real surface): at every sample, and between two samples where a
    joint of its leg moves more than ``BETWEEN_SAMPLES_RAD`` (the executor's linear joint
    interpolation), every ``BETWEEN_STEP_RAD``.
``leg_clearance``
    A thigh or shank capsule (:mod:`planner.body.links`: the URDF's collision cylinder of the
    link, or its documented stand-in) closer to the sharp terrain than
    ``leg_clearance_m`` (0: touching). Points every 2 mm along the axis; Euclidean
    distance to the surface and its vertical faces, refined to 0.2 mm along the axis
    near the closest point.
``balance``
    No contact forces inside the friction cones of the feet in contact balance gravity
    and moments at Pinocchio's whole-body COM (exact SOCP,
    :func:`planner.body.statics.static_feasibility`; normals of the smooth terrain; mu of the
    file).
``joint_torque``
    With three or more feet down, no contact forces inside the friction cones balance the
    robot with every joint torque (gravity of all links and the contact forces through
    Pinocchio's Jacobians) within its URDF effort limit (:mod:`planner.body.torques`).
``keyframe_forces`` (keyframes)
    Stored forces do not balance gravity and moments (eq. 4) to 1e-6 m g (moments in N m
    about the support centroid), or a foot outside ``support`` carries force.

Distances to the sharp surface are Euclidean, to the graph of ``height_sharp`` together
with its vertical faces: sampled on a 1 mm grid around each point, face positions found
by bisection between grid nodes whose heights jump (accurate to ~3e-5 m). Exact tests
run only where a cheap bound (terrain maxima over 2 cm tiles) does not already clear a
sample, which keeps 2000 samples at a few seconds.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from planner.body import statics
from planner.body.contact import (
    E_Z,
    contact_points_from_centres,
    foot_centre_from_contact,
    unique_contact_points,
)
from planner.body.links import LegLinks
from planner.body.robot import LEG_NAMES
from planner.body.rolling import sliding
from planner.body.stability import support_margin_m
from planner.body.torques import TorqueCheck
from planner.core.errors import PlannerError
from planner.core.units import GRAVITY_M_S2
from planner.motion.interpolate import BETWEEN_SAMPLES_RAD, BETWEEN_STEP_RAD, between_q
from planner.planfile.loader import structure_flaws
from planner.planfile.plan import Plan

if TYPE_CHECKING:
    from planner.body.robot import Robot
    from planner.world.terrain import Terrain

__all__ = [
    "CheckReport",
    "CheckTolerances",
    "Violation",
    "check_plan",
    "contact_points_from_centres",
    "main_check",
    "sharp_surface_distance",
]

_Array = NDArray[np.float64]
_LEG_EXACT_M = 0.004  # leg clearances are exact below this [m]; above, a lower bound


@dataclass(frozen=True)
class CheckTolerances:
    """Tolerances of :func:`check_plan` (SI units: m, rad, N).

    Attributes
    ----------
    fk_m : keyframe FK vs stored feet.
    joint_rad : excursion past a joint limit.
    slip_m : sliding of a foot in contact between consecutive samples (travel minus rolling).
    on_terrain_m : ``|f_T|`` of a contact point on the smooth terrain.
    sharp_surface_m : distance of a contact point from the sharp surface; None: the
        terrain's largest smoothing width + 1 mm (6 mm by default).
    body_clearance_m : least height of the body box above the sharp terrain.
    swing_penetration_m : allowed penetration of a swing foot sphere into the sharp terrain.
    leg_clearance_m : least distance of a thigh or shank capsule to the sharp terrain.
    torque_rel : a joint torque may exceed its effort limit by this fraction.
    force_balance_rel : keyframe force/moment residual, as a fraction of m g.
    min_contacts : feet that must be down at every sample.
    balance_tol_N : margin the exact statics test must exceed; None: its default.
    body_grid_m : spacing of the points sampled on the body box's lower faces.
    surface_step_m : grid step of the sharp-surface distance search.

    """

    fk_m: float = 1e-6
    joint_rad: float = 1e-9
    slip_m: float = 1e-6
    on_terrain_m: float = 1e-4
    sharp_surface_m: float | None = None
    body_clearance_m: float = 0.0
    swing_penetration_m: float = 1e-4
    leg_clearance_m: float = 0.0
    torque_rel: float = 1e-6
    force_balance_rel: float = 1e-6
    min_contacts: int = 3
    balance_tol_N: float | None = None
    body_grid_m: float = 0.005
    surface_step_m: float = 1e-3


@dataclass(frozen=True)
class Violation:
    """One failed check.

    ``kind`` (see the module docstring), ``where`` ("sample 17" / "keyframe 3" / "robot",
    0-based indices), the 1-based ``leg`` (or None), the offending ``value`` and its
    ``limit`` (SI units), and a one-line ``message``.
    """

    kind: str
    where: str
    leg: int | None
    value: float
    limit: float
    message: str

    def __str__(self) -> str:
        return f"{self.where}: {self.kind}: {self.message}"


@dataclass
class CheckReport:
    """Outcome of :func:`check_plan`: the violations and a few summary figures.

    ``min_body_clearance_m``: least height of the body box over the sharp terrain (exact
    at the samples within 1 cm of the ground and the 8 closest, elsewhere the lowest
    vertex over the highest terrain node under the body);
    ``min_swing_clearance_m``: least distance of a swing sphere to the sharp surface
    (negative: penetration; a lower bound where the foot is far up); ``min_leg_clearance_m``:
    least distance of a thigh or shank capsule to the sharp terrain (exact below 4 mm, a
    lower bound above); ``max_torque_ratio``: largest joint torque over its effort limit
    (with the least demanding forces); ``min_balance_margin_N``:
    least force margin of the statics test; ``min_tip_margin_m``: least horizontal
    distance of the COM inside a three-leg support triangle (a figure, not a test: the
    planner keeps :data:`planner.body.stability.PATH_BALANCE_MARGIN_M`);
    ``min_sway_stiffness_N_per_m``: least sway stiffness of a three-leg stance where it
    begins, on the robot's servos with the commanded feed-forward (a figure:
    :mod:`planner.body.stiffness`; the planner keeps its bound); ``max_slip_m``:
    largest stance-foot sliding between samples (travel minus rolling). NaN when there was
    nothing to measure.
    """

    violations: list[Violation] = field(default_factory=list)
    n_samples: int = 0
    n_keyframes: int = 0
    min_body_clearance_m: float = math.nan
    min_swing_clearance_m: float = math.nan
    min_leg_clearance_m: float = math.nan
    min_balance_margin_N: float = math.nan
    min_tip_margin_m: float = math.nan
    max_torque_ratio: float = math.nan
    min_sway_stiffness_N_per_m: float = math.nan
    max_slip_m: float = math.nan
    elapsed_s: float = 0.0
    tolerances: CheckTolerances = field(default_factory=CheckTolerances)
    structure_only: bool = False  # a malformed plan: the other checks were skipped

    @property
    def ok(self) -> bool:
        """True when no check failed."""
        return not self.violations

    def by_kind(self) -> dict[str, int]:
        """Number of violations of each kind."""
        return dict(Counter(v.kind for v in self.violations))

    def summary(self) -> str:
        """One line: verdict, counts per kind, and the summary figures."""
        figs = (
            f"min body clearance {_mm(self.min_body_clearance_m)}, min swing clearance "
            f"{_mm(self.min_swing_clearance_m)}, min leg clearance "
            f"{_mm(self.min_leg_clearance_m)}, min balance margin "
            f"{self.min_balance_margin_N:.3g} N, min three-leg tip margin "
            f"{_mm(self.min_tip_margin_m)}, max joint torque "
            f"{100 * self.max_torque_ratio:.0f} % of its limit, min three-leg sway "
            f"stiffness {self.min_sway_stiffness_N_per_m:.0f} N/m, max stance slip "
            f"{_mm(self.max_slip_m)}"
        )
        head = f"checked {self.n_samples} samples and {self.n_keyframes} keyframes"
        if self.ok:
            return f"{head}: OK ({figs}; {self.elapsed_s:.2f} s)"
        kinds = ", ".join(f"{k} {n}" for k, n in sorted(self.by_kind().items()))
        if self.structure_only:
            return (
                f"{head}: FAILED, {len(self.violations)} violations ({kinds}); no motion a "
                f"robot could execute, so the other checks were skipped ({self.elapsed_s:.2f} s)"
            )
        return (
            f"{head}: FAILED, {len(self.violations)} violations ({kinds}) ({figs}; "
            f"{self.elapsed_s:.2f} s)"
        )


def _mm(x: float) -> str:
    return "n/a" if not math.isfinite(x) else f"{1e3 * x:.3g} mm"


def _leg(i: int) -> str:
    return f"leg {i + 1} ({LEG_NAMES[i]})"


# --------------------------------------------------------------------------- geometry
def _rotations_from_quats(q_xyzw: _Array) -> _Array:
    """(N, 3, 3) rotation matrices of (N, 4) unit quaternions (x, y, z, w)."""
    q = q_xyzw / np.linalg.norm(q_xyzw, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def sharp_surface_distance(
    terrain: Terrain, points_W: _Array, radius_m: float, step_m: float = 1e-3
) -> _Array:
    """Signed Euclidean distance [m] of points to the sharp terrain surface.

    The surface is the graph of ``terrain.height_sharp`` closed by vertical faces at its
    jumps. It is sampled on a square grid of ``step_m`` covering ``radius_m`` around each
    point; where two neighbouring nodes differ by more than ``2 step_m`` the face between
    them is located by bisection. The sign is that of ``p_z - height_sharp(p_x, p_y)``
    (negative: under the surface). The magnitude is at most the vertical gap and is
    clipped to ``radius_m`` (nothing nearer). Error ~ step^2 / (4 d) on smooth parts
    (2.5e-5 m at 1 mm and d = 1 cm); faces are exact to step / 4096.

    Parameters
    ----------
    terrain : Terrain
        Provides ``height_sharp``.
    points_W : array (N, 3)
        Points [m], world frame.
    radius_m : float
        Search radius [m].
    step_m : float
        Grid step [m].

    Returns
    -------
    ndarray (N,)
        Signed distances [m].

    """
    p = np.asarray(points_W, dtype=float).reshape(-1, 3)
    if len(p) == 0:
        return np.zeros(0)
    gap = p[:, 2] - np.asarray(terrain.height_sharp(p[:, 0], p[:, 1]), dtype=float).reshape(-1)
    k = int(math.ceil(radius_m / step_m))
    u = step_m * np.arange(-k, k + 1)
    m = len(u)
    ux, uy = np.meshgrid(u, u)  # [iy, ix]
    r2 = ux**2 + uy**2
    best = np.minimum(np.abs(gap), radius_m)
    chunk = max(1, 200_000 // (m * m))
    jump = 2.0 * step_m
    for a in range(0, len(p), chunk):
        pc = p[a : a + chunk]
        n = len(pc)
        hx = pc[:, 0, None, None] + ux[None]
        hy = pc[:, 1, None, None] + uy[None]
        h = terrain.height_sharp_offsets(pc[:, 0], pc[:, 1], ux, uy).reshape(n, m, m)
        d_graph = np.sqrt(r2[None] + (pc[:, 2, None, None] - h) ** 2)
        d = d_graph.reshape(n, -1).min(axis=1)
        for axis in (2, 1):  # faces between x-neighbours, then y-neighbours
            h0 = h[:, :, :-1] if axis == 2 else h[:, :-1, :]
            h1 = h[:, :, 1:] if axis == 2 else h[:, 1:, :]
            sel = np.nonzero(np.abs(h1 - h0) > jump)
            if not sel[0].size:
                continue
            ip, iy, ix = sel
            xa, ya = hx[ip, iy, ix], hy[ip, iy, ix]
            dx, dy = (step_m, 0.0) if axis == 2 else (0.0, step_m)
            xb, yb = xa + dx, ya + dy
            ha, hb = h0[sel], h1[sel]
            for _ in range(12):
                xm, ym = 0.5 * (xa + xb), 0.5 * (ya + yb)
                hm = np.asarray(terrain.height_sharp(xm, ym), dtype=float).reshape(-1)
                left = np.abs(hm - ha) > np.abs(hm - hb)  # the jump is in [a, m]
                xb, yb, hb = np.where(left, xm, xb), np.where(left, ym, yb), np.where(left, hm, hb)
                xa, ya, ha = np.where(left, xa, xm), np.where(left, ya, ym), np.where(left, ha, hm)
            lo, hi = np.minimum(ha, hb), np.maximum(ha, hb)
            z = pc[ip, 2]
            dz = np.maximum(np.maximum(lo - z, z - hi), 0.0)
            dface = np.sqrt(
                (0.5 * (xa + xb) - pc[ip, 0]) ** 2 + (0.5 * (ya + yb) - pc[ip, 1]) ** 2 + dz**2
            )
            np.minimum.at(d, ip, dface)
        best[a : a + n] = np.minimum(best[a : a + n], d)
    return np.where(gap >= 0.0, 1.0, -1.0) * best


class _TileMax:
    """Upper bounds of the sharp terrain over rectangles, from lazily evaluated tiles.

    The plane is cut into ``TILE_M`` square tiles; a tile's bound is the largest
    ``height_sharp`` at its nodes (``NODE_M`` apart, borders included), evaluated once
    when a query first touches it. ``max_in`` returns the largest bound over the tiles a
    rectangle meets: the terrain's maximum there, up to features narrower than ``NODE_M``
    and, on slopes, ``slope * NODE_M`` (callers subtract ``SLACK_M``). Used to skip the
    exact tests far from the ground.
    """

    TILE_M = 0.02
    NODE_M = 0.005
    SLACK_M = 0.005

    def __init__(self, terrain: Terrain):
        self.terrain = terrain
        self.tiles: dict[tuple[int, int], float] = {}

    def max_in(self, boxes: _Array) -> _Array:
        """Bound (K,) over rectangles (K, 4) ``[x0, x1, y0, y1]`` [m]."""
        t = self.TILE_M
        idx = np.column_stack(
            [np.floor(boxes[:, 0] / t), np.floor(boxes[:, 1] / t),
             np.floor(boxes[:, 2] / t), np.floor(boxes[:, 3] / t)]
        ).astype(int)  # fmt: skip
        ix0, iy0 = idx[:, 0].min(), idx[:, 2].min()
        shape = (idx[:, 3].max() - iy0 + 1, idx[:, 1].max() - ix0 + 1)
        need = np.zeros(shape, dtype=bool)
        for a, b, c, d in idx:
            need[c - iy0 : d - iy0 + 1, a - ix0 : b - ix0 + 1] = True
        todo = [
            (int(ix + ix0), int(iy + iy0))
            for iy, ix in zip(*np.nonzero(need), strict=True)
            if (int(ix + ix0), int(iy + iy0)) not in self.tiles
        ]
        if todo:
            n = int(round(t / self.NODE_M)) + 1
            u = np.linspace(0.0, t, n)
            ux, uy = (g.ravel() for g in np.meshgrid(u, u))
            tix = np.array(todo, dtype=float)
            h = self.terrain.height_sharp(tix[:, :1] * t + ux[None], tix[:, 1:] * t + uy[None])
            hmax = np.asarray(h, dtype=float).reshape(len(todo), -1).max(axis=1)
            self.tiles.update(zip(todo, hmax.tolist(), strict=True))
        grid = np.full(shape, -np.inf)
        for iy, ix in zip(*np.nonzero(need), strict=True):
            grid[iy, ix] = self.tiles[(int(ix + ix0), int(iy + iy0))]
        return np.array([grid[c - iy0 : d - iy0 + 1, a - ix0 : b - ix0 + 1].max()
                         for a, b, c, d in idx])  # fmt: skip


def _body_points_B(robot: Robot, spacing_m: float) -> list[tuple[_Array, _Array]]:
    """Faces of the body box P: (outward normal, (K, 3) points incl. edges) in body frame."""
    lo, hi = robot.body_box_B
    faces = []
    for axis in range(3):
        a, b = [j for j in range(3) if j != axis]
        ua = np.linspace(lo[a], hi[a], max(2, int(math.ceil((hi[a] - lo[a]) / spacing_m)) + 1))
        ub = np.linspace(lo[b], hi[b], max(2, int(math.ceil((hi[b] - lo[b]) / spacing_m)) + 1))
        ga, gb = (g.ravel() for g in np.meshgrid(ua, ub))
        for side, value in ((-1.0, lo[axis]), (1.0, hi[axis])):
            pts = np.empty((len(ga), 3))
            pts[:, axis], pts[:, a], pts[:, b] = value, ga, gb
            normal = np.zeros(3)
            normal[axis] = side
            faces.append((normal, pts))
    return faces


def _smoothing_width_m(spec: dict) -> float:
    """Largest ``smoothing_m`` of a terrain spec and its segments [m]."""
    from planner.world.terrain import DEFAULT_SMOOTHING_M

    widths = [float(spec.get("smoothing_m", DEFAULT_SMOOTHING_M))]
    for seg in spec.get("segments", []) or []:
        if isinstance(seg, dict) and "smoothing_m" in seg:
            widths.append(float(seg["smoothing_m"]))
    return max(widths)


# --------------------------------------------------------------------------- the check
class _Checker:
    """State shared by the checks of one plan."""

    def __init__(self, plan: Plan, tol: CheckTolerances):
        self.plan, self.tol = plan, tol
        self.robot = plan.load_robot()
        self.terrain = plan.load_terrain()
        self.model = self.robot.model
        self.data = self.model.createData()
        self.foot_ids = [self.model.getFrameId(f) for f in self.robot.foot_frames]
        self.rho = self.robot.foot_radius_m
        self.mass = self.robot.total_mass_kg
        self.mu = float(plan.friction)
        self.violations: list[Violation] = []
        self.tiles = _TileMax(self.terrain)
        self.q_leg = {
            leg.q_index + j: (leg.index, leg.joint_names[j])
            for leg in self.robot.legs
            for j in range(3)
        }

    def add(self, kind: str, where: str, leg: int | None, value: float, limit: float, msg: str):
        self.violations.append(
            Violation(kind, where, None if leg is None else leg + 1, float(value), limit, msg)
        )

    def kinematics(self, q: _Array) -> tuple[_Array, _Array]:
        """(4, 3) foot sphere centres and (3,) whole-body COM by Pinocchio."""
        com = pin.centerOfMass(self.model, self.data, q)  # also runs forward kinematics
        pin.updateFramePlacements(self.model, self.data)
        return np.array([self.data.oMf[i].translation for i in self.foot_ids]), np.array(com)

    # ---- file-level ------------------------------------------------------------------
    def structure(self) -> bool:
        """The structural flaws (:func:`structure_flaws`) as violations; True if none."""
        flaws = structure_flaws(self.plan)
        for f in flaws:
            self.add(f.kind, f.where, None, f.value, f.limit, f"{f.field}: {f.message}")
        return not flaws

    def not_empty(self) -> None:
        if not self.plan.keyframes:
            self.add("empty_plan", "plan", None, 0.0, 1.0, "no keyframes; a plan has at least 1")

    def robot_consistency(self) -> None:
        r, info = self.robot, self.plan.robot
        for key, mine in (("joint_names", r.joint_names), ("foot_frames", r.foot_frames)):
            if list(info.get(key, [])) != list(mine):
                self.add(
                    "robot_mismatch",
                    "robot",
                    None,
                    1.0,
                    0.0,
                    f"robot.{key} {info.get(key)} differ from the URDF's {mine}",
                )
        d = abs(float(info.get("foot_radius", r.foot_radius_m)) - r.foot_radius_m)
        if d > 1e-9:
            self.add(
                "robot_mismatch",
                "robot",
                None,
                d,
                1e-9,
                f"robot.foot_radius {info['foot_radius']} m differs from the URDF's "
                f"{r.foot_radius_m} m",
            )

    def joint_limits(self, q: _Array, where: str) -> None:
        lo, hi = self.model.lowerPositionLimit, self.model.upperPositionLimit
        over = np.maximum(lo[7:] - q[7:], q[7:] - hi[7:])
        for j in np.flatnonzero(over > self.tol.joint_rad):
            leg, name = self.q_leg[7 + j]
            self.add(
                "joint_limits",
                where,
                leg,
                over[j],
                self.tol.joint_rad,
                f"{_leg(leg)} joint '{name}' at {q[7 + j]:.6g} rad is {over[j]:.3g} rad beyond "
                f"[{lo[7 + j]:.6g}, {hi[7 + j]:.6g}] (limit {self.tol.joint_rad:.0e} rad)",
            )

    # ---- keyframes ------------------------------------------------------------------
    def keyframes(self) -> None:
        tol, terrain, rho = self.tol, self.terrain, self.rho
        for k, kf in enumerate(self.plan.keyframes):
            where = f"keyframe {k}"
            q = self.robot.q_from(kf.base_position, kf.base_quaternion, kf.joints)
            self.joint_limits(q, where)
            centres, com = self.kinematics(q)
            down = np.ones(4, dtype=bool)
            if kf.stratum:
                down[kf.stratum - 1] = False
            for i in range(4):
                r = kf.feet[i]
                if down[i]:
                    err = np.linalg.norm(centres[i] - foot_centre_from_contact(terrain, r, rho))
                    ref = "contact + rho n"
                else:
                    err, ref = np.linalg.norm(centres[i] - (r + rho * E_Z)), "point + rho e_z"
                if err > tol.fk_m:
                    self.add(
                        "keyframe_fk",
                        where,
                        i,
                        err,
                        tol.fk_m,
                        f"{_leg(i)} FK sphere centre is {_mm(err)} from the stored foot's "
                        f"({ref}) (limit {_mm(tol.fk_m)})",
                    )
            f_t = np.abs(np.atleast_1d(terrain.f_T(kf.feet)))
            for i in np.flatnonzero(down & (f_t > tol.on_terrain_m)):
                self.add(
                    "foot_on_terrain",
                    where,
                    i,
                    f_t[i],
                    tol.on_terrain_m,
                    f"{_leg(i)} stored contact point is {_mm(f_t[i])} off the terrain surface "
                    f"(limit {_mm(tol.on_terrain_m)})",
                )
            if kf.forces is not None:
                self.keyframe_forces(where, kf, com)

    def keyframe_forces(self, where: str, kf, com: _Array) -> None:
        weight = self.mass * GRAVITY_M_S2
        limit = self.tol.force_balance_rel * weight
        f = kf.forces
        sup = [i - 1 for i in kf.support]
        for i in range(4):
            if i not in sup and np.linalg.norm(f[i]) > limit:
                self.add(
                    "keyframe_forces",
                    where,
                    i,
                    np.linalg.norm(f[i]),
                    limit,
                    f"{_leg(i)} carries {np.linalg.norm(f[i]):.3g} N but is not in support "
                    f"{kf.support}",
                )
        g = np.array([0.0, 0.0, -GRAVITY_M_S2])
        o = kf.feet[sup].mean(axis=0) if sup else com
        res_f = np.linalg.norm(f.sum(axis=0) + self.mass * g)
        res_m = np.linalg.norm(
            np.cross(kf.feet - o, f).sum(axis=0) + np.cross(com - o, self.mass * g)
        )
        if max(res_f, res_m) > limit:
            self.add(
                "keyframe_forces",
                where,
                None,
                max(res_f, res_m),
                limit,
                f"stored forces do not balance gravity at the Pinocchio COM: force residual "
                f"{res_f:.3g} N, moment residual {res_m:.3g} N m (limit {limit:.2g})",
            )

    # ---- samples --------------------------------------------------------------------
    def samples(self, report: CheckReport) -> None:
        sm, tol, terrain, rho = self.plan.samples, self.tol, self.terrain, self.rho
        n = len(sm)
        if n == 0:
            return
        centres = np.empty((n, 4, 3))
        coms = np.empty((n, 3))
        foot_rot = np.empty((n, 4, 3, 3))
        for k in range(n):
            self.joint_limits(sm.q[k], f"sample {k}")
            centres[k], coms[k] = self.kinematics(sm.q[k])
            foot_rot[k] = [self.data.oMf[i].rotation for i in self.foot_ids]
        down = sm.contact

        # contact points (from FK) of the feet in contact, and how far off the terrain
        contacts = centres - rho * E_Z
        miss = np.zeros(down.shape)
        if down.any():
            contacts[down], miss[down] = unique_contact_points(terrain, centres[down], rho)

        n_down = down.sum(axis=1)
        for k in np.flatnonzero(n_down < tol.min_contacts):
            legs = ", ".join(str(i + 1) for i in np.flatnonzero(down[k])) or "none"
            self.add(
                "contact_count",
                f"sample {k}",
                None,
                n_down[k],
                tol.min_contacts,
                f"only {n_down[k]} feet in contact (legs {legs}); at least "
                f"{tol.min_contacts} must be down",
            )

        # stance sliding between consecutive samples: travel minus rolling (planner.body.rolling)
        if n > 1:
            both = down[1:] & down[:-1]
            moved = np.zeros((n - 1, 4))
            ks, ls = np.nonzero(both)
            if len(ks):
                normals = np.asarray(self.terrain.normal(contacts[ks, ls]), float).reshape(-1, 3)
                moved[ks, ls] = sliding(
                    centres[ks, ls],
                    centres[ks + 1, ls],
                    foot_rot[ks, ls],
                    foot_rot[ks + 1, ls],
                    normals,
                    rho,
                )
            report.max_slip_m = float(moved.max()) if both.any() else math.nan
            for k, i in zip(*np.nonzero(moved > tol.slip_m), strict=True):
                self.add(
                    "stance_slip",
                    f"sample {k + 1}",
                    i,
                    moved[k, i],
                    tol.slip_m,
                    f"{_leg(i)} slid {_mm(moved[k, i])} while in contact (centre travel "
                    f"minus rolling; limit {_mm(tol.slip_m)})",
                )

        # feet on the smooth terrain, and near the sharp one
        ks, ls = np.nonzero(down)
        if len(ks):
            pts = contacts[ks, ls]
            f_t = miss[ks, ls]
            for j in np.flatnonzero(f_t > tol.on_terrain_m):
                self.add(
                    "foot_on_terrain",
                    f"sample {ks[j]}",
                    ls[j],
                    f_t[j],
                    tol.on_terrain_m,
                    f"{_leg(ls[j])} contact point is {_mm(f_t[j])} off the terrain surface "
                    f"(limit {_mm(tol.on_terrain_m)})",
                )
            smooth_w = _smoothing_width_m(self.plan.terrain)
            sharp_tol = tol.sharp_surface_m if tol.sharp_surface_m is not None else smooth_w + 1e-3
            vgap = np.abs(pts[:, 2] - np.asarray(terrain.height_sharp(pts[:, 0], pts[:, 1])))
            far = np.flatnonzero(vgap > sharp_tol)
            if len(far):
                d = np.abs(
                    sharp_surface_distance(terrain, pts[far], sharp_tol + 1e-3, tol.surface_step_m)
                )
                for j, dj in zip(far, d, strict=True):
                    if dj > sharp_tol:
                        self.add(
                            "foot_off_sharp_surface",
                            f"sample {ks[j]}",
                            ls[j],
                            dj,
                            sharp_tol,
                            f"{_leg(ls[j])} contact point is at least {_mm(dj)} from the sharp "
                            f"terrain surface (limit {_mm(sharp_tol)}: smoothing width "
                            f"{_mm(smooth_w)} + 1 mm)",
                        )

        self.body_clearance(report)
        self.leg_clearance(report)
        self.swing_clearance(centres, report)
        self.balance(contacts, coms, report)
        self.joint_torques(contacts, report)
        _sway(self, report)

    def body_clearance(self, report: CheckReport) -> None:
        """Body box P vs the sharp terrain: a tile bound first, exact points where close."""
        sm, tol = self.plan.samples, self.tol
        rot = _rotations_from_quats(sm.q[:, 3:7])
        verts = np.einsum("nij,kj->nki", rot, self.robot.body_vertices_B) + sm.q[:, None, :3]
        pad = _TileMax.NODE_M
        boxes = np.column_stack(
            [
                verts[:, :, 0].min(axis=1) - pad,
                verts[:, :, 0].max(axis=1) + pad,
                verts[:, :, 1].min(axis=1) - pad,
                verts[:, :, 1].max(axis=1) + pad,
            ]
        )
        # lowest vertex over the highest terrain node under the footprint: a lower bound
        bound = verts[:, :, 2].min(axis=1) - self.tiles.max_in(boxes) - _TileMax.SLACK_M
        faces = _body_points_B(self.robot, tol.body_grid_m)
        # exact points for the samples within 1 cm of touching, and the 8 closest
        todo = np.union1d(
            np.flatnonzero(bound < tol.body_clearance_m + 0.01), np.argsort(bound)[:8]
        )
        exact = np.full(len(sm), np.inf)
        for a in range(0, len(todo), 32):
            pts, owner = [], []
            for k in todo[a : a + 32]:
                for normal, p_b in faces:
                    if (rot[k] @ normal)[2] < -1e-9:
                        pts.append(p_b @ rot[k].T + sm.q[k, :3])
                        owner.append(np.full(len(p_b), k))
            pts_w = np.concatenate(pts)
            own = np.concatenate(owner)
            h = np.asarray(self.terrain.height_sharp(pts_w[:, 0], pts_w[:, 1])).reshape(-1)
            np.minimum.at(exact, own, pts_w[:, 2] - h)
        rest = np.setdiff1d(np.arange(len(sm)), todo)
        best = float(exact.min())
        if len(rest):  # not measured exactly: lowest vertex over the tile maximum
            best = min(best, float(bound[rest].min() + _TileMax.SLACK_M))
        report.min_body_clearance_m = best
        for k in np.flatnonzero(exact < tol.body_clearance_m):
            self.add(
                "body_clearance",
                f"sample {k}",
                None,
                exact[k],
                tol.body_clearance_m,
                f"body box reaches {_mm(-exact[k])} below the sharp terrain (least clearance "
                f"{_mm(tol.body_clearance_m)})",
            )

    def leg_clearance(self, report: CheckReport) -> None:
        """Thigh and shank capsules vs the sharp terrain (``leg_clearance``).

        At every sample, and between two samples where a joint moves more than
        ``BETWEEN_SAMPLES_RAD`` (the executor interpolates the joints linearly: a knee
        flipping between two clear samples can sweep its shank through the terrain), at
        configurations ``BETWEEN_STEP_RAD`` apart.
        """
        sm, tol = self.plan.samples, self.tol
        links = LegLinks(self.robot)
        per = self._link_clearances(links, sm.q)
        report.min_leg_clearance_m = float(per.min()) if per.size else math.nan
        for k, c in zip(*np.nonzero(per < tol.leg_clearance_m), strict=True):
            self._leg_violation(links, f"sample {k}", c, per[k, c])
        for k in range(len(sm) - 1):
            jump = float(np.max(np.abs(sm.q[k + 1, 7:] - sm.q[k, 7:])))
            if jump <= BETWEEN_SAMPLES_RAD:
                continue
            m = int(math.ceil(jump / BETWEEN_STEP_RAD))
            qs = np.array([between_q(sm.q[k], sm.q[k + 1], u) for u in np.arange(1, m) / m])
            mid = self._link_clearances(links, qs).min(axis=0)
            report.min_leg_clearance_m = min(report.min_leg_clearance_m, float(mid.min()))
            for c in np.flatnonzero(mid < tol.leg_clearance_m):
                self._leg_violation(links, f"sample {k}", c, mid[c], f" between it and {k + 1}")

    def _leg_violation(self, links: LegLinks, where: str, c: int, value: float, extra="") -> None:
        cap = links.capsules[c]
        tol = self.tol.leg_clearance_m
        self.add(
            "leg_clearance",
            where,
            cap.leg,
            value,
            tol,
            f"{_leg(cap.leg)} {cap.link} ({cap.urdf_link}) reaches {_mm(-value)} into "
            f"the sharp terrain{extra} (least clearance {_mm(tol)})",
        )

    def _link_clearances(self, links: LegLinks, q_all: _Array) -> _Array:
        """(N, capsules) clearances [m] of the leg links at configurations ``q_all``."""
        from scipy.ndimage import maximum_filter

        tol = self.tol
        n, P = len(q_all), len(links.owner)
        pts = np.empty((n, P, 3))
        for k in range(n):
            pts[k] = links.axis_points_W(q_all[k])
        flat = pts.reshape(-1, 3)
        rad = np.tile(links.radius, n)
        # bound: highest terrain node within (radius + node) of a point, on a 5 mm raster
        node = _TileMax.NODE_M
        reach = float(links.radius.max()) + 2.0 * node
        x0, y0 = flat[:, 0].min() - reach, flat[:, 1].min() - reach
        nx = int(math.ceil((flat[:, 0].max() + reach - x0) / node)) + 1
        ny = int(math.ceil((flat[:, 1].max() + reach - y0) / node)) + 1
        gx, gy = np.meshgrid(x0 + node * np.arange(nx), y0 + node * np.arange(ny))
        H = np.asarray(self.terrain.height_sharp(gx, gy), dtype=float).reshape(ny, nx)
        M = maximum_filter(H, size=2 * int(math.ceil(reach / node)) + 1, mode="nearest")
        ix = np.clip(np.rint((flat[:, 0] - x0) / node).astype(int), 0, nx - 1)
        iy = np.clip(np.rint((flat[:, 1] - y0) / node).astype(int), 0, ny - 1)
        clear = flat[:, 2] - rad - M[iy, ix] - _TileMax.SLACK_M  # a lower bound
        near = np.flatnonzero(clear < tol.leg_clearance_m + _LEG_EXACT_M)
        if len(near):
            search = float(rad[near].max()) + tol.leg_clearance_m + _LEG_EXACT_M + 2e-3
            d = sharp_surface_distance(self.terrain, flat[near], search, tol.surface_step_m)
            # a distance clipped at the search radius is only known to be at least that
            clear[near] = np.where(np.abs(d) < search, d - rad[near], search - rad[near])
        per = np.full((n, len(links.capsules)), np.inf)
        owner = np.tile(links.owner, n)
        sample = np.repeat(np.arange(n), P)
        np.minimum.at(per, (sample, owner), clear)
        # refine along the axis around the closest point of the capsules near the limit
        for k, c in zip(*np.nonzero(per < tol.leg_clearance_m + 1e-3), strict=True):
            per[k, c] = min(per[k, c], self._capsule_clearance(links, q_all[k], c))
        return per

    def _capsule_clearance(self, links: LegLinks, q: _Array, c: int) -> float:
        """Clearance of capsule c at q from points 0.2 mm apart along its whole axis."""
        cap = links.capsules[c]
        a, b = (s[c] for s in links.segments_W(q))
        u = np.linspace(0.0, 1.0, max(2, int(math.ceil(cap.length_m / 2e-4)) + 1))[:, None]
        p = (1.0 - u) * a + u * b
        gap = p[:, 2] - np.asarray(self.terrain.height_sharp(p[:, 0], p[:, 1])).reshape(-1)
        search = cap.radius_m + self.tol.leg_clearance_m + _LEG_EXACT_M + 2e-3
        sel = np.flatnonzero(gap < search)
        if not len(sel):
            return float(gap.min() - cap.radius_m)
        d = sharp_surface_distance(self.terrain, p[sel], search, self.tol.surface_step_m)
        return float(min(d.min(), search) - cap.radius_m)

    def swing_clearance(self, centres: _Array, report: CheckReport) -> None:
        """Swing spheres vs the sharp terrain: a tile bound first, distances where close."""
        sm, tol = self.plan.samples, self.tol
        ks, ls = np.nonzero(~sm.contact)
        if not len(ks):
            return
        clear = self._sphere_clearances(centres[ks, ls])
        report.min_swing_clearance_m = float(clear.min())
        for j in np.flatnonzero(clear < -tol.swing_penetration_m):
            self._swing_violation(ks[j], ls[j], clear[j])
        self._swing_between_samples(centres, report)

    def _sphere_clearances(self, c: _Array) -> _Array:
        """(N,) clearances [m] of foot spheres centred at ``c`` (N, 3) over the sharp terrain.

        A tile bound first; the exact distance where it is under 1 mm.
        """
        rho = self.rho
        reach = rho + _TileMax.NODE_M
        boxes = np.column_stack(
            [c[:, 0] - reach, c[:, 0] + reach, c[:, 1] - reach, c[:, 1] + reach]
        )
        clear = c[:, 2] - rho - self.tiles.max_in(boxes) - _TileMax.SLACK_M  # a lower bound
        near = np.flatnonzero(clear < 1e-3)
        if len(near):
            d = sharp_surface_distance(self.terrain, c[near], rho + 1e-3, self.tol.surface_step_m)
            clear[near] = d - rho
        return clear

    def _swing_violation(self, k: int, leg: int, clear: float, extra: str = "") -> None:
        tol, rho = self.tol, self.rho
        self.add(
            "swing_clearance",
            f"sample {k}",
            leg,
            -clear,
            tol.swing_penetration_m,
            f"{_leg(leg)} swing foot sphere penetrates the sharp terrain by "
            f"{'at least ' if -clear >= rho else ''}{_mm(-clear)}{extra} (limit "
            f"{_mm(tol.swing_penetration_m)})",
        )

    def _swing_between_samples(self, centres: _Array, report: CheckReport) -> None:
        """Swing spheres between two samples where their leg's joints jump (``swing_clearance``).

        Where a joint of the leg moves more than ``BETWEEN_SAMPLES_RAD``, at configurations
        ``BETWEEN_STEP_RAD`` apart: the executor interpolates the joints linearly, and a
        knee flipping between two clear samples can sweep the foot through the terrain (as
        :meth:`leg_clearance` does the links). An interval that starts or ends with the
        foot down may go as deep as the foot stands there (near an edge a foot on the
        smooth terrain overlaps the sharp one a little, ``foot_off_sharp_surface``).
        """
        sm, tol = self.plan.samples, self.tol
        where, swept = [], []  # (interval, leg) of each swept sphere centre
        for k in range(len(sm) - 1):
            legs = [i for i in range(4) if not (sm.contact[k, i] and sm.contact[k + 1, i])]
            dq = np.abs(sm.q[k + 1, 7:] - sm.q[k, 7:]).reshape(4, 3).max(axis=1)
            if not legs or float(dq[legs].max()) <= BETWEEN_SAMPLES_RAD:
                continue
            m = int(math.ceil(float(dq[legs].max()) / BETWEEN_STEP_RAD))
            for u in np.arange(1, m) / m:
                feet = self.kinematics(between_q(sm.q[k], sm.q[k + 1], u))[0]
                where += [(k, i) for i in legs]
                swept += [feet[i] for i in legs]
        if not swept:
            return
        clear = self._sphere_clearances(np.array(swept))
        report.min_swing_clearance_m = min(report.min_swing_clearance_m, float(clear.min()))
        worst: dict[tuple[int, int], float] = {}
        for j in np.flatnonzero(clear < -tol.swing_penetration_m):
            worst[where[j]] = min(worst.get(where[j], 0.0), float(clear[j]))
        for (k, i), value in sorted(worst.items()):
            down = [kk for kk in (k, k + 1) if sm.contact[kk, i]]
            ends = self._sphere_clearances(centres[down, i]) if down else np.zeros(0)
            if value < min(float(ends.min(initial=0.0)), 0.0) - tol.swing_penetration_m:
                self._swing_violation(k, i, value, f" between it and {k + 1}")

    def joint_torques(self, contacts: _Array, report: CheckReport) -> None:
        """Joint torques within the URDF effort limits (``joint_torque``)."""
        _joint_torques(self, contacts, report)

    def balance(self, contacts: _Array, coms: _Array, report: CheckReport) -> None:
        sm, tol = self.plan.samples, self.tol
        normals = np.tile(E_Z, (len(sm), 4, 1))
        down = sm.contact
        if down.any():
            normals[down] = self.terrain.normal(contacts[down])
        worst = tip = math.inf
        for k in range(len(sm)):
            sup = np.flatnonzero(down[k])
            if len(sup) < 3:
                continue
            if len(sup) == 3:
                tip = min(tip, support_margin_m(contacts[k][sup], coms[k]))
            res = statics.static_feasibility(
                contacts[k],
                coms[k],
                self.mass,
                sup,
                self.mu,
                normals[k],
                with_com_margin=False,
                tol_N=tol.balance_tol_N,
            )
            worst = min(worst, res.margin_N)
            if not res.feasible:
                legs = ", ".join(str(i + 1) for i in sup)
                self.add(
                    "balance",
                    f"sample {k}",
                    None,
                    res.margin_N,
                    0.0,
                    f"no contact forces inside the friction cones (mu {self.mu:g}) of legs "
                    f"{legs} balance gravity at the COM ({coms[k, 0]:.4f}, {coms[k, 1]:.4f}, "
                    f"{coms[k, 2]:.4f}) m: margin {res.margin_N:.3g} N ({res.status})",
                )
        report.min_balance_margin_N = worst if math.isfinite(worst) else math.nan
        report.min_tip_margin_m = tip if math.isfinite(tip) else math.nan


def _joint_torques(ck: _Checker, contacts: _Array, report: CheckReport) -> None:
    """``joint_torque``: some balancing cone forces within every joint's effort limit."""
    sm, tol = ck.plan.samples, ck.tol
    torques = TorqueCheck(ck.robot)
    down = sm.contact
    worst = -math.inf
    for k in range(len(sm)):
        sup = np.flatnonzero(down[k])
        if len(sup) < 3:
            continue
        normals = np.tile(E_Z, (4, 1))
        normals[sup] = ck.terrain.normal(contacts[k, sup])
        res = torques.solve(sm.q[k], sup, ck.mu, normals)
        if not math.isfinite(res.ratio):
            continue  # no balancing forces at all: ``balance`` reports it
        worst = max(worst, res.ratio)
        if res.ratio > 1.0 + tol.torque_rel:
            j = res.worst_joint
            leg, name = ck.q_leg[ck.robot.legs[j // 3].q_index + j % 3]
            ck.add(
                "joint_torque",
                f"sample {k}",
                leg,
                res.ratio,
                1.0 + tol.torque_rel,
                f"{_leg(leg)} joint '{name}' needs {abs(res.torques_nm[j]):.3g} N m, "
                f"{res.ratio:.3g} x its effort limit {torques.effort[j]:.3g} N m, with the "
                "least demanding balancing forces in the friction cones",
            )
    report.max_torque_ratio = worst if math.isfinite(worst) else math.nan


def _sway(ck: _Checker, report: CheckReport) -> None:
    """The least sway stiffness where a three-leg stance begins (a figure, not a test)."""
    from planner.body.stiffness import sway_stiffness_of
    from planner.body.torques import holding_load
    from planner.core.lie import rotation_from_quat

    sm = ck.plan.samples
    down = np.asarray(sm.contact, bool)
    starts = [
        k for k in range(len(sm)) if down[k].sum() == 3 and (k == 0 or down[k - 1].sum() == 4)
    ]
    if not starts:
        return
    sway = sway_stiffness_of(ck.robot)
    tau = holding_load(TorqueCheck(ck.robot), sm.q[starts], down[starts], ck.mu, ck.terrain)[1]
    least = math.inf
    for k, tk in zip(starts, tau, strict=True):
        q = sm.q[k]
        R = rotation_from_quat(q[3:7])
        st = sway.stance(q[:3], R, ck.robot.joints_from_q(q), np.flatnonzero(down[k]), tk)
        least = min(least, st.least)
    report.min_sway_stiffness_N_per_m = least


def _order(v: Violation) -> tuple[int, int]:
    """Sort key: robot, then keyframes, then samples, each by index (stable within)."""
    head, _, index = v.where.partition(" ")
    group = {"plan": 0, "robot": 0, "keyframe": 1, "sample": 2}.get(head, 3)
    return group, int(index) if index.isdigit() else -1


def check_plan(plan: Plan, tolerances: CheckTolerances | None = None) -> CheckReport:
    """Validate a plan independently of the solver (see the module docstring).

    Parameters
    ----------
    plan : Plan
        A loaded or built plan (DESIGN.md section 3).
    tolerances : CheckTolerances, optional
        Defaults as documented in :class:`CheckTolerances`.

    Returns
    -------
    CheckReport
        ``report.ok`` is True when no check failed; ``report.violations`` lists each
        failure with its sample or keyframe, in file order.

    Raises
    ------
    PlannerError
        The robot or terrain of the file cannot be rebuilt.

    """
    t0 = time.perf_counter()
    tol = tolerances or CheckTolerances()
    ck = _Checker(plan, tol)
    report = CheckReport(
        n_samples=len(plan.samples), n_keyframes=len(plan.keyframes), tolerances=tol
    )
    well_formed = ck.structure()
    ck.not_empty()
    ck.robot_consistency()
    if well_formed:
        ck.keyframes()
        ck.samples(report)
    report.structure_only = not well_formed
    report.violations = sorted(ck.violations, key=_order)
    report.elapsed_s = time.perf_counter() - t0
    return report


MAX_PRINTED = 50  # violations printed one per line; the rest are counted by kind


def main_check(
    path: str | Path,
    out: IO[str] | None = None,
    err: IO[str] | None = None,
    robot: str | Path | None = None,
    show_all: bool = False,
) -> int:
    """``stratawalk check PATH``: print the violations and a summary.

    The first :data:`MAX_PRINTED` violations are printed unless ``show_all``. ``robot``: a
    URDF for the plan's robot (its own path moved).

    Returns
    -------
    int
        0 if the plan passes, 1 on any violation, 2 if the file cannot be read or its
        robot or terrain rebuilt (the one-line error goes to ``err``, default stderr).

    """
    out = sys.stdout if out is None else out
    err = sys.stderr if err is None else err
    try:
        plan = Plan.load(path, robot=robot)
        report = check_plan(plan)
    except PlannerError as exc:
        text = str(exc).replace("\r", "\\r").replace("\n", "\\n")  # one line
        print(f"stratawalk check: error: {text}", file=err)
        return 2
    shown = report.violations if show_all else report.violations[:MAX_PRINTED]
    for v in shown:
        print(v, file=out)
    if len(shown) < len(report.violations):
        print(
            f"... and {len(report.violations) - len(shown)} more violations (--all prints "
            "every one; the counts by kind are in the summary)",
            file=out,
        )
    print(f"{path}: {report.summary()}", file=out)
    return 0 if report.ok else 1
