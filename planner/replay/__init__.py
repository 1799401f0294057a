"""See the walk: a plan replayed in meshcat, live or as one self-contained HTML file.

DESIGN.md section 2, step 6. The parts, one concept each:

- :mod:`planner.replay.scene`: :func:`build_scene` draws a plan (robot, terrain, feet,
  support polygon, COM, contact forces, stratum label, optionally a second motion such as its
  MuJoCo execution) into a :class:`Scene` of meshcat commands;
- :mod:`planner.replay.tracks`: the animation as compact float32 keyframe tracks;
- :mod:`planner.replay.page`: the scene as one HTML page (:func:`scene_html`,
  :func:`write_html`, :func:`notebook_html`);
- :mod:`planner.replay.server`: :class:`ReplayServer`, a meshcat server on loopback;
- :mod:`planner.replay.command`: the ``stratawalk replay`` command.
"""

from planner.replay.command import add_replay_parser, cmd_replay
from planner.replay.page import notebook_html, scene_html, write_html
from planner.replay.scene import GEOMETRIES, Scene, build_scene
from planner.replay.server import DEFAULT_HOST, ReplayServer, check_host, check_port

__all__ = [
    "DEFAULT_HOST",
    "GEOMETRIES",
    "ReplayServer",
    "Scene",
    "add_replay_parser",
    "build_scene",
    "check_host",
    "check_port",
    "cmd_replay",
    "notebook_html",
    "scene_html",
    "write_html",
]
