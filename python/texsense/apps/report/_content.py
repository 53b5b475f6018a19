"""What a report says, as tables of text (shared by the PDF and the HTML writers)."""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from texsense import __version__
from texsense.apps.bed import BANDS, find_regions, region_elements
from texsense.apps.review import BLOCK, Review, side_labels
from texsense.apps.roi import roi_elements
from texsense.apps.views import (
    checked_words,
    format_clock,
    format_duration,
    place_names,
    seat_zones,
    times_words,
)
from texsense.data import units

__all__ = ["ReportContent", "Table", "report_content"]


@dataclass
class Table:
    """A table: a title, column names, rows of text, and a note under it."""

    title: str
    columns: list[str]
    rows: list[list[str]]
    note: str = ""
    align: str = ""  # one letter per column: l or r (default: first l, rest r)

    def aligns(self) -> str:
        """The alignment of every column."""
        return self.align or ("l" + "r" * (len(self.columns) - 1))


@dataclass
class ReportContent:
    """Everything a report shows."""

    review: Review
    title: str
    identity: Table
    summary: Table
    peak_map: np.ndarray
    mean_map: np.ndarray
    regions: Table
    events: Table
    health: Table
    sides: Table | None
    region_outlines: dict[str, np.ndarray] = field(default_factory=dict)


def _fmt(v: float | None, unit: str = "", nd: int = 1) -> str:
    if v is None or not np.isfinite(v):
        return "–"
    return f"{v:.{nd}f}{' ' + unit if unit else ''}"


def _digits(review: Review) -> int:
    return 0 if review.unit in ("mmHg", "kPa", "count") else 2


def _frame_seconds(times: np.ndarray) -> np.ndarray:
    """How long each frame stands for: the gap to the next one (the last: the median gap),
    at most 5 median gaps (a pause in a recording is not time on the mat)."""
    if times.size < 2:
        return np.ones(times.size)
    gaps = np.diff(times)
    med = float(np.median(gaps))
    return np.clip(np.append(gaps, med), 0.0, 5 * med)


def _identity(review: Review) -> Table:
    rec, meta = review.rec, review.rec.meta
    o = review.orientation
    span = f"{format_duration(rec.duration_s)} ({rec.n_frames} frames"
    period = rec.frame_period_s
    span += f", one every {period:.3g} s)" if np.isfinite(period) else ")"
    first, last = review.wall_at(0), review.wall_at(rec.n_frames - 1)
    if first is not None and last is not None:
        a, b = _dt.datetime.fromtimestamp(first), _dt.datetime.fromtimestamp(last)
        to = f"{b:%H:%M:%S}" if a.date() == b.date() else f"{b:%Y-%m-%d %H:%M:%S}"
        span = f"{a:%Y-%m-%d %H:%M:%S} to {to}, " + span
    rate = review.clock_rate
    if abs(rate - 1.0) > 0.05:
        span += (
            f"; the device's clock ran {rate:.3g} x the wall clock (simulated or replayed): "
            "the clock times are the wall clock's, durations the device's"
        )
    cal = meta.get("calibration_id") or meta.get("calibration", {}) or "none declared"
    if isinstance(cal, dict):
        cal = cal.get("id", "none declared")
    rows = [
        ["file", review.name],
        ["source", str(meta.get("source", "–"))],
        ["format", str(meta.get("format", "texsense HDF5"))],
        ["device", str(meta.get("device") or meta.get("sensors") or "–")],
        ["calibration id", str(cal)],
        ["quantity", f"{rec.quantity} in {rec.unit} (shown in {review.unit})"],
        ["span", span],
        [
            "layout",
            f"{rec.n_elements} elements"
            + (f", {rec.layout.shape[0]} x {rec.layout.shape[1]} grid" if rec.layout.shape else ""),
        ],
        ["mode", review.mode.name],
        ["orientation", _orientation_text(o)],
        ["colour scale", _scale_text(review)],
    ]
    if review.threshold is not None:
        s = review.settings
        rows.append(
            [
                "alert settings",
                f"{s['threshold_mmhg']:g} mmHg held "
                f"{s['reposition_min']:g} min; offload {s['offload_min']:g} min",
            ]
        )
    if review.sides is not None:
        rows.append(["turning schedule", f"every {review.settings['turn_every_min']:g} min"])
    if not review.use.all():
        rows.append(
            [
                "left out",
                f"{int((~review.use).sum())} frames the reader labels "
                "unreliable (not in the maps and statistics)",
            ]
        )
    rows += _certainty_rows(review)
    rows.append(["events", _events_origin(review)])
    rows += [["note", n] for n in review.notes]
    rows.append(["made by", f"texsense {__version__}, {_dt.datetime.now():%Y-%m-%d %H:%M}"])
    return Table("Recording", ["", ""], rows, align="ll")


def _certainty_rows(review: Review) -> list[list[str]]:
    """How far the numbers can be trusted (issue 37): the bounds and the in-use drift
    correction the recording declares."""
    meta, rows = review.rec.meta, []
    level = (meta.get("interval") or {}).get("level")
    if review.bounds is not None and level:
        rows.append(["bounds", f"{100 * level:g} % (split conformal; every value ± its bound)"])
    iu = meta.get("in_use_drift")
    if isinstance(iu, dict):
        if iu.get("state") == "correcting":
            text = (
                f"load {100 * iu.get('load_correction', 0):+.1f} % at the end, correcting "
                f"since {format_duration(iu.get('since_t') or 0)} into the data, from "
                f"{format_duration(iu.get('still_s', 0))} still in all; zero taken "
                f"{times_words(iu.get('zeroed', 0))}"
            )
            if iu.get("weight_n") is not None:  # (the load on the mat, not the person's weight)
                text += (
                    f"; reference load {iu['weight_n']:.0f} N (the first still period's), "
                    f"held to it: {times_words(iu.get('weighed', 0))}"
                )
            text += "; " + checked_words(iu, "before the end")
        elif iu.get("state") == "off":
            text = f"off: {iu.get('why', '')}"
        else:
            text = "no still period: nothing corrected"
        rows.append(["drift corrected in use", text])
    return rows


def _peak_with_bound(review: Review) -> str:
    """The highest peak, ± its bound where the recording has bounds."""
    s, nd, u = review.series, _digits(review), review.unit
    peak = float(np.nanmax(s["peak"], initial=np.nan))
    if review.bounds is None or not np.isfinite(peak):
        return _fmt(peak, u, nd)
    k = int(np.nanargmax(s["peak"]))
    i = int(np.nanargmax(np.nan_to_num(review.frame(k), nan=-np.inf)))
    lo, hi = (float(b[k, i]) * review.factor for b in review.bounds)
    level = (review.rec.meta.get("interval") or {}).get("level")
    pct = f" ({100 * level:g} %)" if level else ""
    return f"{peak:.{nd}f} ± {0.5 * (hi - lo):.{nd}f} {u}{pct}"


def _scale_text(review: Review) -> str:
    """The maps' colour scale: the mode's fixed one for pressure, the data's otherwise."""
    if review.pressure:
        return f"{_fmt(review.scale[0], '', 0)}-{_fmt(review.scale[1], review.unit, 0)} (fixed)"
    return (
        f"from the data ({review.rec.quantity}, not pressure): each map from 0 to its highest "
        "value, rounded up"
    )


def _orientation_text(o: dict[str, Any]) -> str:
    """The orientation row: the edges, and whether left and right are known."""
    if not o:
        return "unknown (not declared): no left or right is named"
    edges = ", ".join(f"{k}: {v}" for k, v in o.items() if k in ("top", "bottom", "left", "right"))
    text = edges + (" (assumed)" if o.get("assumed") else "")
    if "left" not in o and "right" not in o:
        text += "; left and right not declared: no side is named"
    return text


def _events_origin(review: Review) -> str:
    """Where the events come from, in words."""
    if not review.live:
        return "recomputed from the frames with the monitor's rules (the file holds none)"
    state = "the state when the recording started" if review.start else "the first frame"
    return (
        "as the monitor raised them while it recorded (live); events it did not raise are "
        f"recomputed from the frames with its rules, from {state}"
    )


def _summary(review: Review) -> Table:
    s, nd, u = review.series, _digits(review), review.unit
    dt = _frame_seconds(review.rec.times)
    loaded = (s["area_cm2"] > 0) & review.use
    rows = [
        ["highest peak", _peak_with_bound(review)],
        [
            "median peak while loaded",
            _fmt(float(np.nanmedian(s["peak"][loaded])) if loaded.any() else None, u, nd),
        ],
        ["time with load on the mat", format_duration(float(dt[loaded].sum()))],
    ]
    if "load_N" in s:
        rows.append(["highest load", _fmt(float(np.nanmax(s["load_N"], initial=np.nan)), "N", 0)])
    if review.threshold is not None:
        above = np.nan_to_num(s["peak"]) > review.threshold
        rows.append(
            [
                f"time with a peak above {review.threshold:.{nd}f} {u}",
                format_duration(float(dt[above].sum())),
            ]
        )
    rows.append(["alerts", _alert_count(review)])
    if review.sides is not None:
        rows.append(["turns", str(review.sides["turns"])])
    return Table("Summary", ["", ""], rows, align="ll")


def _alert_count(review: Review) -> str:
    """``1 reposition (open when the recording started), 0 turn due``; on a bed the exposure
    alert is the *pressure alert* (its action is a turn, as the dashboard says)."""
    parts = []
    exposure = {"turn": "pressure alert", "offload": "offload alert"}.get(
        review.mode.action, "reposition"
    )
    for kind, word in (("reposition", exposure), ("turn-due", "turn due")):
        found = [e for e in review.events if e["kind"] == kind]
        before = sum(e["source"] == "before" for e in found)
        text = f"{len(found)} {word}"
        if before:
            text += f" ({before} open when the recording started)"
        parts.append(text)
    return ", ".join(parts)


def _regions(review: Review, rois: list[dict[str, Any]]) -> tuple[dict[str, Any], str]:
    """name -> (elements, frame mask or None); and a note on where they came from."""

    lay, out, notes = review.rec.layout, {}, []
    for r in rois:
        out[r["name"]] = (roi_elements(r, lay), None)
    if rois:
        notes.append(f"{len(rois)} region(s) of interest drawn by the user")
    for k, v in lay.regions.items():
        out.setdefault(k, (np.asarray(v), None))
    zones = seat_zones(lay) if review.mode.name == "seat" and lay.shape is not None else {}
    for k, v in zones.items():
        out.setdefault(f"{k} (zone)", (v, None))
    if zones:
        notes.append("seat zones by position on the seat, not found anatomy")
    elif review.mode.name == "seat":
        notes.append("no seat zones: the seat's orientation is not declared")
    if review.sides is not None and lay.shape is not None:
        out.update(_bed_regions(review))
        notes.append("bed regions: found on the mean map of each side's frames")
    return out, "; ".join(notes)


def _bed_regions(review: Review) -> dict[str, Any]:

    rec = review.rec
    sides, _ = side_labels(rec)
    out: dict[str, Any] = {}
    if sides is None:  # a model's sides: recomputed from the events' schedule is not kept
        return out
    to_ncm2 = units.factor(review.unit, "N/cm2") if review.pressure else 1.0
    for side in [s for s in BANDS if s in set(sides.tolist())]:
        mask = sides == side
        frames = rec.frames[mask].astype(np.float64) * review.factor * to_ncm2
        mean = np.nanmean(np.where(rec.valid[mask], frames, np.nan), axis=0)
        thr = review.settings["threshold_mmhg"] if review.pressure else 1e9
        found = find_regions(np.nan_to_num(mean), rec.layout, side, threshold=thr)
        for name, elements in region_elements(found).items():
            out[f"{name} ({side})"] = (np.asarray(elements), mask)
    return out


def _region_table(review: Review, rois: list[dict[str, Any]]) -> Table:
    regions, note = _regions(review, rois)
    rec, nd, u = review.rec, _digits(review), review.unit
    dt = _frame_seconds(rec.times)
    cols = ["region", "elements", "area cm²", f"mean {u}", f"peak {u}"]
    if review.threshold is not None:
        cols.append(f"time > {review.threshold:.{nd}f} {u}")
    rows = []
    for name, (idx, mask) in regions.items():
        if idx.size == 0:
            rows.append([name, "0", "0", "–", "–"] + (["–"] if len(cols) > 5 else []))
            continue
        peaks, means = [], []
        for start in range(0, rec.n_frames, BLOCK):
            sl = slice(start, start + BLOCK)
            v = np.where(rec.valid[sl][:, idx], rec.frames[sl][:, idx], np.nan) * review.factor
            with np.errstate(all="ignore"):
                peaks.append(np.nanmax(np.where(np.isfinite(v), v, -np.inf), axis=1))
                means.append(np.nanmean(v, axis=1))
        peak, mean = np.concatenate(peaks), np.concatenate(means)
        use = review.use if mask is None else mask & review.use
        loaded = use & (peak > 0)
        row = [
            name,
            str(idx.size),
            f"{rec.layout.area_cm2[idx].sum():.0f}",
            _fmt(float(np.nanmean(mean[loaded])) if loaded.any() else None, "", nd),
            _fmt(float(np.max(peak[use])) if use.any() else None, "", nd),
        ]
        if review.threshold is not None:
            row.append(format_duration(float(dt[use & (peak > review.threshold)].sum())))
        rows.append(row)
    note = (note + ". " if note else "") + "Mean over the frames with load in the region."
    return Table("Regions", cols, rows, note=note)


#: How an event came about, in the report's words.
_ORIGIN = {"live": "live", "recomputed": "recomputed", "before": "open at start"}


def _event_table(review: Review, limit: int = 300) -> Table:
    rows = []
    for e in review.events[:limit]:
        wall = e.get("wall")
        if wall is None and e["source"] != "before":
            wall = review.wall_at(e["i"])
        when = format_clock(None, e["t"]) if wall is None else format_clock(wall, 0.0)
        into = format_duration(e["t"]) if e["t"] >= 0 else f"{format_duration(-e['t'])} before"
        rows.append([when, into, _ORIGIN.get(e["source"], e["source"]), e["text"]])
        if e.get("places"):  # the grid positions on a line of their own, under the regions
            rows.append(["", "", "", f"  {e['places']}"])
    note = "clock time: the wall clock" if review.wall_at(0) else "time since the start"
    if review.live:
        note += (
            "; live: raised by the monitor while it recorded; recomputed: found from the frames "
            "with the monitor's rules, not raised live; open at start: open when the recording "
            "started (from its clinical state)"
        )
    else:
        note += "; recomputed from the frames with the monitor's rules"
    if len(review.events) > limit:
        note += f"; the first {limit} of {len(review.events)} events"
    if not rows:
        note = "no events: " + (
            "no load held above the threshold long enough, no turns"
            if review.pressure or review.sides
            else "the recording holds no pressure (no exposure alerts) and no sides"
        )
    title = "Events and alerts"
    cols = ["at", "into the recording", "how", "what"]
    return Table(title, cols, rows, note=note, align="rrll")


def _health_table(review: Review) -> Table:
    h, lay = review.health, review.rec.layout
    bad = np.flatnonzero((h["invalid_share"] > 0) | h["silent"])
    rows = []
    for i in bad[np.argsort(-h["invalid_share"][bad], kind="stable")][:60]:
        where = place_names([int(i)], lay)[0]
        what = (
            "silent (near zero throughout, its neighbours loaded)" if h["silent"][i] else "invalid"
        )
        rows.append([where, f"{100 * h['invalid_share'][i]:.1f} %", what])
    note = (
        f"{int((h['invalid_share'] > 0).sum())} element(s) invalid in some frames, "
        f"{int(h['silent'].sum())} silent, of {lay.n_elements}"
    )
    if bad.size > 60:
        note += "; the 60 most often invalid are listed"
    return Table(
        "Sensor health", ["element", "frames invalid", "what"], rows, note=note, align="lrl"
    )


def _sides_table(review: Review) -> Table | None:
    if review.sides is None:
        return None
    per = review.sides["time_per_side_s"]
    total = sum(per.values()) or 1.0
    rows = [[k, format_duration(v), f"{100 * v / total:.0f} %"] for k, v in per.items()]
    note = f"{review.sides['turns']} turn(s); the side of every frame from {review.sides['source']}"
    return Table("Time per side", ["side", "time", "share"], rows, note=note)


def report_content(review: Review, rois: list[dict[str, Any]]) -> ReportContent:
    """Tables and maps of a report."""
    return ReportContent(
        review=review,
        title=f"Pressure report: {review.name}",
        identity=_identity(review),
        summary=_summary(review),
        peak_map=review.summary_map("peak"),
        mean_map=review.summary_map("mean"),
        regions=_region_table(review, rois),
        events=_event_table(review),
        health=_health_table(review),
        sides=_sides_table(review),
    )
