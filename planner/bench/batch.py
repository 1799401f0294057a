"""Batch planning: many (robot, terrain, start, goal, planner, seed) jobs, on one machine or many.

``stratawalk batch scenarios.yaml --out DIR`` plans every job of the scenarios file with
:func:`planner.planning.walk.plan_walk` (local planner, plan assembly, independent validation) and
streams one JSON line per finished job to ``DIR/results.jsonl``:

- jobs run in a local process pool (``--workers``, default the machine's cores), or with
  ``--scheduler tcp://HOST:PORT`` on an existing Dask distributed cluster (a
  ``distributed.Client`` submits them; the cluster's workers need this package installed);
- a job's id is a hash of its fields (:func:`job_id`); a rerun reads the JSONL and skips
  every id already in it, so an interrupted batch resumes without losing or repeating a
  result (``--retry-errors`` runs failed jobs again);
- a job that raises is recorded with ``"status": "error"`` and its error; the others go on;
- a progress bar goes to stderr; ``--save-plans`` also writes ``DIR/plans/<id>.json``.

Scenarios file (YAML)::

    defaults:                       # optional; fills every job's missing fields
      robot: littledog              # name or URDF path
      start: [0.2, 0.0]             # [x, y] metres
      goal: [2.2, 0.0]
      planner: soft                 # soft | hard | recursive
      seed: 0                       # seeds numpy's global RNG in the job
      time_budget_s: 60             # the local planner's budget
    jobs:                           # explicit jobs ...
      - {terrain: flat, goal: [0.45, 0.0]}
    matrix:                         # ... and/or every combination of these lists
      terrain: [flat, rough2cm]
      planner: [soft, recursive]

Terrain and robot paths (``*.yaml``, ``*.urdf`` or containing ``/``) are relative to the
scenarios file. A malformed file gives a one-line :class:`~planner.core.errors.InputError`.
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import itertools
import json
import math
import multiprocessing as mp
import os
import signal
import socket
import sys
import time
import traceback
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from planner.core import interrupts
from planner.core.errors import InputError, OutputError
from planner.core.interrupts import Interrupts
from planner.core.outputs import check_folder

__all__ = [
    "DEFAULTS",
    "JOB_FIELDS",
    "BatchSummary",
    "add_batch_parser",
    "cmd_batch",
    "job_id",
    "load_scenarios",
    "read_results",
    "run_batch",
    "run_job",
]

JOB_FIELDS = ("robot", "terrain", "start", "goal", "planner", "seed", "time_budget_s")
DEFAULTS: dict[str, Any] = {
    "robot": "littledog",
    "start": [0.2, 0.0],
    "goal": [2.2, 0.0],
    "planner": "soft",
    "seed": 0,
    "time_budget_s": 60.0,
}
PLANNER_NAMES = ("soft", "hard", "recursive", "greedy", "global")  # global: 9 over soft
RESULTS_NAME = "results.jsonl"


# ---- jobs ----------------------------------------------------------------------------------
def job_id(job: dict) -> str:
    """16 hex digits of the SHA-256 of the job's fields (canonical JSON, sorted keys)."""
    canon = {k: job[k] for k in JOB_FIELDS}
    text = json.dumps(canon, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _looks_like_path(text: str) -> bool:
    return text.endswith((".yaml", ".yml", ".urdf")) or "/" in text or os.sep in text


def _check_job(raw: Any, source: str, where: str, base: Path) -> dict:
    """A complete, normalised job from ``raw`` (already merged over the defaults)."""

    def fail(fld: str, msg: str) -> InputError:
        return InputError(f"{source}: {where}.{fld}: {msg}")

    if not isinstance(raw, dict):
        raise InputError(f"{source}: {where}: expected a mapping of job fields, got {raw!r}")
    extra = sorted(set(raw) - set(JOB_FIELDS))
    if extra:
        raise fail(extra[0], f"unknown field; use only: {', '.join(JOB_FIELDS)}")
    if raw.get("terrain") is None:
        raise fail("terrain", "missing; give a terrain name (terrains/NAME.yaml) or a YAML path")
    job: dict[str, Any] = {}
    for fld in ("robot", "terrain"):
        v = raw.get(fld)
        if not isinstance(v, str) or not v.strip():
            raise fail(fld, f"expected a name or a path, got {v!r}")
        if _looks_like_path(v) and not Path(v).is_absolute():
            v = str((base / v).resolve())
        job[fld] = v
    for fld in ("start", "goal"):
        v = raw.get(fld)
        ok = (
            isinstance(v, (list, tuple))
            and len(v) == 2
            and all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)
                for c in v
            )
        )
        if not ok:
            raise fail(fld, f"expected [x, y] in metres, got {v!r}")
        job[fld] = [float(v[0]), float(v[1])]
    if job["start"] == job["goal"]:
        raise fail("goal", "equals start; move it")
    if raw.get("planner") not in PLANNER_NAMES:
        raise fail(
            "planner", f"expected one of {', '.join(PLANNER_NAMES)}, got {raw.get('planner')!r}"
        )
    job["planner"] = raw["planner"]
    seed = raw.get("seed")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise fail("seed", f"expected an integer >= 0, got {seed!r}")
    job["seed"] = seed
    tb = raw.get("time_budget_s")
    if isinstance(tb, bool) or not isinstance(tb, (int, float)) or not (tb > 0 and tb < 1e7):
        raise fail("time_budget_s", f"expected seconds > 0, got {tb!r}")
    job["time_budget_s"] = float(tb)
    return job


def load_scenarios(path: str | Path) -> list[dict]:
    """The jobs of a scenarios file (module docstring), duplicates removed, in file order.

    Raises
    ------
    InputError
        One line naming the file, the field and what to do.

    """
    path = Path(path)
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{source}: no such scenarios file; check the path") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{source}: cannot read it ({type(exc).__name__}); check it") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        what = getattr(exc, "problem", None) or "syntax error"
        raise InputError(f"{source}: not valid YAML{at}: {what}; fix the syntax") from None
    if not isinstance(data, dict):
        raise InputError(f"{source}: expected a mapping with 'jobs' and/or 'matrix' at the top")
    extra = sorted(set(data) - {"defaults", "jobs", "matrix"})
    if extra:
        raise InputError(
            f"{source}: {extra[0]}: unknown top-level field; use defaults, jobs, matrix"
        )
    defaults = data.get("defaults") or {}
    if not isinstance(defaults, dict):
        raise InputError(f"{source}: defaults: expected a mapping of job fields")
    bad = sorted(set(defaults) - set(JOB_FIELDS))
    if bad:
        raise InputError(
            f"{source}: defaults.{bad[0]}: unknown field; use only: {', '.join(JOB_FIELDS)}"
        )
    base_fields = DEFAULTS | defaults
    raws: list[tuple[str, Any]] = []
    jobs = data.get("jobs")
    if jobs is not None:
        if not isinstance(jobs, list):
            raise InputError(f"{source}: jobs: expected a list of mappings")
        for i, j in enumerate(jobs):
            if not isinstance(j, dict):
                raise InputError(
                    f"{source}: jobs[{i}]: expected a mapping of job fields, got {j!r}"
                )
            raws.append((f"jobs[{i}]", base_fields | j))
    matrix = data.get("matrix")
    if matrix is not None:
        if not isinstance(matrix, dict) or not matrix:
            raise InputError(f"{source}: matrix: expected a mapping of field: [values]")
        for k, v in matrix.items():
            if k not in JOB_FIELDS:
                raise InputError(
                    f"{source}: matrix.{k}: unknown field; use only: {', '.join(JOB_FIELDS)}"
                )
            if not isinstance(v, list) or not v:
                raise InputError(f"{source}: matrix.{k}: expected a non-empty list of values")
        keys = list(matrix)
        for n, combo in enumerate(itertools.product(*(matrix[k] for k in keys))):
            raws.append((f"matrix[{n}]", base_fields | dict(zip(keys, combo, strict=True))))
    if not raws:
        raise InputError(f"{source}: no jobs; add a 'jobs' list or a 'matrix'")
    out, seen = [], set()
    for where, raw in raws:
        job = _check_job(raw, source, where, path.resolve().parent)
        jid = job_id(job)
        if jid not in seen:
            seen.add(jid)
            out.append(job)
    return out


# ---- one job (runs in a worker process, local or Dask) -------------------------------------
_CACHE: dict[tuple[str, str], Any] = {}


def _cached(kind: str, name: str):
    """Robots and terrains loaded once per worker process."""
    key = (kind, name)
    if key not in _CACHE:
        if kind == "robot":
            from planner.body.robot import load_robot

            _CACHE[key] = load_robot(name)
        else:
            from planner.world.terrain import load_terrain

            _CACHE[key] = load_terrain(name)
    return _CACHE[key]


def run_job(job: dict, keep_plan: bool = False) -> dict:
    """Plan one job with :func:`planner.planning.walk.plan_walk`; never raises, returns its record.

    The record has the job and its id, ``status`` "ok" or "error" (with ``error`` and
    ``traceback``), and for "ok": ``reached`` (validated), ``validated``, ``violations``,
    ``distance_to_goal_m``, ``steps``, ``planning_time_s`` (the local planner's),
    ``walk_time_s`` (``plan.samples.time[-1]``), ``time_ratio`` (planning / walk),
    ``message``, ``longest_stall_cycles`` (the plan's stats), and for the recursive
    planner ``backtracks`` and ``retraces`` (steps undone in a window, committed windows
    planned again); ``wall_time_s``, ``host`` and ``pid``
    always. With ``keep_plan`` the plan
    itself is under ``plan`` (the caller writes it and drops it from the line).
    """
    import numpy as np

    t0 = time.perf_counter()
    rec: dict[str, Any] = {"id": job_id(job), "job": dict(job)}
    try:
        from planner.planning.local import LocalSettings
        from planner.planning.walk import plan_walk

        np.random.seed(int(job["seed"]))
        budget = float(job["time_budget_s"])
        where = (
            _cached("robot", job["robot"]),
            _cached("terrain", job["terrain"]),
            tuple(job["goal"]),
            tuple(job["start"]),
        )
        local = LocalSettings(time_budget_s=budget)
        if job["planner"] == "global":  # one worker: the batch runs jobs side by side
            from planner.planning.global_plan import GlobalSettings, plan_global_walk

            gs = GlobalSettings(workers=1, time_budget_s=budget, seed=max(1, int(job["seed"])))
            plan, report = plan_global_walk(*where, "soft", local, gs)
            # its planning time: the whole search (guide path, tau0, any CMA-ES generations)
            plan.stats["planning_time_s"] = float(plan.stats["global"]["elapsed_s"])
        else:
            plan, report = plan_walk(*where, job["planner"], local)
        walk_s = float(plan.samples.time[-1])
        plan_s = float(plan.stats.get("planning_time_s", float("nan")))
        rec.update(
            status="ok",
            reached=bool(plan.outcome["reached_goal"]),
            validated=bool(report.ok),
            violations=report.by_kind(),
            distance_to_goal_m=float(plan.outcome["distance_to_goal"]),
            steps=int(plan.stats.get("steps", 0)),
            planning_time_s=plan_s,
            walk_time_s=walk_s,
            time_ratio=plan_s / walk_s if walk_s > 0 else None,
            message=plan.outcome["message"],
            longest_stall_cycles=plan.stats.get("longest_stall_cycles"),
        )
        if "backtracks" in plan.stats:  # the recursive planner's tracing back (8.5)
            rec["backtracks"] = int(plan.stats["backtracks"])
            rec["retraces"] = int(plan.stats.get("window_retraces", 0))
        elif "retraces" in plan.stats:  # the soft planner's (none for greedy)
            rec["retraces"] = int(plan.stats["retraces"])
        if keep_plan:
            rec["plan"] = plan.to_dict()
    except Exception as exc:  # one failing job must not stop the others
        rec.update(
            status="error",
            error=f"{type(exc).__name__}: {exc}",
            traceback=traceback.format_exc(limit=-4),
        )
    rec.update(wall_time_s=time.perf_counter() - t0, host=socket.gethostname(), pid=os.getpid())
    return rec


# ---- the results file ----------------------------------------------------------------------
def read_results(path: str | Path) -> dict[str, dict]:
    """Records of a results JSONL by job id (the last one wins; broken lines are skipped)."""
    out: dict[str, dict] = {}
    p = Path(path)
    if not p.is_file():
        return out
    with p.open(encoding="utf-8") as fh:
        for line in fh:
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue  # a line cut short by an interruption
            if isinstance(rec, dict) and isinstance(rec.get("id"), str):
                out[rec["id"]] = rec
    return out


class _Writer:
    """Appends records to the JSONL, one line each, flushed and synced as they come.

    A write that fails (the disk filled up) is an :class:`OutputError`: the records
    written before stay, and a rerun goes on from them.
    """

    def __init__(self, path: Path, plans_dir: Path | None):
        self.path, self.plans_dir, self.written = path, plans_dir, 0
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            if plans_dir is not None:
                plans_dir.mkdir(parents=True, exist_ok=True)
            cut = path.is_file() and path.stat().st_size > 0
            cut = cut and not path.read_bytes().endswith(b"\n")
            self.fh = path.open("a", encoding="utf-8")
            if cut:  # the last line was cut short: end it, so it stays a lone broken line
                self.fh.write("\n")
        except OSError as exc:
            raise self._failed(exc) from None

    def _failed(self, exc: OSError) -> OutputError:
        return OutputError(
            f"--out {self.path.parent}: cannot write {self.path.name} ({exc.strerror or exc});"
            f" the {self.written} records written now stay, rerun to go on from them"
        )

    def write(self, rec: dict) -> None:
        plan = rec.pop("plan", None)
        if plan is not None and self.plans_dir is not None:
            from planner.planfile.plan import Plan

            rec["plan_file"] = str(Plan.from_dict(plan).save(self.plans_dir / f"{rec['id']}.json"))
        try:
            self.fh.write(json.dumps(_clean(rec), allow_nan=False) + "\n")
            self.fh.flush()
            os.fsync(self.fh.fileno())
        except OSError as exc:
            raise self._failed(exc) from None
        self.written += 1

    def close(self) -> None:
        try:
            self.fh.close()
        except OSError:  # a line cut short by a full disk: read_results skips it
            pass


def _clean(v):
    """JSON-safe copy: NaN/inf -> null, numpy scalars -> Python, unknown objects -> str."""
    if isinstance(v, dict):
        return {str(k): _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return v
    if isinstance(v, int):
        return int(v)
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    if f == int(f) and not isinstance(v, float) and abs(f) < 2**53:
        return int(f)
    return f if math.isfinite(f) else None


# ---- progress ------------------------------------------------------------------------------
class _Progress:
    """A one-line progress bar on stderr."""

    def __init__(self, total: int, skipped: int, stream=None, enabled: bool = True):
        self.total, self.skipped, self.done, self.errors = total, skipped, 0, 0
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.t0 = time.perf_counter()
        self.show()

    def update(self, rec: dict) -> None:
        self.done += 1
        self.errors += rec.get("status") != "ok"
        self.show()

    def show(self) -> None:
        if not self.enabled:
            return
        n = max(self.total, 1)
        k = self.done
        bar = "#" * int(30 * k / n)
        el = time.perf_counter() - self.t0
        print(
            f"\r[{bar:<30}] {k}/{self.total} jobs  {self.errors} errors  "
            f"{self.skipped} already done  {el:6.0f} s",
            end="",
            file=self.stream,
            flush=True,
        )

    def close(self) -> None:
        if self.enabled:
            print(file=self.stream, flush=True)


# ---- running -------------------------------------------------------------------------------
@dataclass
class BatchSummary:
    """What :func:`run_batch` did: jobs run now, skipped as done before, errors, records."""

    results_path: Path
    total: int
    skipped: int
    ran: int
    errors: int
    interrupted: bool
    records: dict[str, dict] = field(default_factory=dict)


def _error_record(job: dict, exc: BaseException) -> dict:
    return {
        "id": job_id(job),
        "job": dict(job),
        "status": "error",
        "error": f"{type(exc).__name__}: {exc}",
        "host": socket.gethostname(),
    }


def _init_worker(serial: bool) -> None:
    """Workers leave Ctrl-C to the parent, which stops them (a half-run job is no result).

    ``serial``: a worker per core already plans, so each plans without the overlap
    worker (:mod:`planner.planning.prefetch`): with one per planning process ``make test``
    (pytest -n auto, 2 cores) took 825 s against 763 s, 84 s more CPU.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if serial:
        from planner.planning.prefetch import ENV_OFF

        os.environ[ENV_OFF] = "0"


def run_pool(
    func: Callable[[dict], dict],
    jobs: list[dict],
    workers: int,
    error_record: Callable[[dict, BaseException], dict],
) -> Iterable[dict]:
    """``func(job)`` of every job in a pool of fresh (spawned) processes, as they finish.

    A job whose worker raised yields ``error_record(job, exc)``; Ctrl-C (or the consumer
    stopping) drops the running jobs and terminates the workers.
    """
    ctx = mp.get_context("spawn")  # fresh interpreters: no forked CasADi/IPOPT/MuJoCo state
    serial = workers >= (os.cpu_count() or 1)
    pool = ProcessPoolExecutor(
        max_workers=workers, mp_context=ctx, initializer=_init_worker, initargs=(serial,)
    )
    futs = {pool.submit(func, j): j for j in jobs}
    pending = set(futs)
    try:
        while pending:
            done, pending = wait(pending, timeout=0.25, return_when=FIRST_COMPLETED)
            for fut in done:
                try:
                    yield fut.result()
                except Exception as exc:  # e.g. a worker process died
                    yield error_record(futs[fut], exc)
            interrupts.check()  # Ctrl-C / SIGTERM under planner.core.interrupts: stop here
    except BaseException:  # Ctrl-C or the consumer stopped: drop the running jobs
        # the workers, taken before shutdown() forgets them (it sets _processes to None)
        procs = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            proc.terminate()
        for proc in procs:  # none outlives the batch: SIGKILL after 5 s
            proc.join(5.0)
            if proc.is_alive():
                proc.kill()
                proc.join(5.0)
        raise
    pool.shutdown(wait=True)


def _run_local(jobs, workers, keep_plan) -> Iterable[dict]:
    return run_pool(functools.partial(run_job, keep_plan=keep_plan), jobs, workers, _error_record)


def _connect(address: str, timeout_s: float = 10.0):
    """A ``distributed.Client`` of the scheduler at ``address``; one-line error if none."""
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - a pinned dependency
        raise InputError("--scheduler: needs the 'distributed' package; pip install it") from None
    try:
        return Client(address, timeout=f"{timeout_s}s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        why = " ".join(str(exc).split())[:160]
        raise InputError(
            f"--scheduler {address}: cannot connect ({type(exc).__name__}: {why}); start one "
            "with `dask scheduler` and `dask worker`, or drop --scheduler for a local pool"
        ) from None


def _run_dask(jobs, client, keep_plan) -> Iterable[dict]:
    from distributed import as_completed as dask_completed

    try:
        futs = {}
        for j in jobs:
            f = client.submit(run_job, j, keep_plan, key=f"stratawalk-{job_id(j)}", pure=False)
            futs[f.key] = (f, j)
        try:
            for fut in dask_completed([f for f, _ in futs.values()], loop=client.loop):
                try:
                    yield fut.result()
                except Exception as exc:  # a lost worker, a killed task
                    yield _error_record(futs[fut.key][1], exc)
        finally:
            client.cancel([f for f, _ in futs.values()])
    finally:
        client.close()


def run_batch(
    jobs: list[dict],
    out_dir: str | Path,
    scheduler: str | None = None,
    workers: int | None = None,
    retry_errors: bool = False,
    save_plans: bool = False,
    progress: bool = True,
    results_name: str = RESULTS_NAME,
    on_record: Callable[[dict], None] | None = None,
    connect_timeout_s: float = 10.0,
) -> BatchSummary:
    """Run the jobs not yet in ``out_dir/results.jsonl``, appending each record as it comes.

    ``scheduler`` ("tcp://host:port") runs them on that Dask cluster, else a local process
    pool of ``workers`` (default: the cores). Ctrl-C stops the batch; every record written
    so far stays, and a rerun goes on from there.
    """
    out = Path(out_dir)
    path = out / results_name
    done = read_results(path)
    if retry_errors:
        done = {k: v for k, v in done.items() if v.get("status") == "ok"}
    todo = [j for j in jobs if job_id(j) not in done]
    skipped = len(jobs) - len(todo)
    summary = BatchSummary(path, len(jobs), skipped, 0, 0, False)
    client = _connect(scheduler, connect_timeout_s) if scheduler and todo else None
    writer = _Writer(path, out / "plans" if save_plans else None)
    bar = _Progress(len(todo), skipped, enabled=progress)
    try:
        if todo:
            workers = workers or os.cpu_count() or 1
            stream = (
                _run_dask(todo, client, save_plans)
                if scheduler
                else _run_local(todo, min(workers, len(todo)), save_plans)
            )
            try:
                for rec in stream:
                    writer.write(rec)
                    summary.ran += 1
                    summary.errors += rec.get("status") != "ok"
                    bar.update(rec)
                    if on_record is not None:
                        on_record(rec)
            finally:
                stream.close()
    except KeyboardInterrupt:
        summary.interrupted = True
    finally:
        bar.close()
        writer.close()
        if client is not None:
            client.close()
    summary.records = read_results(path)
    return summary


# ---- command line --------------------------------------------------------------------------
def add_batch_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``batch SCENARIOS --out DIR [--scheduler tcp://H:P] [--workers N] ...``."""
    b = subparsers.add_parser(
        "batch", help="plan many scenarios (local process pool or a Dask cluster), resumable"
    )
    b.add_argument("scenarios", help="scenarios YAML (see planner/bench/batch.py)")
    b.add_argument("--out", required=True, help="output folder (results.jsonl, plans/)")
    b.add_argument("--scheduler", help="tcp://HOST:PORT of a running Dask scheduler")
    b.add_argument("--workers", type=int, default=None, help="local processes (default: cores)")
    b.add_argument("--retry-errors", action="store_true", help="run failed jobs again")
    b.add_argument("--save-plans", action="store_true", help="write OUT/plans/<id>.json")
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    b.set_defaults(func=cmd_batch)
    return b


def cmd_batch(args) -> int:
    """``stratawalk batch``: exit 0 when every job finished without error, 1 otherwise."""
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers: must be >= 1, got {args.workers}")
    check_folder(args.out, "--out")
    jobs = load_scenarios(args.scenarios)
    # Ctrl-C / SIGTERM: the running jobs are dropped, their workers stopped, every record
    # written stays; a second signal waits for that (exit 130 / 143)
    with Interrupts(cooperative=args.scheduler is None) as stop:
        s = run_batch(
            jobs,
            args.out,
            scheduler=args.scheduler,
            workers=args.workers,
            retry_errors=args.retry_errors,
            save_plans=args.save_plans,
            progress=not args.quiet,
        )
    recs = [s.records[job_id(j)] for j in jobs if job_id(j) in s.records]
    reached = sum(bool(r.get("reached")) for r in recs)
    errors = sum(r.get("status") != "ok" for r in recs)
    print(
        f"{s.results_path}: {len(recs)}/{s.total} jobs done ({s.ran} now, {s.skipped} before), "
        f"{reached} reached the goal, {errors} errors"
        + ("; interrupted: rerun the same command to resume" if s.interrupted else "")
    )
    if s.interrupted:
        return stop.exit_code or 130
    return 0 if errors == 0 and len(recs) == s.total else 1
