"""Seeded random courses: rough relief, steps, trenches, stairs and stepping stones.

:func:`generate_course` draws a terrain spec of kind ``course`` (the format of
``terrains/course_rough.yaml``, built by :meth:`planner.world.terrain.Terrain.from_spec`) from
``numpy.random.default_rng(seed)``. Along x (metres, world frame):

- ``x_min`` (-0.5) to ``FLAT_START_END_M`` (0.6): flat, where the robot starts (x = 0.2);
- 0.6 to ``length_m``: features in random order, each in its own segment with flat
  margins, drawn from a shuffled deck of the five kinds (reshuffled when used up; a kind
  whose segment no longer fits is skipped, and what is left stays flat):

  ``rough`` relief of amplitude up to ``MAX_RELIEF_M`` (6 cm), ``step`` up or down by up to
  ``MAX_STEP_M`` (8 cm), ``gap`` (a trench) up to ``MAX_GAP_WIDTH_M`` (8 cm) wide and
  ``MAX_STEP_M`` deep, ``stairs`` of 2-3 steps up or down with rises up to
  ``MAX_STAIR_RISE_M`` (6 cm), ``stepping_stones`` in a pit whose floor is at most
  ``MAX_STEP_M`` below a stone's top; so no edge anywhere is higher than 8 cm;
- ``length_m`` to ``length_m + FLAT_END_M`` (0.4): flat, the goal's landing, so a walk's
  goal is (``length_m``, 0) = the course's end minus 0.4 m (:func:`course_goal_xy`).

Levels stack (a step or stairs leaves the ground higher or lower for what follows; see
:mod:`planner.world.terrain`); the sign of each level change is chosen so that the ground stays
within ``MAX_LEVEL_M`` of the start. ``difficulty`` d in [0, ``MAX_DIFFICULTY``] = [0, 1.5]
scales every size (heights, depths, widths, amplitudes, stone gaps and jitter; stone sizes
and stair runs shrink): a feature's size is easy + d * u * (maximum - easy), u ~ U(0.6, 1)
(``_SIZES``). Every course keeps friction 0.7 (rubber on wood or plastic, as the named
courses), ``x_min`` -0.5 and y in [-0.6, 0.6].

Above 1 the same law goes past the maxima above by (d - 1) u (maximum - easy): at d = 1.3
steps up to about 10 cm (0.02 + 1.3 * 0.06 m), trenches up to 10 cm wide, stair rises up to
7.2 cm on runs down to 17 cm, stones down to 7.5 cm with gaps up to 5.9 cm, inclines up to
22 degrees, barriers up to 11 cm, relief up to about 7 cm; at 1.5 steps up to 11 cm. A
flight of three whose total rise would exceed ``MAX_LEVEL_M`` has two steps (only above
d = 1: three rises of at most 6 cm stay within it), so the level bound holds at every
difficulty; the 8 cm bound on edges above holds only for d <= 1. For d <= 1 the draws are those of
the generator before d > 1 was allowed: ``gen:SEED`` and ``gen:SEED:D`` name the same
courses as in the benchmarks' results.

A generated course is named ``gen:SEED`` (difficulty 1, length 3 m) or
``gen:SEED:DIFFICULTY[:LENGTH[:KIND+KIND...]]``; :func:`write_course` writes it as YAML,
which ``stratawalk plan --terrain`` and batch jobs accept as a path.

Two more kinds, ``incline`` (a ramp up or down, up to ``MAX_INCLINE_DEG``) and
``barrier`` (a wall to step over, up to ``MAX_BARRIER_M`` high), are drawn only when asked
for (``kinds``, ``stratawalk generate-course --kinds``): the default deck stays the five
above, so that ``gen:SEED`` names the same course as in the physics benchmarks.

The feature ladder: :func:`feature_course` makes a course with one feature of
a given size (``feat:KIND:SIZE``, e.g. ``feat:step:0.1``, ``feat:gap:0.12``,
``feat:incline:18``): flat to x = 0.6 m, the feature, flat after it, the goal 0.35-0.45 m
past its last edge (:func:`course_goal_xy`). :data:`LADDER` lists the sizes of the limits
table (``stratawalk bench physics --courses ladder``): the largest step, trench, incline,
barrier, stair rise and stone gap the planner reaches.

The generated set (:func:`generated_set_names`, ``stratawalk bench physics --courses
generated-set``): seeds 0..19 at each of the difficulties 0.6, 1.0 and 1.3 (60 courses),
3 m long, drawn from all seven kinds (``gen:SEED:D:3:rough+step+...+barrier``); each
difficulty is a family (``generated d=0.6``, :func:`generated_set_family`) with a summary
line of its own. The same seed at the three difficulties draws the same numbers, so its
course mostly keeps its order of features and grows its sizes (a longer feature may no
longer fit, and the deck then moves on).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from planner.core.errors import InputError

__all__ = [
    "FEATURE_KINDS",
    "EXTRA_KINDS",
    "LADDER",
    "course_goal_xy",
    "course_name",
    "course_spec",
    "feature_course",
    "feature_course_name",
    "ladder_course_names",
    "parse_feature_name",
    "generate_course",
    "generated_course_names",
    "generated_set_family",
    "generated_set_names",
    "parse_course_name",
    "write_course",
]

FEATURE_KINDS = ("rough", "step", "gap", "stairs", "stepping_stones")  # the default deck
EXTRA_KINDS = ("incline", "barrier")  # drawn only when asked for
FRICTION = 0.7
X_MIN_M = -0.5
Y_MIN_M, Y_MAX_M = -0.6, 0.6
FLAT_START_END_M = 0.6  # the course is flat from x_min to here
FLAT_END_M = 0.4  # flat after the features
DEFAULT_LENGTH_M = 3.0
MIN_LENGTH_M = 1.0
MAX_RELIEF_M = 0.06
MAX_STEP_M = 0.08
MAX_GAP_WIDTH_M = 0.08
MAX_STAIR_RISE_M = 0.06
MAX_INCLINE_DEG = 18.0
MAX_BARRIER_M = 0.09
MAX_LEVEL_M = 0.2  # |ground level| stays below this
MAX_DIFFICULTY = 1.5  # above 1: sizes past the maxima (module docstring)
_MIN_FEATURE_M = 0.45  # the shortest feature segment (step, gap)
MAX_MISFITS = 100_000  # draws in a row that do not fit (~2 s): the kinds are too long, stop
_PREFIX = "gen"

# (easy, hardest) of each size; difficulty d picks easy + d * u * (hardest - easy), u ~ U(0.6, 1)
_SIZES = {
    # the rough kind scales its max |z| on a grid of wavelength / 10; between the nodes the
    # relief rises up to ~3 % higher: 4 % of margin keeps the true peak within MAX_RELIEF_M
    "relief_m": (0.01, MAX_RELIEF_M / 1.04),
    "step_m": (0.02, MAX_STEP_M),
    "gap_width_m": (0.02, MAX_GAP_WIDTH_M),
    "drop_m": (0.04, MAX_STEP_M),  # a trench's depth; a pit's floor below a stone's top
    "stair_rise_m": (0.02, MAX_STAIR_RISE_M),
    "stair_run_m": (0.30, 0.20),
    "stone_size_m": (0.14, 0.09),
    "stone_gap_m": (0.02, 0.05),
    "stone_jitter_m": (0.0, 0.02),
    "incline_deg": (4.0, MAX_INCLINE_DEG),
    "barrier_m": (0.02, MAX_BARRIER_M),
}


def _size(rng: np.random.Generator, key: str, difficulty: float) -> float:
    easy, hard = _SIZES[key]
    return float(easy + difficulty * rng.uniform(0.6, 1.0) * (hard - easy))


def _seed(rng: np.random.Generator) -> int:
    return int(rng.integers(0, 2**31 - 1))


def _signed(rng: np.random.Generator, level_m: float, change_m: float) -> float:
    """``change_m`` up or down at random, down (up) if up (down) would leave MAX_LEVEL_M."""
    sign = 1.0 if rng.random() < 0.5 else -1.0
    if abs(level_m + sign * change_m) > MAX_LEVEL_M:
        sign = -sign
    return sign * change_m


def _r(v: float) -> float:
    """Rounded to 0.1 mm, for a readable YAML."""
    return round(float(v), 4)


def _feature(kind: str, rng: np.random.Generator, d: float, level_m: float) -> dict[str, Any]:
    """One segment of ``kind`` (with its ``length``), drawn at difficulty ``d``.

    Level changes start 0.15 m into the segment and leave at least 0.25 m flat after them.
    """
    if kind == "rough":
        amp = _size(rng, "relief_m", d)
        wl = max(0.15, 5.0 * amp)  # rough2cm: 0.15-0.6 m; 6 cm: 0.3-1.2 m
        length = rng.uniform(0.5, 0.8)
        return {  # inset 5 cm: the taper's tails are below 3 um outside the segment
            "kind": "rough",
            "length": _r(length),
            "amplitude": _r(amp),
            "wavelength": _r(wl),
            "wavelength_max": _r(4.0 * wl),
            "seed": _seed(rng),
            "x_start": 0.05,
            "x_end": _r(length - 0.05),
            "taper": 0.15,
        }
    if kind == "step":
        return {
            "kind": "step",
            "length": _r(rng.uniform(0.45, 0.6)),
            "x": 0.15,
            "height": _r(_signed(rng, level_m, _size(rng, "step_m", d))),
        }
    if kind == "gap":
        return {
            "kind": "gap",
            "length": _r(rng.uniform(0.45, 0.6)),
            "x_start": 0.15,
            "width": _r(_size(rng, "gap_width_m", d)),
            "depth": _r(_size(rng, "drop_m", d)),
        }
    if kind == "stairs":
        count = int(rng.integers(2, 4))
        rise = _size(rng, "stair_rise_m", d)
        run = _r(_size(rng, "stair_run_m", d))
        # above d = 1 three rises may exceed MAX_LEVEL_M (3 x 8 cm at 1.5): one step fewer,
        # so that a direction keeping the level within it exists (never at d <= 1: 3 x 6 cm)
        count = min(count, int(MAX_LEVEL_M / rise + 1e-9))
        return {
            "kind": "stairs",
            "length": _r(0.15 + count * run + 0.1),
            "x_start": 0.15,
            "rise": _r(_signed(rng, level_m, count * rise) / count),
            "run": run,
            "count": count,
        }
    if kind == "stepping_stones":
        # 3-5 columns of stones; the pit is as long as they are plus one gap at each end,
        # so it is no wider than a stone gap anywhere along x (the kind centres its grid)
        count = int(rng.integers(3, 6))
        size = _r(_size(rng, "stone_size_m", d))
        gap = _r(_size(rng, "stone_gap_m", d))
        pit = _r(count * (size + gap) + gap + 0.001)
        jitter = _r(_size(rng, "stone_jitter_m", d))
        return {
            "kind": "stepping_stones",
            "length": _r(pit + 0.25),
            "x_start": 0.15,
            "x_end": _r(0.15 + pit),
            "y_start": Y_MIN_M,
            "y_end": Y_MAX_M,
            "size": size,
            "gap": gap,
            "height": 0.0,
            "height_jitter": jitter,
            "depth": _r(_size(rng, "drop_m", d) - jitter),  # pit floor to the highest top
            "seed": _seed(rng),
        }
    if kind == "incline":  # a ramp of 0.25-0.4 m, up or down
        ramp = rng.uniform(0.25, 0.4)
        grade = math.tan(math.radians(_size(rng, "incline_deg", d)))
        rise = _signed(rng, level_m, grade * ramp)
        return _incline(math.degrees(math.atan(rise / ramp)), ramp)
    if kind == "barrier":
        return _barrier(_size(rng, "barrier_m", d), length_m=rng.uniform(0.45, 0.6))
    kinds = ", ".join(FEATURE_KINDS + EXTRA_KINDS)
    raise InputError(f"feature kind: unknown '{kind}'; use one of {kinds}")


def _incline(angle_deg: float, ramp_m: float) -> dict[str, Any]:
    """A ramp of ``ramp_m`` along x at ``angle_deg`` (< 0 down) from 0.15 m, 0.3 m flat after."""
    return {
        "kind": "slope",
        "length": _r(0.15 + ramp_m + 0.3),
        "angle_deg": _r(angle_deg),
        "start": 0.15,
        "ramp_length": _r(ramp_m),
    }


def _barrier(height_m: float, thickness_m: float = 0.03, length_m: float = 0.5) -> dict:
    """A wall ``height_m`` high and ``thickness_m`` thick across the path, from 0.15 m."""
    return {
        "kind": "barrier",
        "length": _r(length_m),
        "x": 0.15,
        "height": _r(height_m),
        "thickness": _r(thickness_m),
    }


def _level_change(seg: dict[str, Any]) -> float:
    if seg["kind"] == "step":
        return seg["height"]
    if seg["kind"] == "stairs":
        return seg["rise"] * seg["count"]
    if seg["kind"] == "slope":
        return math.tan(math.radians(seg["angle_deg"])) * seg["ramp_length"]
    return 0.0


def _check_kinds(kinds) -> tuple[str, ...]:
    known = FEATURE_KINDS + EXTRA_KINDS
    out = tuple(dict.fromkeys(str(k).strip() for k in kinds))
    bad = [k for k in out if k not in known]
    if bad or not out:
        raise InputError(
            f"--kinds: unknown feature kind {bad[0] if bad else '(none)'!r}; "
            f"use some of {','.join(known)}"
        )
    return out


def _check_args(seed: Any, length_m: float, difficulty: float) -> None:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"--seed: expected an integer >= 0, got {seed!r}")
    if not (isinstance(difficulty, (int, float)) and 0.0 <= difficulty <= MAX_DIFFICULTY):
        raise InputError(f"--difficulty: must be in [0, {MAX_DIFFICULTY:g}], got {difficulty!r}")
    if not (isinstance(length_m, (int, float)) and math.isfinite(length_m)):
        raise InputError(f"--length: expected metres, got {length_m!r}")
    if length_m < MIN_LENGTH_M:
        raise InputError(f"--length: must be >= {MIN_LENGTH_M} m, got {length_m}")


def generate_course(
    seed: int,
    length_m: float = DEFAULT_LENGTH_M,
    difficulty: float = 1.0,
    kinds: tuple[str, ...] = FEATURE_KINDS,
) -> dict:
    """A random course spec (kind ``course``), the same for the same arguments.

    Parameters
    ----------
    seed
        Seed of ``numpy.random.default_rng`` (integer >= 0).
    length_m
        x where the features end and the final 0.4 m of flat ground begins (the goal of a
        walk over the course); features start at x = 0.6 m. At least 1 m.
    difficulty
        In [0, 1.5]: 0 gives the easy sizes, 1 up to the maxima, above 1 past them
        (module docstring).
    kinds
        The feature kinds of the deck: some of ``FEATURE_KINDS + EXTRA_KINDS``. Other
        than the default, the course's name gets them (``gen:SEED:D:L:KIND+KIND``).

    Returns
    -------
    dict
        A terrain spec for :meth:`planner.world.terrain.Terrain.from_spec`, named by
        :func:`course_name`.

    Raises
    ------
    InputError
        A bad argument (the message names the command-line option).

    """
    _check_args(seed, length_m, difficulty)
    kinds = _check_kinds(kinds)
    rng = np.random.default_rng(int(seed))
    d = float(difficulty)
    segments: list[dict[str, Any]] = [{"kind": "flat", "length": FLAT_START_END_M - X_MIN_M}]
    x, level, deck, placed, misfits = FLAT_START_END_M, 0.0, [], [], 0
    while x + _MIN_FEATURE_M <= length_m + 1e-9 and misfits < MAX_MISFITS:
        if not deck:
            deck = [str(k) for k in rng.permutation(kinds)]
        seg = _feature(deck.pop(0), rng, d, level)
        if x + seg["length"] > length_m + 1e-9:
            misfits += 1
            continue  # does not fit in what is left: try the next kind
        misfits = 0
        segments.append(seg)
        placed.append(seg["kind"])
        x += seg["length"]
        level += _level_change(seg)
    segments.append({"kind": "flat", "length": round(length_m - x + FLAT_END_M, 4)})
    return _course(
        course_name(seed, difficulty, length_m, kinds),
        f"Generated course (planner.world.course_gen), seed {seed}, difficulty {d:g}: flat to "
        f"x = {FLAT_START_END_M} m, then {', '.join(placed) or 'nothing'}, flat from "
        f"x = {length_m:g} m.",
        segments,
    )


def _course(name: str, description: str, segments: list[dict[str, Any]]) -> dict[str, Any]:
    """A spec of kind ``course`` with the generator's fixed fields (friction, extent)."""
    return {
        "name": name,
        "description": description,
        "friction": FRICTION,
        "x_min": X_MIN_M,
        "y_min": Y_MIN_M,
        "y_max": Y_MAX_M,
        "kind": "course",
        "segments": segments,
        "length": round(sum(s["length"] for s in segments), 6),
    }


def course_goal_xy(spec: dict) -> tuple[float, float]:
    """The goal of a walk over a generated course: (its end minus 0.4 m, 0)."""
    return (round(spec["x_min"] + spec["length"] - FLAT_END_M, 6), 0.0)


# ------------------------------------------------------------------------------ names
def course_name(
    seed: int,
    difficulty: float = 1.0,
    length_m: float = DEFAULT_LENGTH_M,
    kinds: tuple[str, ...] = FEATURE_KINDS,
) -> str:
    """``gen:SEED`` at the defaults, else ``gen:SEED:DIFFICULTY``, ``...:LENGTH``, ``...:KINDS``.

    KINDS (other than the default deck) joined by ``+``: ``gen:3:1:3:step+incline``.
    """
    if tuple(kinds) != FEATURE_KINDS:
        return f"{_PREFIX}:{seed}:{difficulty:g}:{length_m:g}:{'+'.join(kinds)}"
    if length_m != DEFAULT_LENGTH_M:
        return f"{_PREFIX}:{seed}:{difficulty:g}:{length_m:g}"
    if difficulty != 1.0:
        return f"{_PREFIX}:{seed}:{difficulty:g}"
    return f"{_PREFIX}:{seed}"


def generated_course_names(n: int, seed0: int = 0, difficulty: float = 1.0) -> list[str]:
    """Names of the generated courses of seeds ``seed0 .. seed0 + n - 1``."""
    return [course_name(s, difficulty) for s in range(seed0, seed0 + n)]


GENERATED_SET_DIFFICULTIES = (0.6, 1.0, 1.3)
GENERATED_SET_PER_DIFFICULTY = 20
GENERATED_SET_LENGTH_M = 3.0


def generated_set_names(
    per_difficulty: int = GENERATED_SET_PER_DIFFICULTY,
    difficulties: tuple[float, ...] = GENERATED_SET_DIFFICULTIES,
    kinds: tuple[str, ...] = FEATURE_KINDS + EXTRA_KINDS,
    length_m: float = GENERATED_SET_LENGTH_M,
) -> list[str]:
    """The generated set: seeds 0 .. ``per_difficulty`` - 1 at each difficulty, in that order.

    The default is 60 names ``gen:SEED:D:3:rough+step+gap+stairs+stepping_stones+incline+
    barrier``, D in 0.6, 1, 1.3 (``stratawalk bench physics --courses generated-set``); the
    same seeds at every difficulty (module docstring).

    Raises
    ------
    InputError
        A difficulty outside [0, 1.5], an unknown kind or a length below 1 m.

    """
    kinds = _check_kinds(kinds)
    for d in difficulties:
        _check_args(0, length_m, d)
    return [
        course_name(seed, float(d), float(length_m), kinds)
        for d in difficulties
        for seed in range(int(per_difficulty))
    ]


def generated_set_family(name: str) -> str:
    """The family of a generated course in the set's summaries: ``generated d=D``."""
    parsed = parse_course_name(name)
    if parsed is None:
        raise InputError(f"course '{name}': not a generated course name (gen:SEED...)")
    return f"generated d={parsed[1]:g}"


def parse_course_name(name: str) -> tuple[int, float, float, tuple[str, ...]] | None:
    """(seed, difficulty, length_m, kinds) of ``gen:SEED[:DIFFICULTY[:LENGTH[:KINDS]]]``.

    None if ``name`` is not a ``gen:`` name.

    Raises
    ------
    InputError
        A ``gen:`` name whose numbers or kinds are malformed.

    """
    parts = str(name).split(":")
    if parts[0] != _PREFIX or len(parts) < 2:
        return None
    form = "gen:SEED[:DIFFICULTY[:LENGTH[:KIND+KIND...]]]"
    if len(parts) > 5:
        raise InputError(f"course '{name}': expected {form}")
    try:
        seed = int(parts[1])
        difficulty = float(parts[2]) if len(parts) > 2 else 1.0
        length_m = float(parts[3]) if len(parts) > 3 else DEFAULT_LENGTH_M
    except ValueError:
        raise InputError(f"course '{name}': expected {form} with numbers") from None
    try:
        _check_args(seed, length_m, difficulty)
        kinds = _check_kinds(parts[4].split("+")) if len(parts) > 4 else FEATURE_KINDS
    except InputError as exc:  # name the course, not the generate-course option
        raise InputError(f"course '{name}': {exc}".replace("--", "")) from None
    return seed, difficulty, length_m, kinds


# ------------------------------------------------------------------------------ the ladder
# the sizes of the limits table: steps [m] (< 0 down), trench widths [m] (8 cm deep),
# inclines [deg] (up), barrier heights [m], stair rises [m] (3 steps of 20 cm; < 0 down),
# gaps between 8 cm stepping stones [m] (the pit 8 cm deep); issue 65's sizes (step up 11 cm,
# barrier 10 cm) added between the earlier ones, which the results tables refer to
LADDER = {
    "step": (0.06, 0.08, 0.1, 0.11, 0.12, -0.06, -0.08, -0.1, -0.12),
    "gap": (0.04, 0.08, 0.12, 0.16),
    "incline": (6.0, 12.0, 18.0, 24.0),
    "barrier": (0.03, 0.06, 0.09, 0.1, 0.12),
    "stairs": (0.04, 0.06, 0.08, -0.04, -0.06, -0.08),
    "stones": (0.03, 0.05, 0.07),
}
LADDER_UNITS = {"step": "m", "gap": "m", "incline": "deg", "barrier": "m", "stairs": "m",
                "stones": "m"}  # fmt: skip
_FEAT = "feat"


def feature_course(kind: str, size: float) -> dict:
    """A course with one feature of ``kind`` and ``size`` (:data:`LADDER`'s units).

    Flat from x_min to 0.6 m, the feature's segment, 0.4 m of flat after it; the walk's goal
    (:func:`course_goal_xy`) is the end of the feature's segment, 0.25-0.35 m past its last
    edge, so every foot has crossed it.
    """
    size = float(size)
    if kind not in LADDER:
        raise InputError(f"feature course: unknown kind '{kind}'; use one of {', '.join(LADDER)}")
    if not math.isfinite(size) or size == 0.0 or (kind not in ("step", "stairs") and size < 0):
        raise InputError(
            f"feature course '{kind}': size must be a number > 0 (< 0: down, for step and "
            f"stairs), got {size!r}"
        )
    if kind == "step":
        seg = {"kind": "step", "length": 0.5, "x": 0.15, "height": _r(size)}
    elif kind == "gap":
        seg = {"kind": "gap", "length": _r(0.45 + size), "x_start": 0.15, "width": _r(size),
               "depth": 0.08}  # fmt: skip
    elif kind == "incline":
        seg = _incline(size, 0.4)
    elif kind == "barrier":
        seg = _barrier(size)
    elif kind == "stairs":
        seg = {"kind": "stairs", "length": 1.0, "x_start": 0.15, "rise": _r(size), "run": 0.2,
               "count": 3}  # fmt: skip
    else:
        pit = _r(4 * (0.08 + size) + size + 0.001)
        seg = {"kind": "stepping_stones", "length": _r(pit + 0.45), "x_start": 0.15,
               "x_end": _r(0.15 + pit), "y_start": Y_MIN_M, "y_end": Y_MAX_M, "size": 0.08,
               "gap": _r(size), "height": 0.0, "height_jitter": 0.0, "depth": 0.08,
               "seed": 0}  # fmt: skip
    flat_start = {"kind": "flat", "length": FLAT_START_END_M - X_MIN_M}
    return _course(
        feature_course_name(kind, size),
        f"Feature ladder (planner.world.course_gen): one {kind} of size {size:g} "
        f"{LADDER_UNITS[kind]} from x = {FLAT_START_END_M + 0.15:g} m.",
        [flat_start, seg, {"kind": "flat", "length": FLAT_END_M}],
    )


def feature_course_name(kind: str, size: float) -> str:
    """``feat:KIND:SIZE``."""
    return f"{_FEAT}:{kind}:{float(size):g}"


def ladder_course_names() -> list[str]:
    """The names of the limits table's courses, :data:`LADDER` in order."""
    return [feature_course_name(k, v) for k, sizes in LADDER.items() for v in sizes]


def parse_feature_name(name: str) -> tuple[str, float] | None:
    """(KIND, SIZE) of a ``feat:KIND:SIZE`` name; None for any other name.

    Raises InputError (one line naming the course) for a malformed ``feat:`` name.
    """
    text = str(name)
    if not text.startswith(_FEAT + ":"):
        return None
    parts = text.split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        return parts[1], float(parts[2])
    except ValueError:
        raise InputError(
            f"course '{name}': expected feat:KIND:SIZE (KIND one of {', '.join(LADDER)}, "
            "SIZE a number)"
        ) from None


def course_spec(name: str) -> dict | None:
    """The spec of a ``gen:...`` or ``feat:KIND:SIZE`` name; None for any other name.

    Raises
    ------
    InputError
        A malformed ``gen:`` or ``feat:`` name.

    """
    text = str(name)
    feature = parse_feature_name(text)
    if feature is not None:
        try:
            return feature_course(*feature)
        except InputError as exc:
            raise InputError(
                f"course '{name}': expected feat:KIND:SIZE (KIND one of {', '.join(LADDER)}, "
                f"SIZE a number): {exc}"
            ) from None
    parsed = parse_course_name(text)
    if parsed is None:
        return None
    seed, difficulty, length_m, kinds = parsed
    return generate_course(seed, length_m, difficulty, kinds)


def write_course(spec_or_name: dict | str, path: str | Path) -> Path:
    """Write a generated spec (or the course of a ``gen:...`` name) as YAML; its path.

    ``path`` is a ``.yaml``/``.yml`` file, or else a folder (made if missing; the file is
    then ``gen_SEED....yaml`` in it).
    """
    spec = spec_or_name
    if isinstance(spec_or_name, str):
        spec = course_spec(spec_or_name)
        if spec is None:
            raise InputError(
                f"course '{spec_or_name}': not a generated course name (gen:SEED, feat:KIND:SIZE)"
            )
    from planner.core.outputs import check_file, check_folder, write_atomic

    out = Path(path)
    if out.is_dir() or out.suffix.lower() not in (".yaml", ".yml"):
        out = check_folder(out, "--out") / (spec["name"].replace(":", "_") + ".yaml")
    text = yaml.safe_dump(spec, sort_keys=False, width=90)
    return write_atomic(check_file(out, "--out"), lambda tmp: tmp.write_text(text, "utf-8"))
