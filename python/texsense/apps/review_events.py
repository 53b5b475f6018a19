"""The events of a recording recomputed with the monitor's rules, the time per side of a bed,
and per-element health (part of :mod:`texsense.apps.review`).

- **Exposure** (pressure recordings, modes with alerts): :class:`ExposureTracker` with the
  recording's settings (32 mmHg, 20 min, 1 min offload unless it declares others) — the
  same reposition alerts and clearings the live monitor raised on these frames, minus the
  acknowledgements (a person's act, not in the frames).
- **Turning** (beds with a side per frame: a side model, or the recording's label ``side``
  / ``posture_class``): :class:`texsense.apps.bed.TurningSchedule` — turns, turn due, time per side.
- **Places**: an alert names the at-risk regions of the bed's side at that frame
  (:func:`texsense.apps.bed.find_regions`) or the seat's zones, else rows and columns.
- **Health**: the share of frames each element was invalid (failed and repaired, or not
  read), and *silent* elements: near zero throughout while all their neighbours carried
  load (a dead element on a mat the reader did not flag).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from texsense.apps import stats
from texsense.apps.alerts import REPOSITION_RANGE_MIN, Alert, Event, ExposureTracker
from texsense.apps.bed import (
    BANDS,
    TurningSchedule,
    exposure_with_turns,
    find_regions,
    region_elements,
)
from texsense.apps.clinical import POSTURE_LABEL
from texsense.apps.views import alert_places, format_duration, seat_zones
from texsense.data import budget, stored, units
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

if TYPE_CHECKING:
    from texsense.apps.review import Review

__all__ = [
    "BLOCK",
    "EVENT_TEXT",
    "block_of",
    "element_health",
    "event_places",
    "event_text",
    "merge_events",
    "open_at_start",
    "recompute_events",
    "side_labels",
]

#: Frames per block of the statistics (bounds memory; fewer under a small budget: block_of).
BLOCK = 2048


def block_of(rec: Recording) -> int:
    """Frames per block of the statistics of ``rec``: :data:`BLOCK`, fewer when the float64
    copies of a block of a mat with many elements would take more than a small share of the
    memory budget (:mod:`texsense.data.budget`: a 256th per value)."""
    return max(1, min(BLOCK, budget.max_memory() // (256 * max(1, rec.n_elements))))


#: What the events are called on the pages and in the report.
EVENT_TEXT = {
    "seated": "sat down",
    "left": "got up",
    "in-bed": "in bed",
    "out-of-bed": "out of bed",
    "loaded": "load on the mat",
    "unloaded": "mat unloaded",
    "reposition": "reposition alert",
    "acknowledged": "alert acknowledged",
    "cleared": "alert cleared (skin offloaded)",
    "clock": "the mat's clock jumped (re-synchronised)",
    "turn": "turned",
    "turn-due": "turn due",
    "turn-done": "turn alert closed",
    "calibrated": "calibration in use",
}


def side_labels(rec: Recording, model: Any = None) -> tuple[np.ndarray | None, str]:
    """The side a person lies on in every frame of a bed recording (``None`` for an empty
    bed) and where it came from: a posture model of sides (``model``), else the recording's
    label ``side`` (the virtual bed), ``posture_class`` (PhysioNet PMD) or ``posture_live``
    (the side the monitor showed while it recorded); (None, "") if none of them is there."""

    if model is not None:
        if model.layout != rec.layout:
            raise ParameterError("the posture model was trained on another layout")
        frames = np.nan_to_num(rec.masked_frames())
        sides = np.asarray(model.predict(frames)).astype(object)
        if rec.quantity == "pressure":
            sides[stats.total_load(rec) < 50.0] = None  # under 5 kg: nobody
        return sides, "the posture model"
    for name in ("side", "posture_class", POSTURE_LABEL):
        if name in rec.labels:
            raw = np.asarray(rec.labels[name]).astype(str).astype(object)
            known = np.isin(raw, [*BANDS, "transition"])
            raw[~known] = None  # out, empty, unknown labels: nobody on a side
            return raw, f"the recording's label {name!r}"
    return None, ""


def event_text(kind: str, detail: dict[str, Any]) -> str:
    """One line for an event, in the words of the pages."""

    text = EVENT_TEXT.get(kind, kind)
    if kind == "turn":
        text += f" {detail.get('from')} → {detail.get('to')}"
        if detail.get("after_s") is not None:
            text += f" after {format_duration(detail['after_s'])}"
    elif kind == "turn-due":
        text += f": {format_duration(detail.get('since_s'))} on {detail.get('side')}"
    elif kind == "out-of-bed" and detail.get("after_s") is not None:
        # the event comes once the bed has been empty this long: not how long it stayed empty
        text += f" (empty for {format_duration(detail['after_s'])} by then)"
    elif kind == "cleared" and detail.get("by") == "turned":
        text = "alert cleared (turned)"
    if detail.get("open_at_start"):
        text += " (open when the recording started)"
    if detail.get("where"):
        text += ": " + ", ".join(detail["where"])
    return text


def event_places(detail: dict[str, Any]) -> str:
    """The details line of an event: the grid positions no region names (the text names
    regions only, as the live alert band does: issue 33), or ``""``."""
    if not detail.get("details"):
        return ""
    return ("also " if detail.get("where") else "where on the map: ") + ", ".join(detail["details"])


def _places(
    review: Review, elements: list[int], row: np.ndarray, side: Any
) -> tuple[list[str], list[str]]:

    lay = review.rec.layout
    regions: dict[str, Any] = {}
    if review.mode.name == "bed" and side in BANDS and lay.shape is not None:
        found = find_regions(row, lay, str(side), threshold=review.settings["threshold_mmhg"])
        regions = region_elements(found)
    elif review.mode.name == "seat" and lay.shape is not None:
        regions = seat_zones(lay)
    return alert_places(elements, lay, regions)


def _seeded(
    review: Review, tracker: ExposureTracker | None, schedule: TurningSchedule | None
) -> list[str]:
    """Seed the tracker and the schedule with the state the monitor had when the recording
    started (:mod:`texsense.apps.clinical`); returns notes on what could not be used."""
    state = review.start
    notes: list[str] = []
    if state is None:
        return notes
    if tracker is not None and state.get("exposure") is not None:
        try:
            tracker.restore(state["exposure"])
        except ParameterError as e:
            notes.append(f"the exposure at the start is not used ({e})")
    if schedule is not None and state.get("bed") is not None:
        try:
            schedule.restore(state["bed"])
        except ParameterError as e:
            notes.append(f"the turning schedule at the start is not used ({e})")
    return notes


def _entry(
    i: int, t_rel: float, e: Event | dict[str, Any], source: str, wall: float | None
) -> dict[str, Any]:
    kind = e.kind if isinstance(e, Event) else e["kind"]
    alert = e.alert_id if isinstance(e, Event) else e.get("alert_id")
    detail = dict(e.detail if isinstance(e, Event) else e.get("detail") or {})
    return {"i": i, "t": round(t_rel, 3), "kind": kind, "alert": alert, "detail": detail,
            "text": event_text(kind, detail), "places": event_places(detail),
            "source": source, "wall": wall}  # fmt: skip


def recompute_events(
    review: Review, model: Any = None
) -> tuple[list[dict[str, Any]], dict[str, Any] | None, list[str]]:
    """The events of ``review``'s frames (see the module), seeded with the state the monitor
    had when the recording started; for a bed with sides, the time per side and the turns;
    and notes on the start state."""

    rec, mode, s = review.rec, review.mode, review.settings
    sides, origin = side_labels(rec, model) if mode.name == "bed" else (None, "")
    tracker = None
    if review.pressure and mode.alerts:
        lo, hi = REPOSITION_RANGE_MIN
        tracker = ExposureTracker(
            rec.layout,
            threshold=s["threshold_mmhg"],
            unit="mmHg",
            reposition_min=min(max(s["reposition_min"], lo), hi),
            offload_min=s["offload_min"],
            occupancy=None if sides is not None else mode.occupancy,
            occupancy_hold_s=mode.occupancy_hold_s,
        )
    schedule = None if sides is None else TurningSchedule(interval_min=s["turn_every_min"])
    notes = _seeded(review, tracker, schedule)
    to_ncm2 = units.factor(rec.unit, "N/cm2") if review.pressure else 1.0
    t0 = float(rec.times[0])
    out: list[dict[str, Any]] = []
    step = block_of(rec)
    stepping = tracker is not None or schedule is not None  # neither: no event to find
    for start in range(0, rec.n_frames if stepping else 0, step):
        block = np.where(rec.valid[start : start + step], rec.frames[start : start + step], np.nan)
        for k, row in enumerate(block.astype(np.float64) * to_ncm2):
            i = start + k
            t = float(rec.times[i])
            events: list[Event] = []
            if schedule is not None and sides is not None:
                events += schedule.step(sides[i], t)
            if tracker is not None:
                events = exposure_with_turns(tracker, t, row, schedule, events)
            for e in events:
                if e.kind == "reposition" and tracker is not None:
                    alert = next(a for a in tracker.alerts if a.id == e.alert_id)
                    where, details = _places(
                        review, alert.elements, row, sides[i] if sides is not None else None
                    )
                    e.detail = {"where": where, "details": details, "elements": alert.elements}
                out.append(_entry(i, t - t0, e, "recomputed", review.wall_at(i)))
    beds = None
    if schedule is not None:
        beds = {
            "source": origin,
            "time_per_side_s": {k: round(v, 1) for k, v in schedule.time_per_side.items()},
            "turns": schedule.turns,
            "interval_min": s["turn_every_min"],
        }
    return out, beds, notes


def open_at_start(review: Review) -> list[dict[str, Any]]:
    """The alerts open when the recording started (from its clinical state), as events
    before its first frame: a reposition alert with its places, a turn that was due. A state
    whose values are not of their kinds lists nothing (``_seeded``'s note says it is not
    used)."""
    state = review.start or {}
    t0 = float(review.rec.times[0])
    out: list[dict[str, Any]] = []
    try:
        alert, due = _open_at_start(state)
    except ParameterError:
        return out
    if alert is not None and review.pressure and review.mode.alerts:
        detail: dict[str, Any] = {"where": alert.where, "details": alert.details,
                                  "elements": alert.elements, "open_at_start": True}  # fmt: skip
        e = {"kind": "reposition", "alert_id": alert.id, "detail": detail}
        out.append(_entry(0, alert.opened_t - t0, e, "before", alert.opened_wall))
    if due is not None and review.sides is not None:
        side, since, due_since = due
        detail = {"side": side, "since_s": round(due_since - since, 1), "open_at_start": True}
        e = {"kind": "turn-due", "detail": detail}
        out.append(_entry(0, due_since - t0, e, "before", None))
    return out


def _open_at_start(
    state: dict[str, Any],
) -> tuple[Alert | None, tuple[str | None, float, float] | None]:
    """The open alert and the turn due (side, since, due since) of a clinical state, each
    value of its kind (or a :class:`ParameterError`)."""
    exposure, bed = state.get("exposure") or {}, state.get("bed") or {}
    alert = None
    if exposure.get("alert") is not None:
        size = stored.whole(exposure, "size", "exposure state")
        alert = Alert.from_dict(stored.mapping(exposure, "alert", "exposure state"), places=size)
    due_since = stored.optional_number(bed, "due_since", "turning schedule")
    if due_since is None:
        return alert, None
    since = stored.optional_number(bed, "since_t", "turning schedule")
    side = stored.optional_text(bed, "side", "turning schedule")
    return alert, (side, due_since if since is None else since, due_since)


def merge_events(
    review: Review, live: list[dict[str, Any]], recomputed: list[dict[str, Any]]
) -> list[dict[str, Any]]:
    """The events a report and playback show for a live recording: the alerts open when it
    started, every event the monitor raised while it ran (``source`` ``live``, at its own
    wall-clock time), and the recomputed events the monitor did not raise (``recomputed``:
    a recomputed event matches a live one of the same kind within 2 frames)."""
    t0 = float(review.rec.times[0])
    shown = [_entry(e["i"], e["t"] - t0, e, "live", e.get("wall")) for e in live]
    free = {k: [e["i"] for e in shown if e["kind"] == k] for k in {e["kind"] for e in shown}}
    for e in recomputed:
        near = [i for i in free.get(e["kind"], []) if abs(i - e["i"]) <= 2]
        if near:
            free[e["kind"]].remove(near[0])
        else:
            shown.append(e)
    shown.sort(key=lambda e: (e["i"], e["source"] != "live"))
    return [*open_at_start(review), *shown]


def element_health(rec: Recording) -> dict[str, np.ndarray]:
    """Per element: ``invalid_share`` (share of frames flagged invalid) and ``silent``: its
    highest valid reading stays under 2 % of the mat's high values (the 99th percentile of
    the elements' highest readings) while each of its 3 or 4 neighbours reached a tenth of
    them — a dead element inside a loaded area, not one at its edge or in noise."""

    n = rec.n_elements
    invalid = np.zeros(n)
    top = np.full(n, -np.inf)
    step = block_of(rec)
    for start in range(0, rec.n_frames, step):
        valid = rec.valid[start : start + step]
        invalid += np.sum(~valid, axis=0)
        v = np.where(valid, rec.frames[start : start + step], -np.inf)
        top = np.maximum(top, v.max(axis=0))
    indptr, indices = rec.layout.neighbours
    finite = top[np.isfinite(top)]
    ref = float(np.percentile(finite, 99)) if finite.size else 0.0
    # never valid: already counted as invalid, not silent
    quiet: Any = np.flatnonzero(np.isfinite(top) & (top <= 0.02 * ref)) if ref > 0 else []
    silent = np.zeros(n, bool)
    for i in quiet:  # neighbours that carried real load (a tenth of the mat's high values)
        nb = indices[indptr[i] : indptr[i + 1]]
        silent[i] = nb.size >= 3 and bool(np.all(top[nb] > 0.1 * ref))
    return {"invalid_share": invalid / max(rec.n_frames, 1), "silent": silent}
