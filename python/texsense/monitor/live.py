"""The monitor's engine: frames from a source, through the pipeline, into statistics, the
posture model, the exposure alerts, the recorder and the viewers (docs/monitor.md).

:class:`Monitor` is independent of the web server: ``await monitor.run()`` consumes the source
and ``await monitor.watch()`` says when it falls silent;
:meth:`Monitor.snapshot` is the latest state as a JSON-ready dict (what the dashboard draws);
subscribers (``subscribe()``) get every snapshot as an already serialised JSON text, so twenty
viewers cost one serialisation per frame.

Every frame passes the mat's :class:`~texsense.monitor.clock.FrameClock` first: a frame with
a time no clock has (not a number, beyond 1e12 s) is refused, and a frame whose time is off
the mat's clock (from the future, or backwards) skipped, both counted and logged once, so a
glitch never reaches the pipeline, the exposure and the alerts; a clock that really jumped is
re-synchronised with an event ``clock``.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from texsense.apps import stats
from texsense.apps.alerts import Event, ExposureTracker
from texsense.apps.bed import BANDS, exposure_with_turns, region_elements
from texsense.apps.clinical import clinical_state
from texsense.apps.posture.smoothing import WindowVote
from texsense.apps.stats import raw_rise
from texsense.apps.views import MODES, alert_places, format_duration, orientation_of, seat_zones
from texsense.compensation.pipeline import no_negative
from texsense.data import stored, units
from texsense.data.protocol import Frame
from texsense.exceptions import ParameterError
from texsense.monitor.clock import FrameClock, Quiet
from texsense.monitor.record import Recorder, unused_recording_name
from texsense.monitor.sources import Source
from texsense.monitor.store import EventStore

if TYPE_CHECKING:  # the calibration and models come from the caller; their modules load there
    from texsense.apps.bed import BedWatch
    from texsense.apps.posture.model import PostureModel
    from texsense.compensation.pipeline import Pipeline

__all__ = ["Monitor", "Recorder", "raw_rise"]

log = logging.getLogger("texsense.monitor")

#: Frames of statistics the monitor keeps for the page's charts (a page opened late still
#: draws what came before it: ``GET /api/history``).
HISTORY = 1200
#: The posture shown live is the vote over this many seconds of frame-by-frame predictions
#: (``posture.frame_label`` in the snapshot is the present frame's own).
POSTURE_WINDOW_S = 5.0
#: The latest runs of frames never seen that the monitor names (``missed_runs``: which frames a
#: takeover, the broker or the clock lost; ``missed`` counts them all).
MISSED_RUNS = 20
#: A source that has sent nothing for this long is said to be silent (console and page).
SILENT_S = 10.0


def _rounded(v: npt.ArrayLike, nd: int = 3) -> list[Any]:
    """Values rounded to ``nd`` decimals for JSON, NaN as None (null)."""
    a = np.asarray(v, dtype=np.float64)
    out = np.round(a, nd).astype(object)
    out[~np.isfinite(a)] = None
    return out.tolist()


def _finite(x: float) -> float:
    """``np.nan_to_num`` of one float (NaN -> 0, an infinity -> the largest float), quickly."""
    return x if math.isfinite(x) else float(np.nan_to_num(x))


class Monitor:
    """Source -> pipeline -> stats, posture, alerts, recorder, viewers.

    Parameters
    ----------
    source : Source
        Where frames come from.
    pipeline : Pipeline, optional
        Capacitance -> pressure. Without one, a capacitance source is shown and recorded
        raw (pF): no pressure, statistics, posture or alerts — what a new mat needs before
        it is calibrated (``texsense calibrate wizard``).
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
        (:mod:`texsense.apps.bed`).
    mode : str, optional
        ``seat``, ``bed``, ``foot`` or ``generic`` (:data:`texsense.apps.views.MODES`): the words
        of the events and alerts, whether there are any, the page's unit and colour scale.
        Default: ``bed`` with ``bed``, else ``seat``.
    """

    #: frames never seen (gaps in the frames' numbers, ``seq``: lost on the way, skipped by
    #: the clock, published while no station held the mat) and the latest
    #: :data:`MISSED_RUNS` runs of them, each (first seq, last seq)
    missed: int
    missed_runs: deque[tuple[int, int]]

    def __init__(
        self,
        source: Source,
        *,
        pipeline: Pipeline | None = None,
        tracker: ExposureTracker | None = None,
        posture_model: PostureModel | None = None,
        store: EventStore | None = None,
        record_dir: Path | str = "recordings",
        bed: BedWatch | None = None,
        mode: str | None = None,
    ) -> None:

        #: a capacitance source without a calibration: raw readings only
        self.raw_only = source.quantity == "capacitance" and pipeline is None
        if self.raw_only and (posture_model is not None or bed is not None):
            raise ParameterError(
                "posture and bed monitoring need pressure: give the mat's calibration"
            )
        if pipeline is not None and pipeline.layout.n_elements != source.layout.n_elements:
            raise ParameterError("the pipeline and the source have different element counts")
        if posture_model is not None and posture_model.layout != source.layout:
            raise ParameterError("the posture model was trained on another layout")
        if bed is not None:
            if posture_model is None:
                raise ParameterError("bed monitoring needs a posture model that reports sides")
            if posture_model.classes_ is None:
                raise ParameterError("bed monitoring needs a trained posture model")
            unknown = [str(c) for c in posture_model.classes_ if str(c) not in BANDS]
            if unknown:
                raise ParameterError(
                    f"bed monitoring needs a posture model of sides ({', '.join(BANDS)}); "
                    f"this one also knows {', '.join(unknown)}"
                )
        mode = mode or ("bed" if bed is not None else "seat")
        if mode not in MODES:
            raise ParameterError(f"unknown mode {mode!r}; known: {', '.join(MODES)}")
        self.mode = MODES[mode]
        self.source = source
        self.layout = source.layout
        self.pipeline = pipeline
        self.tracker = tracker or ExposureTracker(source.layout)
        # the mode's words; a bed's schedule says in-bed / out-of-bed itself
        self.tracker.occupancy = None if bed is not None else self.mode.occupancy
        self.tracker.occupancy_hold_s = self.mode.occupancy_hold_s
        self.posture_model = posture_model
        self.bed = bed
        self.store = store or EventStore(":memory:")
        self.record_dir = Path(record_dir)
        self.recorder: Recorder | None = None
        self.session_id = self.store.start_session(source.name)
        self.frames = 0
        self.started = time.time()
        self._latest: dict[str, Any] | None = None
        self._maps: tuple[Any, ...] | None = None  # the latest snapshot's maps, not yet lists
        self._latest_text: str | None = "null"
        self._subscribers: set[asyncio.Queue[str]] = set()
        self._t_first: float | None = None  # the time of the first frame
        self._cof_trace: list[tuple[float, float]] = []
        self._live_stats: stats.LiveStats | None = None  # the frames' statistics (compiled)
        self._skimmed = False  # frames not read since the last frame processed
        self.last_seq: int | None = None  # of the last frame on the time line
        self.missed, self.missed_runs = 0, deque(maxlen=MISSED_RUNS)  # frames never seen (seq)
        self.clock = FrameClock(rate=source.rate)
        self.quiet = Quiet(log)
        self.last_wall: float | None = None  # wall time of the last frame processed
        self.last_pressure: np.ndarray | None = None  # N/cm², NaN where unknown
        self._raw_floor: np.ndarray | None = None  # each element's lowest raw reading so far
        self.changes = 0  # grows with every frame, acknowledgement and recording start/stop
        self.feed: dict[str, Any] = {"state": "waiting", "text": f"waiting for {source.name}"}
        self._vote = WindowVote(POSTURE_WINDOW_S)
        #: the statistics of the last :data:`HISTORY` frames (the page's charts)
        #: (rows are tuples of numbers: the collector leaves them, issue 38: as lists, 1,200 a
        #: mat were most of a station's objects, and a full collection at 1,000 mats took 0.1 s)
        self.history: deque[tuple[Any, ...]] = deque(maxlen=HISTORY)
        self.calibrated_wall: float | None = None  # when the calibration came into use
        self._adopt_orientation(pipeline)
        #: called with every frame on the mat's clock, before it is processed (the page's
        #: calibration steps record the live stream this way)
        self.taps: list[Callable[[Frame], None]] = []

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
        """Start recording to ``record_dir``; returns the file paths. A ``name`` that an
        earlier recording has is refused; the default name (session and time) gets a
        ``-2``, ``-3``... suffix when needed: no recording is ever written over."""
        if self.recorder is not None:
            raise ParameterError("already recording")
        if name is not None and not name.replace("-", "").replace("_", "").isalnum():
            raise ParameterError("recording names may hold letters, digits, - and _ only")
        if name is None:
            stamp = time.strftime("%Y%m%d-%H%M%S")
            name = unused_recording_name(
                self.record_dir,
                f"session-{self.session_id}-{stamp}",
                self.source.quantity,
                not self.raw_only,
            )

        meta = {
            "source": self.source.name,
            "session": self.session_id,
            "mode": self.mode.name,
            "started_at": time.time(),
            "orientation": orientation_of(self.layout, mode=self.mode.name),
            "clinical": self.clinical_state(),
            "alerts": {
                "threshold_mmhg": round(
                    units.convert(self.tracker.threshold_ncm2, "N/cm2", "mmHg"), 3
                ),
                "reposition_min": self.tracker.reposition_s / 60,
                "offload_min": self.tracker.offload_s / 60,
                "turn_every_min": self.bed.schedule.interval_s / 60 if self.bed else 120.0,
            },
        }
        bounds = False
        if self.pipeline is not None:
            meta.update(self.pipeline.provenance())
            bounds = getattr(self.pipeline, "interval", None) is not None
            if bounds:
                meta["interval"] = {"level": self.pipeline.interval}
        self.recorder = Recorder(
            self.record_dir,
            name,
            self.source,
            meta,
            calibrated=not self.raw_only,
            posture=self.posture_model is not None,
            bounds=bounds,
        )
        self.changes += 1
        paths = [str(p) for p in self.recorder.paths]
        self.store.set_recording(self.session_id, paths)
        return paths

    def clinical_state(self) -> dict[str, Any]:
        """What the monitor knows now, for a recording that starts now
        (:func:`texsense.apps.clinical.clinical_state`)."""
        alerts = self.mode.alerts and not self.raw_only
        return clinical_state(
            t=self.clock.last_t,
            wall=self.last_wall,
            exposure=self.tracker.state() if alerts else None,
            bed=self.bed.schedule.state() if self.bed is not None else None,
            calibration_id=None if self.pipeline is None else self.pipeline.calibration_id,
            calibrated_wall=self.calibrated_wall,
        )

    def stop_recording(self) -> int:
        """Stop recording; returns the number of frames written."""
        if self.recorder is None:
            raise ParameterError("not recording")
        n = self.recorder.frames
        extra = None
        if self.pipeline is not None and getattr(self.pipeline, "in_use", False):
            extra = {"in_use_drift": self.pipeline.in_use_status()}
        self.recorder.close(extra)
        self.recorder = None
        self.changes += 1
        return n

    def set_orientation(self, orientation: dict[str, str]) -> None:
        """How the mat lies (what lies beyond each edge of its map; {}: unknown): the maps'
        labels, the seat's zones and the bed's sides follow from the next frame on."""
        self.layout = self.layout.with_orientation(orientation or None)
        self.source.layout = self.source.layout.with_orientation(orientation or None)
        if self.bed is not None:
            self.bed.layout = self.layout
        self.tracker.layout = self.layout
        self.changes += 1

    def _adopt_orientation(self, pipeline: Pipeline | None) -> None:
        """A mat that does not declare its orientation takes its calibration's (declared when
        it was calibrated: the wizard, the page's panel)."""
        declared = pipeline.chain.orientation if pipeline is not None else {}
        if declared and not self.layout.orientation:
            self.set_orientation(dict(declared))

    def use_calibration(self, pipeline: Pipeline, path: Path | str | None = None) -> None:
        """Show pressure through ``pipeline`` from the next frame on (a calibration just made
        on the page, :mod:`texsense.monitor.calibrate`); an event ``calibrated`` says when.
        A recording in progress goes on (its raw file is complete; a pressure file starts
        with the next recording)."""
        if self.source.quantity != "capacitance":
            raise ParameterError(f"{self.source.name} reads pressure: it needs no calibration")
        if pipeline.layout.n_elements != self.layout.n_elements:
            raise ParameterError("the pipeline and the source have different element counts")
        self.pipeline = pipeline
        self._adopt_orientation(pipeline)
        self.raw_only = False
        self.calibrated_wall = time.time()
        # the load the calibration was made with may still lie on the mat: not a person
        self.tracker.wait_for_empty()
        self.changes += 1
        t = self._latest["t"] if self._latest else 0.0
        detail = {
            "calibration_id": pipeline.calibration_id,
            "file": None if path is None else str(path),
        }
        self.record_events([Event("calibrated", t, None, detail)])
        log.warning("%s: now showing pressure through the calibration %s", self.source.name,
                    path or pipeline.calibration_id)  # fmt: skip

    # ------------------------------------------------------------------ checkpoints
    def resume_state(self) -> dict[str, Any]:
        """The state a takeover continues from (copies: the frame count, the first frame's
        time, the last frame's number, the clock, the exposure as arrays' bytes, the bed's
        schedule, the posture vote); :meth:`resume` takes it back."""
        return {
            "frames": self.frames,
            "t_first": self._t_first,
            "seq": self.last_seq,
            "missed": self.missed,
            "missed_runs": [s for run in self.missed_runs for s in run],
            "clock": self.clock.state(),
            "tracker": self.tracker.state_packed(),
            "bed": None if self.bed is None else self.bed.schedule.state(),
            "vote": self._vote.state(),
        }

    def resume(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`resume_state` (of this process or another's). What came
        between that state and the next frame read here is not known unless the frames'
        numbers say that nothing did: the next step counts it as not read. A state that does
        not fit raises :class:`ParameterError` (the monitor is then partly restored: start it
        afresh)."""
        what = "monitor"
        frames = stored.whole(state, "frames", what)
        t_first = stored.optional_number(state, "t_first", what)
        seq = stored.optional_whole(state, "seq", what)  # (an earlier version's has none)
        missed = stored.whole(state, "missed", what, default=0)
        runs = stored.wholes(state, "missed_runs", what) if "missed_runs" in state else []
        if len(runs) % 2:
            raise ParameterError(f"the stored {what} state's missed_runs are not pairs")
        clock = FrameClock(rate=self.clock.rate_hint).restore(stored.mapping(state, "clock", what))
        self.tracker.restore(stored.mapping(state, "tracker", what))
        if self.bed is not None and state.get("bed") is not None:
            self.bed.schedule.restore(stored.mapping(state, "bed", what))
        self._vote.restore(stored.mapping(state, "vote", what))
        self.clock, self.frames, self._t_first = clock, frames, t_first
        self.last_seq, self.missed = seq, missed
        self.missed_runs.clear()
        self.missed_runs.extend(zip(runs[::2], runs[1::2], strict=True))
        self._skimmed = self.last_seq is None
        self.changes += 1

    def start_afresh(self) -> None:
        """No exposure, no alert, a new clock (no state to resume; the pipeline's, the
        sensor's state, is its own: ``pipeline.reset()``)."""
        self.tracker.restore({"size": len(self.tracker.names), "exposed": []})
        if self.bed is not None:
            self.bed.schedule.restore({})
        self._vote.reset()
        self.clock = FrameClock(rate=self.clock.rate_hint)
        self.frames, self._t_first, self.last_seq, self._skimmed = 0, None, None, False
        self.changes += 1

    # ------------------------------------------------------------------ processing
    def record_events(self, events: list[Event], wall: float | None = None) -> None:
        """Store and log events (and keep them for the recording's next frame)."""
        wall = time.time() if wall is None else wall
        for e in events:
            self.store.add_event(self.session_id, e)
            if self.recorder is not None:
                self.recorder.pending.append({**e.to_dict(), "wall": wall})
            log.info(
                "%s: %s %s into the session %s",
                self.source.name,
                e.kind,
                format_duration(e.t - (self._t_first or 0.0)),
                e.detail or "",
            )

    def _where(self, elements: list[int]) -> tuple[list[str], list[str]]:
        """Where elements lie, in words: the bed's at-risk regions or the seat's zones (as
        far as the mat's orientation names them), and the rest as rows and columns for the
        details line (:func:`texsense.apps.views.alert_places`)."""

        if self.tracker.by_region:
            return [self.tracker.names[i] for i in elements], []
        regions: dict[str, Any] = {}
        if self.bed is not None:
            regions = region_elements(self.bed.regions)
        elif self.mode.name == "seat" and self.layout.shape is not None:
            regions = seat_zones(self.layout)
        return alert_places(elements, self.layout, regions)

    def acknowledge(self, alert_id: int) -> Event:
        """Acknowledge an alert."""
        t = self._latest["t"] if self._latest else 0.0
        e = self.tracker.acknowledge(alert_id, t)
        self.record_events([e])
        self.changes += 1
        return e

    def _in_step(self, frame: Frame, wall: float) -> bool:
        """Place the frame on the mat's time line (:class:`FrameClock`); False when it is
        skipped (counted and logged once). A frame whose number (``seq``) is more than one
        past the last one's says that frames were never seen here (lost on the way, skipped
        by the clock, published while no station held the mat): counted as ``missed``, and
        the exposure of the next frame processed spans them (:meth:`ExposureTracker.step`,
        ``skipped``). A number that goes back (the mat restarted) is no gap."""
        verdict, t, jump = self.clock.place_frame(frame, wall)
        if verdict == "unclocked":  # a time no clock has: never reaches the clock
            self.source.errors += 1
            self.source.last_error = f"frame {frame.seq}: {self.clock.fault}"
            self.quiet.warn(self.source.name, "unclocked",
                            f"refused frame {frame.seq}: {self.clock.fault}")  # fmt: skip
            return False
        if verdict in ("ahead", "backwards"):
            self.source.errors += 1
            what = "from the future" if verdict == "ahead" else "from the past"
            self.source.last_error = f"frame {frame.seq}: time {frame.t:.6g} s is {what}"
            text = f"skipped frame {frame.seq}: its time {frame.t:.6g} s is {jump:+.4g} s off"
            self.quiet.warn(self.source.name, "clock", f"{text} the mat's clock ({what})")
            return False
        if self.last_seq is not None and frame.seq > self.last_seq + 1:  # frames not seen
            self.missed += frame.seq - self.last_seq - 1
            self.missed_runs.append((self.last_seq + 1, frame.seq - 1))
            self._skimmed = True
        self.last_seq = frame.seq
        source_t, shift = frame.t, t - frame.t
        if shift != 0.0:
            frame.element_times = frame.element_times + shift
        if verdict == "resync":
            detail = {"jump_s": round(jump, 3), "source_t": source_t, "seq": frame.seq}
            log.warning("%s: the clock jumped %+.4g s; re-synchronised", self.source.name, jump)
            self.record_events([Event("clock", t, None, detail)])
        return True

    def keep_time(self, frame: Frame, wall: float) -> bool:
        """Place a frame whose values are not read (a station far behind peeks at its time
        only) on the mat's time line, so that the clock stays in step; False when its time is
        off the clock (counted and logged as in :meth:`process`). The exposure of the next
        frame processed spans it (:meth:`ExposureTracker.step`, ``skipped``)."""
        kept = self._in_step(frame, wall)
        self._skimmed = self._skimmed or kept
        return kept

    def follow(self, frame: Frame, wall: float) -> bool:
        """A frame a busy station does not process in full (a newer one of the mat waits):
        it goes through what the frames after it depend on, as in :meth:`process` — the
        clock, the pipeline's state (failure detector, Preisach memory eq. 4.18-4.22, drift
        history), for a bed the side vote and the turning schedule, the exposure and its
        alerts and events — and through nothing that only shows it (statistics, maps,
        snapshot, charts, viewers, a bed's regions). The exposure timers and alerts are those
        of processing every frame (issue 38). False when its time is off the clock."""
        return self._take(frame, wall, full=False) is not None

    def _take(self, frame: Frame, wall: float, *, full: bool) -> tuple[Any, ...] | None:
        """What :meth:`follow` and :meth:`process` share: the clock, the taps, the first
        frame's time, a raw mat's floor, the pressure and its bounds, the bed's side, the
        exposure and its events (stored). None when the frame's time is off the clock;
        ``full``: with the statistics, the posture and a bed's regions (what a snapshot
        shows), else ``()`` for a raw mat (nothing else of it outlives the frame)."""
        if not self._in_step(frame, wall):
            return None
        if full:
            self.last_wall = wall
        for tap in self.taps:
            tap(frame)
        if self._t_first is None:
            self._t_first = frame.t
        if self.raw_only:  # nothing of a raw frame outlives it but the clock and the floor
            floor, raw = self._raw_floor, frame.values
            self._raw_floor = np.array(raw, np.float64) if floor is None else np.fmin(floor, raw)
            if not full:
                return ()
        pressure, measured, codes = self._pressure_of(frame)
        bounds = self._bounds_of()
        frame_stats, posture = None, None
        if full:
            frame_stats, load = self._stats_of(frame.t, pressure)
            if bounds is not None and not self.raw_only:
                frame_stats.update(stats.peak_bounds(pressure, bounds))
            posture = self._posture_of(frame.t, pressure, load)
        elif self.bed is not None:  # the side's vote feeds the turning schedule
            load = _finite(stats.one_frame_stats(pressure, self.layout, threshold=0.05)["load_N"])
            posture = self._posture_of(frame.t, pressure, load)
        events = self._exposure(frame.t, pressure, posture, wall, bounds, regions=full)
        if events or full:
            self.record_events(events, wall)
            self.changes += 1
        return pressure, measured, codes, bounds, frame_stats, posture

    def process(self, frame: Frame, wall: float | None = None) -> dict[str, Any] | None:
        """One frame through everything; returns the snapshot, or None for a frame whose
        time is off the mat's clock (skipped: see :class:`FrameClock`). ``wall``: when it
        arrived (Unix s, default now)."""
        received_at = time.time() if wall is None else wall
        taken = self._take(frame, received_at, full=True)
        if taken is None:
            return None
        pressure, measured, codes, bounds, frame_stats, posture = taken
        bed = self.bed.status(frame.t) if self.bed is not None else None
        if bed is not None and bounds is not None:
            self._bound_regions(bed["regions"], pressure, bounds)
        if self.recorder is not None:
            label = posture["label"] if posture else None
            self.recorder.append(frame, pressure, measured, received_at, label, bounds)
        self.frames += 1
        self.last_pressure = np.array(pressure, dtype=np.float64)
        raw = frame.values
        raw_stats = None
        if self.raw_only and self._raw_floor is not None:  # no pressure: the rise, no load...
            raw_stats = {"unit": frame.unit, **raw_rise(raw, self._raw_floor)}
        self._remember(frame.t, frame_stats, raw_stats)
        alert = self.tracker.open_alert
        snap = {
            "seq": frame.seq,
            "frames": self.frames,
            "missed": self.missed,  # frames never seen (gaps in seq)
            "t": frame.t,
            "raw": None,  # the maps: made from _maps when somebody asks (no viewer: no cost)
            "raw_unit": frame.unit,
            "calibrated": not self.raw_only,
            "pressure": None,
            "failed": np.flatnonzero(codes != 0).tolist(),
            "repaired": np.flatnonzero((codes != 0) & np.isfinite(pressure)).tolist(),
            "stats": frame_stats,  # pressure statistics; null for a mat with no calibration
            "raw_stats": raw_stats,  # no calibration: the rise above each element's lowest
            "cof_trace": self._cof_trace,  # grid cells (row, col)
            "posture": posture,
            "bed": bed,
            "exposure_s": None,
            "alert": alert.to_dict() if alert is not None else None,
            "recording": self.recorder is not None,
            "source": self.source.info(),
            "received_at": received_at,  # wall clock (Unix s) when the frame arrived
            "processed_ms": round(1e3 * (time.time() - received_at), 3),
            **self._certainty(bounds),
        }
        self._latest = snap
        self._maps = (raw, self.last_pressure, self.tracker.exposure_map(), bounds)
        self._latest_text = None  # serialised when somebody asks (no viewer: no cost)
        if self._subscribers:
            self._publish(self.latest_text)
        return snap

    def _exposure(
        self,
        t: float,
        pressure: np.ndarray,
        posture: dict[str, Any] | None,
        wall: float,
        bounds: tuple[np.ndarray, np.ndarray] | None = None,
        regions: bool = True,
    ) -> list[Event]:
        """The bed's schedule and the exposure tracker on one frame: a turn hands the
        exposure to new skin (and clears an open alert), no alert opens while a turn is being
        confirmed; a new alert is named by the places of this frame. With ``bounds`` (lower,
        upper) the tracker tells confident from possible exceedances (issue 37); without
        ``regions`` the bed's at-risk regions are not looked for (a followed frame)."""
        events: list[Event] = []
        schedule = None
        if self.bed is not None:
            side = posture["label"] if posture else None
            events += self.bed.step(pressure, side, t, regions=regions)
            schedule = self.bed.schedule
        if not (self.mode.alerts and not self.raw_only):
            return events
        skipped, self._skimmed = self._skimmed, False
        events = exposure_with_turns(self.tracker, t, pressure, schedule, events, bounds, skipped)
        for e in events:
            if e.kind == "reposition" and e.alert_id is not None:
                raised = next(a for a in self.tracker.alerts if a.id == e.alert_id)
                raised.where, raised.details = self._where(raised.elements)
                raised.opened_wall = wall
                e.detail = {"where": raised.where, "details": raised.details,
                            "elements": raised.elements}  # fmt: skip
        return events

    def _pressure_of(self, frame: Frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A frame's pressure (N/cm², NaN where unknown), which elements were measured, and
        the pipeline's codes: the calibration's pipeline, nothing (raw only), or the
        source's own pressure in N/cm²."""
        raw = frame.values
        if self.pipeline is not None and self.source.quantity == "capacitance":
            valid = np.isfinite(raw)
            x = raw if valid.all() else np.nan_to_num(raw)  # (the pipeline reads it only)
            # the frame is kept past the next step by a recorder only (last_pressure: a copy)
            keep = self.recorder is not None
            pressure, measured = self.pipeline.step(x, valid, frame.t, keep=keep)
            # an empty element's estimate just below zero is shown, counted and written as 0:
            # the one rule of the map, the statistics and the pressure file (no_negative)
            return no_negative(pressure)[0], measured, self.pipeline.codes_
        if self.raw_only:
            none = np.full(raw.shape, np.nan)
            return none, np.zeros(raw.shape, dtype=bool), np.zeros(raw.shape, dtype=np.int8)
        pressure = units.convert(raw, frame.unit, "N/cm2")
        measured = np.isfinite(pressure)
        return pressure, measured, np.where(measured, 0, 2)

    def _bounds_of(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The last frame's bounds (lower, upper N/cm²) when the pipeline gives them."""
        b = getattr(self.pipeline, "bounds_", None) if self.pipeline is not None else None
        if b is None or self.source.quantity != "capacitance":
            return None
        return b[0][-1], b[1][-1]

    def _certainty(self, bounds: tuple[np.ndarray, np.ndarray] | None) -> dict[str, Any]:
        """What the snapshot says of the bounds and the in-use drift correction: the lower
        and upper maps, the elements only possibly above the threshold, the state."""
        out: dict[str, Any] = {"in_use": None, "interval": None}
        if self.pipeline is not None and getattr(self.pipeline, "in_use", False):
            out["in_use"] = self.pipeline.in_use_status()
        if bounds is not None and self.pipeline is not None:
            out["interval"] = self.pipeline.interval
            out["lower"], out["upper"] = None, None  # made with the maps (latest)
            out["possible"] = np.flatnonzero(self.tracker.possible).tolist()
            out["count_possible"] = self.tracker.count_possible
        return out

    @staticmethod
    def _bound_regions(
        regions: list[dict[str, Any]], pressure: np.ndarray, bounds: tuple[np.ndarray, np.ndarray]
    ) -> None:
        """Each at-risk region's peak with its bounds (the region table shows value ± bound)."""
        for r in regions:
            els = np.asarray(r["elements"], dtype=np.intp)
            if els.size == 0:
                continue
            k = els[int(np.nanargmax(np.nan_to_num(pressure[els], nan=-np.inf)))]
            r["peak_lo_ncm2"] = round(float(bounds[0][k]), 3)
            r["peak_hi_ncm2"] = round(float(bounds[1][k]), 3)

    def _remember(self, t: float, st: dict[str, Any], raw: dict[str, Any] | None) -> None:
        """One row of the charts' history: t, load, peak, area, centre of force x and y,
        without a calibration the peak rise and the elements responding, and with bounds
        the peak's (:func:`texsense.apps.stats.peak_bounds`)."""
        cof = st.get("cof_cm") or [None, None]
        rise = raw or {}
        self.history.append((round(t, 3), st.get("load_N"), st.get("peak_ncm2"),
                             st.get("contact_area_cm2"), cof[0], cof[1],
                             rise.get("peak_rise"), rise.get("responding"),
                             st.get("peak_lower_ncm2"), st.get("peak_upper_ncm2")))  # fmt: skip

    def _stats_of(self, t: float, pressure: np.ndarray) -> tuple[dict[str, Any], float]:
        """The frame's statistics for the snapshot (null for a mat with no calibration) and
        its load (N); the centre-of-force trace grows by this frame."""
        if self.raw_only:  # no pressure: nothing to say (and no centre of force)
            none = dict.fromkeys(("load_N", "contact_area_cm2", "peak_ncm2", "ppi_ncm2", "cof_cm"))
            return none, 0.0
        live = self._live_stats
        if live is None or live.layout is not self.layout:  # made again when it turns
            live = self._live_stats = stats.LiveStats(self.layout, threshold=0.05)
        fs, cof = live(pressure)
        load = _finite(fs["load_N"])
        if np.all(np.isfinite(cof)):
            self._cof_trace = [*self._cof_trace[-59:], (float(cof[0]), float(cof[1]))]
        cof_cm = fs["cof_cm"]
        return {
            "load_N": round(load, 2),
            "contact_area_cm2": round(_finite(fs["contact_area_cm2"]), 1),
            "peak_ncm2": round(_finite(fs["peak"]), 3),
            "ppi_ncm2": round(_finite(fs["ppi"]), 3),
            "cof_cm": [round(float(v), 2) for v in cof_cm] if np.all(np.isfinite(cof_cm)) else None,
        }, load

    def _posture_of(self, t: float, pressure: np.ndarray, load: float) -> dict[str, Any] | None:
        """The posture of the live vote (thesis §6.2 classifier, a 5 s vote), or None when
        there is no model or nobody on the mat (the vote starts again)."""
        if self.posture_model is None or load <= 0:
            self._vote.reset()  # nobody there: the next person starts a new vote
            return None
        label, confidence = self.posture_model.predict_with_confidence(pressure[None, :])
        conf = float(confidence[0])
        return {
            "label": str(self._vote.step(str(label[0]), t, conf)),
            "frame_label": str(label[0]),
            "confidence": conf,
            "window_s": POSTURE_WINDOW_S,
        }

    @property
    def latest_head(self) -> dict[str, Any] | None:
        """The latest snapshot as it is, its maps not made (``raw``, ``pressure``,
        ``exposure_s``, bounds: None until :attr:`latest` makes them): its statistics, bed,
        posture and alert, what a ward tile shows (made for every changed mat of a group
        member every second: the maps' lists cost ~0.3 ms a mat)."""
        return self._latest

    @property
    def latest(self) -> dict[str, Any] | None:
        """The latest snapshot (its maps as lists made now, once per frame: hundreds of mats
        of a station are not viewed most of the time)."""
        snap, maps = self._latest, self._maps
        if snap is not None and maps is not None:
            raw, pressure, exposure, bounds = maps
            snap["raw"], snap["pressure"] = _rounded(raw), _rounded(pressure)
            snap["exposure_s"] = _rounded(exposure, 1)
            if "lower" in snap and bounds is not None:
                snap["lower"], snap["upper"] = _rounded(bounds[0]), _rounded(bounds[1])
            self._maps = None
        return snap

    @property
    def latest_text(self) -> str:
        """The latest snapshot as JSON text (serialised once per frame, when first asked)."""
        if self._latest_text is None:
            self._latest_text = json.dumps(self.latest, separators=(",", ":"))
        return self._latest_text

    async def run(self, max_frames: int | None = None) -> None:
        """Consume the source (until it ends or ``max_frames``). A frame that fails to be
        processed is counted and logged once, and the monitor goes on."""
        try:
            async for frame in self.source.frames():
                try:
                    self.process(frame)
                except Exception as e:  # one bad frame must not end the monitor
                    self.source.errors += 1
                    self.quiet.warn(self.source.name, "failed",
                                    f"frame {frame.seq} could not be processed: {e}")  # fmt: skip
                if max_frames is not None and self.frames >= max_frames:
                    break
        finally:
            self.close()

    def feed_state(self, now: float | None = None) -> dict[str, Any]:
        """Whether frames come: ``live``, ``waiting`` (none yet), ``silent`` (none for
        :data:`SILENT_S` s) or ``trouble`` (the device is missing or refuses), with the
        sentence the page shows."""
        now = time.time() if now is None else now
        name = self.source.name
        problem = getattr(self.source, "problem", None)
        since = now - (self.last_wall if self.last_wall is not None else self.started)
        if problem:
            state, text = "trouble", f"{name}: {problem}"
        elif since >= SILENT_S:
            state, text = "silent", f"no frames from {name} for {since:.0f} s"
        elif self.last_wall is None:
            state, text = "waiting", f"waiting for the first frame from {name}"
        else:
            state, text = "live", f"frames from {name}"
        return {"state": state, "text": text, "since_frame_s": round(since, 1)}

    async def watch(self, every_s: float = 0.5) -> None:
        """Say on the console when the source falls silent and when it comes back (runs until
        cancelled)."""
        while True:
            feed = self.feed_state()
            was = self.feed["state"]
            if feed["state"] == "silent" and was != "silent":
                log.warning("%s", feed["text"])
            elif feed["state"] == "live" and was == "silent":
                log.warning("frames from %s again", self.source.name)
            self.feed = feed
            await asyncio.sleep(every_s)

    def close(self, end_session: bool = True) -> None:
        """Stop recording, end the session (``end_session=False``: the caller ends many
        sessions at once, :meth:`EventStore.end_sessions`)."""
        if self.recorder is not None:
            self.stop_recording()
        if end_session:
            self.store.end_session(self.session_id)
