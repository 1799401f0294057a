"""Top-view pictures of a terrain (sharp heights, paper section 4.4's z_T)."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from planner.core.outputs import write_atomic  # noqa: E402
from planner.world.terrain import Terrain  # noqa: E402

MAX_PIXELS = 4_000_000  # the height image's cells at most (the grid coarsens beyond)


def plot_top_view(
    terrain: Terrain,
    path_png: str | Path,
    bounds: tuple[float, float, float, float] | None = None,
    resolution: float = 0.005,
) -> Path:
    """Draw the terrain seen from above, coloured by its sharp height, to a PNG.

    Parameters
    ----------
    terrain
        The terrain to draw.
    path_png
        Output file (parent folders are created).
    bounds
        ``(xmin, xmax, ymin, ymax)`` in metres; default ``terrain.bounds``.
    resolution
        Grid spacing in metres (one pixel of the height image); coarser on a course so
        large that the image would pass :data:`MAX_PIXELS`.

    Returns
    -------
    Path
        The written file.

    """
    x0, x1, y0, y1 = terrain.bounds if bounds is None else bounds
    resolution = max(resolution, math.sqrt((x1 - x0) * (y1 - y0) / MAX_PIXELS))
    origin, res, heights = terrain.height_grid(x0, x1, y0, y1, resolution)
    ny, nx = heights.shape
    extent = (
        origin[0] - 0.5 * res,
        origin[0] + (nx - 0.5) * res,
        origin[1] - 0.5 * res,
        origin[1] + (ny - 0.5) * res,
    )
    span_x, span_y = max(x1 - x0, 1e-3), max(y1 - y0, 1e-3)
    width_in = 10.0
    height_in = min(max(width_in * span_y / span_x + 1.2, 3.0), 12.0)
    fig, ax = plt.subplots(figsize=(width_in, height_in))
    try:
        lo, hi = float(np.min(heights)), float(np.max(heights))
        if hi - lo < 1e-9:
            lo, hi = lo - 0.01, hi + 0.01
        img = ax.imshow(
            heights,
            origin="lower",
            extent=extent,
            cmap="viridis",
            vmin=lo,
            vmax=hi,
            interpolation="nearest",
        )
        fig.colorbar(img, ax=ax, label="height z_T [m]", shrink=0.9)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_aspect("equal")
        ax.set_title(f"{terrain.name} ({terrain.kind}, sharp heights, {res * 1000:.3g} mm grid)")
        out = write_atomic(
            path_png,
            lambda tmp: fig.savefig(tmp, dpi=120, bbox_inches="tight", format="png"),
            option="--png",
        )
    finally:
        plt.close(fig)
    return out


def plot_guide_map(tmap, path_xy, path_png: str | Path, title: str) -> Path:
    """Draw a robot's traversability map (:mod:`planner.motion.guide_path`) and a guide path.

    Free cells coloured by their cost (log scale), grown obstacles grey, the obstacles
    themselves black; ``path_xy`` (N, 2) [m] or None.
    """
    ny, nx = tmap.cost.shape
    res = tmap.resolution_m
    extent = (
        tmap.origin[0] - 0.5 * res,
        tmap.origin[0] + (nx - 0.5) * res,
        tmap.origin[1] - 0.5 * res,
        tmap.origin[1] + (ny - 0.5) * res,
    )
    width_in = 10.0
    fig, ax = plt.subplots(figsize=(width_in, min(max(width_in * ny / nx + 1.2, 3.0), 12.0)))
    try:
        cost = np.where(tmap.blocked, np.nan, np.log10(np.where(tmap.blocked, 1.0, tmap.cost)))
        img = ax.imshow(cost, origin="lower", extent=extent, cmap="magma_r", vmin=0.0)
        grey = np.where(tmap.blocked, 0.6, np.nan)
        grey[tmap.obstacle] = 0.0
        ax.imshow(grey, origin="lower", extent=extent, cmap="gray", vmin=0, vmax=1)
        fig.colorbar(img, ax=ax, label="log10 cell cost", shrink=0.9)
        if path_xy is not None:
            xy = np.asarray(path_xy, float)
            ax.plot(xy[:, 0], xy[:, 1], "c-", lw=2, label="guide path")
            ax.plot(*xy[0], "go", label="start")
            ax.plot(*xy[-1], "r*", ms=12, label="goal")
            ax.legend(loc="upper right", fontsize=8)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_aspect("equal")
        ax.set_title(title)
        out = write_atomic(
            path_png,
            lambda tmp: fig.savefig(tmp, dpi=120, bbox_inches="tight", format="png"),
            option="--png",
        )
    finally:
        plt.close(fig)
    return out
