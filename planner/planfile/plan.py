"""The plan file ``stratawalk.plan/1`` (DESIGN.md section 3): build, save, load, rebuild.

A :class:`Plan` mirrors the JSON contract field for field: ``format``, ``robot``,
``terrain`` (the spec), ``terrain_grid`` (sharp heights covering the walk), ``friction``,
``start``, ``goal``, ``keyframes`` (the configurations Psi of the plan, paper sections 4.1
and 4.3, with legs 1-based in ``support``), ``samples`` (Pinocchio free-flyer ``q`` with
per-foot contact flags, the path sampled along the leaves, section 7.1), ``outcome`` and
``stats``.

Conventions: world frame, metres, radians, newtons; quaternions ``(x, y, z, w)``; legs FL,
FR, HL, HR (paper legs 1..4). ``keyframes[k].joints`` follow ``robot.joint_names``;
``samples.q[k][7:]`` follow Pinocchio's joint order (see :meth:`planner.body.robot.Robot.q_from`).
Foot points: a foot in contact is stored as its contact point r_i (sphere centre
``r_i + rho n``), a foot in the air as the point one radius below its sphere centre
(:mod:`planner.body.contact`). Samples do not store feet; :meth:`Plan.sample_states` rebuilds
them from ``q`` with Pinocchio forward kinematics.

Loading refuses a malformed file with a one-line :class:`~planner.core.errors.InputError`
naming the file and the field path (``plan.json: keyframes[3].joints: expected 12
numbers, got 11``). A file that parses yet is no motion (sample times that do not increase,
absurd coordinates) is refused by :func:`planner.planfile.loader.load_plan`, the loader of
the commands.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.body.state import State, contact_mask
from planner.core.errors import InputError

if TYPE_CHECKING:
    from planner.body.robot import Robot
    from planner.world.terrain import Terrain

__all__ = [
    "PLAN_FORMAT",
    "GRID_MARGIN_M",
    "GRID_RESOLUTION_M",
    "Keyframe",
    "Plan",
    "Samples",
    "TerrainGrid",
    "loaded_feet",
    "states_of_samples",
]

PLAN_FORMAT = "stratawalk.plan/1"
GRID_RESOLUTION_M = 0.005  # terrain_grid resolution [m] (the contract's upper bound)
GRID_MARGIN_M = 0.3  # terrain_grid covers the feet and base positions +- this [m]
QUAT_NORM_TOL = 1e-6  # a stored quaternion must have |q| within this of 1
N_JOINTS = 12
NQ = 19  # Pinocchio free-flyer q: xyz, quaternion xyzw, 12 joints
_HINT = "give a file written by `stratawalk plan`"

_Array = NDArray[np.float64]


# ------------------------------------------------------------------------------ parsing
class _Reader:
    """Field access with one-line errors ``<source>: <path>: <problem>; <hint>``."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, path: str, problem: str, hint: str = _HINT) -> InputError:
        text = f"{self.source}: {path}: {problem}" if path else f"{self.source}: {problem}"
        return InputError(f"{text}; {hint}" if hint else text)

    def obj(self, value: Any, path: str) -> dict:
        if not isinstance(value, dict):
            raise self.fail(path, f"expected a JSON object, got {_kind(value)}")
        return value

    def get(self, d: dict, key: str, path: str) -> Any:
        if key not in d:
            where = f"{path}.{key}" if path else key
            raise self.fail(where, "missing")
        return d[key]

    def number(self, value: Any, path: str, positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(path, f"expected a number, got {_kind(value)}")
        v = float(value)
        if not math.isfinite(v) or (positive and v <= 0.0):
            raise self.fail(path, f"expected a finite number{' > 0' if positive else ''}, got {v}")
        return v

    def string(self, value: Any, path: str) -> str:
        if not isinstance(value, str):
            raise self.fail(path, f"expected a string, got {_kind(value)}")
        return value

    def boolean(self, value: Any, path: str) -> bool:
        if not isinstance(value, bool):
            raise self.fail(path, f"expected true or false, got {_kind(value)}")
        return value

    def vector(self, value: Any, path: str, n: int) -> _Array:
        if not isinstance(value, list):
            raise self.fail(path, f"expected {n} numbers, got {_kind(value)}")
        if len(value) != n:
            raise self.fail(path, f"expected {n} numbers, got {len(value)}")
        return np.array([self.number(v, f"{path}[{i}]") for i, v in enumerate(value)])

    def matrix(self, value: Any, path: str, rows: int | None, cols: int) -> _Array:
        if not isinstance(value, list):
            raise self.fail(path, f"expected a list of [{cols} numbers], got {_kind(value)}")
        if rows is not None and len(value) != rows:
            raise self.fail(path, f"expected {rows} rows of {cols} numbers, got {len(value)} rows")
        if not value:
            return np.zeros((0, cols))
        return np.array([self.vector(r, f"{path}[{i}]", cols) for i, r in enumerate(value)])

    def strings(self, value: Any, path: str, n: int) -> list[str]:
        if not isinstance(value, list) or len(value) != n:
            got = len(value) if isinstance(value, list) else _kind(value)
            raise self.fail(path, f"expected {n} strings, got {got}")
        return [self.string(v, f"{path}[{i}]") for i, v in enumerate(value)]

    def quaternion(self, value: Any, path: str) -> _Array:
        q = self.vector(value, path, 4)
        norm = float(np.linalg.norm(q))
        if abs(norm - 1.0) > QUAT_NORM_TOL:
            raise self.fail(path, f"quaternion (x, y, z, w) has norm {norm:.9g}, expected 1")
        return q


def _kind(value: Any) -> str:
    """Short description of a JSON value for messages."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"{str(value).lower()}"
    if isinstance(value, (int, float)):
        return f"the number {value!r}"
    if isinstance(value, str):
        return f"the string {value[:40]!r}"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


def _finite(a: ArrayLike, what: str, shape: tuple[int, ...]) -> _Array:
    """Float array of ``shape``, finite, or ValueError naming ``what`` (for :meth:`build`)."""
    arr = np.asarray(a, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"Plan.build: {what}: expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"Plan.build: {what}: contains NaN or inf")
    return arr


def _jsonable(value: Any) -> Any:
    """Plain-JSON copy of free-form data (numpy to lists, non-finite floats to null)."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, Path):
        return str(value)
    return str(value)


# ------------------------------------------------------------------------------ parts
@dataclass(eq=False)
class TerrainGrid:
    """``terrain_grid``: sharp heights ``heights[iy, ix]`` [m] at ``origin + (ix, iy) * res``."""

    origin: _Array  # (2,) [x0, y0] [m]
    resolution: float  # [m], at most GRID_RESOLUTION_M
    heights: _Array  # (ny, nx) [m]

    def to_dict(self) -> dict:
        """JSON form."""
        return {
            "origin": [float(v) for v in self.origin],
            "resolution": float(self.resolution),
            "heights": self.heights.tolist(),
        }


@dataclass(eq=False)
class Keyframe:
    """One configuration Psi of the plan (``keyframes[k]`` of the contract).

    ``support`` holds 1-based legs, as in the file; ``joints`` (12,) follow
    ``robot.joint_names``; ``feet`` (4, 3) are contact points (or, for the swing leg, the
    point one radius below its sphere centre); ``forces`` (4, 3) [N] or None.
    """

    stratum: int
    base_position: _Array
    base_quaternion: _Array
    joints: _Array
    feet: _Array
    forces: _Array | None
    support: list[int]

    @classmethod
    def from_state(cls, state: State) -> Keyframe:
        """Keyframe of a :class:`~planner.body.state.State` (support made 1-based)."""
        return cls(
            stratum=int(state.stratum),
            base_position=_finite(state.base_position_W, "keyframe base_position", (3,)),
            base_quaternion=np.asarray(state.base_quaternion_xyzw, dtype=float),
            joints=_finite(state.joints_rad, "keyframe joints", (4, 3)).reshape(12),
            feet=_finite(state.feet_W, "keyframe feet", (4, 3)),
            forces=None
            if state.forces_W is None
            else _finite(state.forces_W, "keyframe forces", (4, 3)),
            support=[int(i) + 1 for i in state.support],
        )

    def to_dict(self) -> dict:
        """JSON form."""
        return {
            "stratum": int(self.stratum),
            "base_position": self.base_position.tolist(),
            "base_quaternion": self.base_quaternion.tolist(),
            "joints": self.joints.tolist(),
            "feet": self.feet.tolist(),
            "forces": None if self.forces is None else self.forces.tolist(),
            "support": [int(i) for i in self.support],
        }

    def to_state(self) -> State:
        """The keyframe as a :class:`~planner.body.state.State` (support back to 0-based)."""
        from planner.core.lie import rotation_from_quat

        return State(
            base_position_W=self.base_position.copy(),
            base_rotation_W=rotation_from_quat(self.base_quaternion),
            feet_W=self.feet.copy(),
            joints_rad=self.joints.reshape(4, 3).copy(),
            stratum=int(self.stratum),
            support=tuple(i - 1 for i in self.support),
            forces_W=None if self.forces is None else self.forces.copy(),
        )


@dataclass(eq=False)
class Samples:
    """``samples``: times [s], Pinocchio configurations ``q`` (N, 19), contact flags (N, 4)."""

    time: _Array  # (N,)
    q: _Array  # (N, 19)
    contact: NDArray[np.bool_]  # (N, 4)

    def __len__(self) -> int:
        return len(self.time)

    def to_dict(self) -> dict:
        """JSON form."""
        return {
            "time": self.time.tolist(),
            "q": self.q.tolist(),
            "contact": self.contact.astype(bool).tolist(),
        }


# ------------------------------------------------------------------------------ the plan
@dataclass(eq=False)
class Plan:
    """A plan in the ``stratawalk.plan/1`` format (DESIGN.md section 3), field for field.

    Build one with :meth:`build` from planner states, or read one with :meth:`load` /
    :meth:`from_dict`; write it with :meth:`save`. ``robot``, ``terrain``, ``outcome``
    and ``stats`` are the JSON objects as they are; the numeric parts are numpy arrays.
    """

    robot: dict
    terrain: dict
    terrain_grid: TerrainGrid
    friction: float
    start: _Array
    goal: _Array
    keyframes: list[Keyframe]
    samples: Samples
    outcome: dict
    stats: dict = field(default_factory=dict)
    format: str = PLAN_FORMAT
    source: str = field(default="<plan>", repr=False, compare=False)
    _robot_cache: Any = field(default=None, init=False, repr=False, compare=False)
    _terrain_cache: Any = field(default=None, init=False, repr=False, compare=False)

    # ---- building ---------------------------------------------------------------------
    @classmethod
    def build(
        cls,
        robot: Robot,
        terrain: Terrain,
        friction: float,
        start_W: ArrayLike,
        goal_W: ArrayLike,
        keyframes: Sequence[State],
        samples: Sequence[State],
        times: Sequence[float],
        outcome: dict,
        stats: dict | None = None,
        grid_resolution_m: float = GRID_RESOLUTION_M,
    ) -> Plan:
        """Assemble a plan from the planner's states (DESIGN.md section 3).

        Parameters
        ----------
        robot, terrain
            The robot and terrain planned for; ``terrain.spec`` is stored.
        friction
            mu used by the planner.
        start_W, goal_W
            (3,) start and goal [m], world frame.
        keyframes
            The configurations Psi of the plan (strata, stance feet, forces).
        samples
            The sampled path; each State's stratum gives its contact flags.
        times
            One time [s] per sample.
        outcome
            ``{"reached_goal": bool, "distance_to_goal": float, "message": str}``.
        stats
            Free-form; numpy values become lists, NaN/inf become null.
        grid_resolution_m
            ``terrain_grid`` resolution [m], at most 0.005.

        Raises
        ------
        ValueError
            Inconsistent lengths, non-finite numbers, or a bad outcome.

        """
        if len(times) != len(samples):
            raise ValueError(f"Plan.build: {len(samples)} samples but {len(times)} times")
        if not (0.0 < grid_resolution_m <= GRID_RESOLUTION_M):
            raise ValueError(
                f"Plan.build: grid_resolution_m must be in (0, {GRID_RESOLUTION_M}] m, "
                f"got {grid_resolution_m}"
            )
        kfs = [Keyframe.from_state(s) for s in keyframes]
        q = np.array(
            [robot.q_from(s.base_position_W, s.base_quaternion_xyzw, s.joints_rad) for s in samples]
        ).reshape(len(samples), robot.model.nq)
        q = _finite(q, "samples q", (len(samples), NQ))
        contact = np.array([contact_mask(s.stratum) for s in samples], dtype=bool).reshape(-1, 4)
        t = _finite(times, "times", (len(samples),))

        pts = [np.asarray(start_W, float).reshape(1, 3), np.asarray(goal_W, float).reshape(1, 3)]
        pts += [s.feet_W for s in (*keyframes, *samples)]
        pts += [s.base_position_W[None] for s in (*keyframes, *samples)]
        xyz = np.concatenate(pts)
        lo = np.floor((xyz[:, :2].min(axis=0) - GRID_MARGIN_M) / grid_resolution_m)
        hi = np.ceil((xyz[:, :2].max(axis=0) + GRID_MARGIN_M) / grid_resolution_m)
        x0, y0 = lo * grid_resolution_m
        x1, y1 = hi * grid_resolution_m
        origin, res, heights = terrain.height_grid(x0, x1, y0, y1, grid_resolution_m)

        missing = {"reached_goal", "distance_to_goal", "message"} - set(outcome)
        if missing:
            raise ValueError(f"Plan.build: outcome lacks {sorted(missing)}")
        out = dict(_jsonable(outcome))
        out["reached_goal"] = bool(outcome["reached_goal"])
        out["distance_to_goal"] = float(outcome["distance_to_goal"])
        out["message"] = str(outcome["message"])
        if not math.isfinite(out["distance_to_goal"]):
            raise ValueError("Plan.build: outcome distance_to_goal must be finite")

        plan = cls(
            robot={
                "name": robot.name,
                "urdf": str(Path(robot.urdf_path).resolve()),
                "legs": [leg.name for leg in robot.legs],
                "joint_names": list(robot.joint_names),
                "foot_frames": list(robot.foot_frames),
                "foot_radius": float(robot.foot_radius_m),
            },
            terrain=_jsonable(terrain.spec),
            terrain_grid=TerrainGrid(np.array(origin, float), float(res), np.asarray(heights)),
            friction=float(friction),
            start=_finite(start_W, "start_W", (3,)),
            goal=_finite(goal_W, "goal_W", (3,)),
            keyframes=kfs,
            samples=Samples(t, q, contact),
            outcome=out,
            stats=_jsonable(stats or {}),
        )
        plan._robot_cache, plan._terrain_cache = robot, terrain
        return plan

    # ---- JSON ---------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The plan as plain JSON data, keys in the contract's order."""
        return {
            "format": self.format,
            "robot": _jsonable(self.robot),
            "terrain": _jsonable(self.terrain),
            "terrain_grid": self.terrain_grid.to_dict(),
            "friction": float(self.friction),
            "start": self.start.tolist(),
            "goal": self.goal.tolist(),
            "keyframes": [k.to_dict() for k in self.keyframes],
            "samples": self.samples.to_dict(),
            "outcome": _jsonable(self.outcome),
            "stats": _jsonable(self.stats),
        }

    @classmethod
    def from_dict(cls, d: Any, source: str = "<plan>") -> Plan:
        """Parse and check a ``stratawalk.plan/1`` object.

        Raises
        ------
        InputError
            One line naming ``source`` and the field path at fault.

        """
        rd = _Reader(source)
        if not isinstance(d, dict):
            raise rd.fail(
                "", f'expected a JSON object with "format": "{PLAN_FORMAT}", got {_kind(d)}'
            )
        fmt = d.get("format")
        if fmt != PLAN_FORMAT:
            got = "missing" if "format" not in d else f"got {json.dumps(fmt)[:60]}"
            raise rd.fail("format", f'expected "{PLAN_FORMAT}", {got}')

        robot = rd.obj(rd.get(d, "robot", ""), "robot")
        rd.string(rd.get(robot, "name", "robot"), "robot.name")
        rd.string(rd.get(robot, "urdf", "robot"), "robot.urdf")
        rd.strings(rd.get(robot, "legs", "robot"), "robot.legs", 4)
        rd.strings(rd.get(robot, "joint_names", "robot"), "robot.joint_names", N_JOINTS)
        rd.strings(rd.get(robot, "foot_frames", "robot"), "robot.foot_frames", 4)
        rd.number(rd.get(robot, "foot_radius", "robot"), "robot.foot_radius")
        terrain = rd.obj(rd.get(d, "terrain", ""), "terrain")

        tg = rd.obj(rd.get(d, "terrain_grid", ""), "terrain_grid")
        origin = rd.vector(rd.get(tg, "origin", "terrain_grid"), "terrain_grid.origin", 2)
        res = rd.number(
            rd.get(tg, "resolution", "terrain_grid"), "terrain_grid.resolution", positive=True
        )
        if res > GRID_RESOLUTION_M + 1e-12:
            raise rd.fail(
                "terrain_grid.resolution", f"must be at most {GRID_RESOLUTION_M} m, got {res}"
            )
        raw_h = rd.get(tg, "heights", "terrain_grid")
        if not isinstance(raw_h, list) or not raw_h or not isinstance(raw_h[0], list):
            raise rd.fail("terrain_grid.heights", f"expected rows of numbers, got {_kind(raw_h)}")
        heights = rd.matrix(raw_h, "terrain_grid.heights", None, len(raw_h[0]))

        friction = rd.number(rd.get(d, "friction", ""), "friction", positive=True)
        start = rd.vector(rd.get(d, "start", ""), "start", 3)
        goal = rd.vector(rd.get(d, "goal", ""), "goal", 3)

        raw_kf = rd.get(d, "keyframes", "")
        if not isinstance(raw_kf, list):
            raise rd.fail("keyframes", f"expected a list of keyframes, got {_kind(raw_kf)}")
        keyframes = [cls._keyframe(rd, k, f"keyframes[{i}]") for i, k in enumerate(raw_kf)]

        sm = rd.obj(rd.get(d, "samples", ""), "samples")
        raw_t = rd.get(sm, "time", "samples")
        if not isinstance(raw_t, list):
            raise rd.fail("samples.time", f"expected a list of numbers, got {_kind(raw_t)}")
        n = len(raw_t)
        t = rd.vector(raw_t, "samples.time", n)
        q = rd.matrix(rd.get(sm, "q", "samples"), "samples.q", n, NQ)
        for i in range(n):
            rd.quaternion(q[i, 3:7].tolist(), f"samples.q[{i}][3:7]")
        raw_c = rd.get(sm, "contact", "samples")
        if not isinstance(raw_c, list) or len(raw_c) != n:
            got = f"{len(raw_c)} rows" if isinstance(raw_c, list) else _kind(raw_c)
            raise rd.fail("samples.contact", f"expected {n} rows of 4 booleans, got {got}")
        contact = np.zeros((n, 4), dtype=bool)
        for i, row in enumerate(raw_c):
            if not isinstance(row, list) or len(row) != 4:
                got = len(row) if isinstance(row, list) else _kind(row)
                raise rd.fail(f"samples.contact[{i}]", f"expected 4 booleans, got {got}")
            contact[i] = [rd.boolean(v, f"samples.contact[{i}][{j}]") for j, v in enumerate(row)]

        outcome = rd.obj(rd.get(d, "outcome", ""), "outcome")
        rd.boolean(rd.get(outcome, "reached_goal", "outcome"), "outcome.reached_goal")
        rd.number(rd.get(outcome, "distance_to_goal", "outcome"), "outcome.distance_to_goal")
        rd.string(rd.get(outcome, "message", "outcome"), "outcome.message")
        stats = rd.obj(d.get("stats", {}), "stats")

        return cls(
            robot=robot,
            terrain=terrain,
            terrain_grid=TerrainGrid(origin, res, heights),
            friction=friction,
            start=start,
            goal=goal,
            keyframes=keyframes,
            samples=Samples(t, q, contact),
            outcome=outcome,
            stats=stats,
            format=PLAN_FORMAT,
            source=source,
        )

    @staticmethod
    def _keyframe(rd: _Reader, k: Any, path: str) -> Keyframe:
        k = rd.obj(k, path)
        stratum = rd.get(k, "stratum", path)
        if isinstance(stratum, bool) or not isinstance(stratum, int) or stratum not in range(5):
            raise rd.fail(f"{path}.stratum", f"expected an integer 0..4, got {_kind(stratum)}")
        raw_f = rd.get(k, "forces", path)
        support = rd.get(k, "support", path)
        if (
            not isinstance(support, list)
            or not all(isinstance(i, int) and not isinstance(i, bool) for i in support)
            or not all(1 <= i <= 4 for i in support)
            or len(set(support)) != len(support)
        ):
            raise rd.fail(
                f"{path}.support", f"expected distinct leg numbers 1..4, got {json.dumps(support)}"
            )
        return Keyframe(
            stratum=stratum,
            base_position=rd.vector(rd.get(k, "base_position", path), f"{path}.base_position", 3),
            base_quaternion=rd.quaternion(
                rd.get(k, "base_quaternion", path), f"{path}.base_quaternion"
            ),
            joints=rd.vector(rd.get(k, "joints", path), f"{path}.joints", N_JOINTS),
            feet=rd.matrix(rd.get(k, "feet", path), f"{path}.feet", 4, 3),
            forces=None if raw_f is None else rd.matrix(raw_f, f"{path}.forces", 4, 3),
            support=list(support),
        )

    def save(self, path: str | Path) -> Path:
        """Write the plan as JSON (floats at full precision), atomically (temp file + rename).

        If that fails, the plan goes to the temporary folder and an
        :class:`~planner.core.errors.OutputError` says where
        (:func:`~planner.core.outputs.write_atomic`).
        """
        from planner.core.outputs import write_atomic

        text = json.dumps(self.to_dict(), allow_nan=False, separators=(",", ":")) + "\n"
        return write_atomic(path, lambda tmp: tmp.write_text(text, "utf-8"))

    @classmethod
    def load(cls, path: str | Path, robot: str | Path | None = None) -> Plan:
        """Read a plan file; one-line :class:`InputError` for anything malformed.

        ``robot``: a URDF (or robot name) to use instead of the plan's ``robot.urdf``
        (:meth:`use_robot`), e.g. when that file has moved.
        """
        if robot is not None:
            plan = cls.load(path)
            plan.use_robot(robot)
            return plan
        source = str(path)
        rd = _Reader(source)
        try:
            text = Path(path).read_text(encoding="utf-8")
        except FileNotFoundError:
            raise rd.fail(
                "", "no such file", "give the path of a plan written by `stratawalk plan`"
            ) from None
        except (OSError, UnicodeDecodeError) as exc:
            raise rd.fail("", f"cannot read it ({type(exc).__name__}: {exc})") from None
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise rd.fail(
                "", f"not JSON (line {exc.lineno}, column {exc.colno}): {exc.msg}"
            ) from None
        except RecursionError:
            raise rd.fail("", "not JSON (nested too deeply)") from None
        return cls.from_dict(data, source=source)

    # ---- rebuilding -------------------------------------------------------------------
    def load_robot(self) -> Robot:
        """The plan's robot: ``robot.urdf`` if that file exists, else ``robot.name``.

        Raises
        ------
        InputError
            Neither is found (a custom URDF moved): one line saying to pass ``--robot``
            (:meth:`use_robot`).

        """
        if self._robot_cache is None:
            from planner.body.robot import load_robot
            from planner.core.errors import RobotModelError

            urdf = str(self.robot.get("urdf", ""))
            if urdf and Path(urdf).is_file():
                self._robot_cache = load_robot(urdf)
            else:
                try:
                    self._robot_cache = load_robot(self.robot["name"])
                except RobotModelError:
                    raise InputError(
                        f"{self.source}: the plan's robot {self.robot['name']!r} was loaded from "
                        f"{urdf or 'a URDF'}, which is not there now, and is not a known robot "
                        "name; pass --robot PATH to its URDF"
                    ) from None
        return self._robot_cache

    def use_robot(self, urdf: str | Path) -> Robot:
        """Use the robot of ``urdf`` (e.g. its URDF moved) for this plan; return it.

        Raises
        ------
        InputError
            Its joints are not the plan's ``robot.joint_names``.

        """
        from planner.body.robot import load_robot

        robot = load_robot(urdf)
        names = list(robot.joint_names)
        want = list(self.robot.get("joint_names", names))
        if names != want:
            raise InputError(
                f"--robot {urdf}: its joints {names} are not the plan's {want}; give the URDF "
                f"the plan was made with"
            )
        self._robot_cache = robot
        self.robot = dict(self.robot, urdf=str(robot.urdf_path))
        return robot

    def load_terrain(self) -> Terrain:
        """The plan's terrain, rebuilt from its spec (``Terrain.from_spec``)."""
        if self._terrain_cache is None:
            from planner.world.terrain import Terrain

            self._terrain_cache = Terrain.from_spec(self.terrain, source=f"{self.source}: terrain")
        return self._terrain_cache

    def keyframe_states(self) -> list[State]:
        """The keyframes as :class:`~planner.body.state.State` (support 0-based)."""
        out = []
        for i, k in enumerate(self.keyframes):
            s = k.to_state()
            s.info["keyframe"] = i
            out.append(s)
        return out

    def foot_centres_W(self) -> _Array:
        """(N, 4, 3) foot sphere centres [m] of the samples, Pinocchio forward kinematics."""
        import pinocchio as pin

        robot = self.load_robot()
        model = robot.model
        data = model.createData()
        ids = [model.getFrameId(f) for f in robot.foot_frames]
        out = np.empty((len(self.samples), 4, 3))
        for k, q in enumerate(self.samples.q):
            pin.framesForwardKinematics(model, data, q)
            out[k] = [data.oMf[i].translation for i in ids]
        return out

    def sample_states(self) -> list[State]:
        """The samples as :class:`~planner.body.state.State`, feet rebuilt from ``q``.

        Feet are not stored per sample: each foot's sphere centre c comes from Pinocchio
        forward kinematics; a foot in contact gets the contact point ``c - rho n`` (the
        terrain normal n of whichever contact convention fits c better, see
        :func:`planner.body.contact.contact_points_from_centres`; the two agree on planar
        ground), a swing foot the point ``c - rho e_z``. The stratum comes from the contact flags;
        ``support`` is the feet in contact; ``info`` holds ``sample`` and ``time``.

        Raises
        ------
        ValueError
            A sample with fewer than three feet in contact (no stratum describes it).

        """
        return states_of_samples(
            self.load_robot(),
            self.load_terrain(),
            self.samples.q,
            self.samples.contact,
            self.samples.time,
            self.foot_centres_W(),
            source=self.source,
        )


def states_of_samples(
    robot, terrain, q: _Array, contact: NDArray, time_s: _Array, centres_W: _Array, source=""
) -> list[State]:
    """Samples ``q`` (n, 19) with ``contact`` (n, 4) as :class:`~planner.body.state.State`.

    ``centres_W`` (n, 4, 3): the feet's sphere centres (forward kinematics of ``q``). A
    foot in contact gets the contact point ``c - rho n`` (whichever contact convention
    fits c better, :func:`planner.body.contact.contact_points_from_centres`), a swing foot
    ``c - rho e_z``; the stratum comes from the contact flags, ``support`` is the feet
    in contact, ``info`` holds ``sample`` and ``time``. A ValueError naming ``source``
    for a sample with fewer than three feet down.
    """
    from planner.body.contact import swing_point_from_centre, unique_contact_points
    from planner.core.lie import rotation_from_quat

    rho = robot.foot_radius_m
    down = np.asarray(contact, bool)
    feet_all = swing_point_from_centre(np.asarray(centres_W, float), rho)
    if down.any():
        feet_all[down] = unique_contact_points(terrain, np.asarray(centres_W)[down], rho)[0]
    out = []
    for k, (qk, c) in enumerate(zip(q, down, strict=True)):
        up = np.flatnonzero(~c)
        if len(up) > 1:
            raise ValueError(
                f"{source}: samples.contact[{k}]: {int(c.sum())} feet down, a State "
                "needs at least three"
            )
        out.append(
            State(
                base_position_W=qk[:3].copy(),
                base_rotation_W=rotation_from_quat(qk[3:7]),
                feet_W=feet_all[k],
                joints_rad=robot.joints_from_q(qk),
                stratum=int(up[0]) + 1 if len(up) else 0,
                support=tuple(int(i) for i in np.flatnonzero(c)),
                info={"sample": k, "time": float(time_s[k])},
            )
        )
    return out


def loaded_feet(contact: NDArray[np.bool_], before: NDArray[np.bool_] | None = None) -> NDArray:
    """(N, 4) feet that carry load at each sample: in contact there and at both neighbours.

    A foot that lifts after sample k is unloaded at k (its load moves to the other feet
    over the interval before lift-off); a foot that lands at k is loaded from k + 1 on.
    ``before``: the contact flags of the sample preceding the first (None: unknown).
    """
    c = np.asarray(contact, bool)
    out = c.copy()
    out[1:] &= c[:-1]
    out[:-1] &= c[1:]
    if before is not None and len(c):
        out[0] &= np.asarray(before, bool)
    return out
