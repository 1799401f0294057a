"""Bad input to every command: one line naming the option or file, exit 2, before any work.

Each case here was a traceback, a hang or a silently wrong result once (issue 19).
"""

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from planner.cli import main

LITTLEDOG_URDF = Path(__file__).parents[1] / "models" / "littledog" / "littledog.urdf"


def _one_line_error(capsys, *names):
    """The captured stderr: one line that names each of ``names``."""
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err, err
    for name in names:
        assert str(name) in err, err
    return err


# ------------------------------------------------------------------------------ outputs
def test_outputs_are_checked_before_any_work(short_flat_walk, tmp_path, capsys):
    path, _, _ = short_flat_walk
    a_file = tmp_path / "a_file"
    a_file.write_text("keep me")
    cases = [
        (["plot", str(path), "--out", str(a_file)], "--out"),
        (["plot", str(path), "--out", str(tmp_path / "p"), "--dpi", "-5"], "--dpi"),
        (["plot", str(path), "--out", str(a_file / "sub")], "is a file"),
        (["replay", str(path), "--html", str(tmp_path)], "--html"),
        (["replay", str(path), "--html", str(tmp_path / "r.txt")], ".html"),
        (["export", str(path), "--out", str(a_file / "x.csv")], "is a file"),
        (["terrain", "flat", "--png", str(tmp_path)], "--png"),
        (["batch", str(a_file), "--out", str(a_file)], "--out"),
        (["plan", "--terrain", "flat", "--goal", "0.5,0", "--out", str(tmp_path)], "--out"),
    ]
    for args, expect in cases:
        assert main(args) == 2, args
        _one_line_error(capsys, expect)
    assert a_file.read_text() == "keep me"
    assert not (tmp_path / "p").exists()


def test_outputs_are_written_whole_with_the_usual_mode(short_flat_walk, tmp_path, capsys):
    path, _, _ = short_flat_walk
    out = tmp_path / "new" / "folder" / "replay.html"
    assert main(["replay", str(path), "--html", str(out), "--geometry", "collision"]) == 0
    assert out.stat().st_mode & 0o777 == 0o666 & ~_umask()
    assert [p.name for p in out.parent.iterdir()] == ["replay.html"]  # no temporary left


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


# ------------------------------------------------------------------------------ terrains
@pytest.mark.parametrize(
    "field, value", [("length", "1.0e+300"), ("x_min", "-1.0e+308"), ("y_min", "-1.0e+6")]
)
def test_terrain_of_absurd_extent_is_refused(field, value, tmp_path, capsys):
    text = (Path(__file__).parents[1] / "terrains" / "flat.yaml").read_text()
    course = tmp_path / "huge.yaml"
    course.write_text(re.sub(rf"(?m)^{field}:.*$", f"{field}: {value}", text))
    assert main(["terrain", str(course), "--png", str(tmp_path / "t.png")]) == 2
    _one_line_error(capsys, "huge.yaml", field)
    assert not (tmp_path / "t.png").exists()


def test_a_large_course_draws_on_a_coarser_grid(tmp_path, capsys):
    from PIL import Image

    course = tmp_path / "long.yaml"
    course.write_text("name: long\nkind: flat\nx_min: 0\nlength: 2000\ny_min: -5\ny_max: 5\n")
    assert main(["terrain", str(course), "--png", str(tmp_path / "t.png")]) == 0
    assert "wrote" in capsys.readouterr().out
    assert Image.open(tmp_path / "t.png").size[0] < 3000


# ------------------------------------------------------------------------------ robots
@pytest.mark.parametrize(
    "edit, expect",
    [
        (('lower="-0.6" upper="0.6"', 'lower="0.6" upper="-0.6"'), "swapped"),
        (('<mass value="0.001"/>', '<mass value="-1"/>'), "mass"),
        (('<mass value="2.240"/>', '<mass value="abc"/>'), "mass"),
        (('<mass value="2.240"/>', '<mass value="nan"/>'), "mass"),
    ],
)
def test_urdf_with_impossible_numbers_is_refused(edit, expect, tmp_path, capsys):
    text = LITTLEDOG_URDF.read_text()
    assert edit[0] in text
    urdf = tmp_path / "edited.urdf"
    urdf.write_text(text.replace(edit[0], edit[1], 1))
    for command in (
        ["robot", str(urdf)],
        ["plan", "--robot", str(urdf), "--terrain", "flat", "--goal", "0.5,0"],
    ):
        assert main(command) == 2
        _one_line_error(capsys, "edited.urdf", expect)


def test_a_plan_whose_urdf_moved_names_the_fix(short_flat_walk, tmp_path, capsys):
    path, _, _ = short_flat_walk
    urdf = tmp_path / "mine" / "my_dog.urdf"
    urdf.parent.mkdir()
    shutil.copy(LITTLEDOG_URDF, urdf)
    d = json.loads(Path(path).read_text())
    d["robot"].update(name="my_dog", urdf=str(tmp_path / "gone" / "my_dog.urdf"))
    moved = tmp_path / "moved.json"
    moved.write_text(json.dumps(d))
    commands = [
        ["check", str(moved)],
        ["replay", str(moved), "--html", str(tmp_path / "r.html")],
        ["export", str(moved), "--out", str(tmp_path / "t.csv")],
        ["simulate", str(moved), "--out", str(tmp_path / "s.json")],
    ]
    for args in commands:
        assert main(args) == 2, args
        _one_line_error(capsys, "moved.json", "--robot")
    assert main(["check", str(moved), "--robot", str(urdf)]) == 0
    assert "OK" in capsys.readouterr().out
    assert main(["export", str(moved), "--robot", str(urdf), "--out", str(tmp_path / "t.csv")]) == 0
    # a URDF of another robot is refused, naming its joints
    assert main(["check", str(moved), "--robot", "solo12"]) == 2
    _one_line_error(capsys, "--robot solo12", "joints")


# ------------------------------------------------------------------------------ check
def test_check_rejects_an_empty_plan(short_flat_walk, tmp_path, capsys):
    path, _, _ = short_flat_walk
    d = json.loads(Path(path).read_text())
    no_keyframes = tmp_path / "no_keyframes.json"
    no_keyframes.write_text(json.dumps(dict(d, keyframes=[])))
    one_sample = tmp_path / "one_sample.json"
    s = d["samples"]
    one_sample.write_text(json.dumps(dict(d, samples={k: v[:1] for k, v in s.items()})))
    for bad in (no_keyframes, one_sample):
        assert main(["check", str(bad)]) == 1
        out = capsys.readouterr().out
        assert "empty_plan" in out and "FAILED" in out, out


def test_check_prints_at_most_50_violations(short_flat_walk, tmp_path, capsys):
    path, _, _ = short_flat_walk
    d = json.loads(Path(path).read_text())
    for q in d["samples"]["q"]:
        q[2] -= 0.05  # every sample 5 cm into the ground
    sunk = tmp_path / "sunk.json"
    sunk.write_text(json.dumps(d))
    assert main(["check", str(sunk)]) == 1
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 52 and "more violations" in lines[-2] and "FAILED" in lines[-1]
    total = int(re.search(r"FAILED, (\d+) violations", lines[-1]).group(1))
    assert total > 100
    assert main(["check", str(sunk), "--all"]) == 1
    assert len(capsys.readouterr().out.strip().splitlines()) == total + 1


# ------------------------------------------------------------------------------ signals
def _port_free(port):
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def test_sigterm_to_replay_stops_its_server(short_flat_walk):
    path, _, _ = short_flat_walk
    proc = subprocess.Popen(
        [sys.executable, "-m", "planner.cli", "replay", str(path), "--geometry", "collision"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        line = ""
        while "open http" not in line:
            assert time.monotonic() < deadline, "replay did not start"
            line = proc.stdout.readline()
            assert line or proc.poll() is None, proc.stderr.read()
        port = int(re.search(r":(\d+)/static", line).group(1))
        assert not _port_free(port)
        proc.send_signal(signal.SIGTERM)
        proc.wait(20)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 0, proc.stderr.read()
    # the server subprocess is gone and its port is free again
    time.sleep(0.5)
    assert _port_free(port)
    leftover = subprocess.run(["pgrep", "-s", str(proc.pid)], capture_output=True)
    assert leftover.stdout.strip() == b"", leftover.stdout  # nothing left of its session
