"""NLPs compiled to C (ThetaOptions.jit): same solutions as SX, cached, graceful fallback."""

import shutil

import numpy as np
import pytest

from planner.problems import Theta3
from planner.problems.base import ThetaOptions
from planner.problems.compiled import cache_dir
from planner.world.terrain import load_terrain

pytestmark = pytest.mark.skipif(shutil.which("cc") is None, reason="needs a C compiler")


def placed_start(dog, terrain):
    from planner.problems import Theta4

    return Theta4(dog, terrain).solve([0.3, 0.0, 0.15], [1, 0, 0], [0, 0, 1]).state


def test_compiled_theta3_matches_sx_and_is_cached(littledog, tmp_path, monkeypatch):
    monkeypatch.setenv("STRATAWALK_CACHE", str(tmp_path))
    terrain = load_terrain("flat")
    start = placed_start(littledog, terrain)
    target = start.feet_W[0] + [0.04, 0.01, 0.0]
    sx = Theta3(littledog, terrain, leg=0)
    c = Theta3(littledog, terrain, leg=0, options=ThetaOptions(jit=True))
    assert sx.library is None
    assert c.library is not None and c.library.parent == cache_dir() and c.library.exists()
    assert cache_dir().is_relative_to(tmp_path)
    a, b = sx.solve(start, target), c.solve(start, target)
    assert a.feasible and b.feasible
    np.testing.assert_allclose(b.x, a.x, atol=1e-9)  # same derivatives, same iterates
    assert b.iterations == a.iterations
    again = Theta3(littledog, terrain, leg=0, options=ThetaOptions(jit=True))
    assert again.library == c.library  # the key is stable: no second compile
    assert again.build_time_s < c.build_time_s
    other = Theta3(littledog, terrain, leg=1, options=ThetaOptions(jit=True))
    assert other.library != c.library  # another problem, another library


def test_missing_compiler_falls_back_to_sx_with_a_warning(littledog, tmp_path, monkeypatch):
    monkeypatch.setenv("STRATAWALK_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "no-such-compiler")
    monkeypatch.setenv("PATH", str(tmp_path))  # neither cc nor gcc
    terrain = load_terrain("flat")
    with pytest.warns(UserWarning, match="no C compiler found"):
        prob = Theta3(littledog, terrain, leg=0, options=ThetaOptions(jit=True))
    assert prob.library is None
    start = placed_start(littledog, terrain)
    assert prob.solve(start, start.feet_W[0] + [0.03, 0.0, 0.0]).feasible
