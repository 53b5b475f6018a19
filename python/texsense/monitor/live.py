"""The monitor's engine: frames from a source, through the pipeline, into statistics, the
posture model, the exposure alerts, the recorder and the viewers (docs/monitor.md).

:class:`Monitor` is independent of the web server: ``await monitor.run()`` consumes the source;
:meth:`Monitor.snapshot` is the latest state as a JSON-ready dict (what the dashboard draws);
subscribers (``subscribe()``) get every snapshot as an already serialised JSON text, so twenty
viewers cost one serialisation per frame.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from texsense import stats, units
from texsense.bed import BANDS
from texsense.exceptions import ParameterError
from texsense.monitor.alerts import Event, ExposureTracker
from texsense.monitor.protocol import Frame
from texsense.monitor.sources import Source
from texsense.monitor.store import EventStore
from texsense.posture.smoothing import WindowVote
from texsense.recording import Recording

__all__ = ["Monitor", "Recorder"]

log = logging.getLogger("texsense.monitor")

#: Longest time between two flushes of a live recording: a killed monitor loses at most this.
FLUSH_S = 0.5
#: The posture shown live is the vote over this many seconds of frame-by-frame predictions
#: (``posture.frame_label`` in the snapshot is the present frame's own).
POSTURE_WINDOW_S = 5.0


class Recorder:
    """Crash-safe HDF5 recording of one session: the source's readings (``<name>-raw.h5``,
    re-processable) and, for capacitance sources, the pressure (``<name>.h5``), both flushed
    at least every :data:`FLUSH_S` s."""

    def __init__(self, folder: Path, name: str, source: Source, meta: dict[str, Any]) -> None:
        from texsense.io.hdf5 import RecordingWriter

        folder.mkdir(parents=True, exist_ok=True)
        lay = source.layout
        self.paths = [folder / f"{name}-raw.h5"]
        self._raw = RecordingWriter(
            self.paths[0],
            lay,
            source.quantity,
            source.unit,
            meta=meta,
            element_times=True,
            flush_interval_s=FLUSH_S,
        )
        self._pressure = None
        if source.quantity == "capacitance":
            self.paths.append(folder / f"{name}.h5")
            self._pressure = RecordingWriter(
                self.paths[1],
                lay,
                "pressure",
                "N/cm2",
                meta=meta,
                element_times=True,
                flush_interval_s=FLUSH_S,
            )
        self.frames = 0

    def append(self, frame: Frame, pressure: np.ndarray, measured: np.ndarray) -> None:
        """Append one frame (raw values and pressure)."""
        t = [frame.t]
        et = frame.element_times[None, :]
        valid = np.isfinite(frame.values)[None, :]
        self._raw.append(
            np.nan_to_num(frame.values)[None, :], times=t, valid=valid, element_times=et
        )
        if self._pressure is not None:
            self._pressure.append(
                np.nan_to_num(pressure)[None, :], times=t, valid=measured[None, :], element_times=et
            )
        self.frames += 1

    def close(self) -> None:
        """Finish the files."""
        self._raw.close()
        if self._pressure is not None:
            self._pressure.close()


class Monitor:
    """Source -> pipeline -> stats, posture, alerts, recorder, viewers.

    Parameters
    ----------
    source : Source
        Where frames come from.
    pipeline : Pipeline, optional
        Capacitance -> pressure (required for a capacitance source).
    tracker : ExposureTracker, optional
        Default: 32 mmHg, 20 min.
    posture_model : PostureModel, optional
        Trained on the same layout (``texsense posture train``).
    store : EventStore, optional
        SQLite store of sessions and events (default: in memory).
    record_dir : Path, optional
        Where recordings go (default ``recordings``).
    bed : BedWatch, optional
        For a bed mat: the turning schedule on the side the posture model reports (its
        labels must be sides: supine, prone, left, right, sitting) and the at-risk regions
        (:mod:`texsense.bed`).
    """

    def __init__(
        self,
        source: Source,
        *,
        pipeline: Any = None,
        tracker: ExposureTracker | None = None,
        posture_model: Any = None,
        store: EventStore | None = None,
        record_dir: Path | str = "recordings",
        bed: Any = None,
    ) -> None:
        if source.quantity == "capacitance" and pipeline is None:
            raise ParameterError("a capacitance source needs a pipeline (a calibration)")
        if pipeline is not None and pipeline.layout.n_elements != source.layout.n_elements:
            raise ParameterError("the pipeline and the source have different element counts")
        if posture_model is not None and posture_model.layout != source.layout:
            raise ParameterError("the posture model was trained on another layout")
        if bed is not None:
            if posture_model is None:
                raise ParameterError("bed monitoring needs a posture model that reports sides")
            unknown = [str(c) for c in posture_model.classes_ if str(c) not in BANDS]
            if unknown:
                raise ParameterError(
                    f"bed monitoring needs a posture model of sides ({', '.join(BANDS)}); "
                    f"this one also knows {', '.join(unknown)}"
                )
        self.source = source
        self.layout = source.layout
        self.pipeline = pipeline
        self.tracker = tracker or ExposureTracker(source.layout)
        self.posture_model = posture_model
        self.bed = bed
        self.store = store or EventStore(":memory:")
        self.record_dir = Path(record_dir)
        self.recorder: Recorder | None = None
        self.session_id = self.store.start_session(source.name)
        self.frames = 0
        self.started = time.time()
        self._latest: dict[str, Any] | None = None
        self._latest_text: str | None = "null"
        self._subscribers: set[asyncio.Queue[str]] = set()
        self._t_offset: float | None = None
        self._cof_trace: list[list[float]] = []

        self._vote = WindowVote(POSTURE_WINDOW_S)

    # ------------------------------------------------------------------ viewers
    def subscribe(self) -> asyncio.Queue[str]:
        """A queue receiving every snapshot (JSON text); old ones are dropped for a slow
        viewer (it always gets the newest)."""
        q: asyncio.Queue[str] = asyncio.Queue(maxsize=2)
        self._subscribers.add(q)
        return q

    def unsubscribe(self, q: asyncio.Queue[str]) -> None:
        """Stop sending to ``q``."""
        self._subscribers.discard(q)

    def _publish(self, text: str) -> None:
        for q in self._subscribers:
            if q.full():
                q.get_nowait()
            q.put_nowait(text)

    # ------------------------------------------------------------------ recording
    def start_recording(self, name: str | None = None) -> list[str]:
        """Start recording to ``record_dir``; returns the file paths."""
        if self.recorder is not None:
            raise ParameterError("already recording")
        stamp = time.strftime("%Y%m%d-%H%M%S")
        name = name or f"session-{self.session_id}-{stamp}"
        if not name.replace("-", "").replace("_", "").isalnum():
            raise ParameterError("recording names may hold letters, digits, - and _ only")
        meta = {"source": self.source.name, "session": self.session_id}
        if self.pipeline is not None:
            meta.update(self.pipeline.provenance())
        self.recorder = Recorder(self.record_dir, name, self.source, meta)
        paths = [str(p) for p in self.recorder.paths]
        self.store.set_recording(self.session_id, paths)
        return paths

    def stop_recording(self) -> int:
        """Stop recording; returns the number of frames written."""
        if self.recorder is None:
            raise ParameterError("not recording")
        n = self.recorder.frames
        self.recorder.close()
        self.recorder = None
        return n

    # ------------------------------------------------------------------ processing
    def _events(self, events: list[Event]) -> None:
        for e in events:
            self.store.add_event(self.session_id, e)
            log.info("event %s at %.1f s %s", e.kind, e.t, e.detail or "")

    def acknowledge(self, alert_id: int) -> Event:
        """Acknowledge an alert."""
        t = self._latest["t"] if self._latest else 0.0
        e = self.tracker.acknowledge(alert_id, t)
        self._events([e])
        return e

    def process(self, frame: Frame) -> dict[str, Any]:
        """One frame through everything; returns the snapshot."""
        received_at = time.time()
        raw = frame.values
        if self.pipeline is not None and self.source.quantity == "capacitance":
            valid = np.isfinite(raw)
            pressure, measured = self.pipeline.step(np.nan_to_num(raw), valid, frame.t)
            codes = self.pipeline.codes_
        else:
            pressure = units.convert(raw, frame.unit, "N/cm2")
            measured = np.isfinite(pressure)
            codes = np.where(measured, 0, 2)
        self._events(self.tracker.step(frame.t, pressure))
        if self.recorder is not None:
            self.recorder.append(frame, pressure, measured)
        rec = Recording(
            np.nan_to_num(pressure)[None, :], [frame.t], self.layout, "pressure", "N/cm2"
        )
        fs = stats.frame_stats(rec, threshold=0.05)
        cof = self._cof_cell(pressure)
        load = float(np.nan_to_num(fs.load_N[0])) if fs.load_N is not None else 0.0
        if np.all(np.isfinite(cof)):
            self._cof_trace = [*self._cof_trace[-59:], [float(cof[0]), float(cof[1])]]
        posture = None
        if self.posture_model is not None and load > 0:
            label, confidence = self.posture_model.predict_with_confidence(pressure[None, :])
            conf = float(confidence[0])
            posture = {
                "label": str(self._vote.step(frame.t, str(label[0]), conf)),
                "frame_label": str(label[0]),
                "confidence": conf,
                "window_s": POSTURE_WINDOW_S,
            }
        else:
            self._vote.reset()  # nobody there: the next person starts a new vote
        bed = None
        if self.bed is not None:
            self._events(self.bed.step(frame.t, pressure, posture["label"] if posture else None))
            bed = self.bed.status(frame.t)
        alert = self.tracker.open_alert
        self.frames += 1

        def r(v: np.ndarray, nd: int = 3) -> list[Any]:  # rounded, NaN -> None (JSON null)
            a = np.asarray(v, dtype=np.float64)
            out = np.round(a, nd).astype(object)
            out[~np.isfinite(a)] = None
            return out.tolist()

        snap = {
            "seq": frame.seq,
            "frames": self.frames,
            "t": frame.t,
            "raw": r(raw),
            "raw_unit": frame.unit,
            "pressure": r(pressure),
            "failed": np.flatnonzero(codes != 0).tolist(),
            "repaired": np.flatnonzero((codes != 0) & np.isfinite(pressure)).tolist(),
            "stats": {
                "load_N": round(load, 2),
                "contact_area_cm2": round(float(np.nan_to_num(fs.contact_area_cm2[0])), 1),
                "peak_ncm2": round(float(np.nan_to_num(fs.peak[0])), 3),
                "ppi_ncm2": round(float(np.nan_to_num(fs.ppi[0])), 3),
                "cof_cm": None
                if not np.all(np.isfinite(fs.cof_cm[0]))
                else [round(float(v), 2) for v in fs.cof_cm[0]],
            },
            "cof_trace": self._cof_trace,  # grid cells (row, col)
            "posture": posture,
            "bed": bed,
            "exposure_s": r(self.tracker.exposure_map(), 1),
            "alert": alert.to_dict() if alert is not None else None,
            "recording": self.recorder is not None,
            "source": self.source.info(),
            "received_at": received_at,  # wall clock (Unix s) when the frame arrived
            "processed_ms": round(1e3 * (time.time() - received_at), 3),
        }
        self._latest = snap
        self._latest_text = None  # serialised when somebody asks (no viewer: no cost)
        if self._subscribers:
            self._publish(self.latest_text)
        return snap

    def _cof_cell(self, pressure: np.ndarray) -> np.ndarray:
        """Centre of force in grid cells (row, col) — what the dashboard draws — or in the
        elements' (x, y) cm for a points layout."""
        w = np.clip(np.nan_to_num(pressure), 0.0, None)
        total = w.sum()
        if total <= 0:
            return np.array([np.nan, np.nan])
        if self.layout.cells is not None and self.layout.shape is not None:
            rows, cols = np.divmod(self.layout.cells, self.layout.shape[1])
            return np.array([w @ rows, w @ cols]) / total
        return (w @ self.layout.xy_cm) / total

    @property
    def latest(self) -> dict[str, Any] | None:
        """The latest snapshot."""
        return self._latest

    @property
    def latest_text(self) -> str:
        """The latest snapshot as JSON text (serialised once per frame, when first asked)."""
        if self._latest_text is None:
            self._latest_text = json.dumps(self._latest, separators=(",", ":"))
        return self._latest_text

    async def run(self, max_frames: int | None = None) -> None:
        """Consume the source (until it ends or ``max_frames``)."""
        try:
            async for frame in self.source.frames():
                self.process(frame)
                if max_frames is not None and self.frames >= max_frames:
                    break
        finally:
            self.close()

    def close(self) -> None:
        """Stop recording, end the session."""
        if self.recorder is not None:
            self.stop_recording()
        self.store.end_session(self.session_id)
