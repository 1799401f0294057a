"""User settings (planner.planning.settings) and the plan command's input checks."""

import json

import pytest

from planner.cli.main import _join_negative_xy, main
from planner.core.errors import InputError
from planner.planfile.plan import Plan
from planner.planfile.validate import check_plan
from planner.planning.settings import load_config, resolve


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    return err


def test_negative_coordinates_parse():
    argv = ["plan", "--terrain", "flat", "--goal", "-0.4,0", "--start", "-.2,0.1", "--mu", "0.5"]
    assert _join_negative_xy(argv) == [
        "plan", "--terrain", "flat", "--goal=-0.4,0", "--start=-.2,0.1", "--mu", "0.5",
    ]  # fmt: skip


@pytest.mark.parametrize(
    "start, goal, expect",
    [
        ("10,10", "11,10", "--start: 10,10 is off terrain step5cm"),
        ("-10,0", "0.5,0", "--start: -10,0 is off terrain step5cm"),
        ("0.2,0", "0.5,-0.58", "--goal: 0.5,-0.58 is off terrain step5cm"),
        ("0.2,0", "nan,0", "--goal: expected finite X,Y"),
    ],
)
def test_start_or_goal_off_the_terrain_is_refused(capsys, start, goal, expect):
    rc = main(["plan", "--terrain", "step5cm", "--start", start, "--goal", goal])
    err = _one_line_error(capsys)
    assert rc == 2 and expect in err, err
    if "off terrain" in expect:
        assert "x -0.5..2.5, y -0.6..0.6" in err


def test_config_file_then_options_override(tmp_path):
    cfg = tmp_path / "s.yaml"
    cfg.write_text("mu: 0.5\nswing_time_s: 0.8\ngait: [FL, FR, HL, HR]\ntheta.clearance_m: 0.03\n")
    user = resolve(load_config(cfg), {"mu": "0.4", "step_m": None})
    assert user.mu == 0.4 and user.local.swing_time_s == 0.8
    assert user.local.gait == (0, 1, 2, 3) and user.local.theta.clearance_m == 0.03
    assert resolve().mu is None and resolve().local.gait == (2, 0, 3, 1)


@pytest.mark.parametrize(
    "text, expect",
    [
        ("stride: 0.05\n", "unknown setting 'stride'; known: mu, step_m"),
        ("step_m: 1.0e6\n", "step_m: expected a number, got the text '1.0e6'; write the exponent"),
        ("mu: -1\n", "mu: must be a finite number > 0"),
        ("gait: [HL, HL, FR, FL]\n", "gait: expected each of FL, FR, HL, HR once"),
        ("seed: 1.5\n", "seed: expected a whole number"),
        ("- 1\n- 2\n", "expected a mapping"),
        ("mu: [\n", "not valid YAML at line"),
    ],
)
def test_bad_config_is_one_line_naming_file_and_key(tmp_path, capsys, text, expect):
    cfg = tmp_path / "s.yaml"
    cfg.write_text(text)
    with pytest.raises(InputError, match="s.yaml"):
        load_config(cfg)
    rc = main(["plan", "--terrain", "flat", "--goal", "1,0", "--config", str(cfg)])
    err = _one_line_error(capsys)
    assert rc == 2 and str(cfg) in err and expect in err, err


def test_print_config_shows_the_settings_in_force(capsys):
    rc = main(["plan", "--terrain", "slope10", "--mu", "0.3", "--swing-height", "0.04",
               "--print-config"])  # fmt: skip
    out = capsys.readouterr().out
    assert rc == 0
    lines = dict(line.split(": ", 1) for line in out.strip().splitlines())
    assert lines["mu"] == "0.3" and lines["clearance_m"] == "0.04"
    assert lines["gait"] == "HL,FL,HR,FR" and float(lines["step_m"]) == pytest.approx(0.0628, 1e-3)


def test_plan_records_its_settings_and_friction(tmp_path, capsys):
    out = tmp_path / "p.json"
    rc = main(["plan", "--terrain", "flat", "--goal", "0.35,0", "--mu", "0.45", "--step", "0.05",
               "--gait", "FL,HR,FR,HL", "--out", str(out)])  # fmt: skip
    capsys.readouterr()
    assert rc == 0
    plan = Plan.load(out)
    settings = json.loads(out.read_text())["stats"]["settings"]
    assert plan.friction == 0.45 and settings["mu"] == 0.45 and settings["step_m"] == 0.05
    assert settings["gait"] == ["FL", "HR", "FR", "HL"]
    lifted = [i for k in range(1, len(plan.samples)) for i in range(4)
              if plan.samples.contact[k - 1, i] and not plan.samples.contact[k, i]]  # fmt: skip
    assert lifted[:4] == [0, 3, 1, 2]  # the gait order asked for
    assert check_plan(plan).ok


def test_preset_under_config_and_options(tmp_path, capsys):
    """--preset fast fills the settings; a --config file and the options override it."""
    cfg = tmp_path / "s.yaml"
    cfg.write_text("level_body_accel_m_s2: 1.0\n")
    rc = main(["plan", "--terrain", "flat", "--preset", "fast", "--config", str(cfg),
               "--level-swing-samples", "20", "--print-config"])  # fmt: skip
    out = capsys.readouterr().out
    assert rc == 0
    lines = dict(line.split(": ", 1) for line in out.strip().splitlines())
    assert lines["com_target"] == "two_beat" and lines["level_stride"] == "0.67"
    assert lines["level_body_accel_m_s2"] == "1" and lines["level_swing_samples"] == "20"
    assert lines["swing_samples"] == "12" and lines["body_samples"] == "8"
    assert lines["level_clearance_m"] == "0.02" and lines["level_body_samples"] == "16"
    assert lines["body_accel_m_s2"] == "0.5" and lines["clearance_m"] == "0.029981"


def test_preset_lengths_scale_with_the_robot():
    from planner.planning.settings import PRESETS, preset

    got = preset("fast", 2.0)
    assert got["level_clearance_m"] == pytest.approx(2.0 * PRESETS["fast"]["level_clearance_m"])
    assert got["level_body_accel_m_s2"] == PRESETS["fast"]["level_body_accel_m_s2"]  # Froude


@pytest.mark.parametrize(
    "argv, expect",
    [
        (["--preset", "quick"], "--preset: unknown preset 'quick'; known: fast"),
        (["--com-target", "middle"], "--com-target: expected one of centroid, two_beat"),
        (["--body-samples", "1"], "--body-samples: must be a finite number >= 2"),
    ],
)
def test_bad_preset_or_choice_is_one_line(capsys, argv, expect):
    rc = main(["plan", "--terrain", "flat", "--goal", "1,0", *argv])
    err = _one_line_error(capsys)
    assert rc == 2 and expect in err, err


def test_rolling_feet_and_lift_ready_from_options_and_file(tmp_path, capsys):
    """on/off from the command line, booleans from YAML, into Theta2's options."""
    cfg = tmp_path / "s.yaml"
    cfg.write_text("theta.rolling_feet: true\n")
    user = resolve(load_config(cfg), {"theta.lift_ready": "on"})
    assert user.local.theta.rolling_feet and user.local.theta.lift_ready
    assert not resolve().local.theta.rolling_feet and not resolve().local.theta.lift_ready
    rc = main(["plan", "--terrain", "flat", "--rolling-feet", "on", "--print-config"])
    lines = dict(line.split(": ", 1) for line in capsys.readouterr().out.strip().splitlines())
    assert rc == 0 and lines["theta.rolling_feet"] == "on" and lines["theta.lift_ready"] == "off"
    rc = main(["plan", "--terrain", "flat", "--goal", "1,0", "--lift-ready", "maybe"])
    err = _one_line_error(capsys)
    assert rc == 2 and "--lift-ready: expected on or off, got 'maybe'" in err, err


def test_config_com_target_is_checked(tmp_path):
    cfg = tmp_path / "s.yaml"
    cfg.write_text("com_target: 3\n")
    with pytest.raises(InputError, match="com_target: expected one of centroid, two_beat"):
        load_config(cfg)
