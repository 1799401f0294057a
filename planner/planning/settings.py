"""The settings a user tunes, from the command line or a YAML file, and the plan's record of them.

Names are :class:`~planner.planning.local.LocalSettings`' own (``theta.clearance_m`` for the
Theta problems' body clearance), plus ``mu`` (friction, overriding the terrain's) and
``seed`` (section 9's CMA-ES; the local planners 8.1, 8.2, 8.5 are deterministic). A YAML
file (``stratawalk plan --config settings.yaml``) holds any of them::

    mu: 0.5                 # friction coefficient (the terrain file's otherwise)
    step_m: 0.05            # stride of Lambda_t [m]
    body_speed_m_s: 0.03    # body moves, peak speed [m/s]
    body_accel_m_s2: 0.5    # body moves, acceleration bound [m/s^2]
    swing_time_s: 0.8       # least duration of a swing [s]
    swing_overlap: 1.0      # share of a body move the next swing may overlap (0: none)
    clearance_m: 0.03       # swing height: the foot's lift above the terrain [m]
    theta.clearance_m: 0.03 # body clearance: the body box above the terrain [m]
    com_target: two_beat    # body target before a swing (centroid: the paper's Lambda_c)
    body_samples: 16        # samples of a body move
    swing_samples: 24       # samples of a swing
    gait: [HL, FL, HR, FR]  # the crawl's leg order
    footholds: search       # each step's foothold from the contact-sequence search
    restarts: 2             # a stalled walk planned again with another stance model
    theta.rolling_feet: on  # Theta2 on the centres the stance spheres roll to
    theta.lift_ready: on    # body moves keep the swing leg able to lift off
    seed: 1

Command-line options override the file, which overrides the defaults. The effective
settings (:func:`effective`) are what ``stratawalk plan --print-config`` prints and what the
plan file records under ``stats.settings``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from planner.core.errors import InputError
from planner.core.legs import LEG_NAMES
from planner.motion.gait_queue import CRAWL
from planner.problems.options import LocalSettings

__all__ = [
    "PRESETS",
    "SETTINGS",
    "Setting",
    "UserSettings",
    "effective",
    "load_config",
    "preset",
    "preset_settings",
    "resolve",
]


@dataclass(frozen=True)
class Setting:
    """One tunable: its YAML/record ``name``, command-line ``option``, bounds and help."""

    name: str
    option: str
    kind: str  # "float", "int", "gait", "choice" or "bool"
    help: str
    lo: float = 0.0
    hi: float = math.inf
    lo_open: bool = True
    choices: tuple[str, ...] = ()


SETTINGS: tuple[Setting, ...] = (
    Setting("mu", "--mu", "float", "friction coefficient (overrides the terrain's)", 0.0, 5.0),
    Setting("step_m", "--step", "float", "stride of Lambda_t [m] (0.35 x leg reach)", 0.0, 1.0),
    Setting("body_speed_m_s", "--body-speed", "float", "peak speed of body moves [m/s]", 0.0, 1.0),
    Setting(
        "body_accel_m_s2", "--body-accel", "float",
        "acceleration bound of body moves [m/s^2] (quasi-static)", 0.0, 10.0,
    ),
    Setting("swing_time_s", "--swing-time", "float", "least duration of a swing [s]", 0.0, 60.0),
    Setting(
        "swing_overlap", "--swing-overlap", "float",
        "largest share of a body move the next swing may overlap (0: body still in swings)",
        0.0, 1.0, lo_open=False,
    ),
    Setting("clearance_m", "--swing-height", "float", "swing height over the terrain [m]", 0, 0.5),
    Setting(
        "theta.clearance_m", "--body-clearance", "float",
        "least height of the body box above the terrain [m]", 0.0, 0.5, lo_open=False,
    ),
    Setting(
        "com_target", "--com-target", "choice",
        "body target before a swing: centroid (Lambda_c, eq. 12) or two_beat (two body moves "
        "per cycle)", choices=("centroid", "two_beat"),
    ),
    Setting(
        "level_stride", "--level-stride", "float",
        "stride of Lambda_t over level ground, x leg reach (default: --step everywhere)",
        0.0, 2.0,
    ),
    Setting(
        "level_body_accel_m_s2", "--level-body-accel", "float",
        "acceleration bound of body moves over level ground [m/s^2] (default: --body-accel)",
        0.0, 10.0,
    ),
    Setting(
        "level_clearance_m", "--level-swing-height", "float",
        "swing height over level ground [m] (default: --swing-height)", 0.0, 0.5,
    ),
    Setting(
        "level_body_samples", "--level-body-samples", "int",
        "samples of a body move over level ground (default: --body-samples)", 2, 1000, False,
    ),
    Setting(
        "level_swing_samples", "--level-swing-samples", "int",
        "samples of a swing over level ground (default: --swing-samples)", 4, 1000, False,
    ),
    Setting("body_samples", "--body-samples", "int", "samples of a body move", 2, 1000, False),
    Setting("swing_samples", "--swing-samples", "int", "samples of a swing", 4, 1000, False),
    Setting("gait", "--gait", "gait", "leg order of the crawl, e.g. HL,FL,HR,FR"),
    Setting(
        "footholds", "--footholds", "choice",
        "first foothold of each step: lambda_t (eq. 13, one step ahead) or search (the "
        "contact-sequence search, a gait cycle ahead)", choices=("lambda_t", "search"),
    ),
    Setting(
        "restarts", "--restarts", "int",
        "a walk that stalls with time left is planned again with another model of the "
        "stance, at most this many times (0: never)", 0, 10, False,
    ),
    Setting(
        "theta.rolling_feet", "--rolling-feet", "bool",
        "on: Theta2 solves for where the stance spheres roll (section 4.3); off: contact "
        "points held (the paper's leaf)",
    ),
    Setting(
        "theta.lift_ready", "--lift-ready", "bool",
        "on: a body move before a swing keeps the swing leg able to lift off",
    ),
    Setting("seed", "--seed", "int", "random seed (CMA-ES of --global, >= 1)", 1, 2**31 - 1, False),
    Setting("time_budget_s", "--time-budget", "float", "planning time budget [s]", 0.0, 1e6),
)  # fmt: skip
_BY_NAME = {s.name: s for s in SETTINGS}
_BOOL_TEXT = {"on": True, "off": False, "true": True, "false": False, "yes": True, "no": False}


@dataclass
class UserSettings:
    """The resolved settings: the planner's, the friction override and the seed."""

    local: LocalSettings
    mu: float | None = None
    seed: int = 1


def _value(s: Setting, raw: Any, where: str) -> Any:
    """``raw`` checked against ``s`` (``where`` names the file/key or the option)."""
    if s.kind == "gait":
        items = raw.split(",") if isinstance(raw, str) else raw
        if not isinstance(items, (list, tuple)):
            raise InputError(f"{where}: expected four legs like HL,FL,HR,FR, got {raw!r}")
        names = [str(v).strip().upper() for v in items]
        if sorted(names) != sorted(LEG_NAMES):
            raise InputError(
                f"{where}: expected each of {', '.join(LEG_NAMES)} once (e.g. HL,FL,HR,FR), "
                f"got {raw!r}"
            )
        return tuple(LEG_NAMES.index(n) for n in names)
    if s.kind == "bool":
        text = str(raw).strip().lower()
        if isinstance(raw, bool) or text in _BOOL_TEXT:
            return raw if isinstance(raw, bool) else _BOOL_TEXT[text]
        raise InputError(f"{where}: expected on or off, got {raw!r}")
    if s.kind == "choice":
        if str(raw) not in s.choices:
            raise InputError(f"{where}: expected one of {', '.join(s.choices)}, got {raw!r}")
        return str(raw)
    if isinstance(raw, bool) or raw is None:
        raise InputError(f"{where}: expected a number, got {raw!r}")
    if isinstance(raw, str):
        try:
            float(raw)
        except ValueError:
            raise InputError(f"{where}: expected a number, got {raw!r}") from None
        hint = (
            "write the exponent with a sign (1.0e+6), YAML reads 1.0e6 as text"
            if "e" in raw.lower()
            else "remove the quotes"
        )
        raise InputError(f"{where}: expected a number, got the text {raw!r}; {hint}")
    try:
        v = float(raw)
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected a number, got {raw!r}") from None
    low_bad = v <= s.lo if s.lo_open else v < s.lo
    if not math.isfinite(v) or low_bad or v > s.hi:
        lo = f"> {s.lo:g}" if s.lo_open else f">= {s.lo:g}"
        raise InputError(f"{where}: must be a finite number {lo} and <= {s.hi:g}, got {raw!r}")
    if s.kind == "int":
        if v != int(v):
            raise InputError(f"{where}: expected a whole number, got {raw!r}")
        return int(v)
    return v


# Named settings (``stratawalk plan --preset NAME``), under a --config file and the options.
# LittleDog's values; lengths (names ending in _m) scale with the robot's legs
# (:func:`planner.body.robot_scale.length_scale`), accelerations do not (equal Froude numbers).
PRESETS: dict[str, dict[str, Any]] = {
    # a walk nearly twice as fast on level ground that holds up in MuJoCo
    # (bench/results/speed.md), as careful as the defaults elsewhere: where the ground
    # under the feet (the swing's track) is level, two body moves per crawl cycle instead
    # of four, a stride of 2/3 of the leg's reach (1.9x the default), body moves at
    # 1.5 m/s^2 (the time law lowers it where friction or the zero-moment point ask) and a
    # 2 cm swing height, and samples fine enough for the time law's intervals. Applied
    # everywhere, these settings (and the samples alone) planned fewer of the named and
    # hard courses than the defaults, and a plan fell with feedback
    # (bench/notes/2026-11-26-physics-fast-everywhere.md): level ground only.
    "fast": {
        "com_target": "two_beat",
        "level_stride": 0.67,
        "level_body_accel_m_s2": 1.5,
        "level_clearance_m": 0.02,
        "level_body_samples": 16,
        "level_swing_samples": 24,
    },
}


def _float_or_none(v) -> float | None:
    return None if v is None else float(v)


def _int_or_none(v) -> int | None:
    return None if v is None else int(v)


def preset(name: str, length_scale: float = 1.0) -> dict[str, Any]:
    """The checked settings of preset ``name``, lengths x ``length_scale`` (one-line errors)."""
    if name not in PRESETS:
        raise InputError(f"--preset: unknown preset {name!r}; known: {', '.join(PRESETS)}")
    out = {}
    for key, raw in PRESETS[name].items():
        value = raw * length_scale if key.endswith("_m") else raw
        out[key] = _value(_BY_NAME[key], value, f"--preset {name}: {key}")
    return out


def preset_settings(name: str, robot_name: str = "littledog") -> LocalSettings:
    """The local planner's settings of preset ``name`` for a robot ("default": the defaults)."""
    if name == "default":
        return LocalSettings()
    from planner.body.robot import load_robot
    from planner.body.robot_scale import length_scale

    return resolve(preset(name, length_scale(load_robot(robot_name)))).local


def load_config(path: str | Path) -> dict[str, Any]:
    """Checked settings of a YAML file (one line naming the file and key on any error)."""
    import yaml

    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"{p}: cannot read the settings file ({exc.strerror})") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark is not None else ""
        raise InputError(f"{p}: not valid YAML{at}; fix the file") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise InputError(f"{p}: expected a mapping of settings (name: value)")
    out = {}
    for key, raw in data.items():
        s = _BY_NAME.get(str(key))
        if s is None:
            known = ", ".join(_BY_NAME)
            raise InputError(f"{p}: unknown setting {key!r}; known: {known}")
        out[s.name] = _value(s, raw, f"{p}: {key}")
    return out


def resolve(config: dict[str, Any] | None = None, options: dict[str, Any] | None = None):
    """UserSettings from defaults, then ``config`` (checked), then ``options`` (raw CLI text)."""
    values: dict[str, Any] = dict(config or {})
    for name, raw in (options or {}).items():
        if raw is not None:
            s = _BY_NAME[name]
            if isinstance(raw, str) and s.kind not in ("gait", "choice", "bool"):
                try:
                    raw = float(raw)
                except ValueError:
                    raise InputError(f"{s.option}: expected a number, got {raw!r}") from None
            values[name] = _value(s, raw, s.option)
    local = LocalSettings()
    theta = local.theta
    mu, seed = None, 1
    for name, v in values.items():
        if name == "mu":
            mu = v
        elif name == "seed":
            seed = v
        elif name.startswith("theta."):
            theta = replace(theta, **{name.split(".", 1)[1]: v})
        else:
            local = replace(local, **{name: v})
    return UserSettings(replace(local, theta=theta), mu, seed)


def effective(planner: Any, seed: int = 1) -> dict:
    """The settings in force in a local ``planner``, by their names (defaults resolved)."""
    from planner.motion.interpolate import default_clearance_m

    loc = planner.settings
    return {
        "mu": float(planner.mu),
        "step_m": float(planner.stride_m()),
        "body_speed_m_s": float(loc.body_speed_m_s),
        "body_accel_m_s2": float(loc.body_accel_m_s2),
        "swing_time_s": float(loc.swing_time_s),
        "swing_overlap": float(loc.swing_overlap),
        "clearance_m": float(loc.clearance_m or default_clearance_m(planner.robot)),
        "theta.clearance_m": float(loc.theta.clearance_m),
        "com_target": str(loc.com_target),
        "level_stride": _float_or_none(loc.level_stride),
        "level_body_accel_m_s2": _float_or_none(loc.level_body_accel_m_s2),
        "level_clearance_m": _float_or_none(loc.level_clearance_m),
        "level_body_samples": _int_or_none(loc.level_body_samples),
        "level_swing_samples": _int_or_none(loc.level_swing_samples),
        "body_samples": int(loc.body_samples),
        "swing_samples": int(loc.swing_samples),
        "gait": [LEG_NAMES[i] for i in (loc.gait or CRAWL)],
        "footholds": str(loc.footholds),
        "restarts": int(loc.restarts),
        "theta.rolling_feet": bool(loc.theta.rolling_feet),
        "theta.lift_ready": bool(loc.theta.lift_ready),
        "seed": int(seed),
        "time_budget_s": float(loc.time_budget_s),
    }
