"""Global planning: the trajectory tau of least cost C(tau) (paper section 9, eq. 15-16).

The paper leaves section 9 unimplemented and C open. Here:

Trajectories (eq. 15)
    tau = tau0 + sum_{p=1..P} sin(p pi (lambda - lambda_a) / (lambda_b - lambda_a)) A_p,
    tau0 the straight line the local planner follows by default
    (:meth:`~planner.motion.trajectory.Trajectory.straight`) or, where that line crosses an
    obstacle on the robot's cost map, the guide path around it
    (:mod:`planner.motion.guide_path`, beyond the paper), and
    :meth:`~planner.motion.trajectory.Trajectory.sine_series` the sum. Only **lateral** offsets are
    searched: A_p = a_p n, n the horizontal unit normal of tau0 (left of start -> goal).
    Offsets along a straight tau0 only re-parametrise it, and tau's height matters to the
    local planner only through its tangent, which the body frame projects onto the
    terrain (:func:`planner.motion.heuristics.body_pose_on_trajectory`). The search variables are
    a = (a_1..a_P) [m], P = ``GlobalSettings.terms``; a = 0 is tau0.

Cost C(tau) (eq. 16)
    The local planner of section 8 (``soft``, ``hard`` or ``recursive``) walks along tau
    with a time budget, the plan is assembled and, when the planner says it arrived,
    checked by the independent validator (:func:`planner.planfile.validate.check_plan`). Then,
    with the weights of :class:`CostWeights`::

        C = 100 d_left + 50 [not reached]          d_left: COM to goal at the end [m]
          + 0.05 steps + 0.01 T_walk + 0.01 T_plan steps; walk and planning time [s]
          + 1.0 L_tau                              arc length of tau [m]
          + 50 max(0, 0.03 - m_stab)               m_stab: mean stability margin [m]

    "Reached" means reached *and* validated. The flat 50 makes every reaching tau cheaper
    than every other one (the rest of C differs by ~10 between walks); among those that do
    not reach, the distance left decides. m_stab is the mean, over the keyframes on three
    feet (mid-swing), of the horizontal distance from the whole-body COM to the nearest
    edge of the support triangle (negative outside): a tau that keeps the COM well inside
    its supports costs less. A walk of 2 m on flat ground costs about 6.5.

Optimiser
    CMA-ES (the ``cma`` package) over a, from a = 0 with step size ``sigma0_m`` inside
    +-``bound_m``: derivative-free, since C is a planner run (noisy, discontinuous where a
    foothold switches). Each generation's candidates are evaluated in parallel in a
    process pool (one local planner per process, its Theta problems built once per
    process and reused). Once a candidate reaches, a candidate whose partial walk already
    costs as much (length, steps and planning time so far) stops planning early.

    tau0 is evaluated first, in this process; when it reaches the goal (and validates)
    the search stops there (``GlobalSettings.refine_reached`` searches on): ``--global``
    costs one local plan where the straight line or the guide path is walkable.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import signal
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from planner.core.errors import InputError, NoSolutionFound, PlannerError
from planner.core.interrupts import shielded
from planner.motion.trajectory import Trajectory
from planner.planning.local import LocalSettings
from planner.planning.settings import effective
from planner.planning.walk import assemble_plan

__all__ = [
    "CostWeights",
    "Evaluation",
    "GlobalResult",
    "GlobalSettings",
    "candidate_trajectory",
    "lateral_coefficients",
    "plan_global_walk",
    "print_progress",
    "stability_margin_m",
    "trajectory_cost",
]


@dataclass
class CostWeights:
    """Weights of C(tau) (module docstring); units are per metre, per step, per second."""

    goal_per_m: float = 100.0  # distance of the COM to the goal left at the end
    not_reached: float = 50.0  # flat penalty: not reached, or not validated
    per_step: float = 0.05
    walk_per_s: float = 0.01  # time the walk takes to execute (plan.samples.time[-1])
    planning_per_s: float = 0.01
    length_per_m: float = 1.0  # arc length of tau
    margin_per_m: float = 50.0  # per metre the mean stability margin is below margin_ref_m
    margin_ref_m: float = 0.03


@dataclass
class GlobalSettings:
    """What the global planner searches and for how long.

    terms : P, the number of sine terms (search dimension).
    sigma0_m : CMA-ES initial step size [m]; about the lateral detour expected.
    bound_m : |a_p| <= bound_m [m].
    popsize : candidates per generation (a multiple of ``workers`` wastes no time).
    max_generations, time_budget_s : stop after this many generations or seconds.
    patience : once a candidate reaches the goal, stop after this many generations
        without the best cost improving by more than ``tol`` (0: stop at the first
        generation that reaches).
    workers : processes evaluating candidates (default: the machine's cores).
    seed : CMA-ES random seed (>= 1; cma reads 0 as "from the clock").
    guide : tau0 is the guide path (:mod:`planner.motion.guide_path`) where the straight line
        crosses an obstacle; False: always the straight line (the paper's tau0).
    refine_reached : search with CMA-ES even when tau0 itself reaches the goal.
    """

    terms: int = 3
    sigma0_m: float = 0.2
    bound_m: float = 0.6
    popsize: int = 8
    max_generations: int = 8
    time_budget_s: float = 1800.0
    patience: int = 2
    tol: float = 0.05
    workers: int | None = None
    seed: int = 1
    guide: bool = True
    refine_reached: bool = False
    weights: CostWeights = field(default_factory=CostWeights)

    def check(self) -> None:
        """Raise :class:`InputError` naming the first bad field."""
        bad = [
            ("terms", self.terms >= 1, ">= 1"),
            ("sigma0_m", self.sigma0_m > 0, "> 0"),
            ("bound_m", self.bound_m > 0, "> 0"),
            ("popsize", self.popsize >= 2, ">= 2"),
            ("max_generations", self.max_generations >= 1, ">= 1"),
            ("time_budget_s", self.time_budget_s > 0, "> 0"),
            ("patience", self.patience >= 0, ">= 0"),
            ("seed", self.seed >= 1, ">= 1"),
            ("workers", self.workers is None or self.workers >= 1, ">= 1 or None"),
        ]
        for name, ok, need in bad:
            if not ok:
                raise InputError(
                    f"GlobalSettings.{name}: must be {need}, got {getattr(self, name)!r}"
                )


@dataclass
class Evaluation:
    """One candidate tau and what the local planner made of it; ``cost`` is C(tau)."""

    coefficients_m: list[float]
    cost: float
    reached: bool
    validated: bool | None
    distance_to_goal_m: float
    steps: int
    walk_time_s: float
    planning_time_s: float
    path_length_m: float
    stability_margin_m: float
    message: str
    cost_terms: dict = field(default_factory=dict)
    generation: int = 0


@dataclass
class GlobalResult:
    """Outcome of :func:`plan_global_walk` (also stored in ``plan.stats["global"]``)."""

    best: Evaluation
    tau0: Evaluation
    history: list[dict]
    evaluations: int
    generations: int
    elapsed_s: float
    stop_reason: str

    def to_dict(self) -> dict:
        """Plain JSON data."""
        return {
            "best": asdict(self.best),
            "tau0": asdict(self.tau0),
            "history": self.history,
            "evaluations": self.evaluations,
            "generations": self.generations,
            "elapsed_s": self.elapsed_s,
            "stop_reason": self.stop_reason,
        }


# ---- trajectories (eq. 15) -----------------------------------------------------------------
def lateral_coefficients(a_m, start_xy, goal_xy) -> np.ndarray:
    """A_p = a_p n (P, 3) [m]: n the horizontal unit normal left of start -> goal."""
    d = np.asarray(goal_xy, float)[:2] - np.asarray(start_xy, float)[:2]
    norm = float(np.linalg.norm(d))
    if norm <= 0:
        raise InputError("global planning: start and goal have the same x, y; move the goal")
    n = np.array([-d[1], d[0], 0.0]) / norm
    return np.asarray(a_m, float).reshape(-1, 1) * n


def candidate_trajectory(tau0: Trajectory, a_m, start_xy, goal_xy) -> Trajectory:
    """Eq. 15: tau0 + sum_p sin(p pi lambda / L) a_p n; a = 0 gives tau0 itself."""
    a = np.asarray(a_m, float)
    if not np.any(a):
        return tau0
    return Trajectory.sine_series(tau0, lateral_coefficients(a, start_xy, goal_xy))


# ---- the cost (eq. 16) ---------------------------------------------------------------------
def _cross2(u, v) -> float:
    """The z component of the cross product of two plane vectors."""
    return float(u[0] * v[1] - u[1] * v[0])


def stability_margin_m(robot, check, keyframes) -> float:
    """Mean COM-to-edge distance [m] of the support triangle at the 3-foot keyframes.

    Positive inside the triangle. ``check`` gives the whole-body COM
    (:meth:`planner.problems.base.ConstraintCheck.com_W`). NaN when there are none.
    """
    out = []
    for s in keyframes:
        if len(s.support) != 3:
            continue
        tri = s.feet_W[list(s.support), :2]
        c = np.asarray(check.com_W(s), float)[:2]
        area2 = _cross2(tri[1] - tri[0], tri[2] - tri[0])
        if abs(area2) < 1e-12:
            continue
        sign = 1.0 if area2 > 0 else -1.0
        dists = []
        for k in range(3):
            a, b = tri[k], tri[(k + 1) % 3]
            e = b - a
            dists.append(sign * _cross2(e, c - a) / float(np.linalg.norm(e)))
        out.append(min(dists))
    return float(np.mean(out)) if out else float("nan")


def trajectory_cost(
    weights: CostWeights,
    *,
    reached: bool,
    distance_to_goal_m: float,
    steps: int,
    walk_time_s: float,
    planning_time_s: float,
    path_length_m: float,
    stability_margin_m: float,
) -> tuple[float, dict]:
    """C(tau) and its terms (module docstring); ``reached`` must mean validated too."""
    w = weights
    margin = 0.0 if not np.isfinite(stability_margin_m) else stability_margin_m
    terms = {
        "goal": w.goal_per_m * float(distance_to_goal_m),
        "not_reached": 0.0 if reached else w.not_reached,
        "steps": w.per_step * int(steps),
        "walk_time": w.walk_per_s * float(walk_time_s),
        "planning_time": w.planning_per_s * float(planning_time_s),
        "length": w.length_per_m * float(path_length_m),
        "stability": w.margin_per_m * max(0.0, w.margin_ref_m - margin),
    }
    return float(sum(terms.values())), terms


# ---- evaluation in worker processes --------------------------------------------------------
_WORKER: dict = {}


@dataclass
class _Problem:
    """What every evaluation needs; pickled once to each worker."""

    robot: str
    terrain_spec: dict
    terrain_base_dir: str | None
    planner: str
    settings: LocalSettings
    start_xy: tuple[float, float]
    goal_xy: tuple[float, float]
    weights: CostWeights
    seed: int = 1
    tau0_xy: list | None = None  # the guide path's xy points (N, 2); None: straight


def _init_worker(problem: _Problem) -> None:
    """Load robot and terrain once per process; the Theta problem caches live here too."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    _load(problem)


def _load(problem: _Problem) -> None:
    """What :func:`_evaluate` needs, in this process (a worker, or the parent for tau0)."""
    from planner.body.robot import load_robot
    from planner.world.terrain import Terrain

    terrain = Terrain.from_spec(problem.terrain_spec, base_dir=problem.terrain_base_dir)
    _WORKER.clear()
    _WORKER.update(
        problem=problem,
        robot=load_robot(problem.robot),
        terrain=terrain,
        theta2={},
        theta3={},
    )


def _tau0(local, start_xy, goal_xy, tau0_xy=None) -> Trajectory:
    """The local planner's own default tau (base.LocalPlanner.plan), or the guide path."""
    if tau0_xy is not None:
        return Trajectory.over_terrain(tau0_xy, local.terrain, local.com_height_m(), kind="guide")
    return Trajectory.straight(start_xy, goal_xy, local.terrain, local.com_height_m())


def guide_tau0_xy(robot, terrain, start_xy, goal_xy) -> tuple[list | None, str]:
    """(xy points of the guide path, or None for the straight line; what was decided).

    The straight line is kept where it stays on the free cells of the robot's cost map
    (:func:`planner.motion.guide_path.traversability_map`): the map's relief cost is a hint, and
    a detour the local planner does not need costs steps.
    """
    from planner.motion.guide_path import guide_path

    g = guide_path(robot, terrain, start_xy, goal_xy, height_m=0.0)
    if g.map.segment_free(start_xy, goal_xy):
        return None, "the straight line is clear of obstacles"
    if g.tau is None:
        return None, f"no guide path ({g.message}): the straight line"
    return g.xy_W.tolist(), f"guide path around obstacles, {g.tau.length_m:.2f} m"


_NO_WALK = {
    "reached": False,
    "steps": 0,
    "walk_time_s": 0.0,
    "planning_time_s": 0.0,
    "stability_margin_m": float("nan"),
}


class _Rejected(Exception):
    """A candidate whose partial walk already costs at least the best one's C."""


def _evaluate(
    a_m: list[float], generation: int = 0, bound: float = math.inf, deadline: float = math.inf
):
    """C(tau(a)) in this worker: (Evaluation, plan with its caches dropped).

    ``deadline`` (``time.time()``, the search's time budget): the local planner's own
    budget is cut to what is left of it; a candidate started after it is not planned.

    Early rejection with a finite ``bound`` (the best reaching candidate's C): after each
    step the terms that can only grow (path length, steps so far, planning time so far)
    are a lower bound of C; once it reaches ``bound`` planning stops, and the candidate
    costs that bound plus the distance term of where it stopped and the not-reached
    penalty (no plan kept).
    """
    from planner.planning.walk import PLANNERS

    pb: _Problem = _WORKER["problem"]
    robot, terrain = _WORKER["robot"], _WORKER["terrain"]
    settings = pb.settings
    left = deadline - time.time()
    if left < settings.time_budget_s:
        settings = replace(settings, time_budget_s=max(left, 1e-3))
    local = PLANNERS[pb.planner](robot, terrain, settings=settings)
    local._theta2, local._theta3 = _WORKER["theta2"], _WORKER["theta3"]  # built once
    tau0 = _tau0(local, pb.start_xy, pb.goal_xy, pb.tau0_xy)
    tau = candidate_trajectory(tau0, a_m, pb.start_xy, pb.goal_xy)
    w, t_start = pb.weights, time.perf_counter()
    d_start = float(np.hypot(*np.subtract(pb.goal_xy, pb.start_xy)))  # COM start to goal
    seen = {"distance_m": d_start, "steps": 0, "lower_bound": 0.0}

    def watch(distance_m: float, steps: int) -> None:
        t = time.perf_counter() - t_start
        lower = w.length_per_m * tau.length_m + w.per_step * steps + w.planning_per_s * t
        seen.update(distance_m=float(distance_m), steps=int(steps), lower_bound=lower)
        if lower >= bound:
            raise _Rejected(f"rejected after {steps} steps: C >= {lower:.2f} >= the best's")

    try:
        if left <= 0.0:  # as bad as a candidate that cannot start
            raise _Rejected("not planned: the global search's time budget is spent")
        result = local.plan(
            pb.start_xy, pb.goal_xy, tau=tau, progress=watch if math.isfinite(bound) else None
        )
    except _Rejected as exc:
        return _rejected(a_m, generation, str(exc), seen, tau, w, t_start), None
    except PlannerError as exc:  # e.g. no initial stance along this tau: as bad as no step
        return _unstarted(a_m, generation, str(exc), d_start, tau, pb.weights), None
    return _walked(a_m, generation, pb, robot, terrain, local, tau, result)


def _rejected(a_m, generation: int, message: str, seen: dict, tau, w, t_start: float):
    """The Evaluation of a candidate stopped early: the lower bound of C where it stopped.

    ``seen``: the distance left, steps and lower bound of C at the last step; plus the
    distance term and the not-reached penalty (no plan kept).
    """
    metrics = dict(
        _NO_WALK,
        steps=seen["steps"],
        planning_time_s=time.perf_counter() - t_start,
        distance_to_goal_m=seen["distance_m"],
        path_length_m=float(tau.length_m),
    )
    cost = seen["lower_bound"] + w.goal_per_m * seen["distance_m"] + w.not_reached
    return Evaluation(
        [float(v) for v in a_m], cost, validated=None, message=message,
        cost_terms={"rejected_lower_bound": seen["lower_bound"]}, generation=generation,
        **metrics,
    )  # fmt: skip


def _unstarted(a_m, generation: int, message: str, d_start: float, tau, weights):
    """The Evaluation of a candidate the local planner could not start: C of no step."""
    metrics = dict(_NO_WALK, distance_to_goal_m=d_start, path_length_m=float(tau.length_m))
    cost, terms = trajectory_cost(weights, **metrics)
    return Evaluation(
        [float(v) for v in a_m],
        cost,
        validated=None,
        message=message,
        cost_terms=terms,
        generation=generation,
        **metrics,
    )


def _walked(a_m, generation: int, pb: _Problem, robot, terrain, local, tau, result):
    """(Evaluation, plan with its caches dropped) of a candidate's walk, assembled and checked."""
    extra = {
        "planner": pb.planner,
        "tau": {"kind": tau.kind, "coefficients_m": list(a_m)},
        "settings": effective(local, pb.seed),
    }
    with shielded():
        plan, report = assemble_plan(
            robot, terrain, local.mu, pb.start_xy, pb.goal_xy, result, extra
        )
    _WORKER["report"] = (plan, report)  # the parent's tau0 keeps its check (not pickled)
    reached = bool(plan.outcome["reached_goal"])
    margin = stability_margin_m(robot, local.check, result.keyframes)
    metrics = {
        "reached": reached,
        "distance_to_goal_m": float(result.distance_to_goal_m),
        "steps": int(result.stats.get("steps", 0)),
        "walk_time_s": float(result.times[-1]),
        "planning_time_s": float(result.stats.get("planning_time_s", 0.0)),
        "path_length_m": float(tau.length_m),
        "stability_margin_m": margin,
    }
    cost, terms = trajectory_cost(pb.weights, **metrics)
    ev = Evaluation(
        coefficients_m=[float(v) for v in a_m],
        cost=cost,
        validated=report.ok,
        message=plan.outcome["message"],
        cost_terms=terms,
        generation=generation,
        **metrics,
    )
    plan._robot_cache = plan._terrain_cache = None  # picklable
    return ev, plan


# ---- the optimiser (eq. 16) ----------------------------------------------------------------
def plan_global_walk(
    robot="littledog",
    terrain="flat",
    goal_xy=(2.2, 0.0),
    start_xy=(0.2, 0.0),
    planner: str = "soft",
    settings: LocalSettings | None = None,
    global_settings: GlobalSettings | None = None,
    progress=None,
    mu: float | None = None,
):
    """Section 9: CMA-ES over the sine coefficients of tau; returns (plan, report).

    ``robot`` and ``terrain`` are names or paths (terrain may also be a loaded
    :class:`~planner.world.terrain.Terrain`); ``settings`` are the local planner's, its
    ``time_budget_s`` the budget of each candidate. ``progress(record)`` is called after
    each generation with that generation's history record. The plan of the cheapest
    candidate is returned, validated; ``plan.stats["global"]`` holds
    :meth:`GlobalResult.to_dict` (costs of tau0 and of the best tau, per-generation history).
    """
    import cma

    gs = global_settings or GlobalSettings()
    gs.check()
    robot, robot_model, t, base, start, goal = _walk_inputs(
        robot, terrain, start_xy, goal_xy, planner
    )
    spec = t.spec if mu is None else dict(t.spec, friction=float(mu))  # workers read the spec
    t_begin = time.perf_counter()
    tau0_xy, guide_note = None, "the straight line (guide off)"
    if gs.guide:
        tau0_xy, guide_note = guide_tau0_xy(robot_model, t, start, goal)
    problem = _Problem(
        robot, spec, base, planner, settings or LocalSettings(), start, goal, gs.weights, gs.seed,
        tau0_xy,
    )  # fmt: skip
    workers = gs.workers or os.cpu_count() or 1
    tau0, tau0_plan, tau0_checked = _evaluate_tau0(problem, gs.terms)
    history: list[dict] = [_tau0_record(tau0, gs, t_begin, guide_note)]
    best: tuple[Evaluation, object] | None = (tau0, tau0_plan) if tau0_plan else None
    if progress is not None:
        progress(history[-1])
    stop = "tau0 reached the goal (no search)" if tau0.reached and not gs.refine_reached else ""
    es = cma.CMAEvolutionStrategy(
        np.zeros(gs.terms),
        gs.sigma0_m,
        {
            "popsize": gs.popsize,
            "seed": gs.seed,
            "bounds": [-gs.bound_m, gs.bound_m],
            "verbose": -9,
            "maxiter": gs.max_generations,
        },
    )
    best, n_eval, generation, stop = _search(
        es, problem, gs, workers, t_begin, best, history, progress, stop
    )
    if best is None:
        raise NoSolutionFound(f"global planning: no candidate tau got a plan ({tau0.message})")
    elapsed = time.perf_counter() - t_begin
    ev, plan = best
    res = GlobalResult(ev, tau0, history, n_eval, generation, elapsed, stop)
    return _checked_best(plan, res, tau0_checked, gs, guide_note, workers)


def _walk_inputs(robot, terrain, start_xy, goal_xy, planner: str):
    """(robot name or path, Robot, Terrain, its file's folder or None, start, goal), checked."""
    from planner.body.robot import load_robot
    from planner.planning.walk import PLANNERS, check_endpoints
    from planner.world.terrain import Terrain, load_terrain

    if planner not in PLANNERS:
        raise InputError(f"planner: unknown '{planner}'; available: {', '.join(PLANNERS)}")
    if not isinstance(robot, str):
        robot = str(robot.urdf_path)
    if isinstance(terrain, Terrain):
        t = terrain
        base = None
    else:
        t = load_terrain(terrain)
        base = str(Path(t.source).resolve().parent) if Path(t.source).is_file() else None
    start = (float(start_xy[0]), float(start_xy[1]))
    goal = (float(goal_xy[0]), float(goal_xy[1]))
    lateral_coefficients(np.zeros(1), start, goal)  # start != goal
    robot_model = load_robot(robot)
    check_endpoints(robot_model, t, start, goal)
    return robot, robot_model, t, base, start, goal


def _evaluate_tau0(problem: _Problem, terms: int):
    """(Evaluation, plan, (plan, report) of its check) of tau0, evaluated in this process."""
    _load(problem)  # tau0 here: with the guide path it is often all there is to do
    try:
        tau0, tau0_plan = _evaluate([0.0] * terms, 0)
        tau0_checked = _WORKER.get("report")
    finally:
        _WORKER.clear()
    return tau0, tau0_plan, tau0_checked


def _tau0_record(tau0: Evaluation, gs: GlobalSettings, t_begin: float, guide_note: str) -> dict:
    """The history record of generation 0: tau0 alone."""
    return {
        "generation": 0,
        "evaluations": 1,
        "elapsed_s": time.perf_counter() - t_begin,
        "best_cost": tau0.cost,
        "best_reached": bool(tau0.reached),
        "best_coefficients_m": tau0.coefficients_m,
        "generation_costs": [round(tau0.cost, 3)],
        "generation_reached": int(tau0.reached),
        "sigma": gs.sigma0_m,
        "tau0_cost": tau0.cost,
        "tau0_kind": guide_note,
    }


def _search(
    es, problem, gs: GlobalSettings, workers: int, t_begin: float, best, history, progress, stop
):
    """CMA-ES generations in a process pool until ``stop`` says why (eq. 16).

    Appends each generation's record to ``history`` (and gives it to ``progress``);
    returns (best (Evaluation, plan) or None, evaluations, generations, stop reason).
    Ctrl-C keeps the best plan so far (raises on without one).
    """
    n_eval, generation, stale = 1, 0, 0
    ctx = mp.get_context("spawn")  # no fork of a process holding CasADi/threads
    pool = None if stop else ProcessPoolExecutor(workers, ctx, _init_worker, (problem,))
    try:
        while not stop:
            generation += 1
            xs = es.ask()
            results = _generation(pool, xs, generation, best, gs, t_begin)
            n_eval += len(results)
            prev = best[0].cost if best is not None else math.inf
            for r in results:  # the cheapest candidate that has a plan
                if r[1] is not None and (best is None or r[0].cost < best[0].cost):
                    best = r
            es.tell(xs, [ev.cost for ev, _ in results])
            if best is not None and best[0].reached:
                stale = stale + 1 if prev - best[0].cost <= gs.tol else 0
            record = _generation_record(generation, n_eval, t_begin, best, results, es)
            history.append(record)
            if progress is not None:
                progress(record)
            stop = _stop_reason(gs, es, best, stale, generation, t_begin)
    except KeyboardInterrupt:
        stop = f"interrupted in generation {generation}; the best plan so far is kept"
        procs = list((getattr(pool, "_processes", None) or {}).values())  # before shutdown
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            proc.terminate()
        if best is None:
            raise
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
    return best, n_eval, generation, stop


def _generation(pool, xs, generation: int, best, gs: GlobalSettings, t_begin: float) -> list:
    """A generation's candidates ``xs`` evaluated in the pool: [(Evaluation, plan or None)].

    Bounded by the best reaching candidate's C (early rejection) and by what is left of
    the search's time budget.
    """
    cands = [[float(v) for v in x] for x in xs]
    bound = best[0].cost if best is not None and best[0].reached else math.inf
    n = len(cands)
    deadline = time.time() + gs.time_budget_s - (time.perf_counter() - t_begin)
    return list(pool.map(_evaluate, cands, [generation] * n, [bound] * n, [deadline] * n))


def _generation_record(generation: int, n_eval: int, t_begin: float, best, results, es) -> dict:
    """The history record of a generation (the best so far and this generation's costs)."""
    return {
        "generation": generation,
        "evaluations": n_eval,
        "elapsed_s": time.perf_counter() - t_begin,
        "best_cost": best[0].cost if best else math.inf,
        "best_reached": bool(best and best[0].reached),
        "best_coefficients_m": best[0].coefficients_m if best else [],
        "generation_costs": [round(ev.cost, 3) for ev, _ in results],
        "generation_reached": sum(ev.reached for ev, _ in results),
        "sigma": float(es.sigma),
    }


def _stop_reason(gs: GlobalSettings, es, best, stale: int, generation: int, t_begin: float) -> str:
    """Why the search stops after this generation, or "" to go on."""
    if best is not None and best[0].reached and (gs.patience == 0 or stale >= gs.patience):
        if gs.patience == 0:
            return "a candidate reached the goal (patience 0)"
        return f"no improvement over {gs.tol:g} for {gs.patience} generations"
    if generation >= gs.max_generations:
        return f"max_generations ({gs.max_generations})"
    if time.perf_counter() - t_begin > gs.time_budget_s:
        return f"time budget ({gs.time_budget_s:.0f} s)"
    if es.stop():
        return "CMA-ES: " + ", ".join(es.stop())
    return ""


def _checked_best(
    plan, res: GlobalResult, tau0_checked, gs: GlobalSettings, guide_note: str, workers: int
):
    """(plan, report): the best plan checked (tau0's check reused), its stats completed."""
    from planner.planfile.validate import check_plan

    if tau0_checked is not None and tau0_checked[0] is plan:  # checked here already
        report = tau0_checked[1]
    else:
        report = check_plan(plan)  # the parent's own check of a worker's plan
    plan.stats["validation"] = {"ok": report.ok, "violations": report.by_kind()}
    if not report.ok:
        plan.outcome["reached_goal"] = False
    plan.stats["global"] = res.to_dict() | {"tau0_kind": guide_note}
    plan.stats["global"]["settings"] = {k: v for k, v in asdict(gs).items() if k != "weights"} | {
        "weights": asdict(gs.weights),
        "workers": workers,
    }
    return plan, report


def print_progress(record: dict, file=None) -> None:
    """A one-line report of a generation on stderr (for ``stratawalk plan --global``)."""
    file = file or sys.stderr
    if record["generation"] == 0:
        reached = "reached" if record["best_reached"] else "not reached"
        print(
            f"tau0 ({record.get('tau0_kind', 'the straight line')}): "
            f"C = {record['tau0_cost']:.2f} ({reached}), {record['elapsed_s']:.0f} s",
            file=file,
            flush=True,
        )
        return
    reached = "reached" if record["best_reached"] else "not reached"
    print(
        f"generation {record['generation']}: {record['evaluations']} evaluations, "
        f"best C = {record['best_cost']:.2f} ({reached}, "
        f"a = {np.round(record['best_coefficients_m'], 3).tolist()} m), "
        f"{record['generation_reached']} reached this generation, "
        f"{record['elapsed_s']:.0f} s",
        file=file,
        flush=True,
    )
