import numpy as np
import pytest
import yaml

from planner.cli.main import main
from planner.core.errors import InputError
from planner.world.course_gen import (
    EXTRA_KINDS,
    FEATURE_KINDS,
    LADDER,
    MAX_BARRIER_M,
    MAX_GAP_WIDTH_M,
    MAX_INCLINE_DEG,
    MAX_RELIEF_M,
    MAX_STAIR_RISE_M,
    MAX_STEP_M,
    course_goal_xy,
    course_name,
    course_spec,
    feature_course,
    generate_course,
    generated_course_names,
    ladder_course_names,
    parse_course_name,
    write_course,
)
from planner.world.terrain import Terrain, load_terrain

SEEDS = range(31)
DX_M = 0.001


def _segments(spec):
    """(x0, x1, level before, segment) for every segment of a course spec, world x."""
    out, x, level = [], spec["x_min"], 0.0
    for seg in spec["segments"]:
        out.append((x, x + seg["length"], level, seg))
        x += seg["length"]
        if seg["kind"] == "step":
            level += seg["height"]
        elif seg["kind"] == "stairs":
            level += seg["rise"] * seg["count"]
    return out


@pytest.fixture(scope="module")
def courses():
    return {s: (spec := generate_course(s), Terrain.from_spec(spec)) for s in SEEDS}


def test_same_seed_same_course_different_seeds_differ():
    assert generate_course(7) == generate_course(7)
    assert generate_course(7, 2.0, 0.3) == generate_course(7, 2.0, 0.3)
    specs = [yaml.safe_dump(generate_course(s)) for s in range(10)]
    assert len(set(specs)) == 10
    assert generate_course(7, difficulty=0.2) != generate_course(7)


def test_fixed_fields_and_course_layout(courses):
    kinds = set()
    for seed, (spec, terrain) in courses.items():
        assert spec["kind"] == "course" and spec["name"] == f"gen:{seed}"
        assert (spec["friction"], spec["x_min"], spec["y_min"], spec["y_max"]) == (
            0.7,
            -0.5,
            -0.6,
            0.6,
        )
        assert terrain.bounds == pytest.approx((-0.5, 3.4, -0.6, 0.6))
        assert course_goal_xy(spec) == pytest.approx((3.0, 0.0))
        segs = spec["segments"]
        assert segs[0] == {"kind": "flat", "length": pytest.approx(1.1)}
        assert segs[-1]["kind"] == "flat" and segs[-1]["length"] >= 0.4 - 1e-9
        assert 2 <= len(segs) - 2 <= 6
        kinds |= {s["kind"] for s in segs[1:-1]}
    assert kinds == set(FEATURE_KINDS)


def test_heights_finite_start_and_end_flat_edges_bounded(courses):
    for seed, (_, terrain) in courses.items():
        x0, x1, y0, y1 = terrain.bounds
        _, _, grid = terrain.height_grid(x0, x1, y0, y1, 0.01)
        assert np.isfinite(grid).all(), seed
        gx, gy = np.meshgrid(np.linspace(x0, x1, 300), np.linspace(y0, y1, 25))
        assert np.isfinite(terrain.height(gx, gy)).all(), seed
        # the robot starts on level ground: flat from x_min to 0.6 m
        xs, ys = np.meshgrid(np.arange(x0, 0.6, 0.005), np.linspace(y0, y1, 13))
        assert np.abs(terrain.height_sharp(xs, ys)).max() < 1e-5, seed
        # the goal's landing: flat (one level) over the last 0.4 m
        xe, ye = np.meshgrid(np.arange(3.0, x1, 0.005), np.linspace(y0, y1, 13))
        ze = terrain.height_sharp(xe, ye)
        assert np.ptp(ze) < 1e-5, seed  # a rough patch's tail
        # no edge higher than 8 cm, along y = 0 and off the centre line
        x = np.arange(x0, x1, DX_M)
        for y in (0.0, 0.07, -0.23):
            z = terrain.height_sharp(x, np.full_like(x, y))
            assert np.abs(np.diff(z)).max() <= MAX_STEP_M + 1e-5, (seed, y)


def test_feature_sizes_respect_the_maxima(courses):
    for seed, (spec, terrain) in courses.items():
        for a, b, level, seg in _segments(spec):
            kind = seg["kind"]
            x = np.arange(a, b, DX_M)
            z = terrain.height_sharp(x, np.zeros_like(x))
            if kind == "rough":
                assert seg["amplitude"] <= MAX_RELIEF_M
                xs, ys = np.meshgrid(x[::3], np.linspace(-0.6, 0.6, 121))
                relief = terrain.height_sharp(xs, ys) - level
                assert np.abs(relief).max() <= MAX_RELIEF_M + 1e-5, seed
            elif kind == "step":
                assert abs(seg["height"]) <= MAX_STEP_M
                assert z[-1] - level == pytest.approx(seg["height"], abs=1e-5)
            elif kind == "gap":
                assert seg["width"] <= MAX_GAP_WIDTH_M and seg["depth"] <= MAX_STEP_M
                inside = z < level - 0.5 * seg["depth"]
                assert 0 < inside.sum() * DX_M <= MAX_GAP_WIDTH_M + 2 * DX_M, seed
            elif kind == "stairs":
                assert abs(seg["rise"]) <= MAX_STAIR_RISE_M and seg["count"] in (2, 3)
                assert z[-1] - level == pytest.approx(seg["rise"] * seg["count"], abs=1e-5)
            elif kind == "stepping_stones":
                assert seg["depth"] + seg["height_jitter"] <= MAX_STEP_M + 1e-9
                # along a row of stones, no stretch of pit floor is wider than a stone gap
                size, gap = seg["size"], seg["gap"]
                rows = int(np.floor((1.2 - gap) / (size + gap) + 1e-9))
                y_row = -0.6 + 0.5 * (1.2 - rows * size - (rows - 1) * gap) + 0.5 * size
                z = terrain.height_sharp(x, np.full_like(x, y_row))
                floor = np.isclose(z, level - seg["depth"], atol=1e-5)
                runs = np.diff(np.flatnonzero(np.diff(np.r_[0, floor.astype(int), 0])))[::2]
                assert len(runs) >= 4  # before, between and after 3-5 columns
                assert runs.max() * DX_M <= gap + 0.003 <= MAX_GAP_WIDTH_M, seed
            # the ground keeps within MAX_LEVEL_M plus a feature's depth
            assert np.abs(z).max() <= 0.2 + MAX_STEP_M + 1e-5


def test_difficulty_scales_the_sizes():
    easy = [generate_course(s, difficulty=0.0) for s in range(10)]
    for spec in easy:
        t = Terrain.from_spec(spec)
        x = np.arange(t.bounds[0], t.bounds[1], DX_M)
        z = t.height_sharp(x, np.zeros_like(x))
        assert np.abs(np.diff(z)).max() <= 0.04 + 1e-5
        for seg in spec["segments"]:
            if seg["kind"] == "rough":
                assert seg["amplitude"] == pytest.approx(0.01)
            if seg["kind"] in ("step", "gap"):
                assert abs(seg.get("height", seg.get("width"))) == pytest.approx(0.02)


def test_other_lengths_and_bad_arguments():
    spec = generate_course(3, length_m=1.5)
    t = Terrain.from_spec(spec)
    assert t.bounds[1] == pytest.approx(1.9) and course_goal_xy(spec) == pytest.approx((1.5, 0))
    assert spec["name"] == "gen:3:1:1.5"
    long = generate_course(3, length_m=8.0)
    assert len(long["segments"]) > 8  # the deck is reshuffled
    for kwargs, option in (
        ({"seed": -1}, "--seed"),
        ({"seed": 1.5}, "--seed"),
        ({"seed": 1, "difficulty": 1.6}, "--difficulty"),
        ({"seed": 1, "length_m": 0.5}, "--length"),
    ):
        with pytest.raises(InputError, match=option):
            generate_course(**kwargs)


def test_names_resolve_to_yaml_files(tmp_path):
    assert generated_course_names(3) == ["gen:0", "gen:1", "gen:2"]
    assert course_name(4, 0.5) == "gen:4:0.5"
    assert parse_course_name("gen:4") == (4, 1.0, 3.0, FEATURE_KINDS)
    assert parse_course_name("gen:4:0.5:2") == (4, 0.5, 2.0, FEATURE_KINDS)
    assert parse_course_name("gen:4:1:3:step+barrier") == (4, 1.0, 3.0, ("step", "barrier"))
    with pytest.raises(InputError, match="gen:4:1:3:step\\+wall.*unknown feature kind 'wall'"):
        parse_course_name("gen:4:1:3:step+wall")
    assert parse_course_name("flat") is None
    with pytest.raises(InputError, match="gen:SEED"):
        parse_course_name("gen:x")
    path = write_course("gen:4:0.5", tmp_path)
    assert path.name == "gen_4_0.5.yaml"
    terrain = load_terrain(path)
    assert terrain.name == "gen:4:0.5"
    assert terrain.spec == Terrain.from_spec(generate_course(4, difficulty=0.5)).spec
    # a folder that does not exist yet is made, one file per course (not one file for all)
    folder = tmp_path / "new" / "courses"
    paths = {write_course(f"gen:{seed}", folder) for seed in range(3)}
    assert sorted(p.name for p in paths) == ["gen_0.yaml", "gen_1.yaml", "gen_2.yaml"]
    assert len({load_terrain(p).spec["name"] for p in paths}) == 3


def test_cli_writes_a_yaml_the_terrain_command_accepts(tmp_path, capsys):
    out = tmp_path / "course.yaml"
    assert main(["generate-course", "--seed", "5", "--difficulty", "0.7", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "wrote" in text and "walk to (3.0, 0.0)" in text
    assert yaml.safe_load(out.read_text()) == generate_course(5, difficulty=0.7)
    assert main(["terrain", str(out)]) == 0
    assert "terrain gen:5:0.7: bounds (-0.5, 3.4" in capsys.readouterr().out
    assert main(["generate-course", "--seed", "5", "--difficulty", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--difficulty" in err


def test_a_generated_name_is_a_terrain_name(capsys):
    """``--terrain gen:SEED[:D[:L]]`` draws the course anew (plans store the name)."""
    terrain = load_terrain("gen:4:0.5")
    assert terrain.name == "gen:4:0.5"
    assert terrain.spec == Terrain.from_spec(generate_course(4, difficulty=0.5)).spec
    xy = np.array([[0.3, 0.0], [1.2, 0.1], [2.5, -0.2]])
    want = Terrain.from_spec(generate_course(4, difficulty=0.5)).height(xy[:, 0], xy[:, 1])
    np.testing.assert_array_equal(terrain.height(xy[:, 0], xy[:, 1]), want)
    with pytest.raises(InputError, match="gen:SEED"):
        load_terrain("gen:4:hard")
    assert main(["terrain", "gen:4:0.5"]) == 0
    assert "terrain gen:4:0.5" in capsys.readouterr().out
    assert main(["terrain", "gen:-1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "course 'gen:-1': seed" in err


def test_plan_walks_to_a_generated_course_end_by_default(tmp_path, capsys):
    out = tmp_path / "plan.json"
    code = main(["plan", "--terrain", "gen:4:0.5:1", "--time-budget", "1", "--quiet",
                 "--out", str(out)])  # fmt: skip
    text = capsys.readouterr().out
    assert code in (0, 1) and "goal: 1,0 (the end of gen:4:0.5:1" in text
    assert main(["plan", "--terrain", "flat", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--goal: required" in err


def test_issue_15_kinds_are_drawn_when_asked_for_within_their_maxima():
    """Inclines and barriers only with ``kinds``; their sizes, measured on the sharp terrain,
    stay within MAX_INCLINE_DEG and MAX_BARRIER_M; the default deck never draws them."""
    seen = set()
    for seed in range(12):
        spec = generate_course(seed, kinds=("step",) + EXTRA_KINDS)
        assert spec["name"] == f"gen:{seed}:1:3:step+incline+barrier"
        terrain = load_terrain(spec["name"])
        assert terrain.spec == Terrain.from_spec(spec).spec
        for a, b, _, seg in _segments(spec)[1:-1]:
            seen.add(seg["kind"])
            assert seg["kind"] in ("step", "slope", "barrier")
            x = np.arange(a, b, DX_M)
            z = terrain.height_sharp(x, np.zeros_like(x))
            if seg["kind"] == "slope":
                grade = np.abs(np.diff(z)).max() / DX_M
                assert 0.0 < np.degrees(np.arctan(grade)) <= MAX_INCLINE_DEG + 0.01, seed
            elif seg["kind"] == "barrier":
                assert 0.0 < z.max() - z[0] <= MAX_BARRIER_M + 1e-9
                assert z[-1] == pytest.approx(z[0], abs=1e-9)  # a barrier changes no level
    assert seen == {"step", "slope", "barrier"}
    for seed in range(12):
        assert not {s["kind"] for s in generate_course(seed)["segments"]} & {"slope", "barrier"}
    with pytest.raises(InputError, match="--kinds: unknown feature kind 'wall'"):
        generate_course(1, kinds=("wall",))


def test_the_feature_ladder_measures_what_its_names_say():
    """feat:KIND:SIZE has one feature of that size, measured on the sharp terrain along
    y = 0, and a flat start and end; the goal lies past the feature on level ground."""
    names = ladder_course_names()
    assert len(names) == sum(len(v) for v in LADDER.values()) and "feat:step:-0.1" in names
    for name in names:
        _, kind, size = name.split(":")
        size = float(size)
        terrain = load_terrain(name)
        spec = terrain.spec
        assert course_spec(name) == feature_course(kind, size)
        assert spec == Terrain.from_spec(feature_course(kind, size)).spec
        gx, _ = course_goal_xy(spec)
        x = np.arange(-0.5, gx + 0.3, DX_M)
        z = terrain.height_sharp(x, np.zeros_like(x))
        assert np.abs(z[x < 0.74]).max() < 1e-9, name  # flat start
        end = z[(x > gx - 0.15) & (x < gx + 0.3)]
        assert np.ptp(end) < 1e-9, name  # level around the goal
        jumps = np.diff(z)
        if kind == "step":
            assert z[-1] == pytest.approx(size) and np.abs(jumps).max() == pytest.approx(abs(size))
        elif kind == "stairs":
            assert z[-1] == pytest.approx(3 * size)
            assert np.sort(np.abs(jumps))[-3:] == pytest.approx([abs(size)] * 3)
        elif kind == "gap":
            assert (z < -0.04).sum() * DX_M == pytest.approx(size, abs=2 * DX_M)
        elif kind == "incline":
            grade = np.diff(z).max() / DX_M
            assert np.degrees(np.arctan(grade)) == pytest.approx(size, abs=0.05)
        elif kind == "barrier":
            assert z.max() == pytest.approx(size) and z[-1] == 0.0
        else:  # stones: 8 cm stones, pit floor 8 cm down between them, gaps of ``size``
            rows = int(np.floor((1.2 - size) / (0.08 + size) + 1e-9))
            y_row = -0.6 + 0.5 * (1.2 - rows * 0.08 - (rows - 1) * size) + 0.04
            z = terrain.height_sharp(x, np.full_like(x, y_row))
            floor = np.isclose(z, -0.08)
            runs = np.diff(np.flatnonzero(np.diff(np.r_[0, floor.astype(int), 0])))[::2]
            assert len(runs) == 5 and runs.max() * DX_M == pytest.approx(size, abs=3 * DX_M)
    for bad in ("feat:gap", "feat:wall:0.1", "feat:gap:-0.1", "feat:gap:x"):
        with pytest.raises(InputError, match=f"course '{bad}': expected feat:KIND:SIZE"):
            load_terrain(bad)
