"""Benchmark of the Theta programs: IPOPT with exact derivatives against SLSQP with FD.

``stratawalk bench theta`` (and ``make bench``) draws realistic problem instances for
LittleDog on named terrains and solves each one twice:

(a) IPOPT through the problem's own CasADi ``nlpsol`` (exact first and second
    derivatives), :meth:`~planner.problems.base.ThetaProblem.solve_packed`;
(b) SciPy's SLSQP on the same objective, constraints, bounds, parameters and start point,
    with only function values given (its own forward differences for every gradient and
    Jacobian), the way the paper used Matlab's ``fmincon``.

Both solutions are judged by the same independent numpy/Pinocchio check
(``problem._violations``): feasible iff the largest violation is at most
:data:`~planner.problems.base.FEASIBILITY_TOL`. Results go to ``theta.json`` and
``theta.md`` in the output folder.

Instances (one problem object per (terrain, support or swing leg), reused as the planner
does; build times are reported separately from solve times):

Theta4
    random body positions along the course (random y offset, small random yaw).
Theta2
    a stance placed by Theta4, a random leg about to swing, r_c* = centroid of the three
    support feet lifted by the standing COM height along u_n, plus noise of a few cm.
Theta1
    a stance placed by Theta4 (four-foot support), r_c* = current COM + 0.5-2 cm along
    the heading. Targets whose eq. 5 forces leave the cones are kept: no orientation can
    help them, so both solvers fail them (the planner's pre-check would skip them).
Theta3
    the stance after a Theta2 move off the swing leg, its target foothold 2-6 cm ahead
    (plus lateral noise) on the terrain.
"""

from __future__ import annotations

import os
import sys
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from planner.bench.theta_report import dump_json, render_markdown
from planner.body.state import State
from planner.core.machine import machine_info
from planner.core.outputs import write_atomic
from planner.problems import Theta1, Theta2, Theta3, Theta4
from planner.problems.base import FEASIBILITY_TOL, ThetaOptions, ThetaProblem

__all__ = [
    "THETAS",
    "Instance",
    "ProblemCache",
    "SolveRecord",
    "cmd_bench",
    "make_instances",
    "run_theta_bench",
    "solve_ipopt",
    "solve_slsqp",
]

THETAS = ("Theta1", "Theta2", "Theta3", "Theta4")
IPOPT_OK = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
PLACEMENT_TOL = 1e-4  # [m] a Theta4 stance good enough to start other instances from
COURSE_MARGIN_M = 0.35  # keep the body this far from the ends of the course
TARGETS = {"Theta2_median_ms": 5.0, "Theta3_median_ms": 3.0, "speed_ratio": 20.0}


# ---- problem instances ---------------------------------------------------------------------


class ProblemCache:
    """Theta problems built once per (robot, terrain, kind, support or leg), with build times."""

    def __init__(self, options: ThetaOptions | None = None) -> None:
        self._problems: dict[tuple, ThetaProblem] = {}
        self.options = options

    def get(self, robot, terrain, theta: str, key: Any = None) -> ThetaProblem:
        """The problem ``theta`` for ``key`` (support tuple or swing leg), built on first use."""
        k = (id(robot), terrain.name, theta, key)
        if k not in self._problems:
            mu = _friction(terrain)
            o = self.options
            if theta == "Theta1":
                prob = Theta1(robot, terrain, support=key, options=o, mu=mu)
            elif theta == "Theta2":
                # the NLP with every row its check applies (the planner adds the torque rows
                # to a three-leg Theta2 only when a solve without them overloads a joint)
                prob = Theta2(robot, terrain, support=key, options=o, mu=mu, torque_rows=True)
            elif theta == "Theta3":
                prob = Theta3(robot, terrain, leg=key, options=o, mu=mu)
            elif theta == "Theta4":
                prob = Theta4(robot, terrain, options=o, mu=mu)
            else:
                raise ValueError(f"unknown problem {theta!r}; expected one of {THETAS}")
            self._problems[k] = prob
        return self._problems[k]

    def twin(self, robot, terrain, problem: ThetaProblem, other: ProblemCache) -> ThetaProblem:
        """The problem of ``other`` built for the same (terrain, Theta, key) as ``problem``."""
        for k, prob in other._problems.items():
            if prob is problem:
                return self.get(robot, terrain, k[2], k[3])
        raise KeyError(f"{problem.name} was not built by that cache")

    def build_times(self) -> list[dict[str, Any]]:
        """One record per built problem: terrain, problem, key, build time [s]."""
        return [
            {
                "terrain": k[1],
                "theta": k[2],
                "key": list(k[3]) if isinstance(k[3], tuple) else k[3],
                "build_time_s": prob.build_time_s,
            }
            for k, prob in self._problems.items()
        ]


@dataclass
class Instance:
    """One benchmark instance: a built problem, its parameter vector and start point.

    ``context`` is the fixed part of the state that Theta3 reads when it turns a decision
    vector into a :class:`~planner.body.state.State` (``None`` for the other problems).
    """

    theta: str
    terrain: str
    problem: ThetaProblem
    p: np.ndarray
    x0: np.ndarray
    context: State | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __iter__(self):
        """Unpack as ``(problem, p, x0)``."""
        return iter((self.problem, self.p, self.x0))


def _friction(terrain) -> float:
    return float(terrain.spec.get("friction", 0.7))


def _x_range(terrain) -> tuple[float, float]:
    """Body x range along the course; on a feature course, where the feature is."""
    x_lo, x_hi = terrain.bounds[0] + COURSE_MARGIN_M, terrain.bounds[1] - COURSE_MARGIN_M
    spec = terrain.spec
    lo = max(x_lo, float(spec.get("x_start", x_lo)))
    hi = min(x_hi, float(spec.get("x_end", x_hi)))
    return (lo, hi) if hi > lo else (x_lo, x_hi)


def _directions(terrain, xy: np.ndarray, yaw: float) -> tuple[np.ndarray, np.ndarray]:
    """u_f (heading ``yaw`` in the terrain's tangent plane) and u_n (smoothed normal)."""
    ground = np.array([xy[0], xy[1], float(terrain.height(xy[0], xy[1]))])
    u_n = terrain.smoothed_normal(ground, 0.1)
    u_f = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    u_f = u_f - (u_f @ u_n) * u_n
    return u_f / np.linalg.norm(u_f), u_n


class _Captured(Exception):
    def __init__(self, p: np.ndarray, x0: np.ndarray):
        super().__init__("captured")
        self.p, self.x0 = p, x0


def _capture(problem: ThetaProblem, call) -> tuple[np.ndarray, np.ndarray]:
    """The (p, x0) that ``call`` (a problem's own ``solve``) hands to ``solve_packed``.

    The instance is then exactly what the planner would solve, whatever the problem's
    current parameter packing and warm start.
    """

    def grab(p, x0):
        raise _Captured(np.array(p, dtype=float), np.array(x0, dtype=float))

    problem.solve_packed = grab  # the instance attribute shadows the method
    try:
        call()
    except _Captured as got:
        return got.p, got.x0
    finally:
        del problem.solve_packed
    raise RuntimeError(f"{problem.name}.solve returned before solve_packed")


def _theta4_instance(robot, terrain, rng, cache: ProblemCache) -> Instance:
    """Random body position along the course, small yaw; (p, x0) as :meth:`Theta4.solve`."""
    prob = cache.get(robot, terrain, "Theta4")
    lo, hi = _x_range(terrain)
    xy = np.array([rng.uniform(lo, hi), rng.uniform(-0.05, 0.05)])
    yaw = float(rng.uniform(-0.15, 0.15))
    u_f, u_n = _directions(terrain, xy, yaw)
    z = float(terrain.height(xy[0], xy[1])) + rng.uniform(0.13, 0.16)
    rc = np.array([xy[0], xy[1], z])
    p, x0 = _capture(prob, lambda: prob.solve(rc, u_f, u_n, heading_rad=yaw))
    meta = {"x": float(xy[0]), "y": float(xy[1]), "yaw": yaw, "u_f": u_f, "u_n": u_n}
    return Instance("Theta4", terrain.name, prob, p, x0, meta=meta)


def _placed(robot, terrain, rng, cache: ProblemCache, tries: int = 20):
    """A standing configuration from Theta4 at a random place: (state, u_f, u_n, meta).

    A start stance is accepted when IPOPT converged and the independent violation is
    below ``PLACEMENT_TOL`` (looser than the feasibility tolerance, so that a mismatch
    between the NLP and the check would still leave instances to benchmark).
    """
    for _ in range(tries):
        inst = _theta4_instance(robot, terrain, rng, cache)
        sol = inst.problem.solve_packed(inst.p, inst.x0)
        if sol.status in IPOPT_OK and sol.max_violation() <= PLACEMENT_TOL:
            return sol.state, inst.meta["u_f"], inst.meta["u_n"], inst.meta
    raise RuntimeError(f"could not place {robot.name} on {terrain.name} in {tries} tries")


def _standing_height(prob: ThetaProblem, state: State, u_n: np.ndarray) -> float:
    """Height of the COM above the mean of the four contact points, along u_n."""
    return float((prob.check.com_W(state) - state.feet_W.mean(axis=0)) @ u_n)


def _theta2_target(prob, state, support, u_n, rng, noise_m: float) -> np.ndarray:
    """Centroid of the support feet, lifted by the standing COM height, plus noise."""
    centroid = state.feet_W[list(support)].mean(axis=0)
    h = _standing_height(prob, state, u_n)
    return centroid + h * u_n + rng.normal(0.0, noise_m, 3)


def make_instances(
    robot, terrain, theta: str, n: int, seed: int, cache: ProblemCache | None = None
) -> list[Instance]:
    """``n`` realistic instances of ``theta`` on ``terrain`` (see the module docstring).

    Parameters
    ----------
    robot, terrain : Robot, Terrain
        From :func:`planner.body.robot.load_robot` and :func:`planner.world.terrain.load_terrain`.
    theta : {"Theta1", "Theta2", "Theta3", "Theta4"}
        Which program.
    n : int
        Number of instances.
    seed : int
        Seed of the random draws (same seed, same instances).
    cache : ProblemCache, optional
        Where problems are built and reused (a fresh one if not given).

    Returns
    -------
    list of Instance
        Each unpacks as ``(problem, p, x0)``; Theta3's also carries ``context``.

    """
    if theta not in THETAS:
        raise ValueError(f"unknown problem {theta!r}; expected one of {THETAS}")
    cache = cache if cache is not None else ProblemCache()
    rng = np.random.default_rng(seed)
    out: list[Instance] = []
    attempts = 0
    while len(out) < n:
        attempts += 1
        if attempts > 20 * n + 20:
            raise RuntimeError(f"{theta} on {terrain.name}: too few usable start stances")
        if theta == "Theta4":
            out.append(_theta4_instance(robot, terrain, rng, cache))
            continue
        state, u_f, u_n, meta = _placed(robot, terrain, rng, cache)
        meta = {k: v for k, v in meta.items() if k not in ("u_f", "u_n")}
        if theta == "Theta1":
            prob = cache.get(robot, terrain, "Theta1", (0, 1, 2, 3))
            step = float(rng.uniform(0.005, 0.02))
            rc = prob.check.com_W(state) + step * u_f
            p = prob.params(state, rc, u_f, u_n)
            meta |= {"support": [0, 1, 2, 3], "step_m": step}
            out.append(
                Instance(theta, terrain.name, prob, p, prob.initial_guess(state, p), None, meta)
            )
            continue
        leg = int(rng.integers(4))
        support = tuple(i for i in range(4) if i != leg)
        prob2 = cache.get(robot, terrain, "Theta2", support)
        if theta == "Theta2":
            rc = _theta2_target(prob2, state, support, u_n, rng, 0.02)
            p = prob2.params(state, rc, u_f, u_n)
            meta |= {"support": list(support)}
            out.append(
                Instance(theta, terrain.name, prob2, p, prob2.initial_guess(state, p), None, meta)
            )
            continue
        # Theta3: the stance after a Theta2 move off the swing leg
        rc = _theta2_target(prob2, state, support, u_n, rng, 0.01)
        moved = prob2.solve(state, rc, u_f, u_n)
        if not moved.feasible:
            continue
        prob3 = cache.get(robot, terrain, "Theta3", leg)
        ctx = moved.state
        u_lat = np.cross(u_n, u_f)
        ahead = float(rng.uniform(0.02, 0.06))
        target = ctx.feet_W[leg] + ahead * u_f + rng.normal(0.0, 0.01) * u_lat
        target[2] = float(terrain.height(target[0], target[1]))
        p, x0 = _capture(prob3, lambda: prob3.solve(ctx, target))  # noqa: B023
        meta |= {"leg": leg, "ahead_m": ahead}
        out.append(Instance(theta, terrain.name, prob3, p, x0, ctx, meta))
    return out


# ---- solving -------------------------------------------------------------------------------


@dataclass
class SolveRecord:
    """One solve: feasibility by the independent check, time, iterations.

    ``feasible``: independent max violation <= FEASIBILITY_TOL (the success criterion).
    ``converged``: the solver reported success and the solver-side constraints (the CasADi
    g and the bounds) hold to 1e-6, which tells a solver failure from a model mismatch
    between the NLP and the independent check.
    """

    solver: str
    feasible: bool
    converged: bool
    max_violation: float
    worst_group: str
    solve_time_s: float
    iterations: int
    status: str
    objective: float
    x: np.ndarray = field(repr=False)


def _prepare(problem: ThetaProblem, context: State | None) -> None:
    if context is not None:
        problem._context = context  # Theta3 reads the fixed body and legs from here


def _judge(problem: ThetaProblem, x: np.ndarray, p: np.ndarray) -> tuple[float, str, float]:
    """Independent max violation, its group, and the solver-side max violation."""
    x = np.clip(x, problem.lbx, problem.ubx)
    state = problem._state_from_x(x, p)
    viol = problem._violations(state, x, p)
    worst = max(viol.values(), default=0.0)
    group = max(viol, key=viol.get) if viol else ""
    solver_side = max(problem.solver_violations(x, p).values(), default=0.0)
    return float(worst), group, float(solver_side)


def solve_ipopt(
    problem: ThetaProblem, p: np.ndarray, x0: np.ndarray, context: State | None = None
) -> SolveRecord:
    """IPOPT (exact derivatives) via ``problem.solve_packed``; time = its ``solve_time_s``."""
    _prepare(problem, context)
    sol = problem.solve_packed(p, x0)
    worst = sol.max_violation()
    group = max(sol.violations, key=sol.violations.get) if sol.violations else ""
    solver_side = max(problem.solver_violations(sol.x, sol.p).values(), default=0.0)
    return SolveRecord(
        solver="ipopt",
        feasible=bool(sol.feasible),
        converged=bool(sol.status in IPOPT_OK and solver_side <= 1e-6),
        max_violation=float(worst),
        worst_group=group,
        solve_time_s=float(sol.solve_time_s),
        iterations=int(sol.iterations),
        status=sol.status,
        objective=float(sol.objective),
        x=sol.x,
    )


class _NumericNLP:
    """f and g of a problem as numpy functions of x for fixed p (values only)."""

    def __init__(self, problem: ThetaProblem, p: np.ndarray):
        self.f_fun, self.g_fun, self.p = problem._f_fun, problem._g_fun, np.asarray(p, float)
        lbg, ubg = problem.lbg, problem.ubg
        self.eq = np.isfinite(lbg) & (lbg == ubg)
        self.lo = ~self.eq & np.isfinite(lbg)
        self.hi = ~self.eq & np.isfinite(ubg)
        self.lbg, self.ubg = lbg, ubg
        self._g_cache: dict[bytes, np.ndarray] = {}
        self.n_f = 0
        self.n_g = 0

    def f(self, x: np.ndarray) -> float:
        self.n_f += 1
        return float(self.f_fun(x, self.p))

    def g(self, x: np.ndarray) -> np.ndarray:
        key = x.tobytes()
        g = self._g_cache.get(key)
        if g is None:  # eq and ineq parts are asked for at the same points: evaluate once
            if len(self._g_cache) > 512:
                self._g_cache.clear()
            self.n_g += 1
            g = np.asarray(self.g_fun(x, self.p), dtype=float).ravel()
            self._g_cache[key] = g
        return g

    def eq_fun(self, x: np.ndarray) -> np.ndarray:
        return self.g(x)[self.eq] - self.lbg[self.eq]

    def ineq_fun(self, x: np.ndarray) -> np.ndarray:
        g = self.g(x)
        return np.concatenate([g[self.lo] - self.lbg[self.lo], self.ubg[self.hi] - g[self.hi]])

    def constraints(self) -> list[dict[str, Any]]:
        cons = []
        if self.eq.any():
            cons.append({"type": "eq", "fun": self.eq_fun})
        if self.lo.any() or self.hi.any():
            cons.append({"type": "ineq", "fun": self.ineq_fun})
        return cons


def solve_slsqp(
    problem: ThetaProblem,
    p: np.ndarray,
    x0: np.ndarray,
    context: State | None = None,
    maxiter: int = 200,
    ftol: float = 1e-9,
) -> SolveRecord:
    """SciPy SLSQP on the same NLP with finite-difference derivatives (``jac=None``).

    Objective and constraints are the problem's CasADi Functions of (x, p) evaluated
    numerically; equality rows (lbg == ubg) become one ``'eq'`` constraint, the finite
    sides of the others one ``'ineq'`` constraint (g - lbg >= 0, ubg - g >= 0); bounds
    lbx/ubx; the start point clipped to the bounds as IPOPT's. Feasibility is judged by
    the problem's independent check, as for IPOPT. The same constraint generation as
    IPOPT's (:meth:`~planner.problems.base.ThetaProblem.solve_rounds`: clearance points
    picked at the start pose, a round more if the check finds P too low). Time = the
    rounds without the independent checks, as for IPOPT.
    """
    from scipy.optimize import Bounds, minimize

    _prepare(problem, context)
    bounds = Bounds(problem.lbx, problem.ubx)
    found = {}

    def inner(p_round: np.ndarray, x_start: np.ndarray) -> tuple[np.ndarray, str, int]:
        nlp = _NumericNLP(problem, p_round)
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            res = minimize(
                nlp.f,
                x_start,
                method="SLSQP",
                jac=None,
                bounds=bounds,
                constraints=nlp.constraints(),
                options={"maxiter": maxiter, "ftol": ftol},
            )
        found.update(success=bool(res.success), fun=float(res.fun))
        return np.asarray(res.x, float), str(res.message), int(res.nit)

    x, p_used, status, iterations, _, _, elapsed = problem.solve_rounds(p, x0, inner)
    if np.all(np.isfinite(x)):
        worst, group, solver_side = _judge(problem, x, p_used)
    else:
        worst, group, solver_side = float("inf"), "nan", float("inf")
    feasible = bool(np.isfinite(worst) and worst <= FEASIBILITY_TOL)
    return SolveRecord(
        solver="slsqp",
        feasible=feasible,
        converged=bool(found["success"] and solver_side <= 1e-6),
        max_violation=worst,
        worst_group=group,
        solve_time_s=elapsed,
        iterations=iterations,
        status=status,
        objective=found["fun"] if np.isfinite(found["fun"]) else float("inf"),
        x=x,
    )


# ---- the benchmark -------------------------------------------------------------------------


def _stats(records: list[SolveRecord]) -> dict[str, Any]:
    n = len(records)
    if n == 0:
        return {"instances": 0}
    t = np.array([r.solve_time_s for r in records]) * 1e3
    it = np.array([r.iterations for r in records])
    feas = [r for r in records if r.feasible]
    return {
        "instances": n,
        "feasible": len(feas),
        "success_rate": len(feas) / n,
        "converged": sum(r.converged for r in records),
        "converged_rate": sum(r.converged for r in records) / n,
        "time_ms_median": float(np.median(t)),
        "time_ms_p95": float(np.percentile(t, 95)),
        "time_ms_mean": float(np.mean(t)),
        "iterations_median": float(np.median(it)),
        "iterations_p95": float(np.percentile(it, 95)),
        "max_violation_of_feasible": max((r.max_violation for r in feas), default=0.0),
        "failure_groups": _count(r.worst_group for r in records if not r.feasible),
    }


def _count(items) -> dict[str, int]:
    out: dict[str, int] = {}
    for k in items:
        out[k] = out.get(k, 0) + 1
    return dict(sorted(out.items(), key=lambda kv: -kv[1]))


def _speed_ratio(ipopt: list[SolveRecord], slsqp: list[SolveRecord]) -> float:
    """Median SLSQP time / median IPOPT time on the same instances."""
    if not ipopt or not slsqp:
        return float("nan")
    return float(
        np.median([r.solve_time_s for r in slsqp]) / np.median([r.solve_time_s for r in ipopt])
    )


def _records_json(
    theta: str, terrain: str, solver: str, idx: list[int], recs: list[SolveRecord]
) -> dict[str, Any]:
    """Per-instance results of one (Theta, terrain, solver), as columns."""
    statuses = sorted({r.status for r in recs})
    return {
        "theta": theta,
        "terrain": terrain,
        "solver": solver,
        "index": list(idx),
        "feasible": [int(r.feasible) for r in recs],
        "converged": [int(r.converged) for r in recs],
        "max_violation": [float(f"{r.max_violation:.3g}") for r in recs],
        "worst_group": [r.worst_group for r in recs],
        "time_ms": [round(r.solve_time_s * 1e3, 3) for r in recs],
        "iterations": [r.iterations for r in recs],
        "statuses": statuses,
        "status": [statuses.index(r.status) for r in recs],
    }


def run_theta_bench(
    n_per_theta: int = 200,
    terrains: tuple[str, ...] | list[str] = ("flat", "rough2cm"),
    seed: int = 0,
    out_dir: str | Path = "bench/results",
    slsqp_n: int | None = None,
    robot_name: str = "littledog",
    thetas: tuple[str, ...] = THETAS,
    progress: bool = True,
    jit: bool = False,
) -> dict[str, Any]:
    """Run the Theta benchmark and write ``theta.json`` and ``theta.md`` to ``out_dir``.

    Parameters
    ----------
    n_per_theta : int
        Instances per (Theta, terrain), all solved by IPOPT.
    terrains : sequence of str
        Terrain names (``terrains/NAME.yaml``).
    seed : int
        Seed of the instance draws.
    out_dir : str or Path
        Output folder (created).
    slsqp_n : int, optional
        Solve only a seeded subset of this many instances per (Theta, terrain) with SLSQP
        (default: all). Speed ratios are then taken on that subset.
    robot_name : str
        Robot to load.
    thetas : tuple of str
        Which programs.
    progress : bool
        Print one line per (Theta, terrain) to stderr.
    jit : bool
        Also solve every instance with the NLP compiled to C (solver ``ipopt+C``,
        :mod:`planner.problems.compiled`; compiled once per problem and machine, cached).

    Returns
    -------
    dict
        The content of ``theta.json``.

    """
    from planner.body.robot import load_robot
    from planner.world.terrain import load_terrain

    t_start = time.perf_counter()
    machine = machine_info()
    robot = load_robot(robot_name)
    cache = ProblemCache()
    compiled = ProblemCache(ThetaOptions(jit=True)) if jit else None
    ipopts = ("ipopt", "ipopt+C") if jit else ("ipopt",)
    groups: list[dict[str, Any]] = []
    per_instance: list[dict[str, Any]] = []
    pooled: dict[str, dict[str, list[SolveRecord]]] = {}
    gen_time: dict[str, float] = {}
    for ki, tname in enumerate(terrains):
        terrain = load_terrain(tname)
        for ti, theta in enumerate(thetas):
            t0 = time.perf_counter()
            instances = make_instances(
                robot, terrain, theta, n_per_theta, seed * 1000 + 10 * ti + ki, cache
            )
            gen_time[f"{theta}/{tname}"] = time.perf_counter() - t0
            m = len(instances)
            sl_idx = _slsqp_subset(m, slsqp_n, seed)
            recs, sl_list = _solve_group(robot, terrain, instances, cache, compiled, ipopts, sl_idx)
            per_instance += _group_json(theta, tname, ipopts, m, recs, sl_idx, sl_list)
            pool = pooled.setdefault(theta, {"slsqp": []})
            rows = _group_rows(theta, tname, ipopts, recs, sl_idx, sl_list, pool)
            groups.extend(rows.values())
            pool["slsqp"] += sl_list
            if progress:
                _print_group(theta, tname, m, ipopts, rows, len(sl_list), t_start)
    summary = _summary(pooled, ipopts)
    result = {
        "format": "stratawalk.bench.theta/1",
        "robot": robot_name,
        "terrains": list(terrains),
        "config": _config(n_per_theta, slsqp_n, jit, seed),
        "machine": machine | {"load_average_1_5_15_at_end": [round(v, 2) for v in os.getloadavg()]},
        "groups": groups,
        "summary": summary,
        "targets": _targets(summary),
        "build_times_s": cache.build_times()
        + [b | {"theta": b["theta"] + " (C)"} for b in (compiled.build_times() if jit else [])],
        "instance_generation_s": gen_time,
        "total_time_s": time.perf_counter() - t_start,
        "instances": per_instance,
    }
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "theta.json", lambda p: p.write_text(dump_json(result)))
    write_atomic(out / "theta.md", lambda p: p.write_text(render_markdown(result)))
    return result


def _config(n_per_theta: int, slsqp_n: int | None, jit: bool, seed: int) -> dict[str, Any]:
    """The run's settings, as ``theta.json`` records them."""
    return {
        "n_per_theta": n_per_theta,
        "slsqp_n": slsqp_n,
        "compiled": jit,
        "seed": seed,
        "feasibility_tol": FEASIBILITY_TOL,
        "slsqp_options": {"maxiter": 200, "ftol": 1e-9, "jac": None},
    }


def _group_json(theta, tname, ipopts, m: int, recs, sl_idx, sl_list) -> list[dict[str, Any]]:
    """Per-instance columns of one (Theta, terrain): each IPOPT solver's, then SLSQP's."""
    out = [_records_json(theta, tname, solver, list(range(m)), recs[solver]) for solver in ipopts]
    out.append(_records_json(theta, tname, "slsqp", sl_idx, sl_list))
    return out


def _slsqp_subset(m: int, slsqp_n: int | None, seed: int) -> list[int]:
    """The instances (of ``m``) that SLSQP solves: all, or a seeded subset of ``slsqp_n``."""
    if slsqp_n is None or slsqp_n >= m:
        return list(range(m))
    pick = np.random.default_rng(seed + 7).choice(m, slsqp_n, replace=False)
    return sorted(int(k) for k in pick)


def _solve_group(
    robot, terrain, instances: list[Instance], cache, compiled, ipopts, sl_idx: list[int]
) -> tuple[dict[str, list[SolveRecord]], list[SolveRecord]]:
    """({IPOPT solver: records of every instance}, SLSQP's records of ``sl_idx``).

    Warmed up first (untimed); the solvers interleaved instance by instance, so that all
    see the same machine load. ``compiled`` (a :class:`ProblemCache` of the NLPs compiled
    to C) or None.
    """
    twins = [
        compiled.twin(robot, terrain, inst.problem, cache) if compiled else None
        for inst in instances
    ]
    _warm_up(instances)
    if compiled:
        pairs = zip(instances, twins, strict=True)
        _warm_up([replace(inst, problem=tw) for inst, tw in pairs])
    recs: dict[str, list[SolveRecord]] = {solver: [] for solver in ipopts}
    sl: dict[int, SolveRecord] = {}
    in_subset = set(sl_idx)
    for k, inst in enumerate(instances):  # interleaved: all see the same machine load
        recs["ipopt"].append(solve_ipopt(inst.problem, inst.p, inst.x0, inst.context))
        if compiled:
            recs["ipopt+C"].append(solve_ipopt(twins[k], inst.p, inst.x0, inst.context))
        if k in in_subset:
            sl[k] = solve_slsqp(inst.problem, inst.p, inst.x0, inst.context)
    return recs, [sl[k] for k in sl_idx]


def _group_rows(theta: str, tname: str, ipopts, recs, sl_idx, sl_list, pool) -> dict:
    """{solver: row} of one (Theta, terrain); the IPOPT records pooled into ``pool``.

    Each IPOPT row's speed ratio is taken on the instances SLSQP solved too; SLSQP's row
    repeats IPOPT's.
    """
    rows = {}
    for solver in ipopts:
        common = [recs[solver][k] for k in sl_idx]
        row = {"theta": theta, "terrain": tname, "solver": solver} | _stats(recs[solver])
        row["speed_ratio"] = _speed_ratio(common, sl_list)
        rows[solver] = row
        pool.setdefault(solver, []).extend(recs[solver])
        pool.setdefault(solver + "/common", []).extend(common)
    rows["slsqp"] = {"theta": theta, "terrain": tname, "solver": "slsqp"} | _stats(sl_list)
    rows["slsqp"]["speed_ratio"] = rows["ipopt"]["speed_ratio"]
    return rows


def _print_group(
    theta: str, tname: str, m: int, ipopts, rows: dict, n_slsqp: int, t_start: float
) -> None:
    """One line on stderr for a (Theta, terrain): success rates and median times."""
    s_sl = rows["slsqp"]
    ips = " | ".join(
        f"{solver} {rows[solver]['success_rate']:.0%} {rows[solver]['time_ms_median']:.2f} ms"
        for solver in ipopts
    )
    print(
        f"[bench] {theta:6s} {tname:9s} n={m}: {ips} | slsqp (n={n_slsqp}) "
        f"{s_sl.get('success_rate', 0):.0%} {s_sl.get('time_ms_median', 0):.1f} ms"
        f" | x{rows['ipopt']['speed_ratio']:.0f}"
        f"  [{time.perf_counter() - t_start:.0f} s]",
        file=sys.stderr,
        flush=True,
    )


def _summary(pooled: dict, ipopts) -> list[dict[str, Any]]:
    """Rows over all terrains: each Theta's pooled records, per solver."""
    summary = []
    for theta, pool in pooled.items():
        for solver in ipopts:
            row = {"theta": theta, "terrain": "all", "solver": solver} | _stats(pool[solver])
            row["speed_ratio"] = _speed_ratio(pool[solver + "/common"], pool["slsqp"])
            summary.append(row)
        row = {"theta": theta, "terrain": "all", "solver": "slsqp"} | _stats(pool["slsqp"])
        row["speed_ratio"] = _speed_ratio(pool["ipopt/common"], pool["slsqp"])  # as per terrain
        summary.append(row)
    return summary


def _warm_up(instances: list[Instance]) -> None:
    """Solve one instance per distinct problem once (untimed): first-call set-up costs."""
    seen: set[int] = set()
    for inst in instances:
        if id(inst.problem) not in seen:
            seen.add(id(inst.problem))
            _prepare(inst.problem, inst.context)
            inst.problem.solve_packed(inst.p, inst.x0)


def _targets(summary: list[dict[str, Any]]) -> dict[str, Any]:
    rows = {(r["theta"], r["solver"]): r for r in summary}
    out: dict[str, Any] = {}
    for solver in ("ipopt", "ipopt+C"):
        tag = "" if solver == "ipopt" else " (" + solver + ")"
        for theta, key in (("Theta2", "Theta2_median_ms"), ("Theta3", "Theta3_median_ms")):
            if (theta, solver) in rows:
                med = rows[(theta, solver)]["time_ms_median"]
                met = med < TARGETS[key]
                out[key + tag] = {"target": TARGETS[key], "measured": med, "met": met}
        for theta in THETAS:
            if (theta, solver) in rows and rows[(theta, "slsqp")]["instances"]:
                ip, sl = rows[(theta, solver)], rows[(theta, "slsqp")]
                out[f"{theta}_speed_ratio{tag}"] = {
                    "target": TARGETS["speed_ratio"],
                    "measured": ip["speed_ratio"],
                    "met": bool(ip["speed_ratio"] >= TARGETS["speed_ratio"]),
                }
                out[f"{theta}_success_vs_slsqp{tag}"] = {
                    "ipopt": ip["success_rate"],
                    "slsqp": sl["success_rate"],
                    "met": bool(ip["success_rate"] >= sl["success_rate"]),
                }
    return out


# ---- command line --------------------------------------------------------------------------


def cmd_bench(args) -> int:
    """Run ``stratawalk bench theta`` and print the markdown table."""
    from planner.core.outputs import check_folder

    check_folder(args.out, "--out")
    terrains = tuple(s.strip() for s in args.terrains.split(",") if s.strip())
    result = run_theta_bench(
        n_per_theta=args.n,
        terrains=terrains,
        seed=args.seed,
        out_dir=args.out,
        slsqp_n=args.slsqp_n,
        jit=args.jit,
    )
    print(render_markdown(result))
    print(f"wrote {Path(args.out) / 'theta.json'} and {Path(args.out) / 'theta.md'}")
    return 0
