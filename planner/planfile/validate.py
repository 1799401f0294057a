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

The report and tolerances are in :mod:`planner.planfile.validate_report`, the sharp-surface
distances and bounds in :mod:`planner.planfile.validate_surface`, the body, leg and swing
clearance checks in :mod:`planner.planfile.validate_clearance`.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path
from typing import IO

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
from planner.body.rolling import sliding
from planner.body.stability import support_margin_m
from planner.body.torques import TorqueCheck
from planner.core.errors import PlannerError
from planner.core.units import GRAVITY_M_S2
from planner.planfile.loader import structure_flaws
from planner.planfile.plan import Plan
from planner.planfile.validate_clearance import _ClearanceChecks
from planner.planfile.validate_report import (
    CheckReport,
    CheckTolerances,
    Violation,
    _leg,
    _mm,
)
from planner.planfile.validate_surface import (
    _smoothing_width_m,
    _TileMax,
    sharp_surface_distance,
)

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


# --------------------------------------------------------------------------- the check
class _Checker(_ClearanceChecks):
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
        sm, terrain, rho = self.plan.samples, self.terrain, self.rho
        n = len(sm)
        if n == 0:
            return
        centres, coms, foot_rot = self._sample_kinematics()
        down = sm.contact

        # contact points (from FK) of the feet in contact, and how far off the terrain
        contacts = centres - rho * E_Z
        miss = np.zeros(down.shape)
        if down.any():
            contacts[down], miss[down] = unique_contact_points(terrain, centres[down], rho)

        self._contact_count()
        self._stance_slip(centres, contacts, foot_rot, report)
        self._feet_on_terrain(contacts, miss)

        self.body_clearance(report)
        self.leg_clearance(report)
        self.swing_clearance(centres, report)
        self.balance(contacts, coms, report)
        self.joint_torques(contacts, report)
        _sway(self, report)

    def _sample_kinematics(self) -> tuple[_Array, _Array, _Array]:
        """Foot sphere centres (N, 4, 3), COMs (N, 3) and foot frame rotations (N, 4, 3, 3).

        Checks each sample's joint limits on the way (``joint_limits``).
        """
        sm = self.plan.samples
        n = len(sm)
        centres = np.empty((n, 4, 3))
        coms = np.empty((n, 3))
        foot_rot = np.empty((n, 4, 3, 3))
        for k in range(n):
            self.joint_limits(sm.q[k], f"sample {k}")
            centres[k], coms[k] = self.kinematics(sm.q[k])
            foot_rot[k] = [self.data.oMf[i].rotation for i in self.foot_ids]
        return centres, coms, foot_rot

    def _contact_count(self) -> None:
        """At least ``min_contacts`` feet down at every sample (``contact_count``)."""
        sm, tol = self.plan.samples, self.tol
        down = sm.contact
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

    def _stance_slip(
        self, centres: _Array, contacts: _Array, foot_rot: _Array, report: CheckReport
    ) -> None:
        """Stance sliding between consecutive samples: travel minus rolling (``stance_slip``).

        The rolling of a rigid sphere foot turned with the shank (:mod:`planner.body.rolling`).
        """
        sm, tol, rho = self.plan.samples, self.tol, self.rho
        n = len(sm)
        down = sm.contact
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

    def _feet_on_terrain(self, contacts: _Array, miss: _Array) -> None:
        """Feet on the smooth terrain, and near the sharp one (section 4.4).

        ``foot_on_terrain``: ``miss``, a contact point's distance off the smooth surface;
        ``foot_off_sharp_surface``: farther from the sharp one than the smoothing width.
        """
        sm, tol, terrain = self.plan.samples, self.tol, self.terrain
        down = sm.contact
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
