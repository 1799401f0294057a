"""Figures of a plan for a paper, and the per-sample numbers behind them.

:func:`plan_series` turns a ``stratawalk.plan/1`` file into time series, one row per
sample: base pose, joints, feet (contact points r_i, section 4.1), stratum (4.3),
whole-body COM (Pinocchio), the paper's equilibrating forces on the feet in contact (eqs.
3-5, :func:`planner.body.statics.equilibrating_forces`), each force's friction-cone margin
(inequalities (d), (e) of 7.3), and the exact balance margins of
:func:`planner.body.statics.static_feasibility` (force margin [N] and COM margin [m]).
The replay (:mod:`planner.replay`) draws the same numbers in 3-D.

:func:`plot_plan` writes four PNG figures (Agg backend, no display needed):

``top_view.png``
    terrain heights from the plan's ``terrain_grid`` seen from above, footholds per leg,
    the COM path and the base path;
``stability.png``
    the stability margins and the smallest normal force over time;
``joints.png``
    the twelve joint angles against their limits;
``gait.png``
    the gait diagram: which feet are down, and the stratum, over time.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.core.errors import InputError
from planner.core.legs import LEG_NAMES

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from planner.planfile.plan import Plan

__all__ = [
    "FIGURES",
    "LEG_COLOURS",
    "PlanSeries",
    "add_plot_parser",
    "cone_margin",
    "fig_gait",
    "fig_joints",
    "fig_stability",
    "fig_top_view",
    "plan_series",
    "plot_plan",
    "stance_segments",
]

_Array = NDArray[np.float64]
LEG_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red")  # FL, FR, HL, HR
SWING_SHADE = "0.92"
FIGURES = ("top_view", "stability", "joints", "gait")


# ------------------------------------------------------------------------------ numbers
def cone_margin(forces_W: _Array, normals_W: _Array, mu: float) -> _Array:
    """Share of the friction cone's half-angle left to each force, ``1 - angle / atan(mu)``.

    1 for a force along the normal, 0 on the cone's surface (inequality (e) of 7.3 tight),
    negative outside it; a force pulling (``F.n < 0``, inequality (d) broken) is below
    ``1 - pi / (2 atan mu)``. Shapes (..., 3) -> (...).
    """
    f = np.asarray(forces_W, dtype=float)
    n = np.asarray(normals_W, dtype=float)
    fn = np.einsum("...i,...i->...", f, n)
    ft = np.linalg.norm(f - fn[..., None] * n, axis=-1)
    return 1.0 - np.arctan2(ft, fn) / math.atan(mu)


@dataclass(eq=False)
class PlanSeries:
    """Per-sample quantities of a plan (N samples; legs FL, FR, HL, HR; world frame, SI).

    ``feet_W`` are contact points for feet down and the point one radius below the sphere
    centre for a foot in the air; ``forces_W`` are the eq.-5 forces on the feet in contact
    (zeros in the air); ``normal_force_N``, ``cone_margin`` are NaN for feet in the air;
    ``margin_N`` and ``com_margin_m`` come from the exact SOCP test.
    """

    time: _Array  # (N,) [s]
    stratum: NDArray[np.int_]  # (N,) 0..4
    contact: NDArray[np.bool_]  # (N, 4)
    base_W: _Array  # (N, 3) [m]
    quat_xyzw: _Array  # (N, 4)
    joints_rad: _Array  # (N, 4, 3)
    lower_rad: _Array  # (4, 3)
    upper_rad: _Array  # (4, 3)
    joint_names: list[str]
    feet_W: _Array  # (N, 4, 3) [m]
    normals_W: _Array  # (N, 4, 3)
    com_W: _Array  # (N, 3) [m]
    forces_W: _Array  # (N, 4, 3) [N]
    normal_force_N: _Array  # (N, 4) [N]
    cone_margin: _Array  # (N, 4)
    margin_N: _Array  # (N,) [N]
    com_margin_m: _Array  # (N,) [m]
    mass_kg: float
    mu: float

    def __len__(self) -> int:
        return len(self.time)

    @property
    def min_normal_force_N(self) -> _Array:
        """(N,) smallest normal force over the feet in contact [N]."""
        return np.nanmin(self.normal_force_N, axis=1)


def plan_series(plan: Plan) -> PlanSeries:
    """Compute the per-sample quantities of ``plan`` (eqs. 3-5, 7.3 (d)-(e), exact SOCP).

    Uses the plan's robot (Pinocchio) and terrain spec. The COM margin of a sample is the
    distance of its COM to the border of the feasible COM region of its feet in contact,
    which depends only on those feet: it is computed once per stance.
    """
    import pinocchio as pin

    from planner.body.statics import (
        equilibrating_forces,
        feasible_com_region,
        polygon_signed_distance,
        static_feasibility,
    )

    if len(plan.samples) == 0:
        raise InputError(f"{plan.source}: samples: empty, nothing to show; plan a walk first")
    robot, terrain = plan.load_robot(), plan.load_terrain()
    states = plan.sample_states()
    model, data = robot.model, robot.model.createData()
    n = len(states)
    mass, mu = float(robot.total_mass_kg), float(plan.friction)
    contact = plan.samples.contact.astype(bool)
    feet = np.array([s.feet_W for s in states])
    normals = np.tile([0.0, 0.0, 1.0], (n, 4, 1))
    if contact.any():
        normals[contact] = np.asarray(terrain.normal(feet[contact])).reshape(-1, 3)
    com = np.array([pin.centerOfMass(model, data, q).copy() for q in plan.samples.q])
    forces = np.zeros((n, 4, 3))
    margin = np.full(n, np.nan)
    com_margin = np.full(n, np.nan)
    regions: dict[bytes, _Array] = {}
    for k in range(n):
        sup = np.flatnonzero(contact[k])
        if len(sup) < 3:
            continue
        eq5 = equilibrating_forces(feet[k], com[k], mass, sup)
        if not eq5.degenerate:
            forces[k] = eq5.forces
        res = static_feasibility(feet[k], com[k], mass, sup, mu, normals[k], with_com_margin=False)
        margin[k] = res.margin_N
        key = np.round(feet[k][sup], 9).tobytes() + sup.tobytes()
        if key not in regions:
            regions[key] = feasible_com_region(feet[k], com[k][2], mass, sup, mu, normals[k])
        com_margin[k] = polygon_signed_distance(com[k][:2], regions[key])
    fn = np.einsum("nki,nki->nk", forces, normals)
    fn[~contact] = np.nan
    cm = cone_margin(forces, normals, mu)
    cm[~contact] = np.nan
    return PlanSeries(
        time=plan.samples.time.copy(),
        stratum=np.array([s.stratum for s in states], dtype=int),
        contact=contact,
        base_W=plan.samples.q[:, :3].copy(),
        quat_xyzw=plan.samples.q[:, 3:7].copy(),
        joints_rad=np.array([s.joints_rad for s in states]),
        lower_rad=robot.lower_rad,
        upper_rad=robot.upper_rad,
        joint_names=list(robot.joint_names),
        feet_W=feet,
        normals_W=normals,
        com_W=com,
        forces_W=forces,
        normal_force_N=fn,
        cone_margin=cm,
        margin_N=margin,
        com_margin_m=com_margin,
        mass_kg=mass,
        mu=mu,
    )


def stance_segments(contact: NDArray[np.bool_]) -> list[tuple[int, int, int]]:
    """Runs of samples where a leg is down: ``(leg, first, last)`` (inclusive), leg 0-based."""
    out = []
    for leg in range(contact.shape[1]):
        down = np.concatenate([[False], contact[:, leg], [False]])
        edges = np.flatnonzero(np.diff(down.astype(int)))
        out += [(leg, int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2], strict=True)]
    return out


def _swing_spans(s: PlanSeries, leg: int | None = None) -> list[tuple[float, float]]:
    """Time spans [s] with a foot in the air (of ``leg``, or of any leg)."""
    up = ~s.contact.all(axis=1) if leg is None else ~s.contact[:, leg]
    padded = np.concatenate([[False], up, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(int)))
    t = s.time
    spans = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        lo = t[max(a - 1, 0)]  # the last sample before lift-off ...
        hi = t[min(b, len(t) - 1)]  # ... to the touch-down sample
        spans.append((float(lo), float(hi)))
    return spans


def _shade_swings(ax, s: PlanSeries, leg: int | None = None) -> None:
    for lo, hi in _swing_spans(s, leg):
        ax.axvspan(lo, hi, color=SWING_SHADE, lw=0, zorder=0)


# ------------------------------------------------------------------------------ figures
def _figure(width_in: float, height_in: float) -> Figure:
    """A matplotlib figure on the Agg canvas (no pyplot, no display, no global backend)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def fig_top_view(plan: Plan, s: PlanSeries) -> Figure:
    """Terrain heights (``terrain_grid``) from above, footholds per leg, COM and base paths."""
    g = plan.terrain_grid
    h = g.heights
    ny, nx = h.shape
    x0, y0 = g.origin
    res = g.resolution
    extent = (x0 - res / 2, x0 + (nx - 0.5) * res, y0 - res / 2, y0 + (ny - 0.5) * res)
    span_x, span_y = extent[1] - extent[0], extent[3] - extent[2]
    width = 8.0
    fig = _figure(width, min(max(width * span_y / span_x + 0.9, 3.0), 10.0))
    ax = fig.add_subplot()
    lo, hi = float(h.min()), float(h.max())
    if hi - lo < 1e-6:
        lo, hi = lo - 0.01, hi + 0.01
    img = ax.imshow(
        h, origin="lower", extent=extent, cmap="gist_earth", vmin=lo, vmax=hi,
        interpolation="nearest",
    )  # fmt: skip
    cax = ax.inset_axes([1.01, 0.0, 0.02, 1.0])  # as tall as the (equal-aspect) map
    fig.colorbar(img, cax=cax, label="terrain height [m]")
    ax.plot(s.base_W[:, 0], s.base_W[:, 1], color="0.15", lw=1.0, ls="--", label="base path")
    ax.plot(s.com_W[:, 0], s.com_W[:, 1], color="magenta", lw=1.6, label="COM path")
    for leg, a, b in stance_segments(s.contact):
        p = s.feet_W[a : b + 1, leg].mean(axis=0)
        ax.plot(
            p[0], p[1], marker="o", ms=6, mfc=LEG_COLOURS[leg], mec="k", mew=0.6, ls="none",
            label=LEG_NAMES[leg],
        )  # fmt: skip
    ax.plot(*plan.start[:2], marker="s", ms=8, mfc="white", mec="k", ls="none", label="start")
    ax.plot(*plan.goal[:2], marker="*", ms=13, mfc="gold", mec="k", ls="none", label="goal")
    handles, labels = ax.get_legend_handles_labels()
    uniq = dict(zip(labels, handles, strict=True))
    ax.legend(uniq.values(), uniq.keys(), loc="upper left", fontsize=8, ncols=4, framealpha=0.85)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    name = plan.terrain.get("name", plan.terrain.get("kind", "terrain"))
    ax.set_title(f"{plan.robot['name']} on {name}: footholds and COM path (top view)")
    return fig


def fig_stability(plan: Plan, s: PlanSeries) -> Figure:
    """Force margin, COM margin and the smallest normal force over time (swings shaded)."""
    fig = _figure(8.0, 6.0)
    axes = fig.subplots(3, 1, sharex=True)
    t = s.time
    series = [
        (s.margin_N, "force margin [N]", "tab:blue",
         "exact balance margin (SOCP): distance of the best forces to their cones"),
        (1000.0 * s.com_margin_m, "COM margin [mm]", "tab:purple",
         "distance of the COM to the border of its feasible region"),
        (s.min_normal_force_N, "min F.n [N]", "tab:red",
         "smallest normal force of the feet in contact (eq. 5 forces)"),
    ]  # fmt: skip
    for ax, (y, label, colour, title) in zip(axes, series, strict=True):
        _shade_swings(ax, s)
        ax.plot(t, y, color=colour, lw=1.4)
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_ylabel(label)
        ax.set_title(title, fontsize=9, loc="left")
        ax.grid(alpha=0.3)
        finite = y[np.isfinite(y)]
        if len(finite):
            k = int(np.nanargmin(np.where(np.isfinite(y), y, np.inf)))
            ax.plot(t[k], y[k], "v", color=colour, ms=6)
            ax.annotate(f"min {y[k]:.3g}", (t[k], y[k]), textcoords="offset points",
                        xytext=(4, -12), fontsize=8)  # fmt: skip
    axes[-1].set_xlabel("time [s]  (grey: a foot in the air)")
    fig.suptitle(f"static stability along the walk (mu = {s.mu:g}, m = {s.mass_kg:.3g} kg)")
    return fig


def fig_joints(plan: Plan, s: PlanSeries) -> Figure:
    """The twelve joint angles [deg] against their limits (dashed); each leg's swings shaded."""
    fig = _figure(10.0, 7.5)
    axes = fig.subplots(4, 3, sharex=True)
    t = s.time
    for leg in range(4):
        for j in range(3):
            ax = axes[leg, j]
            _shade_swings(ax, s, leg)
            lo, hi = np.degrees(s.lower_rad[leg, j]), np.degrees(s.upper_rad[leg, j])
            ax.plot(t, np.degrees(s.joints_rad[:, leg, j]), color=LEG_COLOURS[leg], lw=1.3)
            for lim in (lo, hi):
                if np.isfinite(lim):
                    ax.axhline(lim, color="k", ls="--", lw=0.9)
            y = np.degrees(s.joints_rad[:, leg, j])
            pad = 0.08 * max(hi - lo, 1.0)
            ax.set_ylim(min(lo, y.min()) - pad, max(hi, y.max()) + pad)
            ax.set_title(s.joint_names[3 * leg + j], fontsize=8)
            ax.grid(alpha=0.3)
            if j == 0:
                ax.set_ylabel(f"{LEG_NAMES[leg]} [deg]")
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle("joint angles and their limits (dashed); grey: that leg in the air")
    return fig


def fig_gait(plan: Plan, s: PlanSeries) -> Figure:
    """Gait diagram: stance bars per leg and the stratum S0..S4 over time."""
    fig = _figure(9.0, 3.6)
    ax_s, ax = fig.subplots(2, 1, sharex=True, height_ratios=[1, 4])
    t = s.time
    dt = np.diff(t)
    ends = np.concatenate([t[:-1] + dt, [t[-1]]])
    for leg, a, b in stance_segments(s.contact):
        lo = t[a] if a == 0 else t[a - 1] + 0.5 * (t[a] - t[a - 1])
        hi = ends[b] if b == len(t) - 1 else t[b] + 0.5 * (t[b + 1] - t[b])
        ax.broken_barh([(lo, hi - lo)], (3 - leg - 0.35, 0.7), color=LEG_COLOURS[leg])
    ax.set_yticks(range(4), [f"{LEG_NAMES[leg]} (leg {leg + 1})" for leg in range(4)][::-1])
    ax.set_xlabel("time [s]")
    ax.set_xlim(t[0], t[-1])
    ax.grid(axis="x", alpha=0.3)
    ax.set_title("bars: foot on the ground", fontsize=9, loc="left")
    colours = ["0.55", *LEG_COLOURS]
    change = np.flatnonzero(np.diff(s.stratum)) + 1
    starts = np.concatenate([[0], change])
    stops = np.concatenate([change, [len(t)]])
    for a, b in zip(starts, stops, strict=True):
        lo = t[a]
        hi = t[b] if b < len(t) else t[-1]
        st = int(s.stratum[a])
        ax_s.axvspan(lo, hi, color=colours[st], alpha=0.85, lw=0)
        if hi - lo > 0.03 * (t[-1] - t[0]):
            ax_s.text((lo + hi) / 2, 0.5, f"S{st}", ha="center", va="center", fontsize=7,
                      color="white")  # fmt: skip
    ax_s.set_yticks([])
    ax_s.set_ylabel("stratum", rotation=0, ha="right", va="center")
    from matplotlib.patches import Patch

    names = ["S0 four feet down"] + [f"S{i + 1} {LEG_NAMES[i]} up" for i in range(4)]
    ax_s.legend(
        handles=[Patch(color=c, label=n) for c, n in zip(colours, names, strict=True)],
        ncols=5, loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=7, frameon=False,
    )  # fmt: skip
    fig.suptitle(f"gait diagram: {len(change)} stratum changes in {t[-1] - t[0]:.1f} s")
    return fig


_DRAW = {
    "top_view": fig_top_view,
    "stability": fig_stability,
    "joints": fig_joints,
    "gait": fig_gait,
}


def plot_plan(
    plan: Plan | str | Path,
    out_dir: str | Path,
    series: PlanSeries | None = None,
    dpi: int = 150,
) -> list[Path]:
    """Write the four figures of ``plan`` as PNG files into ``out_dir``; return their paths.

    ``plan`` may be a :class:`~planner.planfile.plan.Plan` or a path, read with
    :func:`~planner.planfile.loader.load_plan` (one-line InputError for a bad file).
    """
    from planner.core.outputs import write_atomic
    from planner.planfile.loader import load_plan
    from planner.planfile.plan import Plan

    plan = plan if isinstance(plan, Plan) else load_plan(plan)
    s = plan_series(plan) if series is None else series
    out = Path(out_dir)
    paths = []
    for name in FIGURES:
        fig = _DRAW[name](plan, s)
        path = out / f"{name}.png"
        write_atomic(path, lambda tmp, fig=fig: fig.savefig(tmp, dpi=dpi, format="png"))
        paths.append(path)
    return paths


# ------------------------------------------------------------------------------ command
def add_plot_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``plot plan.json --out DIR [--dpi N]``."""
    p = subparsers.add_parser("plot", help="figures of a plan (PNG): terrain, margins, gait")
    p.add_argument("plan", help="plan.json written by `stratawalk plan`")
    p.add_argument("--out", default="plots", help="output folder (default ./plots)")
    p.add_argument("--dpi", type=int, default=150, help="pixels per inch, 10..1200 (default 150)")
    p.set_defaults(func=cmd_plot)
    return p


def cmd_plot(args) -> int:
    """Run ``stratawalk plot``: write the figures and print where they are."""
    from planner.core.errors import InputError
    from planner.core.outputs import check_file, check_folder

    if not 10 <= args.dpi <= 1200:
        raise InputError(f"--dpi: expected 10..1200 pixels per inch, got {args.dpi}")
    check_folder(args.out, "--out", size_b=4 * 2**20)
    for name in FIGURES:
        check_file(Path(args.out) / f"{name}.png", "--out")
    for path in plot_plan(args.plan, args.out, dpi=args.dpi):
        print(f"wrote {path}")
    return 0
