"""The report's figures (matplotlib): maps on a fixed scale with the threshold contour and the
orientation, the statistics over time, the health map, the time per side."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from texsense.apps.report._content import ReportContent
    from texsense.data.layout import Layout

__all__ = ["draw_values", "maps_figure", "series_figure"]

#: The colour map of every pressure map: perceptually uniform and readable with the common
#: colour-vision deficiencies (matplotlib's viridis; the pages use the same table).
CMAP = "viridis"
#: Text sizes (points) on an A4 page.
SMALL, NORMAL = 7.5, 9


def draw_values(
    ax: Axes,
    layout: Layout,
    values: np.ndarray,
    scale: tuple[float, float],
    *,
    cmap: str = CMAP,
    threshold: float | None = None,
    orientation: dict[str, Any] | None = None,
) -> Any:
    """Per-element ``values`` on ``ax`` on the fixed ``scale`` (cells of a grid, squares of a
    points layout; NaN blank), the ``threshold`` as a white contour, the orientation's labels
    outside the edges. Returns the mappable for a colour bar."""
    x0, x1, y0, y1 = layout.extent_cm
    img: Any
    if layout.shape is not None:
        grid = layout.to_grid(values)
        img = ax.imshow(
            np.ma.masked_invalid(grid),
            cmap=cmap,
            vmin=scale[0],
            vmax=scale[1],
            extent=(x0, x1, y1, y0),
            interpolation="nearest",
        )
        if threshold is not None and np.nanmax(grid, initial=-np.inf) > threshold:
            py, px = layout.pitch_cm or (1.0, 1.0)
            xs = x0 + (np.arange(grid.shape[1]) + 0.5) * px
            ys = y0 + (np.arange(grid.shape[0]) + 0.5) * py
            ax.contour(
                xs, ys, np.nan_to_num(grid), levels=[threshold], colors="white", linewidths=0.9
            )
    else:
        from matplotlib.collections import PatchCollection
        from matplotlib.patches import Rectangle

        patches = [
            Rectangle((x - w / 2, y - h / 2), w, h)
            for (x, y), (w, h) in zip(layout.xy_cm, layout.size_cm, strict=True)
        ]
        cells = PatchCollection(patches, cmap=cmap)
        cells.set_array(np.ma.masked_invalid(values))
        cells.set_clim(*scale)
        ax.add_collection(cells)
        img = cells
        ax.set_xlim(x0, x1)
        ax.set_ylim(y1, y0)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=SMALL)
    _orientation(ax, orientation or {})
    return img


def _orientation(ax: Axes, o: dict[str, Any]) -> None:
    style: dict[str, Any] = {"fontsize": SMALL, "color": "#444", "transform": ax.transAxes}
    mark = " (assumed)" if o.get("assumed") else ""
    if "top" in o:
        ax.text(0.5, 1.01, o["top"] + mark, ha="center", va="bottom", **style)
    if "bottom" in o:
        ax.text(0.5, -0.07, o["bottom"], ha="center", va="top", **style)
    if "left" in o:
        ax.text(-0.13, 0.5, o["left"], ha="right", va="center", rotation=90, **style)
    if "right" in o:
        ax.text(1.02, 0.5, o["right"], ha="left", va="center", rotation=90, **style)


def colour_bar(fig: Figure, img: Any, ax: Axes, label: str, threshold: float | None) -> None:
    """A colour bar with the threshold marked."""
    bar = fig.colorbar(img, ax=ax, shrink=0.8, pad=0.08)
    bar.set_label(label, fontsize=SMALL)
    bar.ax.tick_params(labelsize=SMALL)
    if threshold is not None:
        bar.ax.axhline(threshold, color="white", lw=2)
        bar.ax.axhline(threshold, color="black", lw=0.8, ls="--")
        bar.ax.text(
            1.6,
            threshold,
            f" {threshold:g}",
            transform=bar.ax.get_yaxis_transform(),
            va="center",
            fontsize=SMALL,
        )


def maps_figure(fig: Figure, rect: tuple[float, float, float, float], c: ReportContent) -> None:
    """The peak and mean maps side by side inside ``rect`` (figure fraction)."""
    r = c.review
    lay = r.rec.layout
    left, bottom, width, height = rect
    label = f"{r.rec.quantity} [{r.unit}]"
    for k, (title, values) in enumerate(
        (("peak over the recording", c.peak_map), ("mean while loaded", c.mean_map))
    ):
        ax = fig.add_axes((left + k * width / 2 + 0.05, bottom, width / 2 - 0.08, height))
        img = draw_values(
            ax, lay, values, r.scale, threshold=r.threshold, orientation=r.orientation
        )
        ax.set_title(title, fontsize=NORMAL, pad=14)
        ax.set_xlabel("x [cm]", fontsize=SMALL)
        colour_bar(fig, img, ax, label, r.threshold)


def series_figure(fig: Figure, c: ReportContent) -> None:
    """Load, peak, contact area and centre of force over time, the alerts marked."""
    r = c.review
    s = r.series
    t = s["t"]
    hours = t[-1] > 2 * 3600 if t.size else False
    x = t / 3600 if hours else t / 60
    panels = [
        ("load_N", "load [N]"),
        ("peak", f"peak [{r.unit}]"),
        ("area_cm2", "contact area [cm²]"),
        ("cof", "centre of force [cm]"),
    ]
    panels = [p for p in panels if p[0] in s or p[0] == "cof"]
    axes = fig.subplots(len(panels), 1, sharex=True)
    alerts = [e["t"] for e in r.events if e["kind"] in ("reposition", "turn-due")]
    turns = [e["t"] for e in r.events if e["kind"] == "turn"]
    for ax, (key, label) in zip(axes, panels, strict=True):
        if key == "cof":
            ax.plot(x, s["cof_x"], lw=0.8, label="x (across)")
            ax.plot(x, s["cof_y"], lw=0.8, label="y (along)")
            ax.legend(fontsize=SMALL, loc="upper right")
        else:
            ax.plot(x, s[key], lw=0.8, color="#2764c5")
        if key == "peak" and r.threshold is not None:
            ax.axhline(r.threshold, color="#c2410c", lw=0.8, ls="--")
            ax.text(
                x[0] if x.size else 0,
                r.threshold,
                f" threshold {r.threshold:g} {r.unit}",
                fontsize=SMALL,
                color="#c2410c",
                va="bottom",
            )
        for a in alerts:
            ax.axvline(a / (3600 if hours else 60), color="#c2410c", lw=0.8, alpha=0.8)
        for a in turns:
            ax.axvline(a / (3600 if hours else 60), color="#677189", lw=0.6, ls=":")
        ax.set_ylabel(label, fontsize=SMALL)
        ax.tick_params(labelsize=SMALL)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel(f"time since the start [{'h' if hours else 'min'}]", fontsize=SMALL)
    axes[0].set_title("Over time (red lines: alerts; dotted: turns)", fontsize=NORMAL)


def health_figure(ax: Axes, c: ReportContent) -> None:
    """Share of frames each element was invalid; silent elements crossed."""
    r = c.review
    lay = r.rec.layout
    share = 100 * c.review.health["invalid_share"]
    img = draw_values(ax, lay, share, (0.0, 100.0), cmap="magma_r", orientation=r.orientation)
    silent = np.flatnonzero(c.review.health["silent"])
    if silent.size:
        ax.plot(*lay.xy_cm[silent].T, "x", color="#0ea5e9", ms=5, mew=1.2, label="silent")
        ax.legend(fontsize=SMALL, loc="lower right")
    ax.set_title("failed elements: % of frames invalid", fontsize=NORMAL, pad=14)
    bar = ax.figure.colorbar(img, ax=ax, shrink=0.8, pad=0.08)
    bar.ax.tick_params(labelsize=SMALL)


def sides_figure(ax: Axes, c: ReportContent) -> None:
    """Time per side as bars (hours or minutes)."""
    per = c.review.sides["time_per_side_s"] if c.review.sides else {}
    names = list(per)
    values = np.array([per[k] for k in names])
    hours = values.max(initial=0) > 2 * 3600
    ax.barh(names, values / (3600 if hours else 60), color="#2764c5")
    ax.set_xlabel(f"time [{'h' if hours else 'min'}]", fontsize=SMALL)
    ax.tick_params(labelsize=SMALL)
    ax.set_title(
        f"time per side ({c.review.sides['turns'] if c.review.sides else 0} turns)", fontsize=NORMAL
    )
