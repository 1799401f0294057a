"""The ``stratawalk`` command line (DESIGN.md section 3)."""

from __future__ import annotations

import argparse
import math
import re
import sys

import numpy as np

from planner.core.errors import InputError, PlannerError, RobotModelError
from planner.core.outputs import ROBOT_HELP


def robot_summary(robot) -> str:
    """Human-readable summary: legs, joints, limits, masses, reach, normal stance."""
    from planner.body.kinematics import kinematics_of

    kin = kinematics_of(robot)
    lines = [
        f"robot {robot.name}  ({robot.urdf_path})",
        f"  total mass {robot.total_mass_kg:.3f} kg, body {robot.body_mass_kg:.3f} kg "
        f"(COM {np.round(robot.body_com_B, 4).tolist()} m in body frame)",
        f"  foot radius {robot.foot_radius_m:.4f} m ({robot.foot_radius_source}); "
        "body box P [m, body frame] "
        f"min {np.round(robot.body_box_B[0], 4).tolist()} max "
        f"{np.round(robot.body_box_B[1], 4).tolist()} ({robot.body_box_source})",
    ]
    for leg in robot.legs:
        knee = "forward" if leg.knee_direction > 0 else "rearward"
        lines.append(
            f"  leg {leg.index + 1} {leg.name}: foot frame '{leg.foot_frame}', reach "
            f"{robot.reach_m[leg.index]:.3f} m, knee points {knee}"
        )
        for j in range(3):
            lines.append(
                f"    {leg.joint_names[j]:<22} axis {np.round(leg.axes_B[j], 3).tolist()} at "
                f"{np.round(leg.points_B[j], 4).tolist()}  limits [{leg.lower_rad[j]:+.3f}, "
                f"{leg.upper_rad[j]:+.3f}] rad  theta_nor {robot.theta_nor[leg.index, j]:+.3f}"
            )
    feet = kin.feet_B(robot.theta_nor)
    stand = -feet[:, 2].max() + robot.foot_radius_m
    com = kin.com_B(robot.theta_nor)
    lines.append(
        f"  standing pose (theta_nor on flat ground): body origin {stand:.3f} m above ground, "
        f"whole-body COM {np.round(com, 4).tolist()} m in body frame, body clearance "
        f"{stand + robot.body_box_B[0, 2]:.3f} m"
    )
    lines.append("  feet at theta_nor [m, body frame]: " + str(np.round(feet, 4).tolist()))
    return "\n".join(lines)


def _cmd_robot(args) -> int:
    from planner.body.robot import load_robot, resolve_urdf, robot_names

    if args.list:
        if args.robot is not None:
            raise InputError("--list: lists every robot; give it without a robot name")
        from planner.body.servo_model import servo_model

        print(f"{'robot':12s} {'mass kg':>8s} {'reach m':>8s} {'foot mm':>8s} "
              f"{'servo kp N m/rad':>16s}  URDF")  # fmt: skip
        for name in robot_names():
            try:
                where = str(resolve_urdf(name)[1])
                r = load_robot(name)
            except RobotModelError as exc:  # example-robot-data's folder is missing
                print(f"{name:12s} (unavailable: {exc})")
                continue
            derived = "" if r.foot_radius_source == "urdf collision sphere" else " *"
            print(
                f"{name:12s} {r.total_mass_kg:8.2f} {float(np.mean(r.reach_m)):8.3f} "
                f"{1000 * r.foot_radius_m:6.1f}{derived or '  '} "
                f"{servo_model(r).kp_nm_per_rad:16.1f}  {where}"
            )
        print("* foot radius 0.1 x the shank (no sphere foot in the URDF); servo kp: LittleDog's "
              "scaled by mass x reach (planner.body.servo_model)")  # fmt: skip
        return 0
    if args.robot is None:
        raise InputError("robot: give a robot name (see stratawalk robot --list) or a URDF path")
    print(robot_summary(load_robot(args.robot)))
    return 0


def _cmd_terrain(args) -> int:
    from planner.world.terrain import list_terrains, load_terrain

    if args.name is None:
        print("\n".join(list_terrains()))
        return 0
    if args.png is not None:
        from planner.core.outputs import check_file

        check_file(args.png, "--png", suffixes=(".png",))
    terrain = load_terrain(args.name)
    print(f"terrain {terrain.name}: bounds {terrain.bounds}")
    if args.png is not None and args.guide is not None:  # the robot's cost map and the guide path
        from planner.body.robot import load_robot
        from planner.motion.guide_path import guide_path
        from planner.replay.terrain_plot import plot_guide_map

        start, goal = _parse_xy(args.start, "start"), _parse_xy(args.guide, "guide")
        g = guide_path(load_robot(args.robot), terrain, start, goal, height_m=0.0)
        what = g.message or f"guide path {g.tau.length_m:.2f} m"
        title = (
            f"{terrain.name}: cost map for {args.robot} (max step {100 * g.map.max_step_m:.1f} "
            f"cm, half-width {100 * g.map.half_width_m:.1f} cm); {what}"
        )
        plot_guide_map(g.map, g.xy_W if g.tau is not None else None, args.png, title)
        print(f"{what}; wrote {args.png}")
    elif args.png is not None:
        from planner.replay.terrain_plot import plot_top_view

        plot_top_view(terrain, args.png)
        print(f"wrote {args.png}")
    return 0


def _cmd_check(args) -> int:
    from planner.planfile.validate import main_check

    return main_check(args.plan, robot=args.robot, show_all=args.all)


def _parse_xy(text: str, field: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"--{field}: expected X,Y in metres (e.g. 2.2,0), got '{text}'") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise InputError(f"--{field}: expected finite X,Y in metres, got '{text}'")
    return x, y


_XY_OPTIONS = ("--goal", "--start")


def _join_negative_xy(argv: list[str]) -> list[str]:
    """``--goal -1.0,0`` as ``--goal=-1.0,0`` (argparse takes ``-1.0,0`` for an option)."""
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a in _XY_OPTIONS and i + 1 < len(argv) and re.match(r"^-\.?\d", argv[i + 1]):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


def _user_settings(args, robot):
    """The plan command's settings: --preset, --config file, then the options."""
    from planner.body.robot_scale import length_scale
    from planner.planning.settings import SETTINGS, load_config, preset, resolve

    config = preset(args.preset, length_scale(robot)) if args.preset else {}
    config.update(load_config(args.config) if args.config else {})
    options = {st.name: getattr(args, _dest(st)) for st in SETTINGS}
    return resolve(config, options)


def _dest(setting) -> str:
    return setting.option.lstrip("-").replace("-", "_")


def _cmd_plan(args) -> int:
    import time
    from dataclasses import replace

    from planner.body.robot import load_robot
    from planner.core.interrupts import Interrupts
    from planner.core.outputs import check_file
    from planner.planning.walk import plan_walk
    from planner.world.terrain import load_terrain

    robot, terrain = load_robot(args.robot), load_terrain(args.terrain)
    user = _user_settings(args, robot)
    settings = replace(user.local, theta=replace(user.local.theta, jit=args.jit))
    if args.print_config:
        return _print_config(args, robot, terrain, user, settings)
    goal, start = _plan_endpoints(args, robot, terrain)
    # the plan file is mostly its terrain grid: 5 mm cells over the walk and 0.3 m around
    cells = (abs(goal[0] - start[0]) + 1.3) * (abs(goal[1] - start[1]) + 1.0) / 0.005**2
    check_file(args.out, "--out", size_b=20 * cells + 2**20)
    t0 = time.perf_counter()
    total = float(np.hypot(goal[0] - start[0], goal[1] - start[1]))
    furthest = [0.0]

    def progress(dist_m: float, steps: int) -> None:
        # the furthest the COM has come towards the goal: monotone, though a step may
        # take the COM back a little (e.g. over a more centred support)
        furthest[0] = max(furthest[0], min(1.0, 1 - dist_m / max(total, 1e-9)))
        if args.quiet:
            return
        done = furthest[0]
        bar = "#" * int(30 * done)
        print(
            f"\r[{bar:<30}] {100 * done:5.1f}%  {steps} steps  {time.perf_counter() - t0:6.1f} s",
            end="",
            file=sys.stderr,
            flush=True,
        )

    # Ctrl-C / SIGTERM: the plan so far is saved, exit 130 / 143 (global planning waits on a
    # pool's map, so there the signal interrupts at once)
    with Interrupts(cooperative=not args.global_plan) as stop:
        if getattr(args, "global_plan", False):  # section 9: CMA-ES over tau
            from planner.planning.global_plan import (
                GlobalSettings,
                plan_global_walk,
                print_progress,
            )

            gs = GlobalSettings(
                terms=args.terms,
                max_generations=args.generations,
                seed=user.seed,
                guide=not args.no_guide,
            )
            plan, report = plan_global_walk(
                args.robot, terrain, goal, start, args.planner, settings, gs,
                None if args.quiet else print_progress, user.mu,
            )  # fmt: skip
        else:
            plan, report = plan_walk(
                robot, terrain, goal, start, args.planner, settings, progress=progress, mu=user.mu
            )
        if not args.quiet:
            print(file=sys.stderr)
        with stop.shielded():
            path = plan.save(args.out)
    o = plan.outcome
    print(
        f"wrote {path}: {len(plan.keyframes)} keyframes, {len(plan.samples.time)} samples, "
        f"{plan.stats.get('steps')} steps, planning {plan.stats.get('planning_time_s', 0):.1f} s, "
        f"walk {plan.samples.time[-1]:.1f} s"
    )
    print(f"validation: {'ok' if report.ok else report.summary()}")
    print(("" if o["reached_goal"] else "goal NOT reached: ") + o["message"])
    if stop.exit_code is not None:
        return stop.exit_code
    return 0 if o["reached_goal"] else 1


def _print_config(args, robot, terrain, user, settings) -> int:
    """``plan --print-config``: every setting in effect, one ``name: value`` a line."""
    from planner.planning.settings import effective
    from planner.planning.walk import PLANNERS

    local = PLANNERS[args.planner](robot, terrain, mu=user.mu, settings=settings)
    for name, value in effective(local, user.seed).items():
        if value is None:
            shown = "none"
        elif isinstance(value, bool):
            shown = "on" if value else "off"
        elif isinstance(value, list):
            shown = ",".join(value)
        else:
            shown = value if isinstance(value, str) else f"{value:g}"
        print(f"{name}: {shown}")
    return 0


def _plan_endpoints(args, robot, terrain) -> tuple[tuple[float, float], tuple[float, float]]:
    """The plan's goal (a generated course's end without ``--goal``) and start, checked."""
    from planner.planning.walk import check_endpoints

    if args.goal is None and str(terrain.name).startswith(("gen:", "feat:")):
        from planner.world.course_gen import course_goal_xy

        goal = course_goal_xy(terrain.spec)  # a generated course: walk to its end
        print(f"goal: {goal[0]:g},{goal[1]:g} (the end of {terrain.name}; --goal to change)")
    elif args.goal is None:
        raise InputError("--goal: required; give X,Y in metres (e.g. --goal 2.2,0)")
    else:
        goal = _parse_xy(args.goal, "goal")
    start = _parse_xy(args.start, "start")
    if math.hypot(goal[0] - start[0], goal[1] - start[1]) < 1e-3:
        raise InputError(
            f"--goal {goal[0]:g},{goal[1]:g}: the start itself (--start {start[0]:g},"
            f"{start[1]:g}); give a goal at least 1 mm away from it"
        )
    check_endpoints(robot, terrain, start, goal, ("--start", "--goal"))
    return goal, start


def _cmd_demo(args) -> int:
    from planner.body.robot import load_robot
    from planner.core.outputs import check_file, check_folder

    out = check_folder(args.out, "--out", size_b=20 * 2**20)
    for name in ("plan.json", "replay.html"):
        check_file(out / name, "--out")
    check_folder(out / "figures", "--out")
    robot = load_robot("littledog")
    print(robot_summary(robot))
    print(f"\nplanning LittleDog 2 m over {args.terrain} (soft persuasion, section 8.2) ...")
    plan_args = build_parser().parse_args(  # every option of `plan`, at its default
        ["plan", "--terrain", args.terrain, "--goal", "2.2,0", "--out", str(out / "plan.json")]
    )
    rc = _cmd_plan(plan_args)
    print(f"plan: {out / 'plan.json'}  (check it: stratawalk check {out / 'plan.json'})")
    from planner.planfile.loader import load_plan
    from planner.replay import write_html
    from planner.replay.plots import plan_series, plot_plan

    plan = load_plan(out / "plan.json")
    series = plan_series(plan)
    write_html(plan, out / "replay.html", series=series)
    figures = plot_plan(plan, out / "figures", series=series)
    print(f"replay: {out / 'replay.html'}  (open it in a browser; no server needed)")
    print(f"figures: {', '.join(str(f) for f in figures)}")
    return rc


def _add_simulate_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``simulate plan.json [--feedback|--correct] [--time-scale S] [--out sim.json]``."""
    p = subparsers.add_parser(
        "simulate", help="execute a plan in MuJoCo (open loop, feedback 8.3, correction 8.4)"
    )
    p.add_argument("plan", help="plan.json written by `stratawalk plan`")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--feedback", action="store_true", help="re-plan each step from the measured state (8.3)"
    )
    mode.add_argument(
        "--correct",
        action="store_true",
        help="execute the plan, correcting each step from the measured state (8.4)",
    )
    p.add_argument(
        "--time-scale", type=float, default=1.0, help="simulated s per plan s (default 1)"
    )
    p.add_argument(
        "--no-feedforward",
        action="store_true",
        help="servos track the joint set-points only (no holding-torque feed-forward)",
    )
    p.add_argument("--timestep", type=float, default=0.001, help="physics step [s]")
    p.add_argument("--noise-mm", type=float, default=0.0, help="position noise sigma [mm]")
    p.add_argument("--noise-deg", type=float, default=0.0, help="angle noise sigma [deg]")
    p.add_argument("--latency", type=float, default=0.0, help="measurement latency [s]")
    p.add_argument("--seed", type=int, default=0, help="noise seed")
    p.add_argument(
        "--plan-steps-first",
        action="store_true",
        help="with --feedback: each step is first the plan's own, corrected (8.4)",
    )
    p.add_argument("--out", help="write the executed motion here (stratawalk.plan/1)")
    p.add_argument(
        "--trajectory",
        help="execute this `stratawalk export` file (CSV or npz) of the plan, open loop",
    )
    p.add_argument("--robot", metavar="URDF", help=ROBOT_HELP)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_simulate)
    return p


def _cmd_simulate(args) -> int:
    from planner.sim.execution import cmd_simulate

    return cmd_simulate(args)


def _add_export_parser(subparsers):
    """Add ``export plan.json --rate HZ --out FILE.csv|FILE.npz|BAG.bag [--format F]``."""
    p = subparsers.add_parser(
        "export",
        help="a plan as a fixed-rate trajectory (CSV, npz or ROS 2 bag) for a controller",
    )
    p.add_argument("plan", help="plan.json written by `stratawalk plan`")
    p.add_argument("--rate", type=float, default=500.0, help="rows per second (default 500)")
    p.add_argument(
        "--out",
        required=True,
        help="FILE.csv, FILE.npz, or a ROS 2 bag folder NAME.bag (rosbag2: metadata.yaml and "
        "an SQLite3 .db3; an earlier bag there is replaced)",
    )
    p.add_argument(
        "--format",
        choices=("csv", "npz", "rosbag2"),
        help="the output format (default: from the --out suffix); rosbag2: a ROS 2 bag "
        "folder of any name, written with the Python package rosbags",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="export at a --rate too low to reproduce every plan sample (with a warning)",
    )
    p.add_argument("--robot", metavar="URDF", help=ROBOT_HELP)
    p.set_defaults(func=_cmd_export)
    return p


def _cmd_export(args) -> int:
    """Run ``stratawalk export`` (planner/planfile/export.py, rosbag.py)."""
    from planner.core.outputs import check_file
    from planner.planfile.export import export_format, export_plan, export_rows, file_size_b
    from planner.planfile.loader import load_plan

    fmt = export_format(args.out, args.format)
    if fmt == "rosbag2":
        from planner.planfile import rosbag

        rosbag.require_rosbags()
        rosbag.check_bag(args.out, "--out")
    else:
        check_file(args.out, "--out", suffixes=(f".{fmt}",))
    plan = load_plan(args.plan, robot=args.robot)
    rows = export_rows(plan, args.rate)
    if fmt == "rosbag2":
        rosbag.check_bag(args.out, "--out", size_b=rosbag.bag_size_b(rows))
    else:
        check_file(args.out, "--out", size_b=file_size_b(rows, args.out))
    traj = export_plan(plan, args.rate, force=args.force)
    if traj.skipped:
        print(f"stratawalk: warning: {one_line(traj.skipped)}", file=sys.stderr)
    span = f"{len(traj.t)} rows at {traj.rate_hz:g} Hz, {traj.t[-1] - traj.t[0]:.2f} s"
    if fmt == "rosbag2":
        path, count = rosbag.write_rosbag(
            traj, args.out, base_frame=rosbag.root_link(plan.load_robot())
        )
        print(
            f"wrote {path}: ROS 2 bag (sqlite3), {span}, {count} messages on "
            f"{len(rosbag.TOPICS)} topics"
        )
    else:
        path = traj.save(args.out)
        print(f"wrote {path}: {span}, {len(traj.columns())} columns")
    return 0


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage block), exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {one_line(message)} (see {self.prog} --help)\n")


def one_line(text: object) -> str:
    """``text`` on one line: its line breaks (e.g. in a value given) written as escapes."""
    return str(text).replace("\r", "\\r").replace("\n", "\\n")


def build_parser() -> argparse.ArgumentParser:
    """Argument parser of the ``stratawalk`` command."""
    p = _Parser(prog="stratawalk", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser(
        "robot", help="summary of a robot: legs, joints, limits, masses, reach; or --list"
    )
    r.add_argument("robot", nargs="?", help="littledog, an example-robot-data name, or a URDF path")
    r.add_argument(
        "--list", action="store_true", help="the robots: mass, leg reach, foot, servo, URDF"
    )
    r.set_defaults(func=_cmd_robot)
    t = sub.add_parser("terrain", help="list terrains, or describe/draw one")
    t.add_argument(
        "name", nargs="?", help="terrain name (terrains/NAME.yaml), YAML or mesh (.stl/.obj/.ply)"
    )
    t.add_argument("--png", help="write a top view with height colours to this PNG")
    t.add_argument(
        "--guide", metavar="X,Y", help="with --png: draw ROBOT's cost map and the guide path to X,Y"
    )
    t.add_argument("--start", default="0.2,0", metavar="X,Y", help="the guide path's start")
    t.add_argument("--robot", default="littledog", help="the robot of --guide's cost map")
    t.set_defaults(func=_cmd_terrain)
    pl = sub.add_parser("plan", help="plan a walk and write a stratawalk.plan/1 file")
    pl.add_argument("--robot", default="littledog")
    pl.add_argument(
        "--terrain", required=True, help="terrain name, YAML or mesh (.stl/.obj/.ply) path"
    )
    pl.add_argument(
        "--goal", help="X,Y [m] (required unless --print-config; a gen:... course: its end)"
    )
    pl.add_argument("--start", default="0.2,0", help="X,Y [m] (default 0.2,0)")
    pl.add_argument(
        "--planner",
        default="soft",
        choices=["soft", "hard", "recursive", "greedy"],
        help="soft: 8.2 gait queue, tracing back at dead ends (default); hard: 8.1 search "
        "Omega; recursive: 8.5; greedy: 8.2 as the paper has it, no tracing back",
    )
    from planner.planning.settings import SETTINGS

    for st in SETTINGS:
        pl.add_argument(st.option, dest=_dest(st), help=f"{st.help}; YAML name {st.name}")
    pl.add_argument("--config", help="YAML file of settings (names as in --print-config)")
    pl.add_argument(
        "--preset",
        help="named settings under --config and the options: fast (issue 16: on level "
        "ground two body moves per crawl cycle, long strides, 1.5 m/s^2, 2 cm swings)",
    )
    pl.add_argument(
        "--print-config", action="store_true", help="print the settings in force and exit"
    )
    pl.add_argument("--out", default="plan.json")
    pl.add_argument("--quiet", action="store_true", help="no progress bar")
    pl.add_argument(
        "--jit",
        action="store_true",
        help="Theta NLPs compiled to C, cached per machine (first use on a terrain: "
        "seconds of compiling per problem, counted in the time budget)",
    )
    pl.add_argument(
        "--global",
        dest="global_plan",
        action="store_true",
        help="section 9: from the guide path around obstacles (or the straight line where it "
        "is clear), CMA-ES over sine-series trajectories if that does not reach "
        "(--time-budget per candidate)",
    )
    pl.add_argument(
        "--no-guide", action="store_true", help="--global from the straight line (the paper's tau0)"
    )
    pl.add_argument("--terms", type=int, default=3, help="sine terms of --global's tau")
    pl.add_argument("--generations", type=int, default=8, help="CMA-ES generations (--global)")
    pl.set_defaults(func=_cmd_plan)
    c = sub.add_parser("check", help="validate a plan independently (exit 1 on any violation)")
    c.add_argument("plan", help="plan.json written by `stratawalk plan`")
    c.add_argument("--robot", metavar="URDF", help=ROBOT_HELP)
    c.add_argument("--all", action="store_true", help="print every violation (default: 50)")
    c.set_defaults(func=_cmd_check)
    d = sub.add_parser("demo", help="the main job: LittleDog on a rough course")
    d.add_argument("--terrain", default="rough2cm")
    d.add_argument("--out", default="out/demo")
    d.set_defaults(func=_cmd_demo)
    from planner.bench.cli import add_bench_parser

    add_bench_parser(sub)
    from planner.replay import add_replay_parser

    add_replay_parser(sub)
    from planner.replay.plots import add_plot_parser

    add_plot_parser(sub)
    _add_simulate_parser(sub)
    from planner.bench.batch import add_batch_parser

    add_batch_parser(sub)
    from planner.cli.generate_course import add_generate_parser

    add_generate_parser(sub)
    _add_export_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point; planner errors become a one-line message and exit status 2."""
    argv = _join_negative_xy(list(sys.argv[1:] if argv is None else argv))
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except PlannerError as exc:
        print(f"stratawalk: error: {one_line(exc)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
