"""Property-based fuzzing of the commands (hypothesis): never a traceback, never a hang.

Generated terrain YAML files, URDF edits, plan-file edits and command lines are fed to
``terrain``, ``robot``, ``check``, ``export``, ``replay --html``, ``plot``, ``simulate``,
``plan`` and ``batch``. The property: exit status 0, 1 or 2; on 2 a single line on stderr;
no exception escapes ``main`` (a traceback); each case ends within its time limit.

``make test`` runs a seeded (derandomised) sample of about 330 cases; ``make fuzz`` sets
``STRATAWALK_FUZZ_SCALE=20`` for about 6,600, with a fresh random seed each run.
"""

import contextlib
import copy
import json
import os
import resource
import signal
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
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


def _settings(n: int):
    return settings(
        max_examples=n * SCALE,
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


def _judge(argv: list[str], capfd) -> int:
    """Run ``stratawalk argv``; assert the property; return the exit status."""
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
    _judge(args, capfd)


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
    _judge(["robot", str(path)], capfd)


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
        "export": ["export", str(path), "--rate", "200", "--out", str(d / "t.csv")],
        "replay": ["replay", str(path), "--html", str(d / "r.html"), "--geometry", "collision"],
        "plot": ["plot", str(path), "--out", str(d / "plots"), "--dpi", "30"],
        "simulate": ["simulate", str(path), "--time-scale", "1", "--quiet"],
    }[command]
    _judge(args, capfd)


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
        _judge(args, capfd)


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
