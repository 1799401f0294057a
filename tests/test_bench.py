"""The Theta benchmark (planner.bench.theta): a tiny run, well-formed output, fair comparison."""

import json

import numpy as np
import pytest

from planner.bench import theta as bench
from planner.problems.base import FEASIBILITY_TOL
from planner.world.terrain import load_terrain


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    result = bench.run_theta_bench(
        n_per_theta=3, terrains=("flat",), seed=0, out_dir=out, progress=False
    )
    return out, result


def test_output_files_are_well_formed(tiny_run):
    out, result = tiny_run
    data = json.loads((out / "theta.json").read_text())
    assert data["format"] == "stratawalk.bench.theta/1"
    assert {"nproc", "python", "casadi", "scipy", "date"} <= set(data["machine"])
    rows = {(r["theta"], r["terrain"], r["solver"]) for r in data["groups"]}
    assert rows == {(t, "flat", s) for t in bench.THETAS for s in ("ipopt", "slsqp")}
    for r in data["groups"] + data["summary"]:
        assert r["instances"] == 3
        assert 0.0 <= r["success_rate"] <= 1.0
        assert r["time_ms_p95"] >= r["time_ms_median"] > 0.0
        assert r["speed_ratio"] > 0.0
    assert len(data["instances"]) == 4 * 2  # one column group per (Theta, terrain, solver)
    for g in data["instances"]:
        assert len(g["index"]) == len(g["time_ms"]) == len(g["feasible"]) == 3
        assert all(0 <= k < len(g["statuses"]) for k in g["status"])
    assert data["build_times_s"] and all(b["build_time_s"] > 0 for b in data["build_times_s"])
    md = (out / "theta.md").read_text()
    assert "| Theta | terrain | solver |" in md
    for theta in bench.THETAS:
        assert f"| {theta} | flat | ipopt | 3 |" in md
        assert f"| {theta} | all | slsqp | 3 |" in md


def test_reported_feasible_means_independent_check_passes(tiny_run):
    out, _ = tiny_run
    data = json.loads((out / "theta.json").read_text())
    n_ipopt_feasible = 0
    for g in data["instances"]:
        for ok, viol in zip(g["feasible"], g["max_violation"], strict=True):
            if ok:
                assert viol <= FEASIBILITY_TOL, g
                n_ipopt_feasible += g["solver"] == "ipopt"
    assert n_ipopt_feasible > 0
    for r in data["summary"]:
        assert r["max_violation_of_feasible"] <= FEASIBILITY_TOL


def test_slsqp_subset(tmp_path):
    result = bench.run_theta_bench(
        n_per_theta=3,
        terrains=("flat",),
        out_dir=tmp_path,
        slsqp_n=2,
        thetas=("Theta3",),
        progress=False,
    )
    ip, sl = result["groups"]
    assert (ip["solver"], ip["instances"], sl["solver"], sl["instances"]) == (
        "ipopt",
        3,
        "slsqp",
        2,
    )
    assert "seeded subset of 2" in (tmp_path / "theta.md").read_text()


class _Spy:
    """Wraps a CasADi nlpsol to record what it is called with."""

    def __init__(self, solver):
        self.solver, self.calls = solver, []

    def __call__(self, **kw):
        self.calls.append({k: np.array(v, dtype=float).ravel() for k, v in kw.items()})
        return self.solver(**kw)

    def stats(self):
        return self.solver.stats()


@pytest.mark.parametrize("theta", ["Theta2", "Theta3"])
def test_slsqp_and_ipopt_get_the_same_problem(littledog, monkeypatch, theta):
    import scipy.optimize

    terrain = load_terrain("flat")
    inst = bench.make_instances(littledog, terrain, theta, 1, seed=5)[0]
    problem = inst.problem
    spy = _Spy(problem.solver)
    monkeypatch.setattr(problem, "solver", spy)
    seen = {}
    real_minimize = scipy.optimize.minimize

    def minimize_spy(fun, x0, **kw):
        seen["x0"] = np.array(x0, dtype=float)
        seen["f0"] = fun(np.array(x0, dtype=float))
        seen["constraints"] = kw["constraints"]
        seen["p"] = fun.__self__.p  # the _NumericNLP's parameters
        return real_minimize(fun, x0, **kw)

    monkeypatch.setattr(scipy.optimize, "minimize", minimize_spy)
    rec_ip = bench.solve_ipopt(problem, inst.p, inst.x0, inst.context)
    rec_sl = bench.solve_slsqp(problem, inst.p, inst.x0, inst.context)
    call = spy.calls[-1]
    np.testing.assert_array_equal(call["x0"], seen["x0"])  # same start point
    # same parameters: the caller's, with the clearance points and link witnesses both
    # picked at x0
    np.testing.assert_array_equal(call["p"], seen["p"])
    keep = np.ones(len(inst.p), bool)
    for name, sl in problem._p_slices.items():  # picked by the rounds
        if name == "clearance_points_B" or name.endswith("_witnesses"):
            keep[sl] = False
    np.testing.assert_array_equal(call["p"][keep], inst.p[keep])
    np.testing.assert_array_equal(call["lbx"], problem.lbx)
    # the objective SLSQP evaluates at x0 is IPOPT's objective at x0 with the same p
    assert seen["f0"] == pytest.approx(problem.objective_at(call["x0"], call["p"]), abs=1e-12)
    # the SLSQP constraints are IPOPT's g rows: equalities at lbg == ubg, the rest one-sided
    g0 = np.array(problem._g_fun(call["x0"], call["p"])).ravel()
    eq = problem.lbg == problem.ubg
    cons = {c["type"]: c["fun"](seen["x0"]) for c in seen["constraints"]}
    np.testing.assert_allclose(cons["eq"], g0[eq] - problem.lbg[eq])
    assert (
        cons["ineq"].size
        == np.isfinite(problem.lbg[~eq]).sum() + np.isfinite(problem.ubg[~eq]).sum()
    )
    # both find a feasible point of this easy flat-ground instance, with the same optimum
    assert rec_ip.feasible and rec_sl.feasible
    assert rec_ip.max_violation <= FEASIBILITY_TOL and rec_sl.max_violation <= FEASIBILITY_TOL
    assert rec_sl.objective == pytest.approx(rec_ip.objective, abs=1e-5)


def test_instances_are_reproducible_and_reuse_problems(littledog):
    terrain = load_terrain("flat")
    cache = bench.ProblemCache()
    a = bench.make_instances(littledog, terrain, "Theta2", 4, seed=1, cache=cache)
    b = bench.make_instances(littledog, terrain, "Theta2", 4, seed=1, cache=cache)
    for ia, ib in zip(a, b, strict=True):
        np.testing.assert_array_equal(ia.p, ib.p)
        np.testing.assert_array_equal(ia.x0, ib.x0)
        assert ia.problem is ib.problem  # built once per support pattern
    problem, p, x0 = a[0]
    assert problem.x_block(x0, "theta").shape == (12,) and p.shape == problem._p_sym.shape[:1]


def test_compiled_solver_rows(tmp_path, monkeypatch):
    monkeypatch.setenv("STRATAWALK_CACHE", str(tmp_path / "cache"))
    result = bench.run_theta_bench(
        n_per_theta=2,
        terrains=("flat",),
        out_dir=tmp_path,
        thetas=("Theta3",),
        progress=False,
        jit=True,
    )
    rows = {r["solver"]: r for r in result["groups"]}
    assert set(rows) == {"ipopt", "ipopt+C", "slsqp"}
    assert rows["ipopt+C"]["instances"] == 2 and rows["ipopt+C"]["speed_ratio"] > 0
    by_solver = {g["solver"]: g for g in result["instances"]}
    assert by_solver["ipopt"]["iterations"] == by_solver["ipopt+C"]["iterations"]
    assert "Theta3_median_ms (ipopt+C)" in result["targets"]
    assert "| Theta3 | flat | ipopt+C | 2 |" in (tmp_path / "theta.md").read_text()
