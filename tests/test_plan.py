"""The plan file stratawalk.plan/1 (DESIGN.md section 3): build, save, load, rebuild."""

import json

import numpy as np
import pytest

from planner.body.rolling import end_keyframe
from planner.core.errors import InputError
from planner.motion.interpolate import interpolate_leaf, interpolate_swing
from planner.planfile.plan import GRID_MARGIN_M, PLAN_FORMAT, Plan
from planner.problems import Theta2, Theta3, Theta4
from planner.world.terrain import load_terrain

OUTCOME = {"reached_goal": True, "distance_to_goal": 0.0, "message": "test plan"}


@pytest.fixture(scope="module")
def walk(littledog):
    """A short walk on flat ground: place, shift the COM over legs 2-4, swing leg 1."""
    terrain = load_terrain("flat")
    a = Theta4(littledog, terrain).solve([0.3, 0.0, 0.15], [1, 0, 0], [0, 0, 1]).state
    rc = a.feet_W[[1, 2, 3]].mean(axis=0) + [0.0, 0.0, 0.15]
    b = Theta2(littledog, terrain, support=(1, 2, 3)).solve(a, rc, [1, 0, 0], [0, 0, 1]).state
    move = interpolate_leaf(littledog, terrain, a, b, 8)  # stance feet roll
    b = end_keyframe(littledog, move, (1, 2, 3))
    c = Theta3(littledog, terrain, leg=0).solve(b, b.feet_W[0] + [0.04, 0.0, 0.0]).state
    samples = move[:-1] + [b] + interpolate_swing(littledog, terrain, b, c, 8)[1:]
    times = list(0.1 * np.arange(len(samples)))
    plan = Plan.build(
        littledog, terrain, 0.7, a.base_position_W, c.base_position_W, [a, b, c], samples,
        times, OUTCOME, {"solves": 3, "time_s": np.float64(0.5), "bad": float("nan")},
    )  # fmt: skip
    return terrain, [a, b, c], samples, plan


def test_build_mirrors_the_contract(walk, littledog):
    terrain, keyframes, samples, plan = walk
    d = plan.to_dict()
    assert list(d) == [
        "format", "robot", "terrain", "terrain_grid", "friction", "start", "goal",
        "keyframes", "samples", "outcome", "stats",
    ]  # fmt: skip
    assert d["format"] == PLAN_FORMAT
    assert d["robot"]["legs"] == ["FL", "FR", "HL", "HR"]
    assert d["robot"]["joint_names"] == littledog.joint_names
    assert d["robot"]["foot_radius"] == littledog.foot_radius_m
    assert d["terrain"] == terrain.spec
    kf = d["keyframes"][1]
    assert kf["support"] == [2, 3, 4]  # 1-based legs
    assert kf["stratum"] == 0 and len(kf["joints"]) == 12 and np.shape(kf["forces"]) == (4, 3)
    assert d["keyframes"][2]["forces"] is None
    assert np.shape(d["samples"]["q"]) == (len(samples), 19)
    contact = np.array(d["samples"]["contact"])
    assert contact[:8].all() and not contact[9:-1, 0].any() and contact[-1].all()
    assert d["stats"] == {"solves": 3, "time_s": 0.5, "bad": None}  # NaN -> null
    # the grid: sharp heights, <= 5 mm, covering every foot and base position +- 0.3 m
    grid = d["terrain_grid"]
    h = np.array(grid["heights"])
    x0, y0 = grid["origin"]
    res = grid["resolution"]
    assert res <= 0.005
    pts = np.concatenate([s.feet_W for s in samples] + [s.base_position_W[None] for s in samples])
    assert x0 <= pts[:, 0].min() - GRID_MARGIN_M and y0 <= pts[:, 1].min() - GRID_MARGIN_M
    assert x0 + res * (h.shape[1] - 1) >= pts[:, 0].max() + GRID_MARGIN_M - 1e-9
    assert y0 + res * (h.shape[0] - 1) >= pts[:, 1].max() + GRID_MARGIN_M - 1e-9
    iy, ix = 7, 11
    assert h[iy, ix] == terrain.height_sharp(x0 + ix * res, y0 + iy * res)


def test_save_load_round_trip(walk, tmp_path):
    *_, plan = walk
    path = plan.save(tmp_path / "plan.json")
    assert [p.name for p in tmp_path.iterdir()] == ["plan.json"]  # temp file renamed away
    loaded = Plan.load(path)
    assert loaded.to_dict() == plan.to_dict()  # floats survive at full precision
    assert json.loads(path.read_text())["format"] == PLAN_FORMAT
    again = Plan.load(loaded.save(tmp_path / "plan.json"))
    assert again.to_dict() == plan.to_dict()


def test_states_rebuilt_from_the_file(walk, tmp_path, littledog):
    _, keyframes, samples, plan = walk
    loaded = Plan.load(plan.save(tmp_path / "plan.json"))
    for s, k in zip(keyframes, loaded.keyframe_states(), strict=True):
        np.testing.assert_array_equal(k.joints_rad, s.joints_rad)
        np.testing.assert_array_equal(k.feet_W, s.feet_W)
        np.testing.assert_allclose(k.base_rotation_W, s.base_rotation_W, atol=1e-15)
        assert k.stratum == s.stratum and k.support == s.support
    rebuilt = loaded.sample_states()
    assert len(rebuilt) == len(samples)
    for s, r in zip(samples, rebuilt, strict=True):
        assert r.stratum == s.stratum
        np.testing.assert_array_equal(r.joints_rad, s.joints_rad)
        np.testing.assert_array_equal(r.base_position_W, s.base_position_W)
        # feet from Pinocchio FK: contact points for stance feet, centre - rho e_z in the air
        np.testing.assert_allclose(r.feet_W, s.feet_W, atol=1e-9)
    # q agrees with the keyframe where a sample is one (the first, up to leg IK rounding)
    a = keyframes[0]
    q_a = littledog.q_from(a.base_position_W, a.base_quaternion_xyzw, a.joints_rad)
    np.testing.assert_allclose(loaded.samples.q[0], q_a, atol=1e-12)


def test_build_refuses_inconsistent_input(walk, littledog):
    terrain, keyframes, samples, _ = walk
    with pytest.raises(ValueError, match="times"):
        Plan.build(littledog, terrain, 0.7, [0, 0, 0], [1, 0, 0], keyframes, samples, [0.0],
                   OUTCOME)  # fmt: skip


def _write(tmp_path, text):
    path = tmp_path / "plan.json"
    path.write_text(text)
    return path


def _error(path):
    with pytest.raises(InputError) as exc:
        Plan.load(path)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(str(path))
    return msg


def test_not_json(tmp_path):
    msg = _error(_write(tmp_path, '{\n  "format": "stratawalk.plan/1",\n    oops\n}'))
    assert "not JSON (line 3, column 5)" in msg
    assert "give a file written by `stratawalk plan`" in msg


def test_missing_file(tmp_path):
    assert "no such file" in _error(tmp_path / "nope.json")


@pytest.mark.parametrize(
    "edit,expected",
    [
        (lambda d: d.update(format="stratawalk.plan/0"), 'format: expected "stratawalk.plan/1"'),
        (lambda d: d.pop("format"), 'format: expected "stratawalk.plan/1", missing'),
        (lambda d: d.pop("keyframes"), "keyframes: missing"),
        (
            lambda d: d["keyframes"][1]["joints"].pop(),
            "keyframes[1].joints: expected 12 numbers, got 11",
        ),
        (lambda d: d["samples"]["q"][3].pop(), "samples.q[3]: expected 19 numbers, got 18"),
        (
            lambda d: d["samples"]["contact"][2].__setitem__(0, 1),
            "samples.contact[2][0]: expected true or false",
        ),
        (
            lambda d: d["keyframes"][0]["feet"][2].append(0.0),
            "keyframes[0].feet[2]: expected 3 numbers, got 4",
        ),
        (lambda d: d["keyframes"][0].update(support=[0, 1, 2]), "keyframes[0].support"),
        (lambda d: d["robot"].pop("urdf"), "robot.urdf: missing"),
        (
            lambda d: d["terrain_grid"].update(resolution=0.01),
            "terrain_grid.resolution: must be at most",
        ),
        (lambda d: d["samples"]["q"][1].__setitem__(6, 2.0), "samples.q[1][3:7]: quaternion"),
        (lambda d: d["samples"]["time"].pop(), "samples.q: expected 14 rows"),
    ],
)
def test_bad_fields_are_named(walk, tmp_path, edit, expected):
    *_, plan = walk
    d = plan.to_dict()
    edit(d)
    msg = _error(_write(tmp_path, json.dumps(d)))
    assert expected in msg, msg


def test_not_an_object(tmp_path):
    assert 'expected a JSON object with "format"' in _error(_write(tmp_path, "[1, 2]"))
