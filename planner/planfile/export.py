"""A plan as a fixed-rate trajectory for a robot controller: CSV, npz or a ROS 2 bag.

The format (:func:`export_format`): ``--out`` ending in ``.csv`` or ``.npz`` writes that
file; ending in ``.bag``, or with ``--format rosbag2``, a ROS 2 bag folder of the same rows
(:mod:`planner.planfile.rosbag`).

Rows at t_i = i / rate from the plan's first to its last sample time (the last sample's
time is always a row). Each row holds:

- ``t`` [s]; base position ``base_x..z`` [m] (world) and orientation ``base_qx..qw``
  (quaternion x, y, z, w, body to world); base linear velocity ``base_vx..vz`` [m/s] and
  angular velocity ``base_wx..wz`` [rad/s] (world);
- per joint (robot order FL, FR, HL, HR x hip roll, hip pitch, knee, URDF names in the
  header) the position ``q_<joint>`` [rad] and velocity ``dq_<joint>`` [rad/s];
- per leg the contact flag ``contact_<leg>`` (1 stance, 0 swing), the planned contact force
  ``f<leg>_x..z`` [N] (world) and the feed-forward joint torques ``tau_<joint>`` [N m].

Interpolation: the plan is piecewise linear in time between its samples (what the MuJoCo
executor tracks). A row holds the plan's value at t_i and the slope of the plan segment
that starts at or before t_i, so ``q(t) = q_i + (t - t_i) dq_i`` for t_i <= t < t_{i+1}
reproduces the plan exactly up to the next sample time, and so every sample whose segment
holds a row: all of them at a rate of at least 1 / (the shortest sample interval). Below
that :func:`export_plan` refuses (``--force`` exports all the same, with a warning naming
the samples skipped and how far off they are). The rows' memory is bounded: a rate whose
rows would take more than half the memory available is refused. The quaternion is
interpolated linearly and normalised.
Contact flags are the segment's: a foot in contact at both of its ends.
Forces and torques are the least-squares holding forces of :mod:`planner.body.torques` at the
samples (a foot unloads before lift-off, loads after touch-down:
:func:`planner.planfile.plan.loaded_feet`), linear between them: the servo feed-forward the
executor applies. ``stratawalk simulate plan.json --trajectory FILE`` executes a CSV or npz
export.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.body.robot import LEG_NAMES
from planner.core.errors import InputError
from planner.planfile.loader import refuse_flaws

if TYPE_CHECKING:
    from planner.planfile.plan import Plan

__all__ = [
    "FORMATS",
    "ROW_MEMORY_B",
    "ExportedTrajectory",
    "export_format",
    "export_plan",
    "export_rows",
    "file_size_b",
    "load_trajectory",
    "plan_from_trajectory",
]

_Array = NDArray[np.float64]

ROW_MEMORY_B = 3072  # memory a row takes while it is made and written (measured: 2.5 KiB)
_FILE_ROW_B = {".csv": 1300, ".npz": 600}  # bytes a row takes in the file (CSV measured)


@dataclass
class ExportedTrajectory:
    """Fixed-rate rows (module docstring); arrays have the rows first."""

    rate_hz: float
    joint_names: list[str]
    t: _Array  # (M,)
    base_pos: _Array  # (M, 3)
    base_quat: _Array  # (M, 4) x, y, z, w
    base_vel: _Array  # (M, 3)
    base_omega: _Array  # (M, 3)
    q: _Array  # (M, 12)
    dq: _Array  # (M, 12)
    contact: NDArray[np.bool_]  # (M, 4)
    forces: _Array  # (M, 4, 3)
    torque_ff: _Array  # (M, 12)
    skipped: str = ""  # with force: which plan samples the rows do not reproduce, and why

    def columns(self) -> list[str]:
        """CSV header, in the order of :meth:`table`'s columns."""
        j = self.joint_names
        return [
            "t",
            *[f"base_{a}" for a in "xyz"],
            *[f"base_q{a}" for a in "xyzw"],
            *[f"base_v{a}" for a in "xyz"],
            *[f"base_w{a}" for a in "xyz"],
            *[f"q_{n}" for n in j],
            *[f"dq_{n}" for n in j],
            *[f"contact_{leg}" for leg in LEG_NAMES],
            *[f"f{leg}_{a}" for leg in LEG_NAMES for a in "xyz"],
            *[f"tau_{n}" for n in j],
        ]

    def table(self) -> _Array:
        """(M, 66) the rows as numbers."""
        m = len(self.t)
        return np.hstack(
            [
                self.t[:, None], self.base_pos, self.base_quat, self.base_vel, self.base_omega,
                self.q, self.dq, self.contact.astype(float), self.forces.reshape(m, 12),
                self.torque_ff,
            ]
        )  # fmt: skip

    def pinocchio_q(self) -> _Array:
        """(M, 19) Pinocchio free-flyer configurations (base xyz, quaternion xyzw, joints)."""
        return np.hstack([self.base_pos, self.base_quat, self.q])

    def save(self, path: str | Path) -> Path:
        """Write CSV (``.csv``) or npz (``.npz``), chosen by the suffix."""
        from planner.core.outputs import write_atomic

        path = Path(path)
        if path.suffix.lower() not in (".csv", ".npz"):
            raise InputError(f"--out {path}: give a file name ending in .csv or .npz")

        def write(tmp: Path) -> None:
            if path.suffix.lower() == ".npz":
                with open(tmp, "wb") as fh:
                    np.savez_compressed(
                        fh, columns=np.array(self.columns()), table=self.table(),
                        rate_hz=self.rate_hz,
                    )  # fmt: skip
            else:
                with open(tmp, "w", newline="", encoding="utf-8") as fh:
                    w = csv.writer(fh)
                    w.writerow(self.columns())
                    for row in self.table():
                        w.writerow([repr(float(v)) for v in row])

        return write_atomic(path, write)


FORMATS = ("csv", "npz", "rosbag2")


def export_format(out: str | Path, fmt: str | None = None, option: str = "--out") -> str:
    """The format of ``stratawalk export --out OUT [--format FMT]``: csv, npz or rosbag2.

    ``fmt`` if given (the suffix is then checked where the output is), else from the
    suffix: .csv, .npz, .bag (a ROS 2 bag folder). InputError naming ``option`` otherwise.
    """
    from planner.core.outputs import check_file

    if fmt is not None:
        if fmt not in FORMATS:
            raise InputError(f"--format {fmt}: give one of {', '.join(FORMATS)}")
        return fmt
    suffix = Path(out).suffix.lower()
    if suffix in (".csv", ".npz"):
        return suffix[1:]
    if suffix == ".bag":
        return "rosbag2"
    path = Path(out)
    if str(out).strip() and path.is_dir():
        raise InputError(
            f"{option} {path}: is a folder; give a file name like {path / 'out.csv'}, or a "
            f"ROS 2 bag folder name like {path / 'walk.bag'}"
        )
    check_file(out, option)  # a device, a file on the way, an unwritable folder
    raise InputError(
        f"{option} {path}: give a file name ending in .csv or .npz, or a ROS 2 bag folder name "
        "ending in .bag (or add --format rosbag2)"
    )


def _segment_index(times: _Array, t: _Array) -> NDArray[np.int_]:
    """Index k of the segment [t_k, t_k+1) holding each t (the last segment at the end)."""
    return np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)


def _omega_W(qa: _Array, qb: _Array, dt: float) -> _Array:
    """World angular velocity turning quaternion qa into qb (xyzw) in dt seconds."""
    import pinocchio as pin

    ra = pin.Quaternion(qa[3], qa[0], qa[1], qa[2]).normalized().toRotationMatrix()
    rb = pin.Quaternion(qb[3], qb[0], qb[1], qb[2]).normalized().toRotationMatrix()
    return pin.log3(rb @ ra.T) / dt


def _available_memory_b() -> float:
    """Bytes this process may still allocate (inf if unknown).

    The system's available memory, or less under an address-space limit.
    """
    import resource

    avail = math.inf
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                avail = float(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    soft = resource.getrlimit(resource.RLIMIT_AS)[0]
    if soft != resource.RLIM_INFINITY:
        try:
            status = Path("/proc/self/status").read_text()
            size = next(ln for ln in status.splitlines() if ln.startswith("VmSize:"))
            avail = min(avail, soft - float(size.split()[1]) * 1024)
        except (OSError, ValueError, StopIteration):
            avail = min(avail, soft / 2)
    return avail


def _check_rate(plan: Plan, rate_hz: float) -> _Array:
    """The plan's sample times; InputError for a bad rate or plan."""
    if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f"--rate: must be a number of rows per second > 0, got {rate_hz!r}")
    refuse_flaws(plan)
    return np.asarray(plan.samples.time, float)


def export_rows(plan: Plan, rate_hz: float) -> int:
    """Rows of ``plan`` at ``rate_hz``.

    InputError if they would take more than half the memory available
    (:data:`ROW_MEMORY_B` each), or for a bad rate or plan.
    """
    times = _check_rate(plan, rate_hz)
    dur = float(times[-1] - times[0])
    rows = math.floor(dur * rate_hz + 1e-9) + 2
    avail = _available_memory_b()
    cap = max(2, math.floor(0.5 * avail / ROW_MEMORY_B)) if math.isfinite(avail) else 10**8
    if rows > cap:
        raise InputError(
            f"--rate {rate_hz:g}: {rows:.3g} rows of a {dur:.3g} s walk would take about "
            f"{rows * ROW_MEMORY_B / 2**30:.3g} GiB of memory, more than half of the "
            f"{avail / 2**30:.3g} GiB available; give --rate {max(1, math.floor((cap - 2) / dur))} "
            "or less"
        )
    return rows


def file_size_b(rows: int, path: str | Path) -> float:
    """About the bytes of ``rows`` rows in the file ``path`` (CSV or npz)."""
    return rows * _FILE_ROW_B.get(Path(path).suffix.lower(), _FILE_ROW_B[".csv"])


def _skipped(plan: Plan, times: _Array, t: _Array, rate_hz: float) -> str:
    """Which samples the rows ``t`` skip (none of them in the sample's segment), or ""."""
    lo = np.searchsorted(t, times[:-1], side="left")
    hi = np.searchsorted(t, times[1:], side="right")
    missed = np.flatnonzero(hi == lo) + 1  # sample m: no row in [t_(m-1), t_m]
    if len(missed) == 0:
        return ""
    q = plan.samples.q
    slope = np.diff(q, axis=0) / np.diff(times)[:, None]
    row = np.searchsorted(t, times[missed], side="right") - 1  # the row before the sample
    j = _segment_index(times, t[row])
    off = q[j] + (times[missed] - times[j])[:, None] * slope[j] - q[missed]
    need = math.ceil(1.0 / float(np.diff(times).min()))
    return (
        f"--rate {rate_hz:g}: rows {1e3 / rate_hz:.3g} ms apart skip {len(missed)} of "
        f"{len(times)} plan samples (up to {np.abs(off[:, 7:]).max():.3g} rad off in a joint, "
        f"{1e3 * np.linalg.norm(off[:, :3], axis=1).max():.3g} mm in the base); --rate {need} "
        "or more reproduces every sample"
    )


def export_plan(plan: Plan, rate_hz: float, force: bool = False) -> ExportedTrajectory:
    """The plan at ``rate_hz`` (module docstring).

    InputError for a bad rate or plan, rows that would not fit in memory, or (unless
    ``force``; then the trajectory's ``skipped`` says so) a rate too low to reproduce
    every plan sample.
    """
    from planner.body.torques import TorqueCheck, holding_load
    from planner.planfile.plan import loaded_feet

    export_rows(plan, rate_hz)
    s = plan.samples
    times = np.asarray(s.time, float)
    dur = float(times[-1] - times[0])
    n = int(math.floor(dur * rate_hz + 1e-9))
    t = times[0] + np.arange(n + 1) / rate_hz
    if t[-1] < times[-1] - 1e-12:
        t = np.append(t, times[-1])
    skipped = _skipped(plan, times, t, rate_hz)
    if skipped and not force:
        raise InputError(f"{skipped}; or add --force to export at this rate all the same")
    k = _segment_index(times, t)
    dt_seg = np.diff(times)
    slope = np.diff(s.q, axis=0) / dt_seg[:, None]  # (N-1, 19)
    q = s.q[k] + (t - times[k])[:, None] * slope[k]
    q[:, 3:7] /= np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)
    omega_seg = np.array(
        [_omega_W(s.q[i, 3:7], s.q[i + 1, 3:7], dt_seg[i]) for i in range(len(dt_seg))]
    )
    robot = plan.load_robot()
    try:
        terrain = plan.load_terrain()
    except InputError:
        terrain = None
    check = TorqueCheck(robot)
    loaded = loaded_feet(s.contact)
    forces, tau = holding_load(check, s.q, loaded, plan.friction, terrain)
    u = ((t - times[k]) / dt_seg[k])[:, None]
    joints = np.array([leg.q_index + j for leg in robot.legs for j in range(3)])
    return ExportedTrajectory(
        rate_hz=float(rate_hz),
        joint_names=list(robot.joint_names),
        t=t,
        base_pos=q[:, :3],
        base_quat=q[:, 3:7],
        base_vel=slope[k, :3],
        base_omega=omega_seg[k],
        q=q[:, joints],
        dq=slope[k][:, joints],
        contact=s.contact[k] & s.contact[k + 1],
        forces=((1 - u) * forces[k].reshape(-1, 12) + u * forces[k + 1].reshape(-1, 12)).reshape(
            -1, 4, 3
        ),
        torque_ff=(1 - u) * tau[k] + u * tau[k + 1],
        skipped=skipped,
    )


def load_trajectory(path: str | Path) -> ExportedTrajectory:
    """Read a CSV or npz written by :meth:`ExportedTrajectory.save` (one-line errors)."""
    path = Path(path)
    try:
        if path.suffix == ".npz":
            with np.load(path) as z:
                cols, table = [str(c) for c in z["columns"]], np.asarray(z["table"], float)
                rate = float(z["rate_hz"])
        else:
            with open(path, newline="", encoding="utf-8") as fh:
                rows = list(csv.reader(fh))
            cols, table = rows[0], np.array(rows[1:], float)
            rate = math.nan
    except (OSError, ValueError, KeyError, IndexError) as exc:
        raise InputError(
            f"{path}: not a trajectory written by `stratawalk export` ({exc})"
        ) from None
    if table.ndim != 2 or table.shape[1] != len(cols) or len(cols) != 66 or len(table) < 2:
        raise InputError(f"{path}: expected 66 columns and 2 or more rows (`stratawalk export`)")
    joint_names = [c[2:] for c in cols[14:26]]
    m = len(table)
    return ExportedTrajectory(
        rate_hz=rate if math.isfinite(rate) else 1.0 / float(np.median(np.diff(table[:, 0]))),
        joint_names=joint_names,
        t=table[:, 0],
        base_pos=table[:, 1:4],
        base_quat=table[:, 4:8],
        base_vel=table[:, 8:11],
        base_omega=table[:, 11:14],
        q=table[:, 14:26],
        dq=table[:, 26:38],
        contact=table[:, 38:42] > 0.5,
        forces=table[:, 42:54].reshape(m, 4, 3),
        torque_ff=table[:, 54:66],
    )


def plan_from_trajectory(plan: Plan, traj: ExportedTrajectory) -> Plan:
    """``plan`` (robot, terrain, goal) with the trajectory's rows as its samples."""
    robot = plan.load_robot()
    if list(traj.joint_names) != list(robot.joint_names):
        raise InputError(
            f"trajectory joints {traj.joint_names[:3]}... are not the plan's robot's "
            f"{list(robot.joint_names)[:3]}...; export this plan"
        )
    out = type(plan).from_dict(plan.to_dict(), source=f"{plan.source} (exported trajectory)")
    out.samples = type(plan.samples)(traj.t.copy(), traj.pinocchio_q(), traj.contact.copy())
    out._robot_cache, out._terrain_cache = plan._robot_cache, plan._terrain_cache
    return refuse_flaws(out)
