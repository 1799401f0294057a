import subprocess
import sys

from planner.cli.main import main


def test_robot_summary_prints_littledog(capsys):
    assert main(["robot", "littledog"]) == 0
    out = capsys.readouterr().out
    assert "FL_hip_roll" in out and "3.004 kg" in out and "knee points rearward" in out


def test_robot_list_names_every_loadable_robot_and_its_urdf(capsys):
    from pathlib import Path

    from planner.body.robot import load_robot, robot_names

    assert main(["robot", "--list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()[1:-1]  # header and footnote out
    assert [ln.split()[0] for ln in lines] == robot_names()
    assert all(Path(ln.split()[-1]).is_file() for ln in lines)  # each URDF exists here
    solo = next(ln for ln in lines if ln.startswith("solo12"))
    r = load_robot("solo12")
    assert f"{r.total_mass_kg:.2f}" in solo and "*" in solo  # its foot radius is derived
    for args, option in ((["robot"], "robot:"), (["robot", "go1", "--list"], "--list")):
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and option in err


def test_robot_bad_path_is_one_line_error(capsys, tmp_path):
    assert main(["robot", str(tmp_path / "x.urdf")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "x.urdf" in err and "not found" in err


def test_console_script_entry_point():
    out = subprocess.run(
        [sys.executable, "-m", "planner.cli.main", "robot", "go1"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "go1" in out and "RL_calf_joint" in out


def test_the_help_loads_no_solver_nor_robot_library():
    """Issue 16: `stratawalk --help` and every sub-command's parser start without CasADi,
    Pinocchio, MuJoCo or SciPy (each sub-command imports what it runs)."""
    code = (
        "import sys; from planner.cli.main import build_parser; build_parser(); "
        "print(' '.join(m for m in ('casadi', 'pinocchio', 'mujoco', 'scipy') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == ""


def test_plan_then_check_from_the_command_line(tmp_path, capsys):
    out = tmp_path / "plan.json"
    rc = main(["plan", "--terrain", "flat", "--goal", "0.45,0", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "validation: ok" in text and "reached the goal" in text
    assert main(["check", str(out)]) == 0


def test_plan_bad_goal_is_one_line_error(capsys):
    assert main(["plan", "--terrain", "flat", "--goal", "two,0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--goal" in err
