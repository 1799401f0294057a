"""The replay's animation as compact keyframe tracks (one value per plan sample).

meshcat-python's ``Animation`` stores each key as a ``{"time", "value"}`` map of float64
numbers, one Python call per key. Here every track is a numpy array over all samples, and
the ``set_animation`` command carries each track as three.js reads it natively
(``KeyframeTrack`` ``times`` and ``values``) in float32 typed arrays (msgpack extension 0x17,
which the meshcat viewer decodes to a ``Float32Array``).

Keys are dropped only inside runs where a track holds still: a key whose value equals both
neighbours' (after float32 rounding) adds nothing, since three.js interpolates between the
kept keys to the same value. Every sample is still reproduced to float32 precision (1 um at
10 m). Boolean (visibility) tracks keep the keys where the value changes. Every track keeps
a key at the first and last time of the walk: three.js loops each object's clip over its own
duration, so a shorter clip would run out of step with the others.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Tracks", "SetAnimation"]

_FLOAT32_EXT = 0x17  # meshcat viewer: msgpack extension type of a Float32Array
_WIDTH = {"vector3": 3, "quaternion": 4, "color": 3, "number": 1}


def _float32(x: NDArray) -> bytes:
    import umsgpack

    return umsgpack.Ext(_FLOAT32_EXT, np.ascontiguousarray(x, dtype="<f4").tobytes())


@dataclass
class Tracks:
    """Keyframe tracks of many scene paths over the same sample times ``times`` [s].

    Paths are meshcat paths relative to ``root`` (e.g. ``"robot/FL_upper_0"``, or ``""`` for
    the root itself); ``fps`` is the clip rate, so a key's time in the viewer is
    ``times / fps`` seconds (the playback speed-up).
    """

    root: str
    times: NDArray[np.float64]
    fps: float = 1.0
    end: float | None = None  # last key time of every track (default: times[-1])
    tracks: dict[str, dict[str, tuple[str, NDArray, NDArray]]] = field(default_factory=dict)

    def set(self, path: str, prop: str, jstype: str, values: ArrayLike, times=None) -> None:
        """A numeric track: ``values`` (n, width) at ``times`` (default: every sample)."""
        t = self.times if times is None else np.asarray(times, float)
        v = np.asarray(values, dtype=float).reshape(len(t), -1)
        if v.shape[1] != _WIDTH[jstype]:
            raise ValueError(f"{path}.{prop}: {jstype} needs width {_WIDTH[jstype]}")
        self.tracks.setdefault(path, {})[prop] = (jstype, t, v)

    def transform(self, path: str, matrices: NDArray, times=None) -> None:
        """Position and quaternion tracks from homogeneous transforms (n, 4, 4)."""
        from planner.core.lie import quat_from_rotation

        m = np.asarray(matrices, float)
        self.set(path, "position", "vector3", m[:, :3, 3], times)
        quats = np.array([quat_from_rotation(r) for r in m[:, :3, :3]])  # (x, y, z, w)
        self.set(path, "quaternion", "quaternion", quats, times)

    def visible(self, path: str, shown: ArrayLike, times=None) -> None:
        """A visibility track (keys where ``shown`` changes)."""
        t = self.times if times is None else np.asarray(times, float)
        self.tracks.setdefault(path, {})["visible"] = ("boolean", t, np.asarray(shown, bool))

    # -------------------------------------------------------------------- lowering
    def _keys(self, jstype: str, t: NDArray, v: NDArray) -> tuple[NDArray, NDArray]:
        """The kept (times, values) of one track, ending at :attr:`end`."""
        end = float(t[-1] if self.end is None else max(self.end, t[-1]))
        if t[-1] < end:  # hold the last value to the common end
            t = np.r_[t, end]
            v = np.concatenate([v, v[-1:]])
        if jstype == "boolean":
            keep = np.r_[True, v[1:] != v[:-1]]
        else:
            v32 = v.astype(np.float32)
            same = np.all(v32[1:] == v32[:-1], axis=1)
            keep = np.r_[True, ~(same[:-1] & same[1:]), True] if len(v) > 1 else np.ones(1, bool)
        keep[-1] = True
        return t[keep], v[keep]

    def lower(self) -> list[dict]:
        """The ``animations`` list of meshcat's ``set_animation`` (one clip per path)."""
        out = []
        for path, props in self.tracks.items():
            tracks = []
            for prop, (jstype, t, v) in props.items():
                tk, vk = self._keys(jstype, t, v)
                track = {"name": "." + prop, "type": jstype, "times": _float32(tk)}
                if jstype == "boolean":  # three.js keeps booleans in a plain array
                    track["values"] = [bool(x) for x in vk]
                else:
                    track["values"] = _float32(vk.reshape(-1))
                tracks.append(track)
            full = f"{self.root}/{path}" if path else self.root
            out.append({"path": full, "clip": {"fps": self.fps, "name": "default",
                                               "tracks": tracks}})  # fmt: skip
        return out


@dataclass
class SetAnimation:
    """The ``set_animation`` command of :class:`Tracks`.

    The viewer's animator plays it with play / pause / time controls; ``repetitions`` loops.
    """

    tracks: Tracks
    play: bool = True
    repetitions: int = 1

    def lower(self) -> dict:
        """The command as meshcat's viewer reads it."""
        return {
            "type": "set_animation",
            "animations": self.tracks.lower(),
            "options": {"play": self.play, "repetitions": self.repetitions},
            "path": "",
        }
