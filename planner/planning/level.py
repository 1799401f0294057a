"""Level ground: where a walk may take longer strides, fewer samples and lower swings.

Beyond the paper: on level ground (the terrain within ``LEVEL_TOL_M`` of the feet's
plane, that plane within ``LEVEL_SLOPE`` of horizontal) the settings' ``level_*`` values
apply: a longer stride (:meth:`planner.planning.targets.Targets.stride_at`), a lower swing
(:meth:`LevelGround.swing_clearance_m`), fewer samples per swing and body move, the
two-beat COM target (section 8.2's Lambda_c) and a higher body acceleration (the time law,
:mod:`planner.planning.timing`).

:class:`LevelGround` is a part of :class:`planner.planning.local.LocalPlanner`; it uses
the planner's ``robot``, ``terrain`` and ``settings``.
"""

from __future__ import annotations

import numpy as np

from planner.body.state import State
from planner.motion.heuristics import support_plane_W
from planner.motion.interpolate import default_clearance_m

__all__ = ["LEVEL_GRID_M", "LEVEL_SLOPE", "LEVEL_TOL_M", "LEVEL_WIDTH_M", "LevelGround"]

# stride_at: the ground under a long stride counts as level within these
LEVEL_TOL_M = 0.005  # heights off the feet's plane [m]
LEVEL_SLOPE = 0.09  # the feet's plane's gradient (5 degrees)
LEVEL_WIDTH_M = 0.03  # the swing track's half width [m]
LEVEL_GRID_M = 0.01  # spacing of the heights sampled [m]


class LevelGround:
    """Whether the ground under the feet or a swing's track is level, and what follows."""

    def level_under(self, state: State) -> bool:
        """Whether the ground under the four feet is level (:meth:`stride_at`'s test).

        The terrain every ``LEVEL_GRID_M`` over the feet's bounding box, and the feet,
        within ``LEVEL_TOL_M`` of the feet's plane, that plane within ``LEVEL_SLOPE``.
        """
        feet = np.asarray(state.feet_W, float).reshape(4, 3)
        lo, hi = feet[:, :2].min(axis=0), feet[:, :2].max(axis=0)
        xs = np.arange(lo[0], hi[0] + LEVEL_GRID_M, LEVEL_GRID_M)
        ys = np.arange(lo[1], hi[1] + LEVEL_GRID_M, LEVEL_GRID_M)
        pts = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
        return self._on_feet_plane(feet, pts)

    def _level_track(self, state: State, leg: int, touch_W) -> bool:
        """Whether the ground under ``leg``'s track to ``touch_W`` is level (stride_at's)."""
        feet = np.asarray(state.feet_W, float).reshape(4, 3)
        return self._on_feet_plane(feet, _track_xy(feet[leg], touch_W))

    def _on_feet_plane(self, feet: np.ndarray, pts: np.ndarray) -> bool:
        """The feet's plane is within LEVEL_SLOPE, the terrain at ``pts`` and the feet on it."""
        grad, centre = support_plane_W(feet)
        if float(np.linalg.norm(grad)) > LEVEL_SLOPE:
            return False
        pts = np.vstack([pts, feet[:, :2]])
        z = np.asarray(self.terrain.height_sharp(pts[:, 0], pts[:, 1]), float).reshape(-1)
        plane = centre[2] + (pts - centre[:2]) @ grad
        return float(np.max(np.abs(z - plane))) <= LEVEL_TOL_M

    def swing_clearance_m(self, state: State, leg: int, touch_W) -> float:
        """The swing height [m] of ``leg`` from ``state`` to ``touch_W``.

        ``level_clearance_m`` where the ground under the track is level (:meth:`stride_at`'s
        test), else ``clearance_m`` (default:
        :func:`planner.motion.interpolate.default_clearance_m`).
        """
        st = self.settings
        clearance = st.clearance_m or default_clearance_m(self.robot)
        if st.level_clearance_m is None or not self._level_track(state, leg, touch_W):
            return clearance
        return float(st.level_clearance_m)

    def swing_samples_at(self, state: State, leg: int, touch_W) -> int:
        """Samples of ``leg``'s swing: ``level_swing_samples`` over level ground."""
        st = self.settings
        if st.level_swing_samples is None or not self._level_track(state, leg, touch_W):
            return int(st.swing_samples)
        return int(st.level_swing_samples)

    def body_samples_at(self, state: State) -> int:
        """Samples of a body move from ``state``: ``level_body_samples`` over level ground."""
        st = self.settings
        if st.level_body_samples is None or not self.level_under(state):
            return int(st.body_samples)
        return int(st.level_body_samples)


def _track_xy(a_W, b_W) -> np.ndarray:
    """(K, 2) points every ``LEVEL_GRID_M`` along a foot's track, ``LEVEL_WIDTH_M`` aside."""
    a, b = np.asarray(a_W, float)[:2], np.asarray(b_W, float).reshape(-1)[:2]
    along = b - a
    n = max(int(np.ceil(np.linalg.norm(along) / LEVEL_GRID_M)), 1)
    side = np.array([-along[1], along[0]]) / max(float(np.linalg.norm(along)), 1e-9)
    offsets = np.arange(-LEVEL_WIDTH_M, LEVEL_WIDTH_M + 1e-9, LEVEL_GRID_M)
    pts = a + np.linspace(0.0, 1.0, n + 1)[:, None, None] * along
    return (pts + offsets[None, :, None] * side).reshape(-1, 2)
