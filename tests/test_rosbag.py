"""`stratawalk export --out NAME.bag` (planner.planfile.rosbag) read back with rosbags.

The bag is read with ``rosbags.rosbag2.Reader`` and the ROS 2 Jazzy type store (the writer
uses Humble's), and held against the plan sampled here: piecewise linear in time between
its samples, joints found by name in the plan's Pinocchio model.
"""

from __future__ import annotations

import errno
import subprocess
import sys

import numpy as np
import pytest

from planner.cli.main import main
from planner.core.legs import LEG_NAMES
from planner.planfile.plan import Plan, Samples
from planner.planning.local import LocalSettings
from planner.planning.walk import plan_walk

rosbag2 = pytest.importorskip("rosbags.rosbag2")
typesys = pytest.importorskip("rosbags.typesys")


@pytest.fixture(scope="module")
def plan():
    """A short walk on flat ground (two crawl steps, 37 samples, 2.26 s)."""
    p, report = plan_walk("littledog", "flat", (0.3, 0.0), (0.2, 0.0), "soft", LocalSettings())
    assert report.ok, report.summary()
    return p


@pytest.fixture(scope="module")
def on_grid(plan):
    """The plan re-timed to samples 20 ms apart: at 100 Hz every other row is a sample."""
    s = plan.samples
    out = Plan.from_dict(plan.to_dict(), source=f"{plan.source} (re-timed)")
    out.samples = Samples((2.0 * np.arange(len(s.time))) / 100.0, s.q.copy(), s.contact.copy())
    return out


def _read(path):
    """Topic -> (bag timestamps [ns], deserialised messages), with the Jazzy type store."""
    store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    out: dict[str, tuple[list[int], list]] = {}
    with rosbag2.Reader(path) as reader:
        assert reader.duration >= 0
        for conn, stamp, raw in reader.messages():
            ts, msgs = out.setdefault(conn.topic, ([], []))
            ts.append(stamp)
            msgs.append(store.deserialize_cdr(raw, conn.msgtype))
        types = {c.topic: c.msgtype for c in reader.connections}
    return out, types


def _ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _expected_rows(times: np.ndarray, rate: float) -> np.ndarray:
    """Row times: t_0 + i / rate up to the last sample, which is always a row."""
    n = int(np.floor((times[-1] - times[0]) * rate + 1e-9))
    t = times[0] + np.arange(n + 1) / rate
    return t if t[-1] >= times[-1] - 1e-12 else np.append(t, times[-1])


def _plan_at(plan, t):
    """The plan at times t: joints (by URDF name), base position, quaternion, contacts."""
    s = plan.samples
    robot = plan.load_robot()
    model = robot.model
    cols = [model.joints[model.getJointId(n)].idx_q for n in robot.joint_names]
    joints = np.column_stack([np.interp(t, s.time, s.q[:, c]) for c in cols])
    base = np.column_stack([np.interp(t, s.time, s.q[:, c]) for c in range(3)])
    quat = np.column_stack([np.interp(t, s.time, s.q[:, c]) for c in range(3, 7)])
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    k = np.clip(np.searchsorted(s.time, t, side="right") - 1, 0, len(s.time) - 2)
    contact = s.contact[k] & s.contact[k + 1]  # the segment's: in contact at both ends
    return robot, joints, base, quat, contact


def _export(plan, tmp_path, rate, *extra):
    src = plan.save(tmp_path / "plan.json")
    out = tmp_path / "walk.bag"
    assert main(["export", str(src), "--rate", str(rate), "--out", str(out), *extra]) == 0
    return out


def _check_bag(plan, bag, rate):
    """Every topic against the plan; the rows' times and messages."""
    msgs, types = _read(bag)
    t = _expected_rows(np.asarray(plan.samples.time), rate)
    rows = len(t)
    ns = np.rint((t - t[0]) * 1e9).astype(np.int64)
    robot, joints, base, quat, contact = _plan_at(plan, t)
    assert types["/joint_states"] == "sensor_msgs/msg/JointState"
    assert types["/tf"] == "tf2_msgs/msg/TFMessage"
    assert types["/stratawalk/joint_trajectory"] == "trajectory_msgs/msg/JointTrajectory"
    assert types["/stratawalk/contacts"] == "std_msgs/msg/UInt8MultiArray"
    per_row = ["/joint_states", "/tf", "/stratawalk/contacts"]
    per_row += [f"/stratawalk/contact_force/{leg}" for leg in LEG_NAMES]
    assert sorted(msgs) == sorted([*per_row, "/stratawalk/joint_trajectory"])
    for topic in per_row:
        stamps, m = msgs[topic]
        assert len(m) == rows, topic
        assert stamps == ns.tolist(), topic
    # joint states: URDF names, positions = the plan at the row times
    stamps, states = msgs["/joint_states"]
    assert [_ns(m.header.stamp) for m in states] == ns.tolist()
    assert all(list(m.name) == robot.joint_names for m in states)
    pos = np.array([m.position for m in states])
    vel = np.array([m.velocity for m in states])
    eff = np.array([m.effort for m in states])
    assert pos.shape == vel.shape == eff.shape == (rows, 12)
    assert np.abs(pos - joints).max() < 1e-9
    # velocities: the slope of the plan segment holding each row
    s = plan.samples
    k = np.clip(np.searchsorted(s.time, t, side="right") - 1, 0, len(s.time) - 2)
    cols = [robot.model.joints[robot.model.getJointId(n)].idx_q for n in robot.joint_names]
    slope = (s.q[k + 1][:, cols] - s.q[k][:, cols]) / (s.time[k + 1] - s.time[k])[:, None]
    assert np.abs(vel - slope).max() < 1e-6
    # the trajectory: one message, a point per row, the same numbers
    (stamp,), (traj,) = msgs["/stratawalk/joint_trajectory"]
    assert stamp == 0 and _ns(traj.header.stamp) == 0
    assert list(traj.joint_names) == robot.joint_names and len(traj.points) == rows
    assert [_ns(p.time_from_start) for p in traj.points] == ns.tolist()
    assert np.array_equal(np.array([p.positions for p in traj.points]), pos)
    assert np.array_equal(np.array([p.velocities for p in traj.points]), vel)
    assert np.array_equal(np.array([p.effort for p in traj.points]), eff)
    assert all(len(p.accelerations) == 0 for p in traj.points)
    # the base pose: world -> the URDF's root link
    _, tfs = msgs["/tf"]
    assert all(len(m.transforms) == 1 for m in tfs)
    tr = [m.transforms[0] for m in tfs]
    assert {(x.header.frame_id, x.child_frame_id) for x in tr} == {("world", "body")}
    assert [_ns(x.header.stamp) for x in tr] == ns.tolist()
    xyz = np.array([[x.transform.translation.x, x.transform.translation.y,
                     x.transform.translation.z] for x in tr])  # fmt: skip
    r = [x.transform.rotation for x in tr]
    q = np.array([[a.x, a.y, a.z, a.w] for a in r])
    assert np.abs(xyz - base).max() < 1e-9 and np.abs(q - quat).max() < 1e-9
    # contacts: FL, FR, HL, HR flags
    _, flags = msgs["/stratawalk/contacts"]
    assert {(d.label, d.size, d.stride) for m in flags for d in m.layout.dim} == {
        ("FL,FR,HL,HR", 4, 4)
    }
    got = np.array([m.data for m in flags])
    assert got.dtype == np.uint8 and np.array_equal(got, contact.astype(np.uint8))
    assert (got.sum(axis=1) >= 3).all() and (got.sum(axis=1) == 3).any()
    # forces: world axes; the stance feet carry the weight, the swing feet nothing
    f = np.stack(
        [np.array([[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z]
                   for m in msgs[f"/stratawalk/contact_force/{leg}"][1]]) for leg in LEG_NAMES],
        axis=1,
    )  # fmt: skip
    weight = robot.total_mass_kg * 9.81
    assert np.allclose(f[:, :, 2].sum(axis=1), weight, rtol=1e-3)
    assert np.abs(f[~contact]).max() < 1e-6 * weight
    assert {
        m.header.frame_id for leg in LEG_NAMES for m in msgs[f"/stratawalk/contact_force/{leg}"][1]
    } == {"world"}  # noqa: E501
    return pos, eff


def test_a_bag_reads_back_as_the_plan(plan, tmp_path, capsys):
    bag = _export(plan, tmp_path, 500)
    out = capsys.readouterr().out.strip()
    rows = len(_expected_rows(np.asarray(plan.samples.time), 500))
    assert out == (
        f"wrote {bag}: ROS 2 bag (sqlite3), {rows} rows at 500 Hz, 2.26 s, {7 * rows + 1} "
        "messages on 8 topics"
    )
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "walk.bag.db3"]
    pos, eff = _check_bag(plan, bag, 500)
    # the first and last rows are the plan's first and last samples
    robot, joints, *_ = _plan_at(plan, np.asarray(plan.samples.time)[[0, -1]])
    assert np.abs(pos[[0, -1]] - joints).max() < 1e-9
    # efforts: the export's feed-forward torques
    from planner.planfile.export import export_plan

    assert np.array_equal(eff, export_plan(plan, 500.0).torque_ff)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_rows_at_the_plan_samples_hold_their_q(on_grid, tmp_path):
    bag = _export(on_grid, tmp_path, 100, "--format", "rosbag2")
    pos, _ = _check_bag(on_grid, bag, 100)
    s = on_grid.samples
    robot = on_grid.load_robot()
    cols = [robot.model.joints[robot.model.getJointId(n)].idx_q for n in robot.joint_names]
    assert len(pos) == 2 * len(s.time) - 1
    assert np.abs(pos[::2] - s.q[:, cols]).max() < 1e-9


def test_an_earlier_bag_is_replaced_and_other_folders_kept(plan, tmp_path, capsys):
    src = str(plan.save(tmp_path / "plan.json"))
    bag = tmp_path / "run"  # any folder name with --format rosbag2
    assert main(["export", src, "--rate", "500", "--out", str(bag), "--format", "rosbag2"]) == 0
    assert main(["export", src, "--rate", "300", "--out", str(bag), "--format", "rosbag2"]) == 0
    capsys.readouterr()
    _check_bag(plan, bag, 300)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.json", "run"]
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep me")
    assert main(["export", src, "--out", str(other), "--format", "rosbag2"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--out" in err and "notes.txt" in err, err
    assert [p.name for p in other.iterdir()] == ["notes.txt"]


@pytest.mark.parametrize(
    "out, extra, expect",
    [
        ("a_file", ["--format", "rosbag2"], "is a file, not a folder"),
        ("a_file/w.bag", [], "is a file, not a folder"),
        ("w.csv", ["--format", "rosbag2"], "a ROS 2 bag is a folder"),
        ("w.txt", [], "ending in .csv or .npz, or a ROS 2 bag folder name ending in .bag"),
        ("w.bag", ["--format", "csv"], "ending in .csv"),
        ("", [], "is a folder; give a file name like"),
        ("/proc/w.bag", [], "cannot write into"),
        ("..", ["--format", "rosbag2"], "give the bag a folder name"),
    ],
)
def test_bad_bag_outputs_are_one_line_before_any_work(plan, tmp_path, capsys, out, extra, expect):
    src = plan.save(tmp_path / "plan.json")
    (tmp_path / "a_file").write_text("keep me")
    target = out if out.startswith("/") else str(tmp_path / out)
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["export", str(src), "--out", target, *extra]) == 2
    cap = capsys.readouterr()
    err = cap.err.strip()
    assert err.count("\n") == 0 and err.startswith("stratawalk: error: --out"), err
    assert expect in err, err
    assert cap.out == "" and sorted(p.name for p in tmp_path.iterdir()) == before
    assert (tmp_path / "a_file").read_text() == "keep me"


def test_without_rosbags_the_error_names_the_package(plan, tmp_path, capsys, monkeypatch):
    src = plan.save(tmp_path / "plan.json")
    monkeypatch.setitem(sys.modules, "rosbags.rosbag2", None)  # import fails
    assert main(["export", str(src), "--out", str(tmp_path / "w.bag")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--format rosbag2" in err and "pip install rosbags" in err


def test_a_failed_write_keeps_the_bag_elsewhere(plan, tmp_path, capsys, monkeypatch):
    from planner.planfile import rosbag

    write = rosbag._write_bag

    def full_disk(traj, path, base_frame):
        if path.parent.parent == tmp_path:  # the folder beside --out, not the kept copy
            raise OSError(errno.ENOSPC, "No space left on device")
        return write(traj, path, base_frame)

    monkeypatch.setattr(rosbag, "_write_bag", full_disk)
    src = plan.save(tmp_path / "plan.json")
    bag = tmp_path / "w.bag"
    assert main(["export", str(src), "--rate", "300", "--out", str(bag)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "No space left on device" in err, err
    kept = err.split("the result is kept in ")[1]
    try:
        _check_bag(plan, kept, 300)
    finally:
        import shutil
        from pathlib import Path

        shutil.rmtree(Path(kept).parent)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.json"]


def test_the_help_does_not_load_rosbags():
    code = (
        "import sys; from planner.cli.main import build_parser; build_parser(); "
        "print(' '.join(m for m in sys.modules if m.startswith('rosbags')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == "", out.stderr
    help_text = subprocess.run(
        [sys.executable, "-m", "planner.cli.main", "export", "--help"],
        capture_output=True,
        text=True,
    ).stdout
    assert "ROS 2 bag" in help_text and "rosbag2" in help_text
