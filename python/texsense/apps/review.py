"""Going back through a recording: everything the dashboard's playback and ``texsense report``
show about one recording, computed once (docs/monitor.md "Playback", docs/report.md).

:func:`open_review` takes any recording texsense reads (HDF5, PMD, vendor exports) and gives
a :class:`Review`: the mode (:mod:`texsense.apps.views`), the display unit and the fixed colour
scale, the orientation, the statistics of every frame (load, peak, contact area, centre of
force), the events and alerts, the time per side and the turns of a bed, and per-element
health. The events are **recomputed** from the frames with the monitor's own rules and the
settings the recording declares (a monitor recording stores its threshold, reposition and
turning intervals) — the same events for the same frames, whether the file came from the
monitor, a vendor's software or a simulation. A recording made live carries its clinical
state (:mod:`texsense.apps.clinical`): the recomputation starts from the state the monitor
had when it started (an alert open before the first frame stays open), and the events shown
are the ones the monitor raised, at their wall-clock times, with the recomputed ones it did
not raise marked as such.

Memory: the statistics are computed in blocks of frames, so a night of 27,000 frames of a
2048-element mat needs a few blocks' worth, not a float64 copy of the whole recording. With
``on_demand=True`` (the monitor's playback) a texsense HDF5 recording is not read whole at
all (:mod:`texsense.io.lazy`): the statistics, events and health are streaming passes over
its frames, a frame is read when it is shown, and what the review keeps is its timeline (a
few values per frame), so a recording longer than the memory budget plays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.apps import stats
from texsense.apps.alerts import REPOSITION_RANGE_MIN
from texsense.apps.clinical import frame_walls, live_events, start_state
from texsense.apps.review_events import (
    BLOCK,
    EVENT_TEXT,
    block_of,
    element_health,
    merge_events,
    recompute_events,
    side_labels,
)
from texsense.apps.views import MODES, Mode, guess_mode, orientation_of, recording_scale, started_at
from texsense.data import units
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

__all__ = ["BLOCK", "EVENT_TEXT", "Review", "open_review", "side_labels"]

#: A cell is in contact above this pressure (N/cm², 3.75 mmHg: the monitor's) or, for other
#: quantities, above this share of the colour scale's top.
CONTACT_NCM2 = 0.05
CONTACT_SHARE = 0.02


@dataclass
class Review:
    """One recording, ready to be played back or reported (see :func:`open_review`)."""

    rec: Recording
    name: str
    mode: Mode
    unit: str  # the unit values are shown in (pressure: the mode's or the user's)
    factor: float  # stored value x factor = value in ``unit``
    scale: tuple[float, float]  # fixed colour scale, in ``unit``
    threshold: float | None  # in ``unit``; None: no threshold (not pressure, or foot)
    orientation: dict[str, Any]
    started: float | None  # wall clock (Unix s) of the first frame, if known
    settings: dict[str, float]
    series: dict[str, np.ndarray] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)
    sides: dict[str, Any] | None = None  # a bed: time per side, turns, where the label came from
    health: dict[str, np.ndarray] = field(default_factory=dict)
    #: frames used for the maps and statistics: all but those the reader labels unreliable
    #: (label ``reliable``: PMD's first and last 3 frames of every file, often saturated)
    use: np.ndarray = field(default_factory=lambda: np.ones(0, bool))
    #: (T, N) True where a pressure reading was flagged invalid but carries a repaired value
    #: (it counts, as it does live); None when nothing was repaired
    repaired: np.ndarray | None = None
    #: (lower, upper) (T, N) in the stored unit: the bounds of a processed recording that has
    #: them (``process --interval``, a monitor recording with bounds); None otherwise
    bounds: tuple[np.ndarray, np.ndarray] | None = None
    #: the clinical state the monitor had when the recording started (None: not recorded live)
    start: dict[str, Any] | None = None
    #: the wall clock of every frame (Unix s; None: the file does not say)
    walls: np.ndarray | None = None
    #: whether the events shown are the monitor's own (a live recording) or all recomputed
    live: bool = False
    #: the recording as read, before its repairs counted (kept for a recording read on
    #: demand, whose ``repaired`` mask is not held: :meth:`repaired_at`)
    raw: Recording | None = None
    #: what the review could not use (a start state that does not fit), in words
    notes: list[str] = field(default_factory=list)

    @property
    def on_demand(self) -> bool:
        """True when the frames are read as they are needed (:mod:`texsense.io.lazy`)."""
        from texsense.io import LazyRecording

        return isinstance(self.rec, LazyRecording)

    @property
    def pressure(self) -> bool:
        """True when the recording holds pressure."""
        return self.rec.quantity == "pressure"

    def wall_at(self, i: int) -> float | None:
        """The wall clock (Unix s) of frame ``i``: its own, else the start + its frame time."""
        if self.walls is not None:
            return float(self.walls[i])
        if self.started is None:
            return None
        return self.started + float(self.rec.times[i] - self.rec.times[0])

    @property
    def clock_rate(self) -> float:
        """Frame seconds per wall-clock second over the recording (1 for a real mat; 20 for a
        device simulated or replayed at 20x); 1 when the file does not say."""
        if self.walls is None or self.rec.n_frames < 2:
            return 1.0
        wall = float(self.walls[-1] - self.walls[0])
        frames = float(self.rec.times[-1] - self.rec.times[0])
        return frames / wall if wall > 0 and frames > 0 else 1.0

    def repaired_at(self, i: int) -> list[int]:
        """The elements of frame ``i`` whose values are repairs (flagged invalid by the
        file, counted as valid here: see ``_with_repairs``)."""
        if self.repaired is not None:
            return np.flatnonzero(self.repaired[i]).tolist()
        if self.raw is not None:
            return np.flatnonzero(~self.raw.valid[i]).tolist()
        return []

    def frame(self, i: int) -> np.ndarray:
        """Frame ``i`` in the display unit, NaN where a reading is invalid."""
        if not 0 <= i < self.rec.n_frames:
            raise ParameterError(f"frame {i} is out of range 0..{self.rec.n_frames - 1}")
        v = self.rec.frames[i].astype(np.float64) * self.factor
        v[~self.rec.valid[i]] = np.nan
        return v

    def summary_map(self, how: str) -> np.ndarray:
        """Per element over the whole recording: ``peak`` (the highest valid value) or
        ``mean`` (over the frames with load on the mat), in the display unit."""
        out = np.full(self.rec.n_elements, -np.inf if how == "peak" else 0.0)
        count = np.zeros(self.rec.n_elements)
        loaded = (self.series["area_cm2"] > 0) & self.use
        step = block_of(self.rec)
        for start in range(0, self.rec.n_frames, step):
            sl = slice(start, start + step)
            v = np.where(self.rec.valid[sl], self.rec.frames[sl], np.nan).astype(np.float64)
            v[~self.use[sl]] = np.nan
            if how == "peak":
                with np.errstate(invalid="ignore"):
                    out = np.fmax(out, np.nanmax(np.where(np.isfinite(v), v, -np.inf), axis=0))
            else:
                v = v[loaded[sl]]
                out += np.nansum(v, axis=0)
                count += np.sum(np.isfinite(v), axis=0)
        if how == "peak":
            out[~np.isfinite(out)] = np.nan
            return out * self.factor
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(count > 0, out / count, np.nan) * self.factor


def _display_unit(rec: Recording, mode: Mode, unit: str | None) -> tuple[str, float]:
    if rec.quantity != "pressure":
        if unit is not None and units.canonical(unit) != rec.unit:
            raise ParameterError(f"the recording holds {rec.quantity} in {rec.unit}: no {unit}")
        return rec.unit, 1.0
    want = units.canonical(unit or mode.unit)
    if not units.is_pressure_unit(want):
        raise ParameterError(f"{unit!r} is not a pressure unit")
    return want, units.factor(rec.unit, want)


def _settings_apply(
    mode: str, alerts: bool, model: Any, turn_every: Any, threshold: Any, reposition: Any
) -> None:
    """Refuse a setting given where it does nothing (it would be taken and ignored): a side
    model and a turning schedule outside a bed, exposure settings without exposure alerts (a
    foot, a recording of no pressure)."""
    given = [f for f, v in (("--model", model), ("--turn-every", turn_every)) if v is not None]
    if given and mode != "bed":
        raise ParameterError(
            f"{' and '.join(given)} {'has' if len(given) == 1 else 'have'} no effect here: "
            f"{'it applies' if len(given) == 1 else 'they apply'} to a bed; this recording is "
            f"shown as {mode} (--mode bed shows it as a bed)"
        )
    given = [f for f, v in (("--threshold", threshold), ("--reposition-min", reposition))
             if v is not None]  # fmt: skip
    if given and not alerts:
        raise ParameterError(
            f"{' and '.join(given)} {'has' if len(given) == 1 else 'have'} no effect here: "
            f"{'it applies' if len(given) == 1 else 'they apply'} to exposure alerts, which a "
            f"recording shown as {mode} has none of (a pressure recording as seat, bed, generic)"
        )


#: Where each alert setting may lie (lower, upper, lower excluded): those of the options that
#: set it (``--threshold``, ``--reposition-min``, ``--offload-min``, ``--turn-every``; a test
#: keeps them equal), for a value a recording declares as for a value given.
SETTING_RANGES = {
    "threshold_mmhg": (0.0, 1e4, True),
    "reposition_min": (*REPOSITION_RANGE_MIN, False),
    "offload_min": (0.0, 7 * 24 * 60.0, False),
    "turn_every_min": (0.0, 7 * 24 * 60.0, True),
}


def _settings(meta: dict[str, Any], label: str = "", **given: float | None) -> dict[str, float]:
    """The alert settings: given, else what the recording declares, else the defaults; each a
    real number within :data:`SETTING_RANGES` (a recording's ``true``, ``NaN``, ``-5`` or
    ``1e308`` was taken: clamped, or a run of warnings), else a ``ParameterError`` naming
    the recording (``label``) and the setting."""
    defaults = {
        "threshold_mmhg": 32.0,
        "reposition_min": 20.0,
        "offload_min": 1.0,
        "turn_every_min": 120.0,
    }
    found = meta.get("alerts")
    declared: dict[str, Any] = found if isinstance(found, dict) else {}
    out = {}
    for k, v in defaults.items():
        chosen = given.get(k)
        where = f"the setting {k}"
        if chosen is None:
            chosen = declared.get(k, v)
            where = f"{label or 'the recording'}: the alert setting {k} it declares"
        lo, hi, lo_open = SETTING_RANGES[k]
        number = isinstance(chosen, int | float) and not isinstance(chosen, bool)
        value = float(min(max(chosen, -1e300), 1e300)) if number else math.nan
        if not (value <= hi and (value > lo if lo_open else value >= lo)):  # NaN: never
            room = f"{lo:g}..{hi:g}" + (f", above {lo:g}" if lo_open else "")
            raise ParameterError(f"{where} must be a number in {room}, got {chosen!r}"[:200])
        out[k] = value
    return out


def _series(review: Review) -> dict[str, np.ndarray]:
    """Load (N), peak (display unit), contact area (cm²) and centre of force (cm) per frame."""
    rec = review.rec
    contact = (
        CONTACT_NCM2 * units.factor("N/cm2", rec.unit)
        if review.pressure
        else CONTACT_SHARE * review.scale[1] / review.factor
    )
    parts: dict[str, list[np.ndarray]] = {"load_N": [], "peak": [], "area_cm2": [], "cof": []}
    step = block_of(rec)
    for start in range(0, rec.n_frames, step):
        block = rec.select(slice(start, start + step))
        if review.pressure:
            parts["load_N"].append(stats.total_load(block))
        parts["peak"].append(stats.peak_pressure(block) * review.factor)
        parts["area_cm2"].append(stats.contact_area(block, contact))
        parts["cof"].append(stats.centre_of_force(block))
    cof = np.concatenate(parts["cof"]) if parts["cof"] else np.zeros((0, 2))
    out = {
        "t": rec.times - (rec.times[0] if rec.n_frames else 0.0),
        "peak": np.concatenate(parts["peak"]),
        "area_cm2": np.concatenate(parts["area_cm2"]),
        "cof_x": cof[:, 0],
        "cof_y": cof[:, 1],
    }
    if review.pressure:
        out["load_N"] = np.concatenate(parts["load_N"])
    for k, v in out.items():
        if k != "t":
            v[~review.use] = np.nan
    return out


def open_review(
    source: str | Path | Recording,
    *,
    mode: str | None = None,
    unit: str | None = None,
    scale: tuple[float, float] | None = None,
    threshold_mmhg: float | None = None,
    reposition_min: float | None = None,
    turn_every_min: float | None = None,
    model: Any = None,
    name: str | None = None,
    on_demand: bool = False,
) -> Review:
    """Read a recording (or take one) and compute its :class:`Review`.

    Parameters
    ----------
    source : path or Recording
        Any file or folder :func:`texsense.load` reads.
    mode : str, optional
        ``seat``, ``bed``, ``foot``, ``generic``; default :func:`texsense.apps.views.guess_mode`.
    unit : str, optional
        Display unit for pressure (default: the mode's: mmHg on seats and beds).
    scale : (float, float), optional
        The colour scale in ``unit`` (default: the mode's fixed scale, or one fixed from the
        recording's values for non-pressure data).
    threshold_mmhg, reposition_min, turn_every_min : float, optional
        The alert settings (default: what a monitor recording declares, else 32 mmHg, 20 min,
        120 min).
    model : PostureModel, optional
        A model of sides for a bed recording without side labels.
    name : str, optional
        What to call the recording (default: the file name).
    on_demand : bool
        Read a texsense HDF5 recording's frames when they are needed, not whole
        (:mod:`texsense.io.lazy`: any length plays; other formats are read whole).
    """
    from texsense.io import load, open_recording

    if isinstance(source, Recording):
        original = source
    else:
        original = open_recording(source) if on_demand else load(source)
    rec = _oriented(_with_repairs(original))
    if rec.n_frames == 0:
        raise ParameterError("the recording has no frames")
    label = name or (Path(source).name if not isinstance(source, Recording) else "recording")
    mode = mode or guess_mode(rec.layout, rec.meta)
    if mode not in MODES:
        raise ParameterError(f"unknown mode {mode!r}; known: {', '.join(MODES)}")
    m = MODES[mode]
    _settings_apply(mode, rec.quantity == "pressure" and m.alerts, model, turn_every_min,
                    threshold_mmhg, reposition_min)  # fmt: skip
    shown, factor = _display_unit(rec, m, unit)
    settings = _settings(
        rec.meta,
        label,
        threshold_mmhg=threshold_mmhg,
        reposition_min=reposition_min,
        turn_every_min=turn_every_min,
    )
    scale = _scale(rec, factor, shown, mode) if scale is None else scale
    if not (np.isfinite(scale[0]) and np.isfinite(scale[1]) and scale[1] > scale[0]):
        raise ParameterError(f"the colour scale must run from low to high, got {scale}")
    threshold = None
    if rec.quantity == "pressure" and m.threshold_mmhg is not None:
        threshold = settings["threshold_mmhg"] * units.factor("mmHg", shown)
    review = Review(
        rec,
        label,
        m,
        shown,
        factor,
        (float(scale[0]), float(scale[1])),
        threshold,
        orientation_of(rec.layout, rec.meta, mode),
        started_at(rec.meta),
        settings,
    )
    review.use = _usable(rec)
    review.series = _series(review)
    _events(review, model)
    review.health = element_health(original)
    _repairs_and_bounds(review, original, None if isinstance(source, Recording) else source)
    return review


def _repairs_and_bounds(review: Review, original: Recording, path: str | Path | None) -> None:
    """Where the review's readings are repairs and, for an HDF5 file read whole, its bounds
    (a recording read on demand keeps neither: they are read with each frame)."""
    from texsense.io import LazyRecording

    if isinstance(original, LazyRecording):
        if review.pressure:  # its repairs: read with each frame (Review.repaired_at)
            review.raw = original
        return
    review.repaired = None if review.rec is original else ~original.valid
    if review.pressure and path is not None:
        p = Path(path)
        if p.is_file() and p.suffix.lower() in (".h5", ".hdf5"):
            from texsense.io.hdf5 import read_bounds

            review.bounds = read_bounds(p)
            review.series.update(_bounds_series(review))


def _bounds_series(review: Review) -> dict[str, np.ndarray]:
    """The bounds of the peak (display unit) per frame, from the bounds of every value
    (``process --interval``): every element's true pressure between its lower and upper map
    puts the frame's peak between their highest values over the readings the peak counts —
    what the alert threshold is compared with. (The load gets none: the sums of the maps
    are the case of every element's error at its bound in the same direction at once, on a
    bed night 300-1250 N around a load of 500 N, and an empty mat's 0-750 N.) Empty without
    bounds or when they are not of the review's frames."""
    rec = review.rec
    if review.bounds is None or review.bounds[0].shape != rec.frames.shape:
        return {}
    counted = np.isfinite(stats._values(rec))  # the readings the peak counts: valid, finite
    any_read = counted.any(axis=1) & review.use
    out: dict[str, np.ndarray] = {}
    for name, maps in zip(("lower", "upper"), review.bounds, strict=True):
        peak = np.full(rec.n_frames, np.nan)
        peak[any_read] = stats.highest_bound(counted[any_read], maps[any_read]) * review.factor
        out[f"peak_{name}"] = peak
    return out


def _events(review: Review, model: Any) -> None:
    """The events of a review: a live recording's own (:mod:`texsense.apps.clinical`: its
    wall clock, the state it started in, the events the monitor raised) with the recomputed
    ones it did not raise; else all recomputed."""
    rec = review.rec
    review.walls = frame_walls(rec)
    if review.walls is not None:
        review.started = float(review.walls[0])
    try:
        review.start = start_state(rec.meta)
    except ParameterError as e:
        review.notes.append(f"the clinical state at the start is not used ({e})")
    recomputed, review.sides, notes = recompute_events(review, model)
    review.notes += notes
    try:
        live = live_events(rec)
    except ParameterError as e:  # the file's own label: named, as a reader would
        raise ParameterError(f"{review.name}: {e}") from None
    review.live = live is not None
    review.events = recomputed if live is None else merge_events(review, live, recomputed)


def _scale(rec: Recording, factor: float, shown: str, mode: str) -> tuple[float, float]:
    """The colour scale a recording gets when none is given: the mode's, or one from a sample
    of at most ~400 of its reliable frames (PMD: all but the first and last 3 of a file)."""
    m = MODES.get(mode, MODES["generic"])
    if m.scale is not None and units.is_pressure_unit(shown):
        return recording_scale(np.zeros(0), shown, mode)  # the mode's: no frame needed
    pick = np.flatnonzero(_usable(rec))
    sample = rec.frames[pick[:: max(1, pick.size // 400)]] * factor
    return recording_scale(sample, shown, mode)


def _oriented(rec: Recording) -> Recording:
    """The recording with the orientation its metadata declares on its layout (a monitor's
    recording keeps it in ``meta``, its HDF5 layout does not): its seat zones and a bed's
    left and right are then named as they were live."""
    declared = rec.meta.get("orientation")
    if rec.layout.orientation or not isinstance(declared, dict) or not declared:
        return rec
    edges = {k: v for k, v in declared.items() if k in ("top", "bottom", "left", "right")}
    try:
        layout = rec.layout.with_orientation(edges or None)
    except ParameterError:
        return rec  # a mangled declaration: the map says what orientation_of finds
    from texsense.io import LazyRecording

    if isinstance(rec, LazyRecording):
        return rec.with_layout(layout)
    return Recording(rec.frames, rec.times, layout, rec.quantity, rec.unit, valid=rec.valid,
                     element_times=rec.element_times, labels=rec.labels, meta=rec.meta)  # fmt: skip


def _with_repairs(rec: Recording) -> Recording:
    """A pressure recording whose repaired readings count: the monitor and ``texsense
    process`` flag a repaired element invalid but keep its estimate (eq. 6.14), and the live
    map, statistics and alerts use that estimate; the report and playback do the same.
    Other quantities keep their flags."""
    from texsense.io import LazyRecording

    if rec.quantity != "pressure":
        return rec
    if isinstance(rec, LazyRecording):
        return rec.with_repairs()
    if rec.valid.all():
        return rec
    return Recording(rec.frames, rec.times, rec.layout, rec.quantity, rec.unit,
                     valid=np.isfinite(rec.frames), element_times=rec.element_times,
                     labels=rec.labels, meta=rec.meta)  # fmt: skip


def _usable(rec: Recording) -> np.ndarray:
    """The frames not labelled unreliable (all of them without a ``reliable`` label)."""
    keep = rec.labels.get("reliable")
    if keep is not None and keep.dtype == bool and keep.any():
        return keep.copy()
    return np.ones(rec.n_frames, bool)


def decimate(values: npt.ArrayLike, bins: int, how: str = "max") -> np.ndarray:
    """``values`` reduced to at most ``bins`` points (max or mean per bin, NaN-aware)."""
    v = np.asarray(values, dtype=np.float64)
    if v.size <= bins:
        return v
    edges = np.linspace(0, v.size, bins + 1).astype(int)
    out = np.full(bins, np.nan)
    for k in range(bins):
        part = v[edges[k] : edges[k + 1]]
        part = part[np.isfinite(part)]
        if part.size:
            out[k] = part.max() if how == "max" else part.mean()
    return out
