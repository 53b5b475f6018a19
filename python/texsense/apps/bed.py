"""Bed monitoring: at-risk regions found from the pressure map, and the turning schedule
(thesis §1.1 and §2.1: pressure-ulcer prevention; docs/bed.md).

**At-risk regions** (:func:`find_regions`). Where a person lies, the pressure peaks over the
bony prominences: occiput, scapulae, sacrum and heels lying on the back; shoulder,
trochanter, knee and ankle on the side; iliac crests and knees lying prone; ischia and heels
sitting up. The map alone says where they are: the body's long axis is the principal axis of
the loaded area (its head end towards the mat's row 0), every local maximum of the lightly
smoothed map gets its place along the body as a fraction of the loaded length and its
offset across it, and each prominence is the highest maximum in its band (e.g. the sacrum:
the highest one between 35 % and 65 % of the length, within 7 cm of the centre line; a
scapula: 12-32 % of the length, on its side of the line and at most 16 cm off it). A
region is the prominence's elements within 4 cm that carry at least half its peak; it is
*at risk* when its peak exceeds the exposure threshold (32 mmHg, §1.1). The head end is at
row 0 unless the mat's orientation puts it at the bottom; ``-l`` / ``-r`` are the person's own
left and right, named only when the orientation says which edge is which (a bed declaring
none has a ``heel`` on each side, never a ``heel-l``; see :func:`side_names`).

**Turning schedule** (:class:`TurningSchedule`). Care plans turn a bed-bound person every
2 h (configurable). The schedule takes the side the person lies on frame by frame (from
the posture model), counts a turn when a new side has held ``settle_s`` (a roll that comes
back does not count; nor does a change within ``settle_s`` of getting into bed: that
corrects the first side), keeps the time on each side, opens a ``turn-due`` alert when the
present side has been held for the interval, and closes it at the next turn. Being out of
bed for ``offload_min`` also restarts the clock (the skin has been offloaded).

Examples
--------
>>> from texsense.sim.bed import bed_layout, lying_pressure
>>> lay = bed_layout()
>>> found = find_regions(lying_pressure(lay, "supine"), lay, "supine")
>>> sorted(found)
['heel-l', 'heel-r', 'occiput', 'sacrum', 'scapula-l', 'scapula-r']
>>> s = TurningSchedule(interval_min=120)
>>> events = [e for t in range(0, 7300, 60) for e in s.step("supine", float(t))]
>>> [(e.kind, e.t) for e in events]
[('in-bed', 0.0), ('turn-due', 7200.0)]
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.apps.alerts import Event, ExposureTracker, frame_time
from texsense.data import stored, units
from texsense.data.layout import Layout
from texsense.exceptions import ParameterError, shown

__all__ = [
    "BANDS",
    "BedWatch",
    "Region",
    "TurningSchedule",
    "body_axis",
    "exposure_with_turns",
    "find_regions",
    "region_elements",
    "side_names",
]

#: Per side: prominence -> (band along the body as fractions of the loaded length, where
#: across the body: "mid" within 7 cm of the centre line, "l" / "r" off it on the mat's first /
#: last column side, "any"; the largest distance from the centre line in cm, so that an arm
#: lying beside the body is not taken for a scapula).
BANDS: dict[str, dict[str, tuple[float, float, str, float]]] = {
    "supine": {
        "occiput": (0.0, 0.14, "mid", 7.0),
        "scapula-l": (0.12, 0.32, "l", 16.0),
        "scapula-r": (0.12, 0.32, "r", 16.0),
        "sacrum": (0.35, 0.65, "mid", 7.0),
        "heel-l": (0.72, 1.0, "l", 26.0),
        "heel-r": (0.72, 1.0, "r", 26.0),
    },
    "left": {
        "shoulder": (0.1, 0.3, "any", 20.0),
        "trochanter": (0.38, 0.68, "any", 20.0),
        "knee": (0.66, 0.88, "any", 30.0),
        "ankle": (0.86, 1.0, "any", 30.0),
    },
    "prone": {
        "iliac-crest-l": (0.38, 0.6, "l", 18.0),
        "iliac-crest-r": (0.38, 0.6, "r", 18.0),
        "knee-l": (0.64, 0.86, "l", 22.0),
        "knee-r": (0.64, 0.86, "r", 22.0),
    },
    "sitting": {
        "ischium-l": (0.0, 0.45, "l", 14.0),
        "ischium-r": (0.0, 0.45, "r", 14.0),
        "heel-l": (0.7, 1.0, "l", 26.0),
        "heel-r": (0.7, 1.0, "r", 26.0),
    },
}
BANDS["right"] = BANDS["left"]
#: Radius of a region around its prominence, cm.
_REGION_CM = 4.0


@dataclass(frozen=True)
class Region:
    """One at-risk region: where (x, y cm on the mat), the elements it covers, its peak and
    mean pressure (N/cm²) and whether the peak exceeds the threshold."""

    name: str
    x_cm: float
    y_cm: float
    elements: tuple[int, ...]
    peak: float
    mean: float
    at_risk: bool

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, with the peak also in mmHg."""
        return {
            "name": self.name,
            "xy_cm": [round(self.x_cm, 1), round(self.y_cm, 1)],
            "elements": list(self.elements),
            "peak_ncm2": round(self.peak, 3),
            "peak_mmhg": round(float(units.convert(self.peak, "N/cm2", "mmHg")), 1),
            "mean_ncm2": round(self.mean, 3),
            "at_risk": self.at_risk,
        }


def _grid(pressure: npt.ArrayLike, layout: Layout) -> np.ndarray:
    if layout.shape is None:
        raise ParameterError("at-risk regions need a grid layout (a bed mat)")
    p = np.asarray(pressure, dtype=np.float64)
    if p.shape != (layout.n_elements,):
        raise ParameterError(f"expected one frame of {layout.n_elements} values, got {p.shape}")
    return np.clip(np.nan_to_num(layout.to_grid(p, fill=0.0)), 0.0, None)


#: A cell carries load above this pressure (N/cm²) and 3 % of the frame's largest.
_LOADED_NCM2 = 0.05


def _cell_xy(rows: np.ndarray, cols: np.ndarray, pitch: tuple[float, float]) -> np.ndarray:
    """Centres (x, y cm) of grid cells, as :attr:`Layout.xy_cm` places a grid's elements."""
    return np.column_stack([(cols + 0.5) * pitch[1], (rows + 0.5) * pitch[0]])


def _axis(
    g: np.ndarray, pitch: tuple[float, float], head_top: bool = True
) -> tuple[np.ndarray, np.ndarray, float, float] | None:
    """Centre, long axis (from the head end: row 0, or the last row when not ``head_top``),
    head end (along the axis from the centre) and length of the loaded cells of the map
    ``g``; None with fewer than 3 loaded cells."""
    rows, cols = np.nonzero(g > max(_LOADED_NCM2, 0.03 * g.max()))
    if rows.size < 3:
        return None
    xy = _cell_xy(rows, cols, pitch)
    centre = xy.mean(axis=0)
    w, v = np.linalg.eigh(np.cov((xy - centre).T))
    axis = v[:, np.argmax(w)]
    if (axis[1] < 0) == head_top:
        axis = -axis
    u = (xy - centre) @ axis
    return centre, axis, float(u.min()), float(u.max() - u.min() + min(pitch))


def body_axis(
    pressure: npt.ArrayLike, layout: Layout
) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The loaded area's centre (x, y cm), its long axis (unit vector pointing from the head
    end, i.e. towards growing rows) and its length along that axis in cm — or None when
    nothing carries load (above 0.05 N/cm² and 3 % of the frame's peak)."""
    found = _axis(_grid(pressure, layout), layout.pitch_cm or (1.0, 1.0))
    return None if found is None else (found[0], found[1], found[3])


def side_names(layout: Layout) -> tuple[bool, str | None, str | None]:
    """How a bed mat lies, from its orientation: whether the head end is at row 0 (also when
    nothing is declared: what every bed mat is assumed to be), and the person's side on the
    mat's first and on its last column (``left``, ``right``, or None when not declared)."""
    o = layout.orientation
    head_top = o.get("bottom") != "head"
    first, last = o.get("left"), o.get("right")
    known = {"left", "right"}
    if first not in known or last not in known or first == last:
        return head_top, None, None
    return head_top, first, last


def _named(name: str, where: str, side: str, first: str | None, last: str | None) -> str:
    """A prominence's name with the person's side (``heel-l``), or without it when the
    orientation does not say which side is which (``heel``). Lying prone, the person's left
    is on the other side of the mat from lying on the back."""
    if where not in ("l", "r"):
        return name
    base = name[:-2]
    body = first if where == "l" else last
    if body is None:
        return base
    if side == "prone":
        body = "right" if body == "left" else "left"
    return f"{base}-{body[0]}"


def region_elements(regions: dict[str, Region]) -> dict[str, list[int]]:
    """Name -> elements of found regions (two regions of one name, e.g. both heels of a mat
    whose sides are unknown, pooled)."""
    out: dict[str, list[int]] = {}
    for r in regions.values():
        out.setdefault(r.name, []).extend(r.elements)
    return out


def find_regions(
    pressure: npt.ArrayLike,
    layout: Layout,
    side: str,
    *,
    threshold: float = 32.0,
    unit: str = "mmHg",
) -> dict[str, Region]:
    """The at-risk regions of one frame of a person lying on ``side`` (``supine``,
    ``prone``, ``left``, ``right`` or ``sitting``): name -> :class:`Region`, for the
    prominences found (a prominence off the mat or without a pressure maximum in its band is
    left out)."""
    from scipy import ndimage  # (a second of import: only where a frame is searched)

    if side not in BANDS:
        raise ParameterError(f"unknown side {side!r}; known: {', '.join(BANDS)}")
    if not units.is_pressure_unit(unit):
        raise ParameterError(f"threshold unit must be a pressure unit, got {unit!r}")
    limit = float(units.convert(threshold, unit, "N/cm2"))
    g = _grid(pressure, layout)
    pitch = layout.pitch_cm or (1.0, 1.0)
    head_top, first, last = side_names(layout)
    found_axis = _axis(g, pitch, head_top)
    if found_axis is None:
        return {}
    centre, axis, head_u, length = found_axis
    smooth = ndimage.gaussian_filter(g, 0.7, mode="constant")
    peaks = (smooth == ndimage.maximum_filter(smooth, size=3)) & (smooth > 0.1 * smooth.max())
    pr, pc = np.nonzero(peaks)
    pxy = _cell_xy(pr, pc, pitch)
    across_axis = np.array([axis[1], -axis[0]])  # towards the mat's last column at angle 0
    if across_axis[0] < 0:
        across_axis = -across_axis
    frac = ((pxy - centre) @ axis - head_u) / length
    off = (pxy - centre) @ across_axis
    value = smooth[pr, pc]
    flat = np.nan_to_num(np.asarray(pressure, dtype=np.float64))
    exy = layout.xy_cm
    regions: dict[str, Region] = {}
    for name, (lo, hi, where, widest) in BANDS[side].items():
        ok = (frac >= lo) & (frac <= hi) & (np.abs(off) <= widest)
        if where == "l":
            ok &= off < 0
        elif where == "r":
            ok &= off > 0
        if not ok.any():
            continue
        k = np.flatnonzero(ok)[np.argmax(value[ok])]
        x, y = pxy[k]
        near = (np.hypot(exy[:, 0] - x, exy[:, 1] - y) <= _REGION_CM) & (flat >= 0.5 * value[k])
        if not near.any():
            continue
        vals = flat[near]
        regions[name] = Region(
            _named(name, where, side, first, last),
            float(x),
            float(y),
            tuple(int(i) for i in np.flatnonzero(near)),
            float(vals.max()),
            float(vals.mean()),
            bool(vals.max() > limit),
        )
    return regions


class TurningSchedule:
    """Time per side and the turning-schedule alert.

    Parameters
    ----------
    interval_min : float
        Turn every this many minutes (default 120, the usual care plan; 15-480 allowed).
    settle_s : float
        A new side counts as a turn once held this long (default 60 s).
    offload_min : float
        Out of bed this long restarts the clock (default 1 min).

    :meth:`step` takes the side of each frame (``supine``, ``prone``, ``left``, ``right``,
    ``sitting``, or ``None`` / ``"out"`` for an empty bed) and returns the events:
    ``in-bed``, ``out-of-bed``, ``turn`` (detail: from, to, after_s), ``turn-due`` (the
    alert opens; detail: side, since_s) and ``turn-done`` (the alert closes with a turn or an
    offload).
    """

    def __init__(
        self, interval_min: float = 120.0, settle_s: float = 60.0, offload_min: float = 1.0
    ) -> None:
        if not 15.0 <= interval_min <= 480.0:
            raise ParameterError(f"interval_min must be within 15-480 min, got {interval_min}")
        if settle_s < 0 or offload_min < 0:
            raise ParameterError("settle_s and offload_min must be >= 0")
        self.interval_s = 60.0 * float(interval_min)
        self.settle_s = float(settle_s)
        self.offload_s = 60.0 * float(offload_min)
        self.side: str | None = None  # the confirmed side (None: out of bed)
        self.since_t: float | None = None  # when the confirmed side began (the last turn)
        self.time_per_side: dict[str, float] = {}
        self.turns = 0
        self.due_since: float | None = None  # the open alert's time, None when closed
        self._candidate: str | None = None
        self._candidate_t = 0.0
        self._last_t: float | None = None

    def step(self, side: str | None, t: float) -> list[Event]:
        """One frame at time ``t`` (s): the side the person lies on (None or ``out``: nobody)."""
        t = frame_time(t)
        side = None if side in (None, "out") else str(side)
        events: list[Event] = []
        if self._last_t is not None and self.side is not None:
            dt = max(t - self._last_t, 0.0)
            self.time_per_side[self.side] = self.time_per_side.get(self.side, 0.0) + dt
        self._last_t = t
        if side != self._candidate:
            self._candidate, self._candidate_t = side, t
        if self.since_t is None and side is not None:  # first person in an empty bed
            self.side, self.since_t, self._candidate_t = side, t, t
            events.append(Event("in-bed", t, detail={"side": side}))
        elif self._candidate != self.side:
            # here somebody is (or was) in bed: side and since_t are set together
            held = t - self._candidate_t
            if self._candidate is None:
                if held >= self.offload_s:
                    events.append(Event("out-of-bed", t, detail={"after_s": round(held, 1)}))
                    events += self._close(t, "offloaded")
                    self.side, self.since_t = None, None
            elif held >= self.settle_s and self.since_t is not None:
                start = self._candidate_t
                # a side held shorter than settle_s (the first frames of somebody getting
                # into bed) is corrected, not turned from
                if start - self.since_t >= self.settle_s:
                    self.turns += 1
                    events.append(Event("turn", start, detail={
                        "from": self.side, "to": self._candidate,
                        "after_s": round(start - self.since_t, 1)}))  # fmt: skip
                    events += self._close(t, "turned")
                    self.since_t = start
                self.side = self._candidate
        if (
            self.side is not None
            and self.since_t is not None
            and self.due_since is None
            and t - self.since_t >= self.interval_s
        ):
            self.due_since = t
            events.append(Event("turn-due", t, detail={
                "side": self.side, "since_s": round(t - self.since_t, 1)}))  # fmt: skip
        return events

    @property
    def turning(self) -> bool:
        """A new side is being held but not yet for ``settle_s``: a turn may be under way."""
        return (
            self._candidate is not None and self.side is not None and self._candidate != self.side
        )

    def state(self) -> dict[str, Any]:
        """What the schedule knows now, JSON-ready (see :meth:`restore`)."""
        return {
            "side": self.side,
            "since_t": self.since_t,
            "time_per_side_s": {k: round(v, 3) for k, v in self.time_per_side.items()},
            "turns": self.turns,
            "due_since": self.due_since,
            "candidate": self._candidate,
            "candidate_t": self._candidate_t,
            "t": self._last_t,
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Go on from a :meth:`state`; one that does not fit raises :class:`ParameterError`."""
        what = "turning schedule"
        per_side = state.get("time_per_side_s") or {} if isinstance(state, dict) else None
        if not isinstance(per_side, dict):
            raise ParameterError(f"the stored {what}'s time_per_side_s is {shown(per_side)}")
        values = (
            stored.optional_text(state, "side", what),
            stored.optional_text(state, "candidate", what),
            stored.optional_number(state, "since_t", what),
            stored.optional_number(state, "due_since", what),
            stored.optional_number(state, "t", what),
            stored.optional_number(state, "candidate_t", what) or 0.0,
            {str(k): stored.number(per_side, k, what, lo=0) for k in per_side},
            stored.whole(state, "turns", what, default=0),
        )
        (self.side, self._candidate, self.since_t, self.due_since, self._last_t,
         self._candidate_t, self.time_per_side, self.turns) = values  # fmt: skip

    def _close(self, t: float, why: str) -> list[Event]:
        if self.due_since is None:
            return []
        self.due_since = None
        return [Event("turn-done", t, detail={"by": why})]

    def status(self, t: float) -> dict[str, Any]:
        """What a viewer shows: the side, seconds since the last turn, seconds until the
        next is due (negative: overdue), time per side, turns, whether the alert is open."""
        since = None if self.since_t is None else t - self.since_t
        return {
            "side": self.side,
            "since_turn_s": None if since is None else round(since, 1),
            "due_in_s": None if since is None else round(self.interval_s - since, 1),
            "interval_s": self.interval_s,
            "time_per_side_s": {k: round(v, 1) for k, v in self.time_per_side.items()},
            "turns": self.turns,
            "turn_due": self.due_since is not None,
        }


def exposure_with_turns(
    tracker: ExposureTracker,
    t: float,
    pressure: npt.ArrayLike,
    schedule: TurningSchedule | None = None,
    schedule_events: list[Event] | None = None,
    bounds: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
    skipped: bool = False,
) -> list[Event]:
    """The exposure tracker's step on a bed, after the schedule's step of the same frame
    (``schedule_events``): a confirmed turn hands the exposure to new skin and clears an open
    alert (:meth:`ExposureTracker.turned`), and no alert opens while a new side is being
    held but not yet confirmed (a sleeper who turned right -> supine 24 s before the sacrum's
    exposure reached its limit is not told to reposition). Returns the schedule's events and
    the tracker's. The live monitor and a recording's review both run this; ``bounds``
    (lower, upper) go to the tracker (issue 37: confident or only possible exceedances), and
    ``skipped`` (frames before this one were skimmed, :meth:`ExposureTracker.step`)."""
    events = list(schedule_events or [])
    tracker.hold = schedule is not None and schedule.turning
    for turn in [e for e in events if e.kind == "turn"]:
        events += tracker.turned(t, turn.t)
    lo, hi = (None, None) if bounds is None else bounds
    p = np.asarray(pressure, dtype=np.float64)
    return events + tracker.step(p, t, lo, hi, skipped=skipped)


class BedWatch:
    """What the monitor runs for a bed mat: the turning schedule on the side the posture
    model reports, and the at-risk regions of every frame.

    Parameters
    ----------
    layout : Layout
        The bed mat (a grid, head end at row 0).
    interval_min, settle_s, offload_min
        The :class:`TurningSchedule`.
    threshold, unit
        A region is at risk above this pressure (default 32 mmHg).
    """

    def __init__(
        self,
        layout: Layout,
        *,
        interval_min: float = 120.0,
        settle_s: float = 60.0,
        offload_min: float = 1.0,
        threshold: float = 32.0,
        unit: str = "mmHg",
    ) -> None:
        if layout.shape is None:
            raise ParameterError("bed monitoring needs a grid layout (a bed mat)")
        self.layout = layout
        self.schedule = TurningSchedule(interval_min, settle_s, offload_min)
        if not units.is_pressure_unit(unit):
            raise ParameterError(f"threshold unit must be a pressure unit, got {unit!r}")
        self.threshold, self.unit = float(threshold), unit
        self.regions: dict[str, Region] = {}

    def step(
        self, pressure: npt.ArrayLike, side: str | None, t: float, *, regions: bool = True
    ) -> list[Event]:
        """One frame at ``t`` (s): its pressure (N/cm²) and the side the person lies on (None:
        nobody). Without ``regions`` only the schedule steps (the regions of the last frame
        that looked for them stay: a station's followed frame, :meth:`Monitor.follow`)."""
        events = self.schedule.step(side, t)
        if not regions:
            return events
        self.regions = {}
        if side in BANDS:
            self.regions = find_regions(
                pressure, self.layout, side, threshold=self.threshold, unit=self.unit
            )
        return events

    def status(self, t: float) -> dict[str, Any]:
        """The schedule's status and the regions, JSON-ready."""
        return {
            **self.schedule.status(t),
            "regions": [r.to_dict() for r in self.regions.values()],
        }
