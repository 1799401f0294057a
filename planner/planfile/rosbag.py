"""Export rows (:mod:`planner.planfile.export`) as a ROS 2 bag, written with ``rosbags``.

The pure-Python `rosbags <https://gitlab.com/ternaris/rosbags>`_ library writes the bag: no
ROS installation is needed. A ROS 2 bag is a folder holding ``metadata.yaml`` (rosbag2
format version 8, as ROS 2 Iron writes it; later distributions read it) and one SQLite3
file ``<folder name>.db3``, the storage every ROS 2 distribution reads without a plugin.
Messages are CDR, with the ROS 2 Humble definitions of the standard messages below.

Time: bag time 0 is the first row (the plan's first sample, plan time t_0, normally 0); a
row at plan time t_i is at ``round((t_i - t_0) * 1e9)`` ns, its messages' header stamps
too. The rows are the export's own (no new interpolation); per row:

- ``/joint_states`` (``sensor_msgs/msg/JointState``): the 12 URDF joint names in robot
  order (FL, FR, HL, HR x hip roll, hip pitch, knee), ``position`` [rad], ``velocity``
  [rad/s] and ``effort`` = the feed-forward joint torque [N m];
- ``/tf`` (``tf2_msgs/msg/TFMessage``): one transform ``world`` -> the URDF's root link (the
  body frame): translation = base position [m], rotation = base quaternion (body to world);
- ``/stratawalk/contacts`` (``std_msgs/msg/UInt8MultiArray``): 4 flags, 1 stance, 0 swing,
  in leg order FL, FR, HL, HR; ``layout.dim`` = one dimension, label ``"FL,FR,HL,HR"``,
  size 4, stride 4;
- ``/stratawalk/contact_force/<leg>`` (``geometry_msgs/msg/WrenchStamped``, leg FL, FR,
  HL, HR): the planned force on the foot from the ground [N] in world axes
  (``frame_id`` ``world``); it acts at the foot, so the torque field is 0 (not the moment
  about the world origin).

And one message at bag time 0 on ``/stratawalk/joint_trajectory``
(``trajectory_msgs/msg/JointTrajectory``, header stamp 0: "start now" to a controller):
the joint names, and a point per row with positions, velocities, effort (as
``/joint_states``; no accelerations) and ``time_from_start`` = t_i - t_0.

A bag replaces an earlier bag at its path (a folder of bag files only), as a CSV export
replaces its file: it is written in a new folder beside it, then renamed into place.
"""

from __future__ import annotations

import os
import shutil
import sqlite3
import stat
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from planner.core.errors import InputError, OutputError
from planner.core.legs import LEG_NAMES
from planner.core.outputs import check_folder

if TYPE_CHECKING:
    from planner.body.robot_model import Robot
    from planner.planfile.export import ExportedTrajectory

__all__ = [
    "BAG_ROW_B",
    "TOPICS",
    "bag_size_b",
    "check_bag",
    "require_rosbags",
    "root_link",
    "write_rosbag",
]

WORLD_FRAME = "world"
TRAJECTORY_TOPIC = "/stratawalk/joint_trajectory"
JOINT_STATE_TOPIC = "/joint_states"
TF_TOPIC = "/tf"
CONTACT_TOPIC = "/stratawalk/contacts"
FORCE_TOPIC = "/stratawalk/contact_force/{leg}"
TOPICS = {
    TRAJECTORY_TOPIC: "trajectory_msgs/msg/JointTrajectory",
    JOINT_STATE_TOPIC: "sensor_msgs/msg/JointState",
    TF_TOPIC: "tf2_msgs/msg/TFMessage",
    CONTACT_TOPIC: "std_msgs/msg/UInt8MultiArray",
    **{FORCE_TOPIC.format(leg=leg): "geometry_msgs/msg/WrenchStamped" for leg in LEG_NAMES},
}
BAG_ROW_B = 1700  # bytes a row takes in the .db3 (measured: 1.5 KiB at 500 Hz)
_BAG_SUFFIXES = (".db3", ".mcap", ".zstd", ".db3-shm", ".db3-wal", ".db3-journal")
_NOT_A_BAG = (".csv", ".npz", ".db3", ".mcap", ".yaml", ".json")


def require_rosbags() -> None:
    """InputError unless the ``rosbags`` package can be imported."""
    try:
        import rosbags.rosbag2  # noqa: F401
    except ImportError:
        raise InputError(
            "--format rosbag2: needs the Python package rosbags (pip install rosbags)"
        ) from None


def bag_size_b(rows: int) -> float:
    """About the bytes of a bag of ``rows`` rows (:data:`BAG_ROW_B` each)."""
    return rows * BAG_ROW_B


def root_link(robot: Robot) -> str:
    """The URDF link of the robot's body frame (the free-flyer's child link), else "base"."""
    import pinocchio as pin

    return next(
        (f.name for f in robot.model.frames if f.parentJoint == 1 and f.type == pin.FrameType.BODY),
        "base",
    )


def _is_bag_file(p: Path) -> bool:
    try:
        regular = stat.S_ISREG(p.lstat().st_mode)
    except OSError:
        return False
    return regular and (p.name == "metadata.yaml" or p.name.lower().endswith(_BAG_SUFFIXES))


def check_bag(path: str | Path, option: str = "--out", size_b: float = 0) -> Path:
    """``path`` as a Path to write a bag folder of about ``size_b`` bytes to.

    InputError if :func:`~planner.core.outputs.check_folder` refuses it (a file, under a
    file, not writable, no space), if its name ends like a file (.csv, .npz, ...), or if it
    is a folder holding anything but an earlier bag's files (which the bag replaces).
    """
    path = check_folder(path, option, size_b)
    if path.name in ("", ".", ".."):
        raise InputError(f"{option} {path}: give the bag a folder name, like {path / 'walk.bag'}")
    if path.suffix.lower() in _NOT_A_BAG:
        raise InputError(
            f"{option} {path}: a ROS 2 bag is a folder; give a folder name like "
            f"{path.with_suffix('.bag')}"
        )
    if path.is_symlink():
        raise InputError(f"{option} {path}: is a link; give the bag folder's own path")
    if path.is_dir():
        _refuse_other_files(path, option)
        check_folder(path.parent, option, size_b)  # the new bag is written beside it
    return path


def _refuse_other_files(path: Path, option: str) -> None:
    """InputError if the folder ``path`` holds anything but bag files."""
    other = sorted(p.name for p in path.iterdir() if not _is_bag_file(p))
    if other:
        raise InputError(
            f"{option} {path}: a folder holding other files than a ROS 2 bag (such as "
            f"{other[0]}); give a new folder name (an earlier bag there is replaced)"
        )


def _stamps(ns: int, time_type):
    return time_type(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _write_bag(traj: ExportedTrajectory, path: Path, base_frame: str) -> int:
    """Write the bag folder ``path`` (must not exist); the number of messages."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    ty = store.types
    Time, Duration, Header = (
        ty["builtin_interfaces/msg/Time"],
        ty["builtin_interfaces/msg/Duration"],
        ty["std_msgs/msg/Header"],
    )
    Vector3 = ty["geometry_msgs/msg/Vector3"]
    names = list(traj.joint_names)
    ns = np.rint((traj.t - traj.t[0]) * 1e9).astype(np.int64).tolist()
    q, dq, tau = (
        np.ascontiguousarray(a, dtype=np.float64) for a in (traj.q, traj.dq, traj.torque_ff)
    )
    no_acc = np.zeros(0, np.float64)
    count = 0
    with Writer(path, version=8, storage_plugin=StoragePlugin.SQLITE3) as bag:
        conn = {
            topic: bag.add_connection(topic, msgtype, typestore=store)
            for topic, msgtype in TOPICS.items()
        }

        def put(topic: str, t_ns: int, msg: object) -> None:
            nonlocal count
            bag.write(conn[topic], t_ns, store.serialize_cdr(msg, TOPICS[topic]))
            count += 1

        Point = ty["trajectory_msgs/msg/JointTrajectoryPoint"]
        points = [
            Point(
                positions=q[i], velocities=dq[i], accelerations=no_acc, effort=tau[i],
                time_from_start=_stamps(n, Duration),
            )
            for i, n in enumerate(ns)
        ]  # fmt: skip
        put(
            TRAJECTORY_TOPIC,
            0,
            ty["trajectory_msgs/msg/JointTrajectory"](
                header=Header(stamp=_stamps(0, Time), frame_id=""),
                joint_names=names,
                points=points,
            ),
        )
        del points
        JointState, TFMessage = ty["sensor_msgs/msg/JointState"], ty["tf2_msgs/msg/TFMessage"]
        TransformStamped, Transform = (
            ty["geometry_msgs/msg/TransformStamped"],
            ty["geometry_msgs/msg/Transform"],
        )
        Quaternion = ty["geometry_msgs/msg/Quaternion"]
        UInt8MultiArray = ty["std_msgs/msg/UInt8MultiArray"]
        layout = ty["std_msgs/msg/MultiArrayLayout"](
            dim=[
                ty["std_msgs/msg/MultiArrayDimension"](label=",".join(LEG_NAMES), size=4, stride=4)
            ],
            data_offset=0,
        )
        WrenchStamped, Wrench = (
            ty["geometry_msgs/msg/WrenchStamped"],
            ty["geometry_msgs/msg/Wrench"],
        )
        zero = Vector3(x=0.0, y=0.0, z=0.0)
        pos, quat, forces = traj.base_pos.tolist(), traj.base_quat.tolist(), traj.forces.tolist()
        contact = np.asarray(traj.contact, dtype=np.uint8)
        for i, n in enumerate(ns):
            stamp = _stamps(n, Time)
            put(
                JOINT_STATE_TOPIC,
                n,
                JointState(
                    header=Header(stamp=stamp, frame_id=""), name=names, position=q[i],
                    velocity=dq[i], effort=tau[i],
                ),
            )  # fmt: skip
            (x, y, z), (qx, qy, qz, qw) = pos[i], quat[i]
            tf = TransformStamped(
                header=Header(stamp=stamp, frame_id=WORLD_FRAME),
                child_frame_id=base_frame,
                transform=Transform(
                    translation=Vector3(x=x, y=y, z=z),
                    rotation=Quaternion(x=qx, y=qy, z=qz, w=qw),
                ),
            )
            put(TF_TOPIC, n, TFMessage(transforms=[tf]))
            put(CONTACT_TOPIC, n, UInt8MultiArray(layout=layout, data=contact[i]))
            for k, leg in enumerate(LEG_NAMES):
                fx, fy, fz = forces[i][k]
                put(
                    FORCE_TOPIC.format(leg=leg),
                    n,
                    WrenchStamped(
                        header=Header(stamp=stamp, frame_id=WORLD_FRAME),
                        wrench=Wrench(force=Vector3(x=fx, y=fy, z=fz), torque=zero),
                    ),
                )
    return count


def _reason(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return str(exc).split("\n")[0] or type(exc).__name__


def _keep(traj: ExportedTrajectory, name: str, base_frame: str) -> Path | None:
    """Write the bag into a new folder in the temporary folder, home or here; its path."""
    from rosbags.rosbag2 import WriterError

    for where in (tempfile.gettempdir(), Path.home(), Path.cwd()):
        folder = None
        try:
            folder = Path(tempfile.mkdtemp(prefix="stratawalk-kept-", dir=where))
            _write_bag(traj, folder / name, base_frame)
            return folder / name
        except (OSError, sqlite3.Error, WriterError):
            if folder is not None:
                shutil.rmtree(folder, ignore_errors=True)
    return None


def write_rosbag(
    traj: ExportedTrajectory, path: str | Path, base_frame: str = "base", option: str = "--out"
) -> tuple[Path, int]:
    """Write ``traj`` as the bag folder ``path`` (module docstring); it and its messages.

    ``base_frame``: the TF child frame of the base pose (:func:`root_link`). Check ``path``
    first with :func:`check_bag`. The bag is written in a new folder beside ``path``, then
    renamed to it (an earlier bag there is replaced), so an interruption leaves the old bag
    or the new one.

    Raises
    ------
    OutputError
        The bag could not be written (disk full, folder gone): it was written in a new
        folder in the temporary folder (else home, else here), which the message names.

    """
    from rosbags.rosbag2 import WriterError

    path = Path(path)
    if path.is_dir():
        _refuse_other_files(path, option)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".stratawalk-bag-", suffix=".tmp", dir=path.parent))
        count = _write_bag(traj, tmp / path.name, base_frame)
        if path.is_dir():
            _refuse_other_files(path, option)
            os.rename(path, tmp / f"{path.name}.old")
        os.rename(tmp / path.name, path)
    except (OSError, sqlite3.Error, WriterError) as exc:
        reason = _reason(exc)
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        kept = _keep(traj, path.name, base_frame)
        where = f"the result is kept in {kept}" if kept else "nor could a copy be kept elsewhere"
        raise OutputError(f"{option} {path}: cannot write it ({reason}); {where}", kept) from None
    except BaseException:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        raise
    shutil.rmtree(tmp, ignore_errors=True)
    return path, count
