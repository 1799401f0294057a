"""The guide path (planner.motion.guide_path) and section 9 starting from it."""

import numpy as np
import pytest

from planner.body.robot import load_robot
from planner.motion.guide_path import guide_path, traversability_map
from planner.planning.global_plan import GlobalSettings, guide_tau0_xy, plan_global_walk
from planner.planning.local import LocalSettings
from planner.world.terrain import load_terrain


@pytest.fixture(scope="module")
def robot():
    return load_robot("littledog")


def _clearance_to_tall_terrain(terrain, xy, radius_m, above_m):
    """Least distance [m] from each point to sharp terrain ``above_m`` higher than the
    ground at the start (0 here), sampled on rings: an independent look at the heights."""
    out = np.full(len(xy), np.inf)
    for r in np.linspace(0.0, radius_m, 12):
        ang = np.linspace(0.0, 2 * np.pi, 48, endpoint=False)
        px = xy[:, :1] + r * np.cos(ang)
        py = xy[:, 1:] + r * np.sin(ang)
        tall = (np.asarray(terrain.height_sharp(px, py)) > above_m).any(axis=1)
        out[tall & ~np.isfinite(out)] = r
    return out


def test_a_wall_blocks_the_map_and_the_guide_goes_through_its_opening(robot):
    terrain = load_terrain("barrier15cm_opening")  # wall at x 1.2..1.25, opening y 0.1..0.5
    tmap = traversability_map(robot, terrain)
    assert 0.07 < tmap.max_step_m < 0.09 and 0.08 < tmap.half_width_m < 0.12
    assert not tmap.free(np.array([[1.22, -0.2], [1.22, 0.0], [1.22, 0.65]])).any()
    assert tmap.free(np.array([[1.22, 0.3], [0.6, 0.0], [1.8, -0.3]])).all()
    g = guide_path(robot, terrain, (0.2, 0.0), (2.2, 0.0), height_m=0.15)
    assert g.tau is not None and not g.straight, g.message
    xy = g.tau.sample(0.01)[1][:, :2]
    at_wall = xy[np.abs(xy[:, 0] - 1.225) < 0.03]
    assert len(at_wall) and np.all((at_wall[:, 1] > 0.15) & (at_wall[:, 1] < 0.45))
    # every point of the path keeps the robot's half-width from the wall (heights, not map;
    # less two cells: the map knows the wall to a cell, the path lies between cell centres)
    reach = tmap.half_width_m - 2 * tmap.resolution_m
    near = _clearance_to_tall_terrain(terrain, xy, reach, tmap.max_step_m)
    assert not np.isfinite(near).any(), xy[np.isfinite(near)][:3]
    np.testing.assert_allclose(xy[0], [0.2, 0.0], atol=1e-9)
    np.testing.assert_allclose(xy[-1], [2.2, 0.0], atol=1e-9)
    # the straight line is blocked, so section 9 starts from the guide
    pts, why = guide_tau0_xy(robot, terrain, (0.2, 0.0), (2.2, 0.0))
    assert pts is not None and "guide" in why


@pytest.mark.parametrize("name", ["flat", "trench12cm", "step10cm", "stairs_down", "gap6cm"])
def test_drops_steps_and_trenches_leave_the_straight_line(robot, name):
    """Crossing a trench or a step is the local planner's job: the map blocks only terrain
    too tall and thin to stand on, so tau0 stays the paper's straight line."""
    terrain = load_terrain(name)
    pts, why = guide_tau0_xy(robot, terrain, (0.2, 0.0), (2.2, 0.0))
    assert pts is None and "clear" in why, why


def test_tall_rocks_are_blocked_and_the_guide_winds_between_them(robot):
    terrain = load_terrain("terrains/tall_rocks.yaml")
    tmap = traversability_map(robot, terrain)
    g = guide_path(robot, terrain, (0.2, 0.0), (2.2, 0.0), height_m=0.15)
    assert g.tau is not None and not g.straight
    assert tmap.free(g.xy_W).all()  # the path's vertices; between them, the heights:
    xy = g.tau.sample(0.01)[1][:, :2]
    # the path never comes within the half-width (less two cells) of a rock above max_step
    reach = tmap.half_width_m - 2 * tmap.resolution_m
    near = _clearance_to_tall_terrain(terrain, xy, reach, tmap.max_step_m)
    assert not np.isfinite(near).any()
    line = np.column_stack([np.linspace(0.2, 2.2, 400), np.zeros(400)])
    assert not tmap.free(line).all()  # the straight line runs into a rock


def test_a_start_against_the_wall_or_a_closed_wall_says_why(robot, tmp_path):
    terrain = load_terrain("barrier15cm_opening")
    g = guide_path(robot, terrain, (1.15, -0.2), (2.2, 0.0), height_m=0.15)
    assert g.tau is None and "start" in g.message and "obstacle" in g.message
    closed = tmp_path / "closed.yaml"
    closed.write_text(
        "name: closed\nkind: barrier\nlength: 3.0\nx: 1.2\nheight: 0.15\nthickness: 0.05\n"
    )
    g = guide_path(robot, load_terrain(str(closed)), (0.2, 0.0), (2.2, 0.0), height_m=0.15)
    assert g.tau is None and "no path" in g.message
    pts, why = guide_tau0_xy(robot, load_terrain(str(closed)), (0.2, 0.0), (2.2, 0.0))
    assert pts is None and "straight line" in why


def test_global_is_one_local_plan_where_the_straight_line_is_clear():
    plan, report = plan_global_walk(
        "littledog", "flat", goal_xy=(0.5, 0.0), start_xy=(0.2, 0.0),
        global_settings=GlobalSettings(workers=1),
    )  # fmt: skip
    g = plan.stats["global"]
    assert report.ok and plan.outcome["reached_goal"]
    assert g["evaluations"] == 1 and g["generations"] == 0 and "no search" in g["stop_reason"]
    assert "clear" in g["tau0_kind"]


@pytest.mark.slow
def test_global_walks_through_the_opening_on_the_guide_path_alone():
    """The course of the sine-series test (1 m across the wall), now from the guide path:
    tau0 itself reaches, so no CMA-ES generation runs."""
    plan, report = plan_global_walk(
        "littledog", "barrier15cm_opening", goal_xy=(1.7, 0.0), start_xy=(0.7, 0.0),
        settings=LocalSettings(time_budget_s=60.0),
        global_settings=GlobalSettings(workers=1),
    )  # fmt: skip
    g = plan.stats["global"]
    assert report.ok and plan.outcome["reached_goal"], plan.outcome["message"]
    assert g["evaluations"] == 1 and "guide" in g["tau0_kind"]
    ys = np.array([k.base_position[1] for k in plan.keyframes])
    xs = np.array([k.base_position[0] for k in plan.keyframes])
    assert np.all(ys[np.abs(xs - 1.225) < 0.05] > 0.1)  # through the opening


def test_a_batch_job_can_ask_for_the_global_planner():
    """The course table's 'global' rows: one batch job runs section 9 from the guide path,
    its planning time the whole search."""
    from planner.bench.batch import DEFAULTS, run_job

    job = DEFAULTS | {
        "robot": "littledog", "terrain": "flat", "planner": "global", "start": [0.2, 0.0],
        "goal": [0.5, 0.0], "seed": 0, "time_budget_s": 60.0,
    }  # fmt: skip
    rec = run_job(job)
    assert rec["status"] == "ok", rec.get("traceback")
    assert rec["reached"] and rec["validated"] and rec["planning_time_s"] > 0
