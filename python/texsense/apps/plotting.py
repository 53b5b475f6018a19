"""Figures of recordings: a pressure map and the load / centre of force over time.

Matplotlib is imported lazily with the non-interactive Agg backend, so nothing here needs a
display. Every figure texsense writes goes through :func:`save_figure` (a temporary name in
the same folder, renamed when complete: :mod:`texsense.data.files`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from texsense.apps import stats
from texsense.data.files import pyplot, save_figure
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.cm import ScalarMappable
    from matplotlib.figure import Figure

__all__ = ["draw_map", "overview_figure", "peak_frame", "save_figure"]


def peak_frame(rec: Recording) -> int:
    """Index of the frame with the highest total (load for pressure, sum otherwise).

    Frames labelled ``reliable = False`` (for example the first and last 3 frames of each
    PMD file) are skipped unless no other frame exists.
    """
    if rec.n_frames == 0:
        raise ParameterError("the recording has no frames")
    totals = (
        stats.total_load(rec)
        if rec.quantity == "pressure"
        else np.nansum(rec.masked_frames(), axis=1)
    )
    totals = np.nan_to_num(totals, nan=-np.inf)
    reliable = rec.labels.get("reliable")
    if reliable is not None and reliable.dtype == bool and reliable.any():
        totals = np.where(reliable, totals, -np.inf)
    return int(np.argmax(totals))


def draw_map(ax: Axes, rec: Recording, frame: int, *, vmax: float | None = None) -> ScalarMappable:
    """Draw frame ``frame`` of ``rec`` on ``ax``: cells for grids, squares for points.

    Empty grid cells are left blank, invalid readings are hatched grey. Returns the mappable
    for a colour bar.
    """
    values = np.where(rec.valid[frame], rec.frames[frame], np.nan).astype(np.float64)
    lay = rec.layout
    top = vmax if vmax is not None else float(np.nanmax(values)) if np.isfinite(values).any() else 1
    top = top if top > 0 else 1.0
    x0, x1, y0, y1 = lay.extent_cm
    if lay.shape is not None:
        grid = lay.to_grid(values)
        img: ScalarMappable = ax.imshow(
            np.ma.masked_invalid(grid),
            cmap="viridis",
            vmin=0,
            vmax=top,
            extent=(x0, x1, y1, y0),
            interpolation="nearest",
        )
        invalid = lay.to_grid(~rec.valid[frame], fill=False).astype(bool)
        if invalid.any():
            ax.imshow(
                np.ma.masked_where(~invalid, np.ones_like(grid)),
                cmap="Greys",
                vmin=0,
                vmax=2,
                extent=(x0, x1, y1, y0),
                interpolation="nearest",
            )
    else:
        from matplotlib.collections import PatchCollection
        from matplotlib.patches import Rectangle

        patches = [
            Rectangle((x - w / 2, y - h / 2), w, h)
            for (x, y), (w, h) in zip(lay.xy_cm, lay.size_cm, strict=True)
        ]
        coll = PatchCollection(patches, cmap="viridis")
        coll.set_array(np.ma.masked_invalid(values))
        coll.set_clim(0, top)
        ax.add_collection(coll)
        ax.set_xlim(x0, x1)
        ax.set_ylim(y1, y0)
        img = coll
    cof = stats.centre_of_force(rec.select([frame]))[0]
    if rec.quantity == "pressure" and np.all(np.isfinite(cof)):
        ax.plot(*cof, marker="+", color="red", markersize=14, mew=2, label="centre of force")
        ax.legend(loc="lower right", fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("x [cm]")
    ax.set_ylabel("y [cm]")
    return img


def overview_figure(rec: Recording, frame: int | None = None, title: str = "") -> Figure:
    """A figure with the map of one frame (default: the peak frame) beside the load (or sum)
    and the centre of force over time."""
    plt = pyplot()
    frame = peak_frame(rec) if frame is None else frame
    if not 0 <= frame < rec.n_frames:
        raise ParameterError(f"frame {frame} is out of range 0..{rec.n_frames - 1}")
    fig = plt.figure(figsize=(12, 5.5), layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=[1, 1.4])
    ax_map = fig.add_subplot(grid[:, 0])
    img = draw_map(ax_map, rec, frame)
    fig.colorbar(img, ax=ax_map, label=f"{rec.quantity} [{rec.unit}]", shrink=0.85)
    ax_map.set_title(f"frame {frame} at t = {rec.times[frame]:.3f} s")
    ax_load = fig.add_subplot(grid[0, 1])
    t = rec.times
    # Frames labelled unreliable (PMD: first and last 3 of each file) are left out of the
    # time series: they are often saturated and would flatten the rest.
    reliable = rec.labels.get("reliable")
    hide = ~reliable if reliable is not None and reliable.dtype == bool else np.zeros(len(t), bool)
    if rec.quantity == "pressure":
        total = stats.total_load(rec)
        ax_load.set_ylabel("total load [N]")
    else:
        total = np.nansum(rec.masked_frames(), axis=1)
        ax_load.set_ylabel(f"sum of {rec.quantity} [{rec.unit}]")
    ax_load.plot(t, np.where(hide, np.nan, total), lw=1)
    if hide.any():
        ax_load.set_title(f"{int(hide.sum())} unreliable frames not shown", fontsize=8)
    ax_load.axvline(t[frame], color="red", lw=0.8, ls="--")
    ax_load.grid(alpha=0.3)
    ax_cof = fig.add_subplot(grid[1, 1], sharex=ax_load)
    cof = stats.centre_of_force(rec)
    cof[hide] = np.nan
    ax_cof.plot(t, cof[:, 0], lw=1, label="x")
    ax_cof.plot(t, cof[:, 1], lw=1, label="y")
    ax_cof.set_ylabel("centre of force [cm]")
    ax_cof.set_xlabel("time [s]")
    ax_cof.legend(fontsize=8)
    ax_cof.grid(alpha=0.3)
    fig.suptitle(title or rec.meta.get("source", ""), fontsize=10)
    return fig


def save_overview(
    rec: Recording, path: str | Path, frame: int | None = None, title: str = ""
) -> Path:
    """Render :func:`overview_figure` to a PNG file."""
    plt = pyplot()
    fig = overview_figure(rec, frame, title)
    try:
        return save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
