"""``stratawalk generate-course``: a seeded random course or a ladder feature as YAML.

The command line of :mod:`planner.world.course_gen` (which draws the specs), kept apart so that
the generator does not import :mod:`planner.world.terrain`, which loads generated names with it.
"""

from __future__ import annotations

import argparse

from planner.world.course_gen import (
    _FEAT,
    DEFAULT_LENGTH_M,
    EXTRA_KINDS,
    FEATURE_KINDS,
    _check_kinds,
    course_goal_xy,
    course_spec,
    generate_course,
    write_course,
)


def add_generate_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``generate-course --seed S [--difficulty D] [--length L] [--kinds K,K] --out F``."""
    g = subparsers.add_parser(
        "generate-course", help="write a seeded random course (steps, gaps, stairs, ...) as YAML"
    )
    g.add_argument("--seed", type=int, default=0, help="random seed (integer >= 0)")
    g.add_argument(
        "--difficulty", type=float, default=1.0, help="0 (easy) .. 1 (maxima) .. 1.5 (past them)"
    )
    g.add_argument(
        "--length", type=float, default=DEFAULT_LENGTH_M, help="[m] x where the features end"
    )
    g.add_argument(
        "--kinds",
        default=",".join(FEATURE_KINDS),
        help=f"feature kinds drawn, comma-separated, of {','.join(FEATURE_KINDS + EXTRA_KINDS)}",
    )
    g.add_argument("--feature", help="instead: one feature, KIND:SIZE (feat:KIND:SIZE, LADDER)")
    g.add_argument("--out", required=True, help="YAML file (or an existing folder)")
    g.add_argument("--png", help="also draw a top view to this PNG")
    g.set_defaults(func=cmd_generate)
    return g


def cmd_generate(args) -> int:
    """Run ``stratawalk generate-course``: write the spec, check that it loads."""
    import os

    from planner.core.outputs import check_file, check_folder

    try:  # an existing folder gets COURSE.yaml; anything else is the file's name
        folder = str(args.out).strip() != "" and os.path.isdir(args.out)
    except ValueError:  # a NUL character: check_file says so
        folder = False
    (check_folder if folder else check_file)(args.out, "--out")
    if args.png is not None:
        check_file(args.png, "--png", suffixes=(".png",))
    if args.feature:
        spec = course_spec(f"{_FEAT}:{args.feature}")
    else:
        kinds = _check_kinds(k for k in args.kinds.split(",") if k.strip())
        spec = generate_course(args.seed, args.length, args.difficulty, kinds)
    from planner.world.terrain import load_terrain  # CasADi: only when the command runs

    path = write_course(spec, args.out)
    terrain = load_terrain(path)
    kinds = [s["kind"] for s in terrain.spec["segments"][1:-1]]
    print(
        f"wrote {path}: {terrain.name}, bounds {terrain.bounds}, features {', '.join(kinds)}; "
        f"walk to {course_goal_xy(terrain.spec)}"
    )
    if args.png is not None:
        from planner.replay.terrain_plot import plot_top_view

        plot_top_view(terrain, args.png)
        print(f"wrote {args.png}")
    return 0
