"""Tests of planner.world.terrain / planner.world.heightfield / planner.replay.terrain_plot (paper
4.4-4.5)."""

from __future__ import annotations

import json
import math
import re

import casadi as ca
import numpy as np
import pytest
import yaml
from PIL import Image

from planner.bench.courses import HARD_COURSES
from planner.core.errors import InputError, TerrainError
from planner.replay.terrain_plot import plot_top_view
from planner.world.terrain import (
    NP,
    Terrain,
    list_terrains,
    load_terrain,
    terrains_dir,
)

NAMED = [
    "flat",
    "slope10",
    "step5cm",
    "stairs",
    "gap6cm",
    "barrier75mm",
    "stepping_stones",
    "rough2cm",
    "rough4cm",
    "rocks",
    "logs",
    "course_rough",
    *HARD_COURSES,
    "step6cm",
]
W = 0.005  # default smoothing width

HF_HEIGHTS = 0.02 * np.sin(np.linspace(0, 3, 25))[None, :] * np.cos(np.linspace(0, 2, 20))[
    :, None
] + 0.003 * np.random.default_rng(7).standard_normal((20, 25))


def _hf_spec(**extra):
    spec = {
        "name": "hf",
        "kind": "heightfield",
        "heights": HF_HEIGHTS.tolist(),
        "origin": [0.1, -0.25],
        "resolution": 0.025,
    }
    spec.update(extra)
    return spec


def _course_all_kinds():
    """A course using every kind, including an inline height field."""
    return {
        "name": "all_kinds",
        "kind": "course",
        "segments": [
            {"kind": "flat", "length": 0.4},
            {"kind": "slope", "length": 0.5, "angle_deg": 5.0, "start": 0.1, "ramp_length": 0.3},
            {"kind": "step", "length": 0.3, "x": 0.1, "height": -0.03},
            {"kind": "stairs", "length": 0.5, "x_start": 0.1, "rise": 0.03, "run": 0.1, "count": 3},
            {"kind": "gap", "length": 0.3, "x_start": 0.1, "width": 0.05, "depth": 0.15},
            {"kind": "barrier", "length": 0.3, "x": 0.1, "height": 0.05, "thickness": 0.04},
            {
                "kind": "stepping_stones",
                "length": 0.6,
                "size": 0.08,
                "gap": 0.04,
                "seed": 3,
                "height_jitter": 0.01,
            },
            {"kind": "rough", "length": 0.6, "amplitude": 0.02, "wavelength": 0.1, "seed": 9},
            {"kind": "rocks", "length": 0.8, "count": 6, "seed": 2},
            {
                "kind": "logs",
                "length": 0.6,
                "x_start": 0.15,
                "spacing": 0.25,
                "count": 2,
                "radius": 0.04,
                "yaw_jitter_deg": 8.0,
                "seed": 1,
            },
            {
                "kind": "heightfield",
                "length": 0.7,
                "heights": HF_HEIGHTS.tolist(),
                "origin": [0.05, -0.25],
                "resolution": 0.025,
            },
        ],
    }


def _all_terrains():
    out = [(n, load_terrain(n)) for n in NAMED]
    out.append(("heightfield", Terrain.from_spec(_hf_spec())))
    out.append(("all_kinds", Terrain.from_spec(_course_all_kinds())))
    return out


ALL = _all_terrains()
IDS = [n for n, _ in ALL]


def _random_points(t: Terrain, n: int, seed: int = 0) -> np.ndarray:
    x0, x1, y0, y1 = t.bounds
    rng = np.random.default_rng(seed)
    return np.column_stack(
        [rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), rng.uniform(-0.2, 0.4, n)]
    )


def _fd_height_grad(t: Terrain, x, y, h=1e-6):
    gx = (t.height(x + h, y) - t.height(x - h, y)) / (2 * h)
    gy = (t.height(x, y + h) - t.height(x, y - h)) / (2 * h)
    return gx, gy


# ---------------------------------------------------------------------------------------
# numpy == CasADi, gradients == finite differences


@pytest.mark.parametrize(("name", "t"), ALL, ids=IDS)
def test_numpy_and_casadi_agree(name, t):
    p = _random_points(t, 60, seed=1)
    P = ca.SX.sym("p", 3)
    f_sx = ca.Function("f", [P], [t.f_T_ca(P), t.normal_ca(P)])
    Pm = ca.MX.sym("p", 3)
    f_mx = ca.Function("f", [Pm], [t.f_T_ca(Pm)])
    xs = ca.SX.sym("x")
    ys = ca.SX.sym("y")
    z_fun = ca.Function("z", [xs, ys], [t.height_ca(xs, ys)])
    f_np = t.f_T(p)
    n_np = t.normal(p)
    for i in range(p.shape[0]):
        f_c, n_c = f_sx(p[i])
        assert abs(float(f_c) - f_np[i]) <= 1e-9
        assert abs(float(f_mx(p[i])) - f_np[i]) <= 1e-9
        assert abs(float(z_fun(p[i, 0], p[i, 1])) - t.height(p[i, 0], p[i, 1])) <= 1e-9
        np.testing.assert_allclose(np.array(n_c).ravel(), n_np[i], atol=1e-9, rtol=0)
    # f_T is p_z minus the height, whatever p_z
    np.testing.assert_allclose(f_np, p[:, 2] - t.height(p[:, 0], p[:, 1]), atol=1e-15)


@pytest.mark.parametrize(("name", "t"), ALL, ids=IDS)
def test_f_T_and_normal_in_one_pass_are_the_two_calls(name, t):
    p = _random_points(t, 50, seed=4)
    f, n = t.f_T_and_normal(p)
    # the height from the gradient's pass (complex step, or the relief's exponentials):
    # the same number to rounding
    np.testing.assert_allclose(f, t.f_T(p), rtol=0, atol=1e-13)
    np.testing.assert_array_equal(n, t.normal(p))
    f1, n1 = t.f_T_and_normal(p[7])  # one point, as (3,)
    assert float(f1) == pytest.approx(t.f_T(p[7]), abs=1e-13) and n1.shape == (3,)


@pytest.mark.parametrize(("name", "t"), ALL, ids=IDS)
def test_gradients_match_finite_differences(name, t):
    p = _random_points(t, 40, seed=2)
    gx_fd, gy_fd = _fd_height_grad(t, p[:, 0], p[:, 1])
    g_fd = np.column_stack([-gx_fd, -gy_fd, np.ones(len(p))])
    np.testing.assert_allclose(t.gradient(p), g_fd, atol=1e-6, rtol=0)
    P = ca.SX.sym("p", 3)
    jac = ca.Function("j", [P], [ca.jacobian(t.f_T_ca(P), P)])
    for i in range(len(p)):
        np.testing.assert_allclose(np.array(jac(p[i])).ravel(), g_fd[i], atol=1e-6, rtol=0)


def test_gradient_known_values():
    s = load_terrain("slope10")
    g = s.gradient([1.5, 0.2, 0.0])
    np.testing.assert_allclose(g, [-math.tan(math.radians(10.0)), 0.0, 1.0], atol=1e-12)
    st = load_terrain("step5cm")
    g_edge = st.gradient([0.8, 0.0, 0.0])  # d/dx of 0.05 (1 + tanh(u / w)) / 2 at u = 0
    assert g_edge[0] == pytest.approx(-0.05 / (2 * W), rel=1e-12)


# ---------------------------------------------------------------------------------------
# normals (section 4.5)


@pytest.mark.parametrize(("name", "t"), ALL, ids=IDS)
def test_pseudo_normal_unit_and_perpendicular_to_tangents(name, t):
    p = _random_points(t, 40, seed=3)
    n = t.normal(p)
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-12)
    assert np.all(n[:, 2] > 0)
    gx, gy = _fd_height_grad(t, p[:, 0], p[:, 1])
    tx = np.column_stack([np.ones(len(p)), np.zeros(len(p)), gx])
    ty = np.column_stack([np.zeros(len(p)), np.ones(len(p)), gy])
    tx /= np.linalg.norm(tx, axis=1, keepdims=True)
    ty /= np.linalg.norm(ty, axis=1, keepdims=True)
    assert np.max(np.abs(np.sum(n * tx, axis=1))) < 1e-6
    assert np.max(np.abs(np.sum(n * ty, axis=1))) < 1e-6


def test_slope10_normal_is_10_degrees_from_z():
    t = load_terrain("slope10")
    x = np.linspace(0.6, 2.4, 25)
    p = np.column_stack([x, np.linspace(-0.5, 0.5, 25), np.zeros(25)])
    ang = np.degrees(np.arccos(t.normal(p)[:, 2]))
    np.testing.assert_allclose(ang, 10.0, atol=1e-9)
    # and it tilts back against the uphill direction +x
    assert np.all(t.normal(p)[:, 0] < 0)
    assert np.allclose(t.normal(p)[:, 1], 0.0, atol=1e-15)
    # before the ramp it is flat
    np.testing.assert_allclose(t.normal([0.0, 0.0, 0.0]), [0, 0, 1], atol=1e-15)


def test_smoothed_normal():
    flat = load_terrain("flat")
    p = _random_points(flat, 10)
    assert np.array_equal(flat.smoothed_normal(p, 0.08), np.tile([0.0, 0.0, 1.0], (10, 1)))
    slope = load_terrain("slope10")
    q = np.column_stack([np.linspace(0.8, 2.2, 7), np.zeros(7), np.full(7, 0.3)])
    np.testing.assert_allclose(slope.smoothed_normal(q, 0.1), slope.normal(q), atol=1e-12)
    # at a step edge the smoothed normal is much less tilted than the pseudo-normal
    step = load_terrain("step5cm")
    e = np.array([0.8, 0.0, 0.05])
    tilt = np.degrees(np.arccos(step.normal(e)[2]))
    tilt_s = np.degrees(np.arccos(step.smoothed_normal(e, 0.05)[2]))
    assert tilt > 70.0 and tilt_s < 40.0


# ---------------------------------------------------------------------------------------
# sharp vs smooth


def test_step_sharp_is_exact():
    t = load_terrain("step5cm")
    assert t.height_sharp(0.8 + 1e-9, 0.3) == 0.05
    assert t.height_sharp(0.8, 0.0) == 0.05
    assert t.height_sharp(0.8 - 1e-9, 0.0) == 0.0
    assert t.height(0.8, 0.0) == pytest.approx(0.025, abs=1e-15)  # smooth: half way
    x = np.linspace(-0.5, 2.5, 3001)
    d = np.abs(x - 0.8)
    err = np.abs(t.height(x, 0 * x) - t.height_sharp(x, 0 * x))
    assert np.all(err <= 0.05 * np.exp(-2 * d / W) + 1e-15)
    assert np.all(err[d > 10 * W] < 1e-9)


@pytest.mark.parametrize(
    ("name", "edges", "jumps"),
    [
        ("stairs", [0.8, 1.05, 1.3, 1.55], [0.04] * 4),
        ("gap6cm", [0.8, 0.86], [0.2, 0.2]),
        ("barrier75mm", [0.8, 0.83], [0.075, 0.075]),
    ],
)
def test_edge_kinds_smoothing_bound(name, edges, jumps):
    t = load_terrain(name)
    x = np.linspace(-0.5, 2.5, 6001)
    err = np.abs(t.height(x, 0.1 + 0 * x) - t.height_sharp(x, 0.1 + 0 * x))
    bound = sum(j * np.exp(-2 * np.abs(x - e) / W) for e, j in zip(edges, jumps, strict=True))
    assert np.all(err <= bound + 1e-15)


def test_sharp_values_of_edge_kinds():
    stairs = load_terrain("stairs")
    np.testing.assert_array_equal(
        stairs.height_sharp(np.array([0.79, 0.8, 1.1, 1.3, 1.6, 2.4]), 0.0),
        [0.0, 0.04, 0.08, 0.12, 0.16, 0.16],
    )
    gap = load_terrain("gap6cm")
    np.testing.assert_array_equal(
        gap.height_sharp(np.array([0.79, 0.8, 0.83, 0.861]), 0.0), [0.0, -0.2, -0.2, 0.0]
    )
    assert gap.height(0.83, 0.0) == pytest.approx(-0.2, abs=1e-3)  # 6 w from the walls
    bar = load_terrain("barrier75mm")
    assert bar.height_sharp(0.815, 0.0) == 0.075
    assert bar.height_sharp(0.8301, 0.0) == 0.0


def test_stepping_stones_sharp_and_smooth():
    t = load_terrain("stepping_stones")
    k = t._segments[0][1]
    cx = k.xa + 0.05
    cy = k.ya + 0.05
    X, Y = np.meshgrid(cx, cy)
    tops = t.height_sharp(X, Y)
    assert np.all(tops >= -0.015) and np.all(tops <= 0.015) and np.std(tops) > 0.003
    np.testing.assert_allclose(t.height(X, Y), tops, atol=1e-8)  # 10 w from every edge
    # pit between stones and ground outside the region
    assert t.height_sharp(k.xa[0] + 0.12, cy[0]) == -0.1
    assert t.height(k.xa[0] + 0.12, cy[0]) == pytest.approx(-0.1, abs=1e-4)
    assert t.height_sharp(0.45, 0.0) == 0.0 and t.height_sharp(2.05, 0.0) == 0.0


def test_hand_placed_stones_sharp_smooth_and_spec(tmp_path):
    """``stones``: each stone's top over its square (jittered, or its own third number),
    the pit between and around them, smooth within 1e-8 of sharp 10 w from the edges;
    the spec rebuilds the same course; overlapping, outside and grid-and-list specs are
    refused with the field named."""
    spec = {
        "name": "placed", "length": 2.5, "kind": "stepping_stones", "x_start": 0.5, "x_end": 1.5,
        "size": 0.1, "depth": 0.1, "height_jitter": 0.01, "seed": 3,
        "stones": [[0.6, 0.07], [0.6, -0.07], [0.9, 0.0, 0.02], [1.3, 0.3]],
    }  # fmt: skip
    t = Terrain.from_spec(spec)
    cx = np.array([0.6, 0.6, 0.9, 1.3])
    cy = np.array([0.07, -0.07, 0.0, 0.3])
    tops = t.height_sharp(cx, cy)
    assert tops[2] == 0.02 and np.all(np.abs(tops[[0, 1, 3]]) <= 0.01) and np.ptp(tops) > 0
    for dx, dy in ((0.049, 0.0), (-0.05, 0.049), (0.0, -0.05)):  # the squares' corners
        np.testing.assert_array_equal(t.height_sharp(cx + dx, cy + dy), tops)
    np.testing.assert_allclose(t.height(cx, cy), tops, atol=1e-8)
    for x, y in ((0.75, 0.0), (0.6, 0.2), (1.3, 0.0), (0.9, 0.051)):  # the pit
        assert t.height_sharp(x, y) == -0.1
    assert t.height(0.75, 0.0) == pytest.approx(-0.1, abs=1e-4)
    assert t.height_sharp(0.45, 0.0) == 0.0 and t.height_sharp(1.55, 0.0) == 0.0
    again = Terrain.from_spec(t.spec)
    p = _random_points(t, 300, seed=5)
    np.testing.assert_array_equal(
        again.height_sharp(p[:, 0], p[:, 1]), t.height_sharp(p[:, 0], p[:, 1])
    )
    for change, field in (
        ({"stones": [[0.6, 0.07], [0.65, 0.1]]}, "stones[1]"),
        ({"stones": [[0.52, 0.0]]}, "stones[0]"),
        ({"gap": 0.05}, "gap"),
        ({"stones": [[0.6]]}, "stones[0]"),
    ):
        with pytest.raises(TerrainError, match=re.escape(field)):
            Terrain.from_spec({**spec, **change})


def test_logs_sharp_and_smooth():
    t = load_terrain("logs")
    k = t._segments[0][1]
    for c, r in zip(k.c, k.r, strict=True):
        assert t.height_sharp(c, 0.0) == pytest.approx(r, abs=1e-15)
        assert t.height(c, 0.0) == pytest.approx(r, abs=2e-6)
    x = np.linspace(-0.5, 2.5, 4001)
    y = np.full_like(x, 0.3)
    smooth, sharp = t.height(x, y), t.height_sharp(x, y)
    assert np.all(smooth >= sharp - 1.01e-6)  # rounding only adds material (but 1 um)
    d_edge = np.min(np.abs(k._d(x, y, NP)) - k.r, axis=-1)
    far = d_edge > 8 * W
    assert np.all(smooth[far] - sharp[far] < 1e-5)


def test_smooth_kinds_have_identical_sharp_height():
    for name in ("rough2cm", "rocks", "slope10"):
        t = load_terrain(name)
        p = _random_points(t, 200, seed=4)
        err = np.abs(t.height(p[:, 0], p[:, 1]) - t.height_sharp(p[:, 0], p[:, 1]))
        if name == "slope10":  # only the kink at x = 0.5 is rounded
            far = np.abs(p[:, 0] - 0.5) > 10 * W
            assert np.all(err[far] < 1e-9)
            assert np.max(err) <= math.tan(math.radians(10)) * W * math.log(2) / 2 + 1e-12
        else:
            assert np.max(err) == 0.0


# ---------------------------------------------------------------------------------------
# named courses


def test_named_terrains_present():
    assert set(NAMED) <= set(list_terrains())
    assert terrains_dir().name == "terrains"


@pytest.mark.parametrize("name", NAMED)
def test_named_course_loads_and_round_trips(name):
    t = load_terrain(name)
    x0, x1, y0, y1 = t.bounds
    assert t.name == name and t.description
    assert x1 - x0 >= 2.5 and y0 <= -0.5 and y1 >= 0.5
    assert 0 < t.friction <= 1.5
    # flat start: the robot starts near x = 0
    x = np.linspace(x0, 0.3, 50)
    for y in (-0.5, 0.0, 0.5):
        assert np.max(np.abs(t.height(x, y + 0 * x))) < 1e-5
        assert np.max(np.abs(t.height_sharp(x, y + 0 * x))) < 1e-5
    # something happens further on (except flat)
    xx = np.linspace(0.5, x1, 400)
    assert (np.ptp(t.height_sharp(xx, 0.0 * xx + 0.05)) > 0.01) == (name != "flat")
    # round trip through the spec, also via JSON and YAML text
    spec = json.loads(json.dumps(t.spec))
    t2 = Terrain.from_spec(yaml.safe_load(yaml.safe_dump(spec)))
    assert t2.spec == t.spec and t2.bounds == t.bounds and t2.friction == t.friction
    p = _random_points(t, 100, seed=5)
    np.testing.assert_array_equal(t2.height(p[:, 0], p[:, 1]), t.height(p[:, 0], p[:, 1]))
    np.testing.assert_array_equal(
        t2.height_sharp(p[:, 0], p[:, 1]), t.height_sharp(p[:, 0], p[:, 1])
    )


def test_course_levels_stack():
    t = load_terrain("course_rough")
    assert t.bounds == (-0.5, 3.5, -0.6, 0.6)
    # after the 5 cm step (segment 3 starts at x = 1.5, step at + 0.25) the level stays up
    assert t.height_sharp(1.8, 0.0) == pytest.approx(0.05, abs=1e-12)
    assert t.height(3.3, 0.4) == pytest.approx(0.05, abs=1e-9)
    assert t.height_sharp(1.74, 0.0) == pytest.approx(0.0, abs=1e-6)


def test_rough_amplitude_and_seed():
    t = load_terrain("rough4cm")
    x = np.arange(0.8, 2.2, 0.005)
    y = np.arange(-0.6, 0.6, 0.005)
    z = t.height(x[None, :], y[:, None])
    assert 0.03 < np.max(np.abs(z)) <= 0.0401
    spec = dict(t.spec)
    spec["seed"] = 5
    z5 = Terrain.from_spec(spec).height(x[None, :], y[:, None])
    assert np.max(np.abs(z - z5)) > 0.01


def test_env_var_overrides_terrains_dir(tmp_path, monkeypatch):
    (tmp_path / "mine.yaml").write_text("kind: step\nx: 0.2\nheight: 0.1\nlength: 3\n")
    monkeypatch.setenv("STRATAWALK_TERRAINS", str(tmp_path))
    assert list_terrains() == ["mine"]
    t = load_terrain("mine")
    assert t.name == "mine" and t.height_sharp(0.3, 0.0) == 0.1


# ---------------------------------------------------------------------------------------
# body clearance (section 7.2 (b)), height grid, plot


def test_height_grid():
    t = load_terrain("step5cm")
    origin, res, h = t.height_grid(0.7, 0.9, -0.1, 0.1, 0.005)
    assert origin == [0.7, -0.1] and res == 0.005 and h.shape == (41, 41)
    gx = 0.7 + 0.005 * np.arange(41)
    np.testing.assert_array_equal(h, np.tile(t.height_sharp(gx, 0.0), (41, 1)))
    assert np.all(h[:, :20] == 0.0) and np.all(h[:, 21:] == 0.05)
    json.dumps(h.tolist())


def test_plot_top_view(tmp_path):
    out = plot_top_view(load_terrain("course_rough"), tmp_path / "sub" / "c.png", resolution=0.01)
    with Image.open(out) as img:
        assert img.size[0] > 400 and img.size[1] > 100


# ---------------------------------------------------------------------------------------
# height-field files


def _write_yaml(path, spec):
    path.write_text(yaml.safe_dump(spec))
    return path


def test_heightfield_png_round_trip(tmp_path):
    rng = np.random.default_rng(11)
    raw = rng.integers(0, 65535, size=(12, 18), dtype=np.uint16)
    raw[0, 0], raw[-1, -1] = 0, 65535
    Image.fromarray(raw).save(tmp_path / "hf.png")
    with Image.open(tmp_path / "hf.png") as img:
        assert img.mode.startswith("I;16")
    spec = {
        "kind": "heightfield",
        "file": "hf.png",
        "metres_per_unit": 1e-5,
        "offset": -0.3,
        "origin": [0.2, -0.1],
        "resolution": 0.01,
    }
    t = load_terrain(_write_yaml(tmp_path / "pngterrain.yaml", spec))
    iy, ix = np.meshgrid(np.arange(12), np.arange(18), indexing="ij")
    xn, yn = 0.2 + 0.01 * ix, -0.1 + 0.01 * iy
    expected = raw * 1e-5 - 0.3
    np.testing.assert_allclose(t.height(xn, yn), expected, atol=1e-12)
    np.testing.assert_allclose(t.height_sharp(xn, yn), expected, atol=1e-12)
    assert t.height(0.2, -0.1) == pytest.approx(-0.3, abs=1e-12)
    assert t.height(0.37, 0.01) == pytest.approx(65535e-5 - 0.3, abs=1e-12)
    assert t.bounds == pytest.approx((0.2, 0.37, -0.1, 0.01))
    assert t.spec["file"] == str((tmp_path / "hf.png").resolve())
    # rebuilt from the spec anywhere (absolute path)
    np.testing.assert_array_equal(Terrain.from_spec(t.spec).height(xn, yn), t.height(xn, yn))


def test_heightfield_formats_agree(tmp_path):
    H = HF_HEIGHTS
    np.save(tmp_path / "h.npy", H)
    np.savetxt(tmp_path / "h.csv", H, delimiter=",")
    iy, ix = np.meshgrid(np.arange(H.shape[0]), np.arange(H.shape[1]), indexing="ij")
    xyz = np.column_stack([0.1 + 0.025 * ix.ravel(), -0.25 + 0.025 * iy.ravel(), H.ravel()])
    rows = np.random.default_rng(0).permutation(len(xyz))
    with open(tmp_path / "xyz.csv", "w") as fh:
        fh.write("x,y,z\n")
        for r in rows:
            fh.write(",".join(repr(float(v)) for v in xyz[r]) + "\n")
    base = {"kind": "heightfield", "origin": [0.1, -0.25], "resolution": 0.025}
    ref = Terrain.from_spec(_hf_spec())
    p = _random_points(ref, 50, seed=6)
    for spec in (
        {**base, "file": "h.npy"},
        {**base, "file": "h.csv"},
        {"kind": "heightfield", "file": "xyz.csv"},
        {**base, "file": "xyz.csv"},
    ):
        t = Terrain.from_spec(spec, base_dir=tmp_path)
        np.testing.assert_allclose(
            t.height(p[:, 0], p[:, 1]), ref.height(p[:, 0], p[:, 1]), atol=1e-12
        )
    # outside the grid the terrain continues at the edge values, finite and smooth
    assert np.isfinite(ref.height(5.0, 5.0))
    assert ref.height(-3.0, 0.0) == pytest.approx(ref.height(0.1 - 0.05, 0.0), abs=1e-12)


# ---------------------------------------------------------------------------------------
# bad input: one-line TerrainError naming the file and the field


def _raises(fn, *fragments):
    with pytest.raises(TerrainError) as info:
        fn()
    msg = str(info.value)
    assert "\n" not in msg
    for frag in fragments:
        assert frag in msg, msg
    assert isinstance(info.value, InputError)
    return msg


def test_error_nan_and_inf_heights(tmp_path):
    H = HF_HEIGHTS.copy()
    H[3, 4] = np.nan
    np.save(tmp_path / "nan.npy", H)
    spec = {"kind": "heightfield", "file": "nan.npy", "origin": [0, 0], "resolution": 0.01}
    path = _write_yaml(tmp_path / "nanfield.yaml", spec)
    _raises(lambda: load_terrain(path), "nanfield.yaml", "field 'file'", "finite", "heights[3][4]")
    H[3, 4] = 0.0
    H[1, 2] = np.inf
    np.savetxt(tmp_path / "inf.csv", H, delimiter=",")
    path = _write_yaml(tmp_path / "inffield.yaml", {**spec, "file": "inf.csv"})
    _raises(lambda: load_terrain(path), "inffield.yaml", "field 'file'", "inf", "heights[1][2]")


def test_error_non_uniform_grid(tmp_path):
    with open(tmp_path / "bad.csv", "w") as fh:
        fh.write("x,y,z\n")
        for x in (0.0, 0.01, 0.025, 0.03):
            for y in (0.0, 0.01):
                fh.write(f"{x},{y},0.0\n")
    path = _write_yaml(tmp_path / "nonuni.yaml", {"kind": "heightfield", "file": "bad.csv"})
    _raises(lambda: load_terrain(path), "nonuni.yaml", "field 'file'", "not uniformly spaced")


def test_error_inconsistent_resolution(tmp_path):
    with open(tmp_path / "g.csv", "w") as fh:
        fh.write("x,y,z\n")
        for x in (0.0, 0.02, 0.04):
            for y in (0.0, 0.02, 0.04):
                fh.write(f"{x},{y},0.0\n")
    spec = {"kind": "heightfield", "file": "g.csv", "resolution": 0.01}
    path = _write_yaml(tmp_path / "incons.yaml", spec)
    _raises(lambda: load_terrain(path), "incons.yaml", "field 'resolution'", "inconsistent")
    with open(tmp_path / "rect.csv", "w") as fh:
        fh.write("x,y,z\n")
        for x in (0.0, 0.02, 0.04):
            for y in (0.0, 0.01, 0.02):
                fh.write(f"{x},{y},0.0\n")
    path = _write_yaml(tmp_path / "rect.yaml", {"kind": "heightfield", "file": "rect.csv"})
    _raises(lambda: load_terrain(path), "rect.yaml", "field 'file'", "square cells")


def test_error_unknown_kind(tmp_path):
    path = _write_yaml(tmp_path / "k.yaml", {"kind": "lava", "length": 3})
    _raises(lambda: load_terrain(path), "k.yaml", "field 'kind'", "'lava'", "stairs")
    spec = {"kind": "course", "segments": [{"kind": "flat", "length": 1}, {"kind": "ice"}]}
    path = _write_yaml(tmp_path / "k2.yaml", spec)
    _raises(lambda: load_terrain(path), "k2.yaml", "field 'segments[1].kind'", "'ice'")


def test_error_missing_and_wrong_fields(tmp_path):
    path = _write_yaml(tmp_path / "m.yaml", {"kind": "step", "x": 0.5, "length": 3})
    _raises(lambda: load_terrain(path), "m.yaml", "field 'height'", "missing")
    spec = {
        "kind": "course",
        "segments": [
            {"kind": "flat", "length": 1.0},
            {"kind": "flat", "length": 1.0},
            {"kind": "step", "length": 1.0, "height": "abc"},
        ],
    }
    path = _write_yaml(tmp_path / "foo.yaml", spec)
    msg = _raises(lambda: load_terrain(path))
    assert msg.endswith("foo.yaml: field 'segments[2].height': expected a number, got 'abc'")
    path = _write_yaml(
        tmp_path / "typo.yaml", {"kind": "step", "heigth": 0.1, "height": 0.1, "length": 3}
    )
    _raises(lambda: load_terrain(path), "typo.yaml", "field 'heigth'", "unknown field")
    _raises(
        lambda: Terrain.from_spec(
            {"kind": "stairs", "rise": 0.04, "run": -0.2, "count": 3, "length": 3}
        ),
        "<spec>",
        "field 'run'",
        "> 0.0",
    )
    _raises(
        lambda: Terrain.from_spec(
            {"kind": "gap", "width": 0.1, "depth": float("inf"), "length": 3}
        ),
        "field 'depth'",
        "finite",
    )
    _raises(
        lambda: Terrain.from_spec(
            {"kind": "course", "segments": [{"kind": "flat", "length": 1}], "length": 2}
        ),
        "field 'length'",
        "sum",
    )
    _raises(
        lambda: Terrain.from_spec({"kind": "heightfield", "file": "x.png", "heights": [[0]]}),
        "field 'file'",
        "exactly one",
    )


def test_error_unreadable_files(tmp_path):
    (tmp_path / "junk.npy").write_bytes(b"this is not numpy")
    spec = {"kind": "heightfield", "file": "junk.npy", "origin": [0, 0], "resolution": 0.01}
    path = _write_yaml(tmp_path / "junk.yaml", spec)
    _raises(lambda: load_terrain(path), "junk.yaml", "field 'file'", "cannot read")
    path = _write_yaml(tmp_path / "gone.yaml", {**spec, "file": "missing.npy"})
    _raises(lambda: load_terrain(path), "gone.yaml", "field 'file'", "no such file")
    (tmp_path / "bad.yaml").write_text("kind: step\n  height: [0.1\n")
    _raises(lambda: load_terrain(tmp_path / "bad.yaml"), "bad.yaml", "field '(file)'", "YAML")
    _raises(lambda: load_terrain(tmp_path / "absent.yaml"), "absent.yaml", "no such")
    Image.new("RGB", (4, 4)).save(tmp_path / "rgb.png")
    path = _write_yaml(tmp_path / "rgb.yaml", {**spec, "file": "rgb.png", "metres_per_unit": 1})
    _raises(lambda: load_terrain(path), "rgb.yaml", "field 'file'", "greyscale")


def test_error_nonexistent_name():
    msg = _raises(
        lambda: load_terrain("no_such_course"),
        "no_such_course.yaml",
        "field 'name'",
        "no terrain named 'no_such_course'",
    )
    assert "step5cm" in msg


@pytest.mark.parametrize("name", ["rough4cm", "logs", "course_rough"])
def test_ipopt_projects_points_onto_the_surface(name):
    """Exact CasADi derivatives let IPOPT solve min |p - p0|^2 s.t. f_T(p) = 0."""
    t = load_terrain(name)
    p, p0 = ca.SX.sym("p", 3), ca.SX.sym("p0", 3)
    nlp = {"x": p, "p": p0, "f": ca.sumsqr(p - p0), "g": t.f_T_ca(p)}
    opts = {"ipopt.print_level": 0, "print_time": 0, "ipopt.sb": "yes"}
    solver = ca.nlpsol("proj", "ipopt", nlp, opts)
    rng = np.random.default_rng(8)
    for _ in range(5):
        q = [rng.uniform(0.5, 2.4), rng.uniform(-0.5, 0.5), 0.12]
        x = np.array(solver(x0=q, p=q, lbg=0, ubg=0)["x"]).ravel()
        assert solver.stats()["success"]
        assert abs(t.f_T(x)) < 1e-8
        # the offset from p0 is along the surface normal (KKT)
        d = np.asarray(q) - x
        assert np.linalg.norm(np.cross(d, t.normal(x))) < 1e-6 * max(1.0, np.linalg.norm(d))


@pytest.mark.parametrize(("name", "t"), ALL, ids=IDS)
def test_heights_at_offsets_are_the_heights_of_the_moved_points(name, t):
    """height_sharp_offsets (a relief's matrix product) against height_sharp point by point."""
    p = _random_points(t, 30, seed=3)
    rng = np.random.default_rng(4)
    dx, dy = rng.uniform(-0.05, 0.05, 17), rng.uniform(-0.05, 0.05, 17)
    got = t.height_sharp_offsets(p[:, 0], p[:, 1], dx, dy)
    want = t.height_sharp(p[:, 0, None] + dx[None, :], p[:, 1, None] + dy[None, :])
    np.testing.assert_allclose(got, want, atol=1e-14, rtol=0)


@pytest.mark.parametrize(("name", "t"), ALL, ids=IDS)
def test_heights_on_a_grid_are_the_heights_at_its_nodes(name, t):
    """height_sharp_grid (a relief's separable product) against height_sharp at the nodes."""
    x0, x1, y0, y1 = t.bounds
    xs = np.linspace(x0, x1, 173)
    ys = np.linspace(y0, y1, 41)
    gx, gy = np.meshgrid(xs, ys)
    got = t.height_sharp_grid(xs, ys)
    assert got.shape == (len(ys), len(xs))
    np.testing.assert_allclose(got, t.height_sharp(gx, gy), atol=1e-14, rtol=0)


def test_the_relief_s_numpy_heights_are_its_expression_s_to_the_bit():
    """The rough kind's in-place numpy path (and its window skipped where tanh is 1 to the
    last bit) gives the numbers of the generic expression, in the tapers and between."""
    from planner.world.terrain_backends import NP

    t = load_terrain("rough2cm")
    ((_, k),) = t._segments
    rng = np.random.default_rng(9)
    for lo, hi in ((k.x_start - 0.05, k.x_start + 0.3), (0.8, 1.2), (k.x_end - 0.3, k.x_end)):
        u, y = rng.uniform(lo, hi, 500), rng.uniform(-0.5, 0.5, 500)
        want = np.asarray(k.expr(u, y, NP), dtype=float) + 0.0 * u
        assert np.array_equal(k.sharp(u, y), want)
        assert np.array_equal(k.value_np(u, y), want)


def test_the_relief_gradient_is_casadi_s_exact_one():
    """The relief's analytic numpy gradient against CasADi's algorithmic derivative."""
    t = Terrain.from_spec(
        {
            "name": "r",
            "x_min": -0.5,
            "length": 3.0,
            "kind": "rough",
            "amplitude": 0.03,
            "wavelength": 0.1,
            "x_start": 0.0,
            "x_end": 2.0,
            "seed": 7,
        }  # fmt: skip
    )
    p = _random_points(t, 50, seed=5)
    p[:5, 0] = [0.0, 0.05, 1.95, 2.0, -0.1]  # in the tapers too
    P = ca.SX.sym("p", 3)
    jac = ca.Function("j", [P], [ca.jacobian(t.f_T_ca(P), P)])
    g = t.gradient(p)
    for i in range(len(p)):
        np.testing.assert_allclose(np.array(jac(p[i])).ravel(), g[i], atol=1e-12, rtol=1e-10)
