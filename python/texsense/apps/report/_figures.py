"""The report's figures (matplotlib): maps on a fixed scale with the threshold contour and the
orientation, the statistics over time, the health map, the time per side."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from texsense.apps.views import outline_segments, threshold_mask

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


def nice_top(values: np.ndarray) -> float:
    """The top of a colour scale from the data: the largest finite value rounded up to 1, 2,
    2.5 or 5 times a power of ten (1 when there is nothing above 0)."""
    v = np.asarray(values, dtype=np.float64)
    top = float(np.nanmax(np.where(np.isfinite(v), v, np.nan), initial=0.0)) if v.size else 0.0
    if not top > 0:
        return 1.0
    step = 10 ** np.floor(np.log10(top))
    return float(next(k * step for k in (1, 2, 2.5, 5, 10) if k * step >= top))


def grid_extent(layout: Layout) -> tuple[float, float, float, float]:
    """The extent (x0, x1, y0, y1, cm) of a grid layout's whole grid, empty rows and columns
    included (the seat's first three rows hold no element: its elements' extent would
    stretch the map over them)."""
    assert layout.shape is not None and layout.cells is not None
    rows, cols = layout.shape
    py, px = layout.pitch_cm or (1.0, 1.0)
    r, c = divmod(int(layout.cells[0]), cols)
    x0 = float(layout.xy_cm[0, 0]) - (c + 0.5) * px
    y0 = float(layout.xy_cm[0, 1]) - (r + 0.5) * py
    return x0, x0 + cols * px, y0, y0 + rows * py


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
    points layout; NaN blank), the region above ``threshold`` outlined (white over black, the
    page's rule: :func:`texsense.apps.views.threshold_mask`), the axes in cm and the
    orientation's labels outside the edges ("orientation unknown" when none is declared).
    Returns the mappable for a colour bar."""
    x0, x1, y0, y1 = layout.extent_cm
    img: Any
    if layout.shape is not None:
        x0, x1, y0, y1 = grid_extent(layout)
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
            _outline(ax, layout, grid, threshold)
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
    ax.set_xlabel("x [cm]", fontsize=SMALL, labelpad=1)
    ax.set_ylabel("y [cm]", fontsize=SMALL, labelpad=1)
    _orientation(ax, orientation or {})
    return img


def _outline(ax: Axes, layout: Layout, grid: np.ndarray, threshold: float) -> None:
    """The outline of the region above ``threshold`` along the cells' edges."""
    from matplotlib.collections import LineCollection

    active = np.zeros(grid.shape, bool)
    assert layout.cells is not None
    active.ravel()[layout.cells] = True
    segs = outline_segments(threshold_mask(grid, active, threshold))
    x0, x1, y0, y1 = grid_extent(layout)  # the image's extent: grid.shape cells across it
    cell = np.array([(x1 - x0) / grid.shape[1], (y1 - y0) / grid.shape[0]])
    xy = segs * cell + np.array([x0, y0])
    for colour, width in (("black", 2.2), ("white", 1.0)):
        ax.add_collection(LineCollection(list(xy), colors=colour, linewidths=width))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y1, y0)


#: Where each edge's label goes: (x, y) in axes fraction, offset in points past the tick
#: labels and axis labels, alignment and rotation.
_EDGE_PLACES = {
    "top": ((0.5, 1.0), (0, 2), "center", "bottom", 0),
    "bottom": ((0.5, 0.0), (0, -27), "center", "top", 0),
    "left": ((0.0, 0.5), (-33, 0), "right", "center", 90),
    "right": ((1.0, 0.5), (3, 0), "left", "center", 90),
}


def _orientation(ax: Axes, o: dict[str, Any]) -> None:
    """What lies beyond each edge, outside the ticks and axis labels."""
    style: dict[str, Any] = {"fontsize": SMALL, "color": "#444", "xycoords": "axes fraction",
                             "textcoords": "offset points", "annotation_clip": False}  # fmt: skip
    labels = {k: str(o[k]) for k in _EDGE_PLACES if o.get(k)}
    if not labels:
        labels, style["style"] = {"top": "orientation unknown"}, "italic"
    elif o.get("assumed") and "top" in labels:
        labels["top"] += " (assumed)"
    for edge, text in labels.items():
        xy, offset, ha, va, rotation = _EDGE_PLACES[edge]
        ax.annotate(text, xy, xytext=offset, ha=ha, va=va, rotation=rotation, **style)


def colour_bar(fig: Figure, img: Any, cax: Axes, label: str, threshold: float | None) -> None:
    """A colour bar in ``cax`` (as tall as its map) with the threshold marked: a line across
    the bar, a pointer beside it and the threshold as a tick of its own, labelled in bold
    (the ticks too close to it give way)."""
    bar = fig.colorbar(img, cax=cax)
    bar.set_label(label, fontsize=SMALL)
    bar.ax.tick_params(labelsize=SMALL)
    if threshold is None:
        return
    lo, hi = img.get_clim()
    if not lo <= threshold <= hi:
        return
    bar.ax.axhline(threshold, color="white", lw=2.5)
    bar.ax.axhline(threshold, color="black", lw=1.2, ls="--")
    bar.ax.plot([-0.35], [threshold], marker=">", color="black", ms=6, clip_on=False)
    near = 0.1 * (hi - lo)
    ticks = [t for t in bar.get_ticks() if lo <= t <= hi and abs(t - threshold) > near]
    ticks = sorted([*ticks, threshold])
    bar.set_ticks(ticks, labels=[f"{t:g}" for t in ticks])
    for text, tick in zip(bar.ax.get_yticklabels(), ticks, strict=True):
        if tick == threshold:
            text.set_fontweight("bold")


Box = tuple[float, float, float, float]


def map_boxes(
    fig: Figure, rect: tuple[float, float, float, float], aspect: float, n: int = 2
) -> list[tuple[Box, Box]]:
    """Where ``n`` maps of height/width ``aspect`` go inside ``rect`` (figure fraction), each
    with its colour bar beside it, as large as they fit: side by side or one above the other,
    whichever gives the larger maps, at the top of ``rect``. Returns (map box,
    colour bar box) per map. Each map leaves room for its axis labels and edge labels."""
    fw, fh = fig.get_size_inches()
    left, bottom, width, height = rect
    W, H = width * fw, height * fh  # inches
    # inches: tick labels, axis label and edge label on the left; edge label, colour bar
    # with its ticks and label on the right; title and edge labels above and below
    pad_l, pad_r, pad_v, bar, gap = 0.62, 0.78, 0.48, 0.14, 0.2

    def size(cols: int, rows: int) -> float:  # the map's width in inches
        cell_w, cell_h = W / cols - pad_l - pad_r, H / rows - 2 * pad_v
        return max(0.0, min(cell_w, cell_h / aspect))

    cols, rows = max(((n, 1), (1, n)), key=lambda cr: size(*cr))
    w = size(cols, rows)
    h = w * aspect
    cell_w = W / cols
    y_top = H  # at the top of the space: whatever is left over is below them
    boxes: list[tuple[Box, Box]] = []
    for k in range(n):
        c, r = (k, 0) if cols == n else (0, k)
        x = c * cell_w + (cell_w - (pad_l + w + pad_r)) / 2 + pad_l
        y = y_top - r * (h + 2 * pad_v) - pad_v - h
        box = (float(left + x / fw), float(bottom + y / fh), float(w / fw), float(h / fh))
        cbar = (float(left + (x + w + gap) / fw), box[1], float(bar / fw), box[3])
        boxes.append((box, cbar))
    return boxes


def maps_figure(fig: Figure, rect: tuple[float, float, float, float], c: ReportContent) -> None:
    """The peak and mean maps inside ``rect`` (figure fraction), as large as they fit, each
    with a colour bar as tall as the map: pressure on the mode's fixed scale with the
    threshold; other quantities (raw counts) each on a scale from its own data (a peak map on
    the scale of the typical frame would saturate)."""
    r = c.review
    lay = r.rec.layout
    x0, x1, y0, y1 = grid_extent(lay) if lay.shape is not None else lay.extent_cm
    label = f"{r.rec.quantity} [{r.unit}]"
    maps = (("peak over the recording", c.peak_map), ("mean while loaded", c.mean_map))
    for (title, values), (box, cbox) in zip(
        maps, map_boxes(fig, rect, (y1 - y0) / max(x1 - x0, 1e-9)), strict=True
    ):
        scale = r.scale if r.pressure else (0.0, nice_top(values))
        ax = fig.add_axes(box)
        img = draw_values(ax, lay, values, scale, threshold=r.threshold, orientation=r.orientation)
        ax.set_title(title, fontsize=NORMAL, pad=12)
        colour_bar(fig, img, fig.add_axes(cbox), label, r.threshold)


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
            if f"{key}_lower" in s:  # the bounds of every value, as a band (issue 37)
                ax.fill_between(x, s[f"{key}_lower"], s[f"{key}_upper"], color="#2764c5",
                                alpha=0.2, lw=0, label="bounds")  # fmt: skip
                ax.legend(fontsize=SMALL, loc="upper right")
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


def health_figure(fig: Figure, rect: tuple[float, float, float, float], c: ReportContent) -> None:
    """Share of frames each element was invalid; silent elements crossed; inside ``rect``."""
    r = c.review
    lay = r.rec.layout
    x0, x1, y0, y1 = grid_extent(lay) if lay.shape is not None else lay.extent_cm
    ((box, cbox),) = map_boxes(fig, rect, (y1 - y0) / max(x1 - x0, 1e-9), n=1)
    ax = fig.add_axes(box)
    share = 100 * c.review.health["invalid_share"]
    img = draw_values(ax, lay, share, (0.0, 100.0), cmap="magma_r", orientation=r.orientation)
    silent = np.flatnonzero(c.review.health["silent"])
    if silent.size:
        ax.plot(*lay.xy_cm[silent].T, "x", color="#0ea5e9", ms=5, mew=1.2, label="silent")
        ax.legend(fontsize=SMALL, loc="lower right")
    ax.set_title("failed elements: % of frames invalid", fontsize=NORMAL, pad=12)
    bar = fig.colorbar(img, cax=fig.add_axes(cbox))
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
