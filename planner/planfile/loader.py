"""The plan loader of every command that reads a plan: parsed, then refused if impossible.

:meth:`Plan.load <planner.planfile.plan.Plan.load>` checks the JSON contract field by field
(types, lengths, finite numbers, unit quaternions). A file can pass it and still be no
motion at all; :func:`structure_flaws` finds those plans:

``empty_plan``
    Fewer than two samples.
``time_order``
    A sample time not after the previous one (by more than :data:`MIN_INTERVAL_S`).
``out_of_range``
    A number no walk has: a time beyond :data:`MAX_TIME_S`, a position (start, goal, a
    keyframe's base or feet, a sample's base) more than :data:`REACH_M` outside the
    terrain grid the plan carries (which covers its walk), a grid height or origin beyond
    :data:`MAX_COORD_M`, a joint angle beyond :data:`MAX_JOINT_RAD`, a contact force beyond
    :data:`MAX_FORCE_N`.
``plan_structure``
    A terrain grid of fewer than 2 x 2 heights.

:func:`load_plan` refuses such a plan with one line naming the file and the field (exit 2
in the commands); ``stratawalk check`` reports each flaw as a violation.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planner.core.errors import InputError
from planner.planfile.plan import Plan

__all__ = [
    "MAX_COORD_M",
    "MAX_FORCE_N",
    "MAX_JOINT_RAD",
    "MAX_TIME_S",
    "MIN_INTERVAL_S",
    "REACH_M",
    "Flaw",
    "load_plan",
    "refuse_flaws",
    "structure_flaws",
]

REACH_M = 2.0  # positions lie within the terrain grid's extent grown by this [m]
MAX_COORD_M = 1e4  # terrain grid origin and heights at most this far from 0 [m]
MAX_TIME_S = 1e5  # sample times within +- this [s] (a walk of a day)
MIN_INTERVAL_S = 1e-9  # consecutive sample times at least this far apart [s]
MAX_JOINT_RAD = 100.0  # joint angles within +- this [rad]
MAX_FORCE_N = 1e6  # contact forces at most this [N]


@dataclass(frozen=True)
class Flaw:
    """One structural flaw.

    ``kind`` (module docstring), ``where`` ("sample 3", "keyframe 1", "plan"), the JSON
    ``field`` path, the offending ``value`` and its ``limit``, and a one-line ``message``.
    """

    kind: str
    where: str
    field: str
    value: float
    limit: float
    message: str


def _outside(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(n,) how far each of the points ``p`` (n, 3) lies outside the box [lo, hi] [m].

    inf for a point that is not finite.
    """
    with np.errstate(invalid="ignore", over="ignore"):
        d = np.max(np.maximum(lo - p, p - hi), axis=-1).clip(min=0.0)
        return np.where(np.isfinite(p).all(axis=-1), d, np.inf)


def _xyz(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in p) + ") m"


def structure_flaws(plan: Plan) -> list[Flaw]:
    """The structural flaws of ``plan`` (module docstring), in file order; [] if none."""
    out: list[Flaw] = []
    add = out.append
    s, g = plan.samples, plan.terrain_grid
    n = len(s.time)
    if n < 2:
        add(Flaw("empty_plan", "plan", "samples", n, 2, f"{n} samples; a motion needs 2 or more"))

    # the terrain grid: the box the walk lies in
    h = np.asarray(g.heights, float)
    if h.ndim != 2 or min(h.shape) < 2:
        add(Flaw("plan_structure", "plan", "terrain_grid.heights", h.size, 4,
                 f"{h.shape[0] if h.ndim else 0} x {h.shape[1] if h.ndim == 2 else 0} "
                 "heights; a terrain grid has 2 x 2 or more"))  # fmt: skip
        return out
    big = max(float(np.abs(g.origin).max()), float(np.abs(h).max()))
    if not big <= MAX_COORD_M:
        add(Flaw("out_of_range", "plan", "terrain_grid", big, MAX_COORD_M,
                 f"a coordinate of {big:.6g} m; terrain grids lie within {MAX_COORD_M:g} m "
                 "of the origin"))  # fmt: skip
        return out
    span = np.array([h.shape[1] - 1, h.shape[0] - 1]) * g.resolution
    lo = np.r_[g.origin, h.min()] - REACH_M
    hi = np.r_[g.origin + span, h.max()] + REACH_M

    def position(p: np.ndarray, where: str, name: str) -> None:
        d = float(_outside(p, lo, hi))
        if d > 0:
            add(Flaw("out_of_range", where, name, d, 0.0,
                     f"{_xyz(p)} lies {d:.3g} m beyond the terrain grid it was planned on "
                     f"(grown by {REACH_M:g} m)"))  # fmt: skip

    position(plan.start, "plan", "start")
    position(plan.goal, "plan", "goal")
    for k, kf in enumerate(plan.keyframes):
        where, at = f"keyframe {k}", f"keyframes[{k}]"
        position(kf.base_position, where, f"{at}.base_position")
        for i in range(len(kf.feet)):
            position(kf.feet[i], where, f"{at}.feet[{i}]")
        j = float(np.abs(kf.joints).max(initial=0.0))
        if not j <= MAX_JOINT_RAD:
            add(Flaw("out_of_range", where, f"{at}.joints", j, MAX_JOINT_RAD,
                     f"a joint at {j:.6g} rad; joint angles lie within +-{MAX_JOINT_RAD:g} "
                     "rad"))  # fmt: skip
        if kf.forces is not None:
            f = float(np.linalg.norm(kf.forces, axis=1).max(initial=0.0))
            if not f <= MAX_FORCE_N:
                add(Flaw("out_of_range", where, f"{at}.forces", f, MAX_FORCE_N,
                         f"a contact force of {f:.6g} N; forces are at most {MAX_FORCE_N:g} "
                         "N"))  # fmt: skip

    if n == 0:
        return out
    t, q = np.asarray(s.time, float), np.asarray(s.q, float)
    for k in np.flatnonzero(~(np.abs(t) <= MAX_TIME_S)):
        add(Flaw("out_of_range", f"sample {k}", f"samples.time[{k}]", t[k], MAX_TIME_S,
                 f"time {t[k]:.6g} s; sample times lie within +-{MAX_TIME_S:g} s"))  # fmt: skip
    dt = np.diff(t)
    for k in np.flatnonzero(~(dt > MIN_INTERVAL_S)) + 1:
        add(Flaw("time_order", f"sample {k}", f"samples.time[{k}]", t[k] - t[k - 1],
                 MIN_INTERVAL_S,
                 f"time {t[k]:.6g} s is not after the previous sample's {t[k - 1]:.6g} s; "
                 "sample times must increase"))  # fmt: skip
    d = _outside(q[:, :3], lo, hi)
    for k in np.flatnonzero(d > 0):
        add(Flaw("out_of_range", f"sample {k}", f"samples.q[{k}][0:3]", d[k], 0.0,
                 f"base at {_xyz(q[k, :3])} lies {d[k]:.3g} m beyond the terrain grid it was "
                 f"planned on (grown by {REACH_M:g} m)"))  # fmt: skip
    j = np.abs(q[:, 7:]).max(axis=1, initial=0.0)
    for k in np.flatnonzero(~(j <= MAX_JOINT_RAD)):
        add(Flaw("out_of_range", f"sample {k}", f"samples.q[{k}][7:]", j[k], MAX_JOINT_RAD,
                 f"a joint at {j[k]:.6g} rad; joint angles lie within +-{MAX_JOINT_RAD:g} "
                 "rad"))  # fmt: skip
    return out


def refuse_flaws(plan: Plan) -> Plan:
    """``plan`` if it has no structural flaw, else a one-line InputError naming the first."""
    flaws = structure_flaws(plan)
    if flaws:
        f = flaws[0]
        more = ""
        if len(flaws) > 1:
            more = f" (and {len(flaws) - 1} more: `stratawalk check` lists them)"
        raise InputError(
            f"{plan.source}: {f.field}: {f.message}{more}; give a plan written by `stratawalk plan`"
        )
    return plan


def load_plan(path: str | Path, robot: str | Path | None = None) -> Plan:
    """Read a plan file as every command does; InputError (one line) if it is no plan.

    :meth:`Plan.load` (``robot``: a URDF for a plan whose own moved), then
    :func:`refuse_flaws`.
    """
    return refuse_flaws(Plan.load(path, robot=robot))
