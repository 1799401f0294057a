"""Top-view pictures of a terrain (sharp heights, paper section 4.4's z_T)."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from planner.outputs import write_atomic  # noqa: E402
from planner.terrain import Terrain  # noqa: E402

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
            path_png, lambda tmp: fig.savefig(tmp, dpi=120, bbox_inches="tight", format="png")
        )
    finally:
        plt.close(fig)
    return out
