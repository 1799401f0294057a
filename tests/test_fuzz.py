"""Property-based fuzzing of the commands (hypothesis): never a traceback, never a hang.

Generated terrain YAML files, URDF edits, plan-file edits, structural plan edits (times
reversed or repeated, absurd or non-finite coordinates, sizes that disagree, keyframes out
of order), output locations (unwritable, a folder for a file, a device, a full disk, too
long a name) and command lines are fed to ``terrain``, ``robot``, ``check``, ``export``,
``replay`` (HTML and the live server), ``plot``, ``simulate``, ``plan``, ``batch``,
``generate-course``, ``demo`` and ``bench``. The property: exit status 0, 1 or 2; on 2 a
single line on stderr; no exception escapes ``main`` (a traceback); each case ends within
its time limit. Oracles judge the results: a plan no robot could execute is refused by
every command (``check``: not passed), a bad output location is refused (exit 2), and on
exit 0 the output is right: a plan passes ``check``, an export reproduces the plan's
samples at its rate, a replay file holds the plan's samples, the figures are images.

``make test`` runs a seeded (derandomised) sample of about 450 cases; ``make fuzz`` sets
``STRATAWALK_FUZZ_SCALE=20`` for about 7,400 (the output locations are few enough to be
all tried), with a fresh random seed each run.
"""

import base64
import contextlib
import copy
import gzip
import json
import os
import re
import resource
import signal
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
import umsgpack
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from planner.cli.main import main

SCALE = int(os.environ.get("STRATAWALK_FUZZ_SCALE", "1"))
ROOT = Path(__file__).resolve().parents[1]
LITTLEDOG_URDF = (ROOT / "models" / "littledog" / "littledog.urdf").read_text()
CASE_LIMIT_S = 60  # a case that runs longer is a hang
MEMORY_LIMIT_B = 10 * 2**30  # a case that needs more is a memory bomb (MemoryError, a failure)


@pytest.fixture(scope="module", autouse=True)
def _address_space_limit():
    """Cap this process's address space, so that input which would take all the machine's
    memory fails the test with MemoryError instead of calling the OOM killer."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    cap = MEMORY_LIMIT_B if hard == resource.RLIM_INFINITY else min(MEMORY_LIMIT_B, hard)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    yield
    resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _settings(n: int, scale: int = SCALE):
    return settings(
        max_examples=n * scale,
        deadline=None,
        derandomize=SCALE == 1,
        database=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )


class Hang(Exception):
    pass


@contextlib.contextmanager
def _time_limit(seconds: float):
    def expire(signum, frame):
        raise Hang(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


@contextlib.contextmanager
def _working_dir(path):
    """``os.chdir`` for the block (contextlib.chdir needs Python 3.11)."""
    old = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(old)


def _judge(argv: list[str], capfd, streams: list | None = None) -> int:
    """Run ``stratawalk argv``; assert the property; return the exit status.

    ``streams``: a list that gets the captured (stdout, stderr).
    """
    capfd.readouterr()
    with _time_limit(CASE_LIMIT_S):
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse: --help, or a bad option
            rc = exc.code if isinstance(exc.code, int) else 2
    out, err = capfd.readouterr()
    assert rc in (0, 1, 2), (argv, rc, err[-500:])
    assert "Traceback" not in err, (argv, err[-2000:])
    if rc == 2:
        assert err.strip() and err.strip().count("\n") == 0, (argv, err[-2000:])
    if streams is not None:
        streams[:] = [out, err]
    return rc


# ------------------------------------------------------------------------------ values
NUMBERS = st.one_of(
    st.integers(-(10**6), 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, 1e-300, 1e300, -0.0, 0.05, 3.0, 1.0e6]),
)
SCALARS = st.one_of(NUMBERS, st.text(max_size=12), st.booleans(), st.none())
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6),
                                                                          inner, max_size=3)),
    max_leaves=8,
)  # fmt: skip


def _yaml(value) -> str:
    """``value`` as YAML (JSON is YAML; NaN and infinities as YAML spells them)."""
    text = json.dumps(value, allow_nan=True)
    return text.replace("-Infinity", "-.inf").replace("Infinity", ".inf").replace("NaN", ".nan")


# ------------------------------------------------------------------------------ terrains
KINDS = ["flat", "slope", "step", "rough", "gap", "stairs", "stepping_stones", "barrier",
         "heightfield", "course", "logs", "rocks", "nosuch"]  # fmt: skip
TERRAIN_KEYS = ["name", "description", "friction", "x_min", "length", "y_min", "y_max",
                "smoothing_m", "amplitude", "angle_deg", "count", "depth", "direction_deg",
                "file", "gap", "height", "height_jitter", "height_max", "height_min", "heights",
                "offset", "radius", "radius_max", "radius_min", "ramp_length", "rise", "run",
                "seed", "size", "spacing", "start", "taper", "terms", "thickness", "wavelength",
                "width", "x", "x_end", "x_start", "y_end", "y_start", "segments"]  # fmt: skip


@st.composite
def terrain_yaml(draw) -> str:
    spec = {"name": "fuzz", "kind": draw(st.sampled_from(KINDS))}
    for key in draw(st.lists(st.sampled_from(TERRAIN_KEYS), max_size=6, unique=True)):
        spec[key] = draw(st.one_of(NUMBERS, VALUES))
    if draw(st.booleans()):
        spec.setdefault("length", draw(st.floats(0.1, 6.0)))
    if draw(st.integers(0, 9)) == 0:  # not a mapping at all, or broken YAML
        return draw(st.one_of(st.text(max_size=40), st.just("kind: [flat\n")))
    return "\n".join(f"{k}: {_yaml(v)}" for k, v in spec.items()) + "\n"


@_settings(100)
@given(text=terrain_yaml(), png=st.integers(0, 9))
def test_fuzz_terrain_files(text, png, tmp_path_factory, capfd):
    d = tmp_path_factory.mktemp("terrain")
    path = d / "fuzz.yaml"
    path.write_text(text)
    args = ["terrain", str(path)] + (["--png", str(d / "t.png")] if png == 0 else [])
    if _judge(args, capfd) == 0 and png == 0:
        _is_png(d / "t.png")


# ------------------------------------------------------------------------------ robots
@st.composite
def urdf_edit(draw) -> str:
    """LittleDog's URDF with a few attributes changed, or elements dropped or doubled."""
    text = LITTLEDOG_URDF
    for _ in range(draw(st.integers(1, 3))):
        how = draw(st.sampled_from(["attribute", "drop", "double", "type"]))
        if how == "attribute":
            attrs = ["lower", "upper", "effort", "velocity", "value", "radius", "xyz", "size",
                     "ixx", "iyy", "izz"]  # fmt: skip
            name = draw(st.sampled_from(attrs))
            n = text.count(f'{name}="')
            if n == 0:
                continue
            k = draw(st.integers(0, n - 1))
            at = -1
            for _ in range(k + 1):
                at = text.index(f'{name}="', at + 1)
            start = at + len(name) + 2
            end = text.index('"', start)
            value = draw(st.one_of(NUMBERS.map(str), st.text("0123456789.-e abcinf", max_size=8)))
            text = text[:start] + value + text[end:]
        elif how in ("drop", "double"):
            tag = draw(st.sampled_from(["<joint ", "<link ", "<mass ", "<limit ", "<collision"]))
            n = text.count(tag)
            if n == 0:
                continue
            at = -1
            for _ in range(draw(st.integers(1, n))):
                at = text.index(tag, at + 1)
            close = {"<joint ": "</joint>", "<link ": "</link>", "<collision": "</collision>"}
            end_tag = close.get(tag, "/>")
            end = text.index(end_tag, at) + len(end_tag)
            piece = text[at:end]
            text = text[:at] + (piece + piece if how == "double" else "") + text[end:]
        else:
            n = text.count('type="revolute"')
            if n:
                new = draw(st.sampled_from(["fixed", "prismatic", "continuous", "floating", "x"]))
                text = text.replace('type="revolute"', f'type="{new}"', 1)
    return text


@_settings(60)
@given(text=urdf_edit())
def test_fuzz_urdf_edits(text, tmp_path_factory, capfd):
    d = tmp_path_factory.mktemp("urdf")
    path = d / "edited.urdf"
    path.write_text(text)
    streams = []
    if _judge(["robot", str(path)], capfd, streams) == 0:  # the summary of a 4 x 3 robot
        assert streams[0].count("limits [") == 12 and streams[0].count(": foot frame") == 4


# ------------------------------------------------------------------------------ plan files
@pytest.fixture(scope="module")
def plan_dict(short_flat_walk):
    path, _, _ = short_flat_walk
    return json.loads(Path(path).read_text())


def _paths(value, prefix=()):
    """Every path (tuple of keys / indices) into a JSON value, sampled in long lists."""
    yield prefix
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(value, list):
        idx = range(len(value)) if len(value) <= 6 else [0, 1, len(value) // 2, len(value) - 1]
        for i in idx:
            yield from _paths(value[i], (*prefix, i))


@st.composite
def plan_edit(draw, base):
    d = copy.deepcopy(base)
    paths = [p for p in _paths(d) if p and (p[0] != "terrain_grid" or len(p) <= 2)]
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(paths))
        parent = d
        try:
            for key in path[:-1]:
                parent = parent[key]
            if draw(st.integers(0, 4)) == 0 and isinstance(parent, dict):
                parent.pop(path[-1], None)
            else:
                parent[path[-1]] = draw(VALUES)
        except (KeyError, IndexError, TypeError):
            continue
    return d


COMMANDS = ["check"] * 12 + ["export"] * 4 + ["replay", "plot", "simulate"]


@_settings(80)
@given(data=st.data())
def test_fuzz_plan_file_edits(data, plan_dict, tmp_path_factory, capfd):
    d = tmp_path_factory.mktemp("plan")
    edited = data.draw(plan_edit(plan_dict))
    path = d / "edited.json"
    path.write_text(json.dumps(edited, allow_nan=True))
    command = data.draw(st.sampled_from(COMMANDS))
    args = {
        "check": ["check", str(path)],
        "export": ["export", str(path), "--rate", "500", "--out", str(d / "t.csv")],
        "replay": ["replay", str(path), "--html", str(d / "r.html"), "--geometry", "collision"],
        "plot": ["plot", str(path), "--out", str(d / "plots"), "--dpi", "30"],
        "simulate": ["simulate", str(path), "--time-scale", "1", "--quiet"],
    }[command]
    rc = _judge(args, capfd)
    if _impossible(edited):
        assert rc == 1 and command == "check" or rc == 2, (command, rc)
    if rc == 0 and command in ("export", "replay", "plot"):
        from planner.planfile.plan import Plan

        plan = Plan.load(path)
        if command == "export":
            _export_reproduces(plan, d / "t.csv", 500.0)
        elif command == "replay":
            _replay_holds(plan, d / "r.html")
        else:
            _figures_are_images(d / "plots")


# ------------------------------------------------------------------------------ command lines
WORDS = st.one_of(
    st.sampled_from(["0", "-1", "nan", "inf", "1e308", "0.3,0", "-0.4,0", "1,2,3", "", ",",
                     "flat", "step5cm", "nosuch", "littledog", "solo12", "soft", "hard",
                     "FL,FR,HL,HR", "FL,FL", "x.yaml", "/", "-", "--", "0.5"]),
    st.text(max_size=8),
)  # fmt: skip
OPTIONS = {
    "plan": ["--robot", "--terrain", "--goal", "--start", "--planner", "--mu", "--step",
             "--body-speed", "--swing-time", "--swing-height", "--body-clearance", "--gait",
             "--seed", "--time-budget", "--config", "--out"],
    "robot": [],
    "terrain": ["--png"],
    "check": ["--robot"],
    "generate-course": ["--seed", "--difficulty", "--length", "--out"],
    "export": ["--rate", "--out", "--robot"],
    "simulate": ["--time-scale", "--timestep", "--noise-mm", "--noise-deg", "--latency",
                 "--seed", "--out", "--trajectory"],
}  # fmt: skip


@_settings(60)
@given(data=st.data())
def test_fuzz_command_lines(data, short_flat_walk, tmp_path_factory, capfd):
    d = tmp_path_factory.mktemp("cli")
    command = data.draw(st.sampled_from(sorted(OPTIONS)))
    args = [command]
    if command in ("robot", "terrain"):
        args.append(data.draw(WORDS))
    if command in ("check", "export", "simulate"):
        args.append(str(short_flat_walk[0]) if data.draw(st.booleans()) else data.draw(WORDS))
    for option in data.draw(st.lists(st.sampled_from(OPTIONS[command] or ["--help"]),
                                     max_size=4)):  # fmt: skip
        args += [option, data.draw(WORDS)]
    args = [a.replace("x.yaml", str(d / "x.yaml")) for a in args]
    if command == "plan":  # a plan that parses walks for a second at most
        args += ["--out", str(d / "p.json"), "--time-budget", "1", "--quiet"]
    if command == "simulate":
        args += ["--time-scale", "0.05", "--quiet"]  # not a whole walk: a fuzz case is short
    with _working_dir(d):  # relative outputs ("--out 0") land in the case's folder
        rc = _judge(args, capfd)
        if rc == 0:
            _command_line_result_is_right(args, short_flat_walk[1])


def _last(args: list[str], option: str, default=None):
    """The value of the last ``option`` in ``args`` (argparse keeps the last)."""
    values = [args[i + 1] for i in range(len(args) - 1) if args[i] == option]
    return values[-1] if values else default


def _command_line_result_is_right(args: list[str], walk) -> None:
    """The oracle of an exit-0 command line: its output is what it says."""
    out = _last(args, "--out")
    if args[0] == "plan":
        _plan_passes_check(out)
    elif args[0] == "export":
        _export_reproduces(walk, out, float(_last(args, "--rate", "500")))
    elif args[0] == "generate-course":
        from planner.world.terrain import load_terrain

        load_terrain(next(Path(out).glob("*.yaml")) if Path(out).is_dir() else out)
    elif args[0] == "simulate" and out is not None:
        assert not _impossible(json.loads(Path(out).read_text()))


def test_fuzz_batch_scenarios(tmp_path, capfd):
    """A few malformed scenario files to ``batch`` (each spawns workers: kept few)."""
    cases = ["jobs: 3\n", "jobs: []\n", "defaults: {goal: [nan, 0]}\njobs: [{}]\n",
             "jobs:\n  - {terrain: nosuch}\n", "jobs:\n  - {goal: [0.4, 0.0], planner: x}\n",
             "{{{\n", "defaults: 7\njobs: [{}]\n"]  # fmt: skip
    for i, text in enumerate(cases):
        scen = tmp_path / f"s{i}.yaml"
        scen.write_text(text)
        _judge(["batch", str(scen), "--out", str(tmp_path / f"o{i}"), "--workers", "1",
                "--quiet"], capfd)  # fmt: skip


# ------------------------------------------------------------------------------ oracles
ABSURD = 1e5  # beyond it: a coordinate [m], joint angle [rad] or time [s] no walk has


def _impossible(d) -> bool:
    """A plan no robot could execute, by a judgement of its own (not the loader's): sizes
    that disagree, fewer than 2 samples, non-finite or absurd numbers, times that do not
    increase, a terrain grid of fewer than 2 x 2 heights. Malformed types: False (the
    reader's business)."""
    try:
        s, g = d["samples"], d["terrain_grid"]
        t = np.array(s["time"], float)
        q = np.array(s["q"], float)
        n_contact = len(s["contact"])
        points = [np.array(d[k], float).reshape(-1) for k in ("start", "goal")]
        points.append(np.array(g["origin"], float).reshape(-1))
        for kf in d["keyframes"]:
            points += [np.array(kf[k], float).reshape(-1) for k in ("base_position", "joints")]
            points.append(np.array(kf["feet"], float).reshape(-1))
        heights = np.array(g["heights"], float)
    except (KeyError, TypeError, ValueError, IndexError):
        return False
    if t.ndim != 1 or q.shape != (len(t), 19) or n_contact != len(t) or len(t) < 2:
        return True
    if heights.ndim != 2 or min(heights.shape) < 2:
        return True
    with np.errstate(invalid="ignore"):
        if not (np.isfinite(t).all() and np.isfinite(q).all()) or np.any(np.diff(t) <= 0):
            return True
        return any(not np.all(np.abs(p) <= ABSURD) for p in [t, q[:, :3], q[:, 7:], *points])


def _robot_joints(robot):
    """Pinocchio q indices of the robot's joints, in its joint order (the export's)."""
    return [leg.q_index + j for leg in robot.legs for j in range(3)]


def _export_reproduces(plan, path, rate_hz: float) -> None:
    """The export at ``path``: rows ``1 / rate_hz`` apart over the walk, and every plan
    sample reproduced by the row before it (value + slope x time)."""
    from planner.planfile.export import load_trajectory

    tr, s = load_trajectory(path), plan.samples
    assert abs(tr.t[0] - s.time[0]) < 1e-9 and tr.t[-1] == s.time[-1], path
    if len(tr.t) > 2:
        assert np.allclose(np.diff(tr.t)[:-1], 1 / rate_hz, rtol=1e-6, atol=1e-9), path
    i = np.clip(np.searchsorted(tr.t, s.time, side="right") - 1, 0, len(tr.t) - 1)
    dt = (s.time - tr.t[i])[:, None]
    scale = 1.0 + np.abs(s.q).max()
    joints = s.q[:, _robot_joints(plan.load_robot())]
    assert np.abs(tr.q[i] + dt * tr.dq[i] - joints).max() < 1e-6 * scale
    assert np.abs(tr.base_pos[i] + dt * tr.base_vel[i] - s.q[:, :3]).max() < 1e-6 * scale


def _replay_holds(plan, path) -> None:
    """The HTML replay at ``path`` holds the plan's sample times and base positions."""
    page = Path(path).read_text()
    info = json.loads(re.search(r"const info = (.*);\n", page).group(1))
    t = plan.samples.time
    assert np.allclose(info["time"], t, atol=6e-5) and len(info["time"]) == len(t), path
    packed = re.findall(r'inflate\("([A-Za-z0-9+/=]+)"\)', page)[-1]
    data = gzip.decompress(base64.b64decode(packed))
    commands, at = [], 0
    while at < len(data):
        n = int.from_bytes(data[at : at + 4], "little")
        commands.append(umsgpack.unpackb(data[at + 4 : at + 4 + n]))
        at += 4 + n
    (anim,) = [c for c in commands if c.get("type") == "set_animation"]
    (clip,) = [a["clip"] for a in anim["animations"] if a["path"].endswith("/stratum")]
    (track,) = [tr for tr in clip["tracks"] if tr["name"] == ".position"]
    tk = np.frombuffer(track["times"].data, dtype="<f4").astype(float)
    v = np.frombuffer(track["values"].data, dtype="<f4").astype(float).reshape(len(tk), 3)
    at_t = np.stack([np.interp(t, tk, v[:, j]) for j in range(3)], axis=1)
    base = plan.samples.q[:, :3]
    off = at_t - base  # the label floats a fixed height over the base
    tol = 2e-5 * (1.0 + np.abs(base).max())
    assert np.abs(off[:, :2]).max() < tol and np.ptp(off[:, 2]) < tol, path


def _is_png(path) -> None:
    from PIL import Image

    with Image.open(path) as im:
        assert im.format == "PNG" and min(im.size) > 10, path


def _figures_are_images(folder) -> None:
    from planner.replay.plots import FIGURES

    for name in FIGURES:
        _is_png(Path(folder) / f"{name}.png")


def _plan_passes_check(path) -> None:
    from planner.planfile.plan import Plan
    from planner.planfile.validate import check_plan

    report = check_plan(Plan.load(path))
    assert report.ok, (path, report.summary())


# ------------------------------------------------------------------------------ structural edits
STRUCTURE_COMMANDS = ["check", "export", "replay", "plot", "simulate", "feedback", "compare",
                      "trajectory"]  # fmt: skip
SIMILAR = st.sampled_from([3.0, 0.5, -0.2, 10.0, 1e4, 1e5, -1e6, 1e300, -1e300])
HUGE = st.sampled_from([1e5, -1e6, 1e300, -1e300, float("nan"), float("inf")])


@st.composite
def structure_edit(draw, base):
    """The plan with 1 or 2 structural edits: its times, coordinates, sizes, keyframes."""
    d = copy.deepcopy(base)
    s, kfs = d["samples"], d["keyframes"]
    n = len(s["time"])
    for _ in range(draw(st.integers(1, 2))):
        how = draw(st.sampled_from([  # edits that may leave a plausible plan first
            "scale_times", "shift_times", "reverse_keyframes", "swap_keyframes", "no_keyframes",
            "reverse_motion", "drop_sample", "foot_position", "endpoint", "sample_position",
            "keyframe_position", "grid_origin", "joint", "reverse_times", "repeat_time",
            "swap_times", "time_value", "grid_heights", "truncate", "few_samples",
            "duplicate_sample"]))  # fmt: skip
        t, n = s["time"], min(len(s["time"]), len(s["q"]), len(s["contact"]))
        k = draw(st.integers(0, max(n - 1, 0)))
        if how == "reverse_times":
            s["time"] = t[::-1]
        elif how == "repeat_time" and n > 1:
            t[max(k, 1)] = t[max(k, 1) - 1]
        elif how == "swap_times" and n > 1:
            j = draw(st.integers(0, n - 1))
            t[k], t[j] = t[j], t[k]
        elif how == "scale_times":
            c = draw(st.sampled_from([0.5, 2.0, 10.0, 1e-6, 1e6]))
            s["time"] = [c * v for v in t]
        elif how == "shift_times":
            c = draw(st.sampled_from([-1.0, 5.0, 100.0, 1e6]))
            s["time"] = [c + v for v in t]
        elif how == "time_value" and n:
            t[k] = draw(st.one_of(SIMILAR, HUGE))
        elif how == "sample_position" and n:
            s["q"][k][draw(st.integers(0, 2))] = draw(st.one_of(SIMILAR, HUGE))
        elif how == "keyframe_position" and kfs:
            kf = kfs[draw(st.integers(0, len(kfs) - 1))]
            kf["base_position"][draw(st.integers(0, 2))] = draw(st.one_of(SIMILAR, HUGE))
        elif how == "foot_position" and kfs:
            kf = kfs[draw(st.integers(0, len(kfs) - 1))]
            kf["feet"][draw(st.integers(0, 3))][draw(st.integers(0, 2))] = draw(SIMILAR)
        elif how == "endpoint":
            d[draw(st.sampled_from(["start", "goal"]))][draw(st.integers(0, 2))] = draw(SIMILAR)
        elif how == "grid_origin":
            d["terrain_grid"]["origin"][draw(st.integers(0, 1))] = draw(SIMILAR)
        elif how == "grid_heights":
            grids = [[[0.0]], [[0.0, 0.0]], [[1e300, 0.0], [0.0, 0.0]], [[0.0, 0.0], [0.0, 0.0]]]
            d["terrain_grid"]["heights"] = draw(st.sampled_from(grids))
        elif how == "joint" and n:
            s["q"][k][7 + draw(st.integers(0, 11))] = draw(st.one_of(SIMILAR, HUGE))
        elif how == "truncate" and n:
            key = draw(st.sampled_from(["time", "q", "contact"]))
            s[key] = s[key][: draw(st.integers(0, n - 1))]
        elif how == "few_samples":
            m = draw(st.integers(0, 1))
            for key in ("time", "q", "contact"):
                s[key] = s[key][:m]
        elif how == "duplicate_sample" and n:
            for key in ("time", "q", "contact"):
                s[key].insert(k, copy.deepcopy(s[key][k]))
        elif how == "reverse_keyframes":
            d["keyframes"] = kfs = kfs[::-1]
        elif how == "swap_keyframes" and len(kfs) > 1:
            i, j = draw(st.permutations(range(len(kfs))))[:2]
            kfs[i], kfs[j] = kfs[j], kfs[i]
        elif how == "no_keyframes":
            d["keyframes"] = kfs = []
        elif how == "reverse_motion":  # the same times, the motion backwards
            s["q"], s["contact"] = s["q"][::-1], s["contact"][::-1]
        elif how == "drop_sample" and n > 2:
            for key in ("time", "q", "contact"):
                del s[key][k]
    return d


@pytest.mark.parametrize("command", STRUCTURE_COMMANDS)
@_settings(6)
@given(data=st.data())
def test_fuzz_plan_structure(command, data, plan_dict, tmp_path_factory, capfd):
    """Structural edits: a plan no robot could execute is refused by every command that
    reads one (``check``: not passed); on exit 0 the result is right."""
    from planner.planfile.plan import Plan

    d = tmp_path_factory.mktemp("structure")
    edited = data.draw(structure_edit(plan_dict))
    path = d / "edited.json"
    path.write_text(json.dumps(edited, allow_nan=True))
    impossible = _impossible(edited)
    if command == "feedback" and not impossible:
        return  # it re-plans from measured states, for minutes: a plausible plan takes long
    rate = data.draw(st.sampled_from([500.0, 1000.0, 50.0]))
    try:  # simulated at most 100 s (a plausible plan may hold a pose for hours)
        t = edited["samples"]["time"]
        scale = f"{min(1.0, 100.0 / (max(t) - min(t))):.6g}"
    except (TypeError, ValueError, ZeroDivisionError, OverflowError):
        scale = "1"
    original = d / "original.json"
    if command in ("compare", "trajectory"):
        original.write_text(json.dumps(plan_dict))
    if command == "trajectory":  # the edited plan as an export: rows of its own
        _save_as_trajectory(edited, d / "t.csv")
    args = {
        "check": ["check", str(path)],
        "export": ["export", str(path), "--rate", f"{rate:g}", "--out", str(d / "t.csv")],
        "replay": ["replay", str(path), "--html", str(d / "r.html"), "--geometry", "collision"],
        "plot": ["plot", str(path), "--out", str(d / "plots"), "--dpi", "30"],
        "simulate": ["simulate", str(path), "--quiet", "--out", str(d / "s.json"),
                     "--time-scale", scale],
        "feedback": ["simulate", str(path), "--feedback", "--quiet"],
        "compare": ["replay", str(original), "--compare", str(path), "--html", str(d / "r.html"),
                    "--geometry", "collision"],
        "trajectory": ["simulate", str(original), "--trajectory", str(d / "t.csv"), "--quiet",
                       "--time-scale", scale],
    }[command]  # fmt: skip
    streams = []
    rc = _judge(args, capfd, streams)
    event(f"{command}: {'impossible' if impossible else 'plausible'} plan, exit {rc}")
    if command == "check" and rc == 1 and impossible:
        kinds = ("empty_plan", "time_order", "out_of_range", "plan_structure")
        assert any(f": {k}:" in streams[0] for k in kinds), streams[0][-2000:]
    if impossible and command != "trajectory":
        assert rc == (1 if command == "check" and rc == 1 else 2), (command, rc, streams)
    if rc != 0:
        return
    if command == "export":
        _export_reproduces(Plan.load(path), d / "t.csv", rate)
    elif command == "replay":
        _replay_holds(Plan.load(path), d / "r.html")
    elif command == "plot":
        _figures_are_images(d / "plots")
    elif command == "simulate":
        assert not _impossible(json.loads((d / "s.json").read_text()))


def _save_as_trajectory(d, path) -> None:
    """A plan's samples (as many as every array has) as an export's rows at ``path``."""
    from planner.body.robot import load_robot
    from planner.planfile.export import ExportedTrajectory

    s = d["samples"]
    m = min(len(s["time"]), len(s["q"]), len(s["contact"]))
    t, q = np.array(s["time"][:m], float), np.array(s["q"][:m], float).reshape(m, 19)
    zeros = np.zeros((m, 3))
    robot = load_robot("littledog")
    ExportedTrajectory(
        rate_hz=100.0, joint_names=list(robot.joint_names), t=t, base_pos=q[:, :3],
        base_quat=q[:, 3:7], base_vel=zeros, base_omega=zeros, q=q[:, _robot_joints(robot)],
        dq=np.zeros((m, 12)), contact=np.array(s["contact"][:m], bool).reshape(m, 4),
        forces=np.zeros((m, 4, 3)), torque_ff=np.zeros((m, 12)),
    ).save(path)  # fmt: skip


# ------------------------------------------------------------------------------ output locations
NAMES = {"plan": ".json", "export": ".csv", "export_npz": ".npz", "simulate": ".json",
         "replay": ".html", "terrain": ".png", "generate-course": ".yaml"}  # fmt: skip
FOLDER_OUTPUTS = ("plot", "batch", "demo", "bench theta", "bench courses", "bench physics",
                  "bench speed", "bench robots")  # fmt: skip
# commands cheap enough to run where the location is good
RUNS = ("plan", "export", "export_npz", "simulate", "replay", "terrain", "generate-course",
        "plot")  # fmt: skip
BAD = ["proc", "sys", "proc_file", "device", "under_file", "wrong_kind", "long", "empty", "full"]
GOOD = ["new", "existing", "relative"]


def _location(kind: str, d: Path, folder: bool, suffix: str) -> str:
    a_file, a_folder = d / "a_file", d / "a_folder"
    name = "out" if folder else f"out{suffix}"
    return {
        "proc": f"/proc/stratawalk-fuzz/{name}",
        "sys": f"/sys/{name}",
        "proc_file": "/proc/self" if folder else "/proc/version",
        "device": "/dev/null",
        "under_file": str(a_file / name),
        "wrong_kind": str(a_file if folder else a_folder),
        "long": str(d / ("x" * 300 + suffix)),
        "empty": "",
        "full": str(d / "room" / name),
        "new": str(d / "new" / "deep" / name),
        "existing": str(a_folder if folder or suffix == ".yaml" else d / f"old{suffix}"),
        "relative": f"rel/{name}",
    }[kind]


@pytest.mark.parametrize("command", [*NAMES, *FOLDER_OUTPUTS])
@_settings(5)
@given(data=st.data())
def test_fuzz_output_locations(command, data, short_flat_walk, tmp_path_factory, capfd):
    """Every output option: a location that cannot take the file is refused before any
    work (exit 2, one line naming the option); a good one gets a right result."""
    plan_path = str(short_flat_walk[0])
    d = tmp_path_factory.mktemp("outputs")
    (d / "a_file").write_text("keep me")
    (d / "a_folder").mkdir()
    folder = command in FOLDER_OUTPUTS
    runs = command in RUNS
    kind = data.draw(st.sampled_from(GOOD if runs and data.draw(st.booleans()) else BAD))
    if command == "generate-course" and kind == "wrong_kind":
        kind = "existing"  # it takes a folder (and writes COURSE.yaml in it)
    suffix = NAMES.get(command, "")
    if kind == "existing" and not folder:
        (d / f"old{suffix}").write_text("old")
    out = _location(kind, d, folder, suffix)
    option = {"replay": "--html", "terrain": "--png"}.get(command, "--out")
    args = {
        "plan": ["plan", "--terrain", "flat", "--goal", "0.3,0", "--quiet"],
        "export": ["export", plan_path],
        "export_npz": ["export", plan_path],
        "simulate": ["simulate", plan_path, "--quiet"],
        "replay": ["replay", plan_path, "--geometry", "collision"],
        "terrain": ["terrain", "flat"],
        "generate-course": ["generate-course", "--seed", "3"],
        "plot": ["plot", plan_path, "--dpi", "30"],
        "batch": ["batch", str(ROOT / "examples" / "scenarios.yaml"), "--quiet"],
        "demo": ["demo"],
    }.get(command, command.split()) + [option, out]
    streams = []
    full = mock.patch("planner.core.outputs.free_bytes", lambda folder: 1000)  # a full disk
    with _working_dir(d), full if kind == "full" else contextlib.nullcontext():
        rc = _judge(args, capfd, streams)
    assert (d / "a_file").read_text() == "keep me"
    event(f"{'bad' if kind in BAD else 'good'} location, exit {rc}")
    if kind in BAD:
        assert rc == 2 and option in streams[1], (args, rc, streams[1][-500:])
        return
    assert rc == 0, (args, rc, streams[1][-500:])
    target = d / out
    if command == "plan":
        _plan_passes_check(target)
    elif command.startswith("export"):
        from planner.planfile.plan import Plan

        _export_reproduces(Plan.load(plan_path), target, 500.0)
    elif command == "simulate":
        assert not _impossible(json.loads(target.read_text()))
    elif command == "replay":
        _replay_holds(short_flat_walk[1], target)
    elif command == "plot":
        _figures_are_images(target)
    elif command == "terrain":
        _is_png(target)
    elif command == "generate-course":
        from planner.world.terrain import load_terrain

        load_terrain(next(target.glob("*.yaml")) if target.is_dir() else target)


# ------------------------------------------------------------------ demo, bench, live replay
def _not_a_terrain(word: str) -> bool:
    """``word`` names no terrain (so ``demo --terrain word`` must stop before planning)."""
    w = word.strip()
    return not (
        w.startswith(("gen:", "feat:"))
        or (ROOT / "terrains" / f"{w}.yaml").is_file()
        or (w and Path(w).is_file())
    )


BENCH_OPTIONS = ["--n", "--seed", "--terrains", "--courses", "--planners", "--workers",
                 "--modes", "--repeats", "--robots", "--time-budget", "--resume",
                 "--start-offsets"]  # fmt: skip


@_settings(15)
@given(data=st.data())
def test_fuzz_demo_and_bench(data, tmp_path_factory, capfd):
    """``demo`` on a terrain that does not exist, and ``bench`` with a bad ``--out``: one
    line and exit 2, quickly (a good run of either takes minutes)."""
    d = tmp_path_factory.mktemp("demo")
    (d / "a_file").write_text("keep me")
    if data.draw(st.booleans()):
        terrain = data.draw(WORDS.filter(_not_a_terrain))
        args = ["demo", "--terrain", terrain, "--out", str(d / "demo")]
    else:
        target = data.draw(st.sampled_from(["theta", "courses", "physics", "speed", "robots"]))
        bad = [str(d / "a_file"), "/proc/stratawalk-fuzz", str(d / "a_file" / "x"), ""]
        args = ["bench", target, "--out", data.draw(st.sampled_from(bad))]
        for option in data.draw(st.lists(st.sampled_from(BENCH_OPTIONS), max_size=3)):
            args += [option, data.draw(WORDS)]
    with _working_dir(d):
        assert _judge(args, capfd) == 2, args
    assert (d / "a_file").read_text() == "keep me"


@_settings(6, scale=min(SCALE, 3))
@given(data=st.data())
def test_fuzz_live_replay_options(data, short_flat_walk, capfd):
    """The live replay server's options: a port or host it cannot use is one line and exit
    2; on exit 0 the URL printed is the port asked for (else one from 7000 on)."""
    args = ["replay", str(short_flat_walk[0]), "--geometry", "collision", "--seconds",
            data.draw(st.sampled_from(["0", "0.2", "-1", "nan"]))]  # fmt: skip
    host = data.draw(st.sampled_from(["127.0.0.1", "localhost", "::1", "0.0.0.0", "example.org",
                                      "", "999.1.1.1"]))  # fmt: skip
    if host != "127.0.0.1" or data.draw(st.booleans()):
        args += ["--host", host]
    port = data.draw(st.one_of(st.none(), st.sampled_from([0, -5, 99999, 65536, 1]),
                               st.integers(20000, 60000)))  # fmt: skip
    if port is not None:
        args += ["--port", str(port)]
    if host in ("127.0.0.1", "localhost", "::1") and data.draw(st.booleans()):
        args.append("--allow-remote")  # loopback only: no server open to the network
    for option in data.draw(st.lists(st.sampled_from(["--speed", "--fixed-camera"]), max_size=2)):
        args += [option] + ([data.draw(st.sampled_from(["4", "0", "-1", "inf"]))]
                            if option == "--speed" else [])  # fmt: skip
    streams = []
    rc = _judge(args, capfd, streams)
    event(f"exit {rc}")
    if rc == 0:
        url = re.search(r"open http://(\S+?):(\d+)/static/", streams[0])
        assert url, streams[0]
        if port is not None:
            assert int(url.group(2)) == port, (args, streams[0])
        assert 1 <= int(url.group(2)) <= 65535
