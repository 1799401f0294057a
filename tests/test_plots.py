"""Figures of a plan and the per-sample numbers behind them."""

import numpy as np
import pytest
from PIL import Image

from planner.body.robot import LEG_NAMES as ROBOT_LEG_NAMES
from planner.body.statics import GRAVITY_W
from planner.cli.main import main
from planner.replay.plots import (
    FIGURES,
    LEG_NAMES,
    cone_margin,
    fig_gait,
    stance_segments,
)


@pytest.fixture(scope="module")
def walk(short_flat_walk):
    return short_flat_walk


def test_series_matches_the_plan(walk):
    _, plan, s = walk
    n = len(plan.samples)
    assert len(s) == n and s.forces_W.shape == (n, 4, 3) and LEG_NAMES == ROBOT_LEG_NAMES
    np.testing.assert_array_equal(s.contact, plan.samples.contact)
    assert set(np.unique(s.stratum)) <= {0, 1, 2, 3, 4} and (s.stratum > 0).any()
    for k in range(n):  # stratum i <=> leg i in the air
        up = np.flatnonzero(~s.contact[k])
        assert s.stratum[k] == (up[0] + 1 if len(up) else 0)
    # eq. 4: the forces carry the weight, and only feet on the ground carry any
    np.testing.assert_allclose(
        s.forces_W.sum(axis=1), np.tile(-s.mass_kg * np.array(GRAVITY_W), (n, 1)), atol=1e-6
    )
    assert np.all(s.forces_W[~s.contact] == 0.0)
    assert np.all(np.isnan(s.normal_force_N[~s.contact]))
    # a validated plan stands: positive margins and pushing feet all along
    assert np.all(s.margin_N > 0) and np.all(s.com_margin_m > 0)
    assert np.all(s.min_normal_force_N > 0)
    assert np.all(s.cone_margin[s.contact] > 0)


def test_cone_margin():
    n = np.array([0.0, 0.0, 1.0])
    mu = 0.5
    assert cone_margin(np.array([0.0, 0.0, 3.0]), n, mu) == pytest.approx(1.0)
    assert cone_margin(np.array([mu, 0.0, 1.0]), n, mu) == pytest.approx(0.0)  # on the cone
    assert cone_margin(np.array([1.0, 0.0, 1.0]), n, mu) < 0.0  # outside
    assert cone_margin(np.array([0.0, 0.0, -1.0]), n, mu) < -1.0  # pulling
    assert cone_margin(np.zeros((2, 4, 3)) + [0, 0, 1], n, mu).shape == (2, 4)


def test_stance_segments():
    contact = np.array([[1, 1], [1, 0], [1, 0], [1, 1], [0, 1]], dtype=bool)
    assert stance_segments(contact) == [(0, 0, 3), (1, 0, 0), (1, 3, 4)]


def test_plot_command_writes_the_figures(walk, tmp_path, capsys):
    path, plan, s = walk
    out = tmp_path / "figures"
    assert main(["plot", str(path), "--out", str(out), "--dpi", "80"]) == 0
    printed = capsys.readouterr().out
    for name in FIGURES:
        png = out / f"{name}.png"
        assert f"wrote {png}" in printed
        img = np.asarray(Image.open(png).convert("L"), dtype=float)
        assert img.shape[0] > 200 and img.shape[1] > 400
        assert img.std() > 10  # drawn on, not blank
    # the gait diagram has one bar per stance of each leg
    fig = fig_gait(plan, s)
    bars = sum(len(c.get_paths()) for c in fig.axes[1].collections)
    assert bars == len(stance_segments(s.contact))


def test_demo_ends_with_the_replay_and_the_figures(walk, tmp_path, monkeypatch, capsys):
    import planner.cli.main

    path, plan, _ = walk

    def short_plan(args):  # stands in for the 2 m walk of the demo
        # the demo hands _cmd_plan every option of `stratawalk plan` (a missing one crashed it)
        assert (args.planner, args.time_budget, args.jit, args.global_plan) == (
            "soft",
            None,  # the settings' default (120 s)
            False,
            False,
        )
        plan.save(args.out)
        return 0

    monkeypatch.setattr(planner.cli.main, "_cmd_plan", short_plan)
    assert main(["demo", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "replay.html").stat().st_size > 100_000
    assert f"replay: {tmp_path / 'replay.html'}" in out
    for name in FIGURES:
        assert (tmp_path / "figures" / f"{name}.png").is_file()
        assert str(tmp_path / "figures" / f"{name}.png") in out
