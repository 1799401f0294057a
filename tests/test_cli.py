import subprocess
import sys

from planner.cli import main


def test_robot_summary_prints_littledog(capsys):
    assert main(["robot", "littledog"]) == 0
    out = capsys.readouterr().out
    assert "FL_hip_roll" in out and "3.004 kg" in out and "knee points rearward" in out


def test_robot_bad_path_is_one_line_error(capsys, tmp_path):
    assert main(["robot", str(tmp_path / "x.urdf")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "x.urdf" in err and "not found" in err


def test_console_script_entry_point():
    out = subprocess.run(
        [sys.executable, "-m", "planner.cli", "robot", "go1"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "go1" in out and "RL_calf_joint" in out
