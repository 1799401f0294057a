"""Mesh terrain (planner.world.mesh_terrain, kind ``mesh``): STL/OBJ/PLY rasterised to the
height field z_T(x, y) of the paper's section 4.4; overhangs refused; a plan on a mesh course
matches the same course written with the analytic ``step`` kind.

The meshes are built here with trimesh and numpy (no fixture files).
"""

import shutil
import subprocess
import sys

import numpy as np
import pytest
import yaml

trimesh = pytest.importorskip("trimesh")

from planner.cli.main import main  # noqa: E402
from planner.core.errors import TerrainError  # noqa: E402
from planner.planfile.plan import Plan  # noqa: E402
from planner.planning.local import LocalSettings  # noqa: E402
from planner.planning.walk import plan_walk  # noqa: E402
from planner.world import mesh_terrain as mt  # noqa: E402
from planner.world.terrain import Terrain, load_terrain  # noqa: E402

REGION = (-0.5, 2.5, -0.6, 0.6)  # terrains/step5cm.yaml's extent [m]
STEP_X, STEP_H = 0.8, 0.05  # terrains/step5cm.yaml's step [m]


def _box(lo, hi):
    """A closed box (12 triangles, outward normals) from corner lo to corner hi [m]."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    b = trimesh.creation.box(extents=hi - lo)
    b.apply_translation((lo + hi) / 2)
    return b


def _step_course(x=STEP_X, h=STEP_H, region=REGION):
    """A CAD-like step course: a 10 cm floor slab and a block on it from x, both closed."""
    x0, x1, y0, y1 = region
    floor = _box((x0, y0, -0.1), (x1, y1, 0.0))
    block = _box((x, y0, -0.1), (x1, y1, h))  # overlaps the slab: two solids, one top
    return trimesh.util.concatenate([floor, block])


def _ramp_z(x):
    """The ramp's analytic height [m]: flat, up 0.15 m from x = 1.0 to 2.5, flat."""
    return np.clip((np.asarray(x) - 1.0) * 0.1, 0.0, 0.15)


def _ramp_sheet():
    """An open triangulated sheet of the ramp over REGION, on an irregular vertex grid
    that holds both kinks (x = 1.0 and 2.5), so its surface is exactly :func:`_ramp_z`."""
    xs = np.unique(np.r_[np.linspace(-0.5, 2.5, 23), 1.0, 2.5, 0.123, 1.777])
    ys = np.linspace(-0.6, 0.6, 7)
    gx, gy = np.meshgrid(xs, ys)
    v = np.column_stack([gx.ravel(), gy.ravel(), _ramp_z(gx).ravel()])
    n = len(xs)
    j, i = np.meshgrid(np.arange(len(ys) - 1), np.arange(n - 1), indexing="ij")
    a = (j * n + i).ravel()
    f = np.concatenate(
        [np.column_stack([a, a + 1, a + n + 1]), np.column_stack([a, a + n + 1, a + n])]
    )
    return trimesh.Trimesh(v, f, process=False)


def _write(mesh, path):
    mesh.export(path)
    return path


def _yaml(path, spec):
    path.write_text(yaml.safe_dump(spec))
    return path


def _nodes(t):
    """Node coordinates (x (nx,), y (ny,)) of a mesh terrain's grid."""
    k = t._segments[0][1]
    ny, nx = k.heights.shape
    return k.origin[0] + k.resolution * np.arange(nx), k.origin[1] + k.resolution * np.arange(ny)


# ---------------------------------------------------------------------------- rasterising
def test_step_stl_rasterises_exactly(tmp_path):
    stl = _write(_step_course(), tmp_path / "course.stl")
    t = load_terrain(str(stl))  # a mesh path: every default (metres, z up, its bounds, 1 cm)
    assert t.kind == "mesh" and t.name == "course"
    assert t.bounds == pytest.approx(REGION, abs=1e-9)
    k = t._segments[0][1]
    assert k.resolution == mt.DEFAULT_RESOLUTION_M and k.heights.shape == (121, 301)
    gx, gy = _nodes(t)
    # exact at every node, the step's line included (it takes the upper level, as the step
    # kind's sharp height does at u = x); the B-spline passes through the nodes
    want = np.where(gx >= STEP_X - 1e-9, STEP_H, 0.0)[None, :] + 0 * gy[:, None]
    np.testing.assert_array_equal(k.heights, want)
    np.testing.assert_allclose(t.height(gx[None, :], gy[:, None]), want, atol=1e-9)
    # away from the edge the surface is flat between nodes too (exact on the flat parts)
    x = np.r_[np.linspace(-0.5, 0.7, 50), np.linspace(0.9, 2.5, 50)]
    np.testing.assert_allclose(t.height_sharp(x, 0.123), np.where(x > STEP_X, STEP_H, 0), atol=2e-5)
    # the spec carries the grid: the terrain rebuilds without the mesh (a plan file)
    stl.unlink()
    again = Terrain.from_spec(t.spec)
    np.testing.assert_array_equal(again._segments[0][1].heights, k.heights)
    assert again.bounds == t.bounds


@pytest.mark.parametrize("suffix", ["obj", "ply"])
def test_ramp_sheet_matches_the_analytic_surface(tmp_path, suffix):
    path = _write(_ramp_sheet(), tmp_path / f"ramp.{suffix}")
    t = load_terrain(path)
    gx, gy = _nodes(t)
    np.testing.assert_allclose(
        t._segments[0][1].heights, _ramp_z(gx)[None, :] + 0 * gy[:, None], atol=1e-6
    )  # nodes: to the micrometre the heights are rounded to
    x = np.linspace(-0.4, 0.9, 40)  # flat: exact between nodes too
    np.testing.assert_allclose(t.height(x, 0.05), 0.0, atol=1e-6)


def test_units_up_axis_offset_region_resolution(tmp_path):
    """A ramp in millimetres with +y up, moved by an offset, over a chosen region and step."""
    sheet = _ramp_sheet()
    v = np.asarray(sheet.vertices) * 1000.0
    mm_yup = trimesh.Trimesh(np.column_stack([v[:, 0], v[:, 2], -v[:, 1]]), sheet.faces)
    _write(mm_yup, tmp_path / "ramp_mm.stl")
    spec = {
        "kind": "mesh",
        "file": "ramp_mm.stl",
        "metres_per_unit": 0.001,
        "up": "y",
        "offset": [0.5, 0.0, 0.2],
        "region": [0.5, 2.5, -0.3, 0.3],
        "resolution": 0.02,
    }
    t = load_terrain(_yaml(tmp_path / "ramp.yaml", spec))
    k = t._segments[0][1]
    assert k.heights.shape == (31, 101) and t.bounds == pytest.approx((0.5, 2.5, -0.3, 0.3))
    gx, gy = _nodes(t)
    want = 0.2 + _ramp_z(gx - 0.5)[None, :] + 0 * gy[:, None]
    np.testing.assert_allclose(k.heights, want, atol=1e-6)
    assert t.spec["region"] == [0.5, 2.5, -0.3, 0.3] and t.spec["up"] == "y"


def test_big_scan_rasterises_quickly(tmp_path):
    """A 500k-triangle scan-like sheet at the default grid (1 cm over 3 m x 1.2 m)."""
    xs, ys = np.linspace(-0.5, 2.5, 601), np.linspace(-0.6, 0.6, 211)
    gx, gy = np.meshgrid(xs, ys)
    z = 0.02 * np.sin(3 * gx) * np.cos(4 * gy)
    n = len(xs)
    j, i = np.meshgrid(np.arange(len(ys) - 1), np.arange(n - 1), indexing="ij")
    a = (j * n + i).ravel()
    f = np.concatenate(
        [np.column_stack([a, a + 1, a + n + 1]), np.column_stack([a, a + n + 1, a + n])]
    )
    v = np.column_stack([gx.ravel(), gy.ravel(), z.ravel()])
    path = _write(trimesh.Trimesh(v, f, process=False), tmp_path / "scan.ply")
    grid = mt.mesh_heights(path, "scan")
    hx = grid.origin[0] + grid.resolution * np.arange(grid.heights.shape[1])
    hy = grid.origin[1] + grid.resolution * np.arange(grid.heights.shape[0])
    exact = 0.02 * np.sin(3 * hx)[None, :] * np.cos(4 * hy)[:, None]
    assert grid.triangles == len(f) and np.abs(grid.heights - exact).max() < 2e-5  # chords


# -------------------------------------------------------------------- height-field test
def _floor():
    x0, x1, y0, y1 = REGION
    return _box((x0, y0, -0.1), (x1, y1, 0.0))


def _sheet(z, x0=-0.5, x1=2.5, y0=-0.6, y1=0.6):
    """An open horizontal rectangle (two triangles) at height z."""
    v = [[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]])


OVERHANGS = {
    "slab": lambda: [_floor(), _box((1.0, -0.2, 0.3), (1.5, 0.2, 0.35))],
    "mushroom": lambda: [
        _floor(),
        _box((1.0, -0.05, 0.0), (1.1, 0.05, 0.3)),
        _box((0.9, -0.2, 0.3), (1.2, 0.2, 0.35)),
    ],
    "open_roof": lambda: [_sheet(0.0), _sheet(0.3, 1.0, 1.5, -0.2, 0.2)],
}


@pytest.mark.parametrize("name", sorted(OVERHANGS))
def test_overhang_is_refused_in_one_line(tmp_path, name):
    stl = _write(trimesh.util.concatenate(OVERHANGS[name]()), tmp_path / f"{name}.stl")
    with pytest.raises(TerrainError) as err:
        load_terrain(str(stl))
    msg = str(err.value)
    assert "\n" not in msg and f"{name}.stl" in msg and "not a height field" in msg
    assert "(x, y) = (" in msg and "remove it" in msg


ACCEPTED = {  # (parts, top height [m] at x = 1.2, y = 0)
    "box_on_floor": (lambda: [_floor(), _box((1.0, -0.2, 0.0), (1.5, 0.2, 0.1))], 0.1),
    "box_sunk_in_floor": (lambda: [_floor(), _box((1.0, -0.2, -0.005), (1.5, 0.2, 0.1))], 0.1),
    "box_5mm_above_floor": (lambda: [_floor(), _box((1.0, -0.2, 0.005), (1.5, 0.2, 0.1))], 0.1),
    "stacked_boxes": (
        lambda: [
            _floor(),
            _box((1, -0.2, 0), (1.5, 0.2, 0.1)),
            _box((1, -0.2, 0.1), (1.5, 0.2, 0.2)),
        ],
        0.2,
    ),
    "box_on_open_sheet": (lambda: [_sheet(0.0), _box((1.0, -0.2, 0.0), (1.5, 0.2, 0.1))], 0.1),
}


@pytest.mark.parametrize("name", sorted(ACCEPTED))
def test_closed_solids_on_a_floor_are_accepted(tmp_path, name):
    parts, top = ACCEPTED[name]
    t = load_terrain(_write(trimesh.util.concatenate(parts()), tmp_path / f"{name}.stl"))
    assert t.height_sharp(1.2, 0.0) == pytest.approx(top, abs=1e-6)
    assert t.height_sharp(0.5, 0.0) == pytest.approx(0.0, abs=1e-6)


def test_open_step_sheet_with_a_vertical_wall_is_a_step(tmp_path):
    v = [[-0.5, -0.6, 0], [0.8, -0.6, 0], [0.8, 0.6, 0], [-0.5, 0.6, 0],
         [0.8, -0.6, 0.05], [2.5, -0.6, 0.05], [2.5, 0.6, 0.05], [0.8, 0.6, 0.05]]  # fmt: skip
    f = [[0, 1, 2], [0, 2, 3], [1, 4, 7], [1, 7, 2], [4, 5, 6], [4, 6, 7]]
    t = load_terrain(_write(trimesh.Trimesh(v, f), tmp_path / "sheet.obj"))
    gx, _ = _nodes(t)
    np.testing.assert_array_equal(t._segments[0][1].heights[5], np.where(gx >= 0.8 - 1e-9, 0.05, 0))


def test_region_beyond_the_mesh_is_an_error(tmp_path):
    _write(_step_course(), tmp_path / "course.stl")
    spec = {"kind": "mesh", "file": "course.stl", "region": [-0.5, 2.7, -0.6, 0.6]}
    with pytest.raises(TerrainError) as err:
        load_terrain(_yaml(tmp_path / "wide.yaml", spec))
    msg = str(err.value)
    assert "\n" not in msg and "wide.yaml: field 'region'" in msg and "course.stl" in msg
    assert "not under the mesh" in msg and "(2.51, -0.6)" in msg


# ------------------------------------------------------------------------------ bad input
def _junk(tmp_path):
    (tmp_path / "text.stl").write_text("solid? no, just a note\n")
    (tmp_path / "empty.obj").write_bytes(b"")
    (tmp_path / "noise.ply").write_bytes(np.random.default_rng(1).bytes(400))
    (tmp_path / "noise.stl").write_bytes(np.random.default_rng(2).bytes(400))


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("missing.stl", "no such terrain file"),
        ("text.stl", "holds no triangles"),
        ("empty.obj", "holds no triangles"),
        ("noise.ply", "cannot read"),
        ("noise.stl", "holds no triangles"),
    ],
)
def test_bad_mesh_is_a_one_line_error_exit_2(tmp_path, capsys, name, expected):
    _junk(tmp_path)
    assert main(["terrain", str(tmp_path / name)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("stratawalk: error: ") and expected in err
    assert name in err and "Traceback" not in err


def test_bad_mesh_fields_are_named(tmp_path):
    _write(_step_course(), tmp_path / "course.stl")
    for extra, field in [
        ({"up": "x"}, "up"),
        ({"offset": [0, 0]}, "offset"),
        ({"region": [1, 0, -0.5, 0.5]}, "region"),
        ({"resolution": 0.001}, "resolution"),  # 3001 x 1201 nodes: over MAX_NODES
        ({"metres_per_unit": 0}, "metres_per_unit"),
        ({"colour": "red"}, "colour"),
    ]:
        with pytest.raises(TerrainError, match=f"field '{field}'"):
            Terrain.from_spec({"kind": "mesh", "file": "course.stl", **extra}, base_dir=tmp_path)
    with pytest.raises(TerrainError, match="field 'file': missing"):
        Terrain.from_spec({"kind": "mesh"})


def test_trimesh_is_imported_only_for_a_mesh():
    code = (
        "import sys; from planner.world.terrain import load_terrain; load_terrain('step5cm'); "
        "load_terrain('rough2cm'); print('trimesh' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_terrain_command_describes_and_draws_a_mesh(tmp_path, capsys):
    stl = _write(_step_course(), tmp_path / "course.stl")
    png = tmp_path / "course.png"
    assert main(["terrain", str(stl), "--png", str(png)]) == 0
    out = capsys.readouterr().out
    assert "terrain course: bounds (-0.5, 2.5, -0.6, 0.6)" in out and png.stat().st_size > 1000
    assert main(["plan", "--terrain", str(stl), "--goal", "2.2,0", "--print-config"]) == 0


# ----------------------------------------------------------- a plan on a mesh course
@pytest.fixture(scope="module")
def plans(tmp_path_factory):
    """The step course planned as a mesh (5 mm grid) and as terrains/step5cm.yaml, to
    x = 1.2 m: every foot crosses the step (at 0.8 m)."""
    folder = tmp_path_factory.mktemp("mesh_plan")
    _write(_step_course(), folder / "course.stl")
    spec = {"name": "course", "kind": "mesh", "file": "course.stl", "resolution": 0.005}
    course = _yaml(folder / "course.yaml", spec)
    out = {}
    for key, terrain in (("mesh", str(course)), ("yaml", "step5cm")):
        plan, report = plan_walk(
            "littledog", terrain, (1.2, 0.0), (0.2, 0.0), "soft", LocalSettings()
        )
        out[key] = (plan.save(folder / f"{key}.json"), plan, report)
    return folder, out


def _touch_downs(plan):
    """(leg, contact point [m]) of each touch-down after the first stance, in time order."""
    out, before = [], (1, 2, 3, 4)
    for k in plan.keyframes:
        out += [(leg, np.asarray(k.feet[leg])) for leg in range(4)
                if leg + 1 in k.support and leg + 1 not in before]  # fmt: skip
        before = k.support
    return out


def test_mesh_course_plans_to_the_goal_and_checks(plans):
    folder, out = plans
    path, plan, report = out["mesh"]
    assert report.ok, report.summary()
    assert plan.outcome["reached_goal"], plan.outcome
    feet = np.array(plan.keyframes[-1].feet)  # every foot on the step's top
    assert np.all(feet[:, 0] > STEP_X) and np.allclose(feet[:, 2], STEP_H, atol=1e-3), feet
    assert plan.terrain["kind"] == "mesh" and len(plan.terrain["heights"]) == 241
    # the plan file is self-contained: checked elsewhere, its terrain needs no mesh
    shutil.move(folder / "course.stl", folder / "moved.stl")
    again = Plan.load(path).load_terrain()
    xy = plan.samples.q[:, :2]
    np.testing.assert_array_equal(
        again.height(xy[:, 0], xy[:, 1]), plan.load_terrain().height(xy[:, 0], xy[:, 1])
    )


def test_mesh_plan_has_the_steps_of_the_yaml_course(plans):
    """Same footholds as the analytic step, within the rasterisation's reach.

    The 5 mm grid is exact at its nodes (the upper level from x = 0.800 m), but the
    bicubic B-spline through them rises between 0.795 and 0.800 m and rings by about 10 %
    of the step over two cells each side, where the step kind is a 5 mm sigmoid: the
    foothold chooser's edge clearances then differ by up to about three cells (1.5 cm) on
    the approach. On the flat ground more than 20 cm before the edge (beyond the stride
    that looks ahead to it) the terrains are the same: 5 mm. At the edge the walks may part:
    a swing that fails on one terrain (a hind leg folded at its lift-off) is recovered with
    shorter strides, and the step counts then differ (measured 28-33 mesh against 28-29
    analytic steps over starts 0.199-0.21 m), so the touch-downs are compared in order up
    to the first within 10 cm of the edge.
    """
    _, out = plans
    tm, tr = _touch_downs(out["mesh"][1]), _touch_downs(out["yaml"][1])
    n_mesh, n_ref = len(tm), len(tr)
    worst = worst_flat = 0.0
    n_near = n_flat = 0
    for (leg_m, p), (leg_r, q) in zip(tm, tr, strict=False):  # the walks in step, up to the edge
        if max(p[0], q[0]) >= STEP_X - 0.1:
            break
        assert leg_m == leg_r, (n_near, leg_m, leg_r)
        d = float(np.linalg.norm(p - q))
        worst = max(worst, d)
        n_near += 1
        if max(p[0], q[0]) < STEP_X - 0.2:
            worst_flat = max(worst_flat, d)
            n_flat += 1
    assert worst < 0.015 and worst_flat < 0.005, (worst, worst_flat)
    assert n_flat >= 4 and n_near > n_flat, (n_flat, n_near)  # both parts were compared
    print(f"mesh {n_mesh} steps, yaml {n_ref}; footholds differ by at most {1000 * worst:.1f} mm")


def test_mesh_plan_replays(plans):
    from planner.replay import build_scene

    _, out = plans
    plan = Plan.load(out["mesh"][0])
    scene = build_scene(plan)
    assert scene.commands
    g = plan.terrain_grid  # what the replay draws: the mesh's top surface
    gx = g.origin[0] + g.resolution * np.arange(g.heights.shape[1])
    far = np.abs(gx - STEP_X) > 0.02
    np.testing.assert_allclose(
        g.heights[:, far],
        np.where(gx[far] > STEP_X, STEP_H, 0)[None, :] + 0 * g.heights[:, far],
        atol=1e-6,
    )
