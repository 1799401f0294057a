"""The ``stratawalk bench`` command line: its sub-commands' parsers, with no heavy import.

Each benchmark lives in its own module (:mod:`planner.bench.theta` for the Theta programs,
:mod:`planner.bench.courses`, :mod:`planner.bench.physics`, :mod:`planner.bench.speed`,
:mod:`planner.bench.robots`) and is imported when its command runs, so ``stratawalk
--help`` does not load CasADi or Pinocchio.
"""

from __future__ import annotations

import argparse

__all__ = ["add_bench_parser"]


def _cmd_theta(args) -> int:
    from planner.bench.theta import cmd_bench

    return cmd_bench(args)


def add_bench_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``bench theta [--n N] [--out DIR] [--seed S] [--terrains a,b] [--slsqp-n M]``."""
    bench = subparsers.add_parser(
        "bench",
        help="benchmarks (theta: IPOPT vs SLSQP; courses: walks; physics: MuJoCo runs; "
        "speed; robots)",
    )
    sub = bench.add_subparsers(dest="bench_target", required=True)
    t = sub.add_parser("theta", help="Theta1-4: IPOPT vs SLSQP with finite differences")
    t.add_argument("--n", type=int, default=200, help="instances per Theta and terrain")
    t.add_argument("--out", default="bench/results", help="output folder")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--terrains", default="flat,rough2cm", help="comma-separated names")
    t.add_argument(
        "--slsqp-n", type=int, default=None, help="SLSQP on a seeded subset of this size"
    )
    t.add_argument(
        "--jit", action="store_true", help="also solve with the NLPs compiled to C (cached)"
    )
    t.set_defaults(func=_cmd_theta)
    from planner.bench.courses import add_courses_parser

    add_courses_parser(sub)
    from planner.bench.physics import add_physics_parser

    add_physics_parser(sub)
    from planner.bench.speed import add_speed_parser

    add_speed_parser(sub)
    from planner.bench.robots import add_robots_parser

    add_robots_parser(sub)
    return bench
