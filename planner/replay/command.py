"""``stratawalk replay``: write a plan's HTML replay, or serve it live until Ctrl-C."""

from __future__ import annotations

import argparse
import math
import time

from planner.core.interrupts import Interrupts
from planner.core.outputs import ROBOT_HELP, check_file
from planner.replay.page import write_html
from planner.replay.scene import GEOMETRIES, build_scene
from planner.replay.server import DEFAULT_HOST, ReplayServer, check_host, check_port

__all__ = ["add_replay_parser", "cmd_replay"]


def add_replay_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``replay plan.json [--html OUT] [--host H] [--port P] [--allow-remote] ...``."""
    p = subparsers.add_parser(
        "replay", help="play a plan in meshcat (browser), or write it as one HTML file"
    )
    p.add_argument("plan", help="plan.json written by `stratawalk plan`")
    p.add_argument("--html", help="write a self-contained HTML replay here instead of serving")
    p.add_argument("--host", default=DEFAULT_HOST, help="address to serve on (default 127.0.0.1)")
    p.add_argument(
        "--port", type=int, default=None, help="web port, 1..65535 (default: first free >= 7000)"
    )
    p.add_argument(
        "--allow-remote", action="store_true", help="allow a non-loopback --host (no auth!)"
    )
    p.add_argument("--speed", type=float, default=4.0, help="playback speed-up (default 4)")
    p.add_argument(
        "--geometry", choices=GEOMETRIES, default="visual", help="robot geometry of the URDF"
    )
    p.add_argument(
        "--seconds", type=float, default=None, help="stop serving after this long (default: Ctrl-C)"
    )
    p.add_argument("--open", action="store_true", help="open the page in a web browser")
    p.add_argument(
        "--fixed-camera",
        action="store_true",
        help="frame the whole walk once (default: the view follows the body)",
    )
    p.add_argument(
        "--compare",
        metavar="FILE",
        help="a second motion of the robot drawn see-through on the same clock, e.g. its "
        "MuJoCo execution: `replay plan.json --compare exec.json` after "
        "`simulate plan.json --out exec.json`",
    )
    p.add_argument("--robot", metavar="URDF", help=ROBOT_HELP)
    p.set_defaults(func=cmd_replay)
    return p


def cmd_replay(args) -> int:
    """Run ``stratawalk replay``: write the HTML file, or serve the walk until Ctrl-C."""
    from planner.planfile.loader import load_plan

    host = None if args.html else check_host(args.host, args.allow_remote)
    if args.html is not None:
        check_file(args.html, "--html", suffixes=(".html", ".htm"), size_b=4 * 2**20)
    else:
        check_port(host, args.port)
    plan = load_plan(args.plan, robot=args.robot)
    compare = None if args.compare is None else load_plan(args.compare, robot=args.robot)
    options = dict(
        speed=args.speed, geometry=args.geometry, follow=not args.fixed_camera, compare=compare
    )
    if args.html:
        path = write_html(plan, args.html, **options)
        print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB; open it in a browser)")
        return 0
    scene = build_scene(plan, **options)
    # Ctrl-C or SIGTERM end the replay (exit 0): the flag is polled, so a signal at any
    # moment, even while the server starts, stops the server subprocess and frees its ports
    with (
        Interrupts() as stop,
        ReplayServer(host, args.port, allow_remote=args.allow_remote) as server,
    ):
        server.show(scene)
        print(f"replay of {args.plan}: open {server.url}", flush=True)
        print("(play / pause / time: Open Controls > Animations; Ctrl-C to stop)", flush=True)
        if args.open:
            import webbrowser

            webbrowser.open(server.url, new=2)
        end = math.inf if args.seconds is None else time.monotonic() + max(0.0, args.seconds)
        while not stop.interrupted and time.monotonic() < end:
            time.sleep(min(0.2, max(0.0, end - time.monotonic())))
        if stop.interrupted:
            print("\nstopped", flush=True)
    return 0
