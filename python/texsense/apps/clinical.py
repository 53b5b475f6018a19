"""The clinical state a recording carries (docs/data-model.md, "The clinical state of a live
recording"): what the monitor knew when the recording started, and every event it raised
while the recording ran, so that a review or a report of the recording says what the nurse
saw live (issue 33: an alert open before the recording started is not forgotten).

A recording started on a live mat (``texsense monitor``, a station's mat) holds

- ``meta["clinical"]``: the state when it started (:func:`clinical_state`): the exposure
  tracker's state (:meth:`texsense.apps.alerts.ExposureTracker.state`: the exposure and relief
  of every exposed element, whether the mat was loaded, the open alert with its places and the
  wall-clock time it opened), a bed's turning schedule
  (:meth:`texsense.apps.bed.TurningSchedule.state`), the calibration in use, and the frame
  time and wall-clock time it was taken at;
- per frame, the labels ``wall_s`` (the wall clock, Unix s, when the frame reached the
  monitor: a device replayed or simulated at 20x runs 20 frame-seconds a second, the wall
  clock does not), ``events`` (the events raised with that frame, a JSON list; ``""`` for
  none; an event raised between frames — an acknowledgement — goes with the next frame) and,
  with a posture model, ``posture_live`` (the side or posture the monitor showed: its vote,
  not a truth).

:func:`live_events` and :func:`frame_walls` read them back; a file without them (a vendor's
export, a recording of an earlier version) has none, and its events are recomputed.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from texsense.data.files import json_loads
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

__all__ = [
    "EVENTS_LABEL",
    "POSTURE_LABEL",
    "STATE_VERSION",
    "WALL_LABEL",
    "clinical_state",
    "encode_events",
    "frame_walls",
    "live_events",
    "start_state",
]

#: The per-frame labels of a live recording.
WALL_LABEL, EVENTS_LABEL, POSTURE_LABEL = "wall_s", "events", "posture_live"
#: The version of ``meta["clinical"]``.
STATE_VERSION = 1


def clinical_state(
    *,
    t: float | None,
    wall: float | None,
    exposure: dict[str, Any] | None,
    bed: dict[str, Any] | None,
    calibration_id: str | None,
    calibrated_wall: float | None,
) -> dict[str, Any]:
    """``meta["clinical"]`` of a recording that starts now (see the module)."""
    return {
        "version": STATE_VERSION,
        "t": t,
        "wall": wall,
        "exposure": exposure,
        "bed": bed,
        "corrections": {"calibration_id": calibration_id, "in_use_since_wall": calibrated_wall},
    }


def start_state(meta: Mapping[str, Any]) -> dict[str, Any] | None:
    """The clinical state a recording's metadata holds, or None; a state of an unknown
    version or shape raises :class:`ParameterError` naming what."""
    state = meta.get("clinical")
    if state is None:
        return None
    if not isinstance(state, Mapping):
        raise ParameterError("meta 'clinical': expected an object")
    if state.get("version") != STATE_VERSION:
        raise ParameterError(
            f"meta 'clinical': version {state.get('version')!r} is not {STATE_VERSION}"
        )
    for key in ("exposure", "bed"):
        if state.get(key) is not None and not isinstance(state.get(key), Mapping):
            raise ParameterError(f"meta 'clinical': {key!r} must be an object")
    return dict(state)


def encode_events(events: list[dict[str, Any]]) -> str:
    """The ``events`` label of one frame (``""`` for none)."""
    return json.dumps(events, separators=(",", ":")) if events else ""


def live_events(rec: Recording) -> list[dict[str, Any]] | None:
    """The events the monitor raised while it recorded ``rec``, each with ``i`` (the frame it
    came with), ``kind``, ``t`` (frame time, s), ``wall``, ``alert_id`` and ``detail``; None
    when the recording has no ``events`` label (it was not recorded live)."""
    labels = rec.labels.get(EVENTS_LABEL)
    if labels is None:
        return None
    out: list[dict[str, Any]] = []
    for i in np.flatnonzero(np.asarray(labels).astype(str) != ""):
        try:
            items = json_loads(str(labels[i]))
            if not isinstance(items, list):
                raise ValueError("not a list")
            for e in items:
                out.append({
                    "i": int(i),
                    "kind": str(e["kind"]),
                    "t": float(e["t"]),
                    "wall": None if e.get("wall") is None else float(e["wall"]),
                    "alert_id": None if e.get("alert_id") is None else int(e["alert_id"]),
                    "detail": dict(e.get("detail") or {}),
                })  # fmt: skip
        except (ValueError, TypeError, KeyError, OverflowError) as err:
            raise ParameterError(
                f"label {EVENTS_LABEL!r} of frame {int(i)} is not a list of events: {err}"
            ) from None
    return out


def frame_walls(rec: Recording) -> np.ndarray | None:
    """The wall clock (Unix s) of every frame, when the recording has it (a live recording),
    else None."""
    walls = rec.labels.get(WALL_LABEL)
    if walls is None:
        return None
    w = np.asarray(walls, dtype=np.float64)
    return w if w.shape == (rec.n_frames,) and np.all(np.isfinite(w)) else None
