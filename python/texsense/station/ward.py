"""The ward station's engine: many mats over one MQTT connection, each with its own layout,
calibration, pipeline state, exposure and reposition alerts (docs/station.md).

A mat publishes its frames to ``<prefix>/<mat id>/frames`` with the payload of
:mod:`texsense.data.protocol`. The station subscribes to one topic filter (default
``texsense/+/frames``; ``--mats 'ward3/+/frames'`` lets several stations split a site without
any coordination of their own: the broker routes). Every mat is a
:class:`~texsense.monitor.live.Monitor` fed by the station; what the station adds per mat:

- **arrival**: messages, malformed payloads (counted per mat, logged once and skipped), the
  frame period (running mean of arrival gaps);
- **glitches never blind a mat**: a payload longer than a frame of the mat can need is refused
  by its length, unparsed; a frame with another number of values is skipped like any
  malformed payload; a frame whose time is off the mat's clock is skipped and a clock that
  really jumped is re-synchronised (:class:`~texsense.monitor.clock.FrameClock`, event
  ``clock``). None of them reaches the pipeline or the exposure, so no glitch clears an
  alert;
- **stale**: a mat that has not sent for two of its frame periods and at least
  :data:`MIN_STALE_S` (checked every 20 ms; ``min_stale_s`` sets another floor) is marked
  stale and an event
  is stored with how long it was silent; its next frame marks it live again. Silence is
  judged on the time line of what the station has read (:meth:`Inbox.read_until`): a mat
  whose frames wait in a busy station's inbox is not silent;
- **refused**: a mat whose every frame has had another number of elements than its layout for
  ``refuse_after_s`` (and at least :data:`REFUSE_AFTER_N` messages in a row) is refused with
  an event that says both counts; the other mats go on. :meth:`MatEntry.admit` (the API and
  the ward page) lifts it;
- **unknown topics**: counted, at most :data:`UNKNOWN_MAX` of them, each forgotten
  :data:`UNKNOWN_TTL_S` after its last message;
- **connection**: the MQTT client reconnects by itself when the broker goes away and comes
  back, and subscribes again;
- **the pages stay served under load**: messages are handled in slices of the event loop,
  and a station that cannot keep up makes no snapshot of the older frames of a mat whose newer
  ones wait (counted as ``behind``; they still go through the pipeline and the exposure, so
  timers and alerts are exact; only their time is read when they waited more than
  :data:`FOLLOW_S`, counted as ``peeked``) instead of falling ever further behind
  (:mod:`texsense.station.inbox`).
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections import OrderedDict
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import numpy as np

from texsense.apps.alerts import Event, ExposureTracker
from texsense.apps.bed import BedWatch
from texsense.compensation.pipeline import Pipeline
from texsense.data import units
from texsense.data.protocol import (
    CountError,
    Frame,
    PayloadSizeError,
    ProtocolError,
    parse_mqtt_payload,
    payload_limit,
    peek_mqtt_payload,
)
from texsense.exceptions import ParameterError
from texsense.monitor.clock import Quiet
from texsense.monitor.live import SILENT_S, Monitor
from texsense.monitor.sources import Source
from texsense.monitor.store import EventStore
from texsense.station.broker import BrokerURL, check_mat_id, mat_id_of, mqtt_client
from texsense.station.config import MatConfig
from texsense.station.inbox import Inbox
from texsense.station.tiles import BlockMap

__all__ = ["MatConfig", "MatEntry", "Station", "mat_id_of"]

log = logging.getLogger("texsense.station")

#: A mat is never called silent sooner than this, s: a fast mat (10 Hz, or a simulated one
#: at 10x) missed for 0.2 s is a hiccup of the station's reading thread under load, not a
#: silent mat (its tiles flickered "stale" while every mat sent, issue 33).
MIN_STALE_S = 1.0
#: Every mat's silence is judged this often, s (a station of 1,000 mats judged 50 times a
#: second spent a tenth of its event loop on it).
CHECK_S = 0.25
#: A frame the station skips because it is behind (a newer one of its mat waits) is still
#: followed through the pipeline and the exposure (exact timers and alerts, issue 38) unless
#: it waited longer than this, s: then only its time is read (the station is far behind).
FOLLOW_S = 5.0
#: Urgency order of a mat's state on the ward page (highest first).
URGENCY = {"alert": 4, "stale": 3, "refused": 3, "acknowledged": 2, "live": 1, "waiting": 0}
#: Messages in a row with another element count, at least, before a mat is refused.
REFUSE_AFTER_N = 10
#: The inbox waits for pages this long after the last was served, s (:meth:`Station.pages_first`).
PAGE_GRACE_S = 0.3
#: Unknown topics kept at most (the least recently seen go first) ...
UNKNOWN_MAX = 100
#: ... and each forgotten this long after its last message, s.
UNKNOWN_TTL_S = 600.0


class _FedSource(Source):
    """The Source a mat's Monitor sees: frames are handed to it by the station."""

    def __init__(self, config: MatConfig) -> None:
        super().__init__()
        self.layout = config.layout
        self.quantity = config.quantity
        self.unit = "pF" if config.quantity == "capacitance" else "N/cm2"
        self.name = f"mat {config.id} ({config.source})"
        self.rate = config.rate

    def frames(self) -> AsyncIterator[Frame]:  # pragma: no cover - never iterated
        raise NotImplementedError("the station hands frames to the monitor")


def _monitor(config: MatConfig, source: Source, store: EventStore, record_dir: Path) -> Monitor:
    """The single-mat monitor of a mat of the ward."""

    pipeline = None
    if config.quantity == "capacitance":
        if config.calibration is None:
            raise ParameterError(f"mat {config.id}: a capacitance mat needs a calibration")
        # the drift corrected in use, and bounds where the calibration has held-out residuals
        try:
            pipeline = Pipeline(config.calibration, config.layout, in_use=True, interval=0.95)
        except ParameterError:
            pipeline = Pipeline(config.calibration, config.layout, in_use=True)
    tracker = ExposureTracker(config.layout, reposition_min=config.reposition_min)
    bed = None
    if config.bed:
        if config.posture_model is None:
            raise ParameterError(f"mat {config.id}: a bed needs a side model (model = ...)")
        bed = BedWatch(config.layout, interval_min=config.turn_every_min)
    return Monitor(source, pipeline=pipeline, tracker=tracker, posture_model=config.posture_model,
                   store=store, record_dir=record_dir / config.id, bed=bed)  # fmt: skip


class MatEntry:
    """One mat's state in the station. ``version`` counts its visible changes (the ward
    WebSocket sends a mat again only when it changed)."""

    def __init__(
        self,
        config: MatConfig,
        store: EventStore,
        record_dir: Path,
        min_stale_s: float,
        refuse_after_s: float = 10.0,
        quiet: Quiet | None = None,
    ) -> None:
        self.config = config
        self.id = config.id
        self.source = _FedSource(config)
        self.monitor = _monitor(config, self.source, store, record_dir)
        self.quiet = quiet or Quiet(log)
        self.blocks = BlockMap(config.layout)
        self.max_bytes = payload_limit(config.layout.n_elements)
        self.min_stale_s = min_stale_s
        self.refuse_after_s = refuse_after_s
        self.messages = self.malformed = self.ignored = self.failed = 0
        self.behind = 0  # frames not processed in full (followed or peeked): it was behind
        self.peeked = 0  # ... of them, frames whose time only was read: it was far behind
        self.last_error: str | None = None
        self.last_wall: float | None = None  # arrival of the last frame processed
        self.last_seen: float | None = None  # ... or of a frame skimmed after it
        self.period_s: float | None = None
        self.state = "waiting"
        self.refused: str | None = None
        self.local: Source | None = None  # a serial, IIO or replay source read by the station
        self.problem: str | None = None
        self.created = time.time()
        self.version = 0
        self._mismatch: tuple[int, float, int] | None = None  # (run length, since, count)
        self._tile: tuple[int, str] | None = None
        self._view: tuple[int, str, int] | None = None

    # ---------------------------------------------------------------- messages
    def _event(self, kind: str, detail: dict[str, Any]) -> None:
        t = self.monitor.clock.last_t or 0.0
        self.monitor.record_events([Event(kind, t, None, {"mat": self.id, **detail})])

    def _malformed(self, kind: str, text: str) -> None:
        """Count a message that gave no frame and log it once (then once a minute)."""
        self.malformed += 1
        self.source.errors += 1
        self.last_error = text
        self.source.last_error = f"message {self.messages}: {text}"
        self.version += 1
        self.quiet.warn(f"mat {self.id}", kind, f"skipped message {self.messages}: {text}")

    def handle(self, payload: bytes, now: float, *, skim: bool = False, peek: bool = False) -> bool:
        """One message; True when it gave a frame. Its length is checked first: an oversized
        payload is never parsed. ``skim``: the station is behind and a newer frame of this
        mat waits: the frame is followed (:meth:`feed`), not processed in full; with ``peek``
        only its time is read (:meth:`skim`)."""
        self.messages += 1  # every message that came, the ignored ones too
        if self.refused is not None:
            self.ignored += 1
            return False
        n = self.config.layout.n_elements
        try:
            head = peek_mqtt_payload(payload, n, self.max_bytes) if skim and peek else None
            if head is not None:  # its time only: the values are not read
                seq, t = head
                frame = Frame(seq, np.array([t]), np.empty(n), "")
            else:
                frame = parse_mqtt_payload(payload, n, self.max_bytes)
        except PayloadSizeError as e:
            self._malformed("size", str(e))
            return False
        except CountError as e:
            self._malformed("count", str(e))
            self._count_mismatch(e.got, now)
            return False
        except ProtocolError as e:
            self._malformed("malformed", str(e))
            return False
        if head is not None:
            return self.skim(frame, now)
        return self.feed(frame, now, follow=skim)

    def skim(self, frame: Frame, now: float) -> bool:
        """A frame the station peeks at because it is far behind (more than
        :data:`FOLLOW_S`) and a newer one of this mat waits (:mod:`texsense.station.inbox`):
        only its time is taken, which keeps the mat's clock in step (a burst of buffered
        frames skipped in the middle is no jump of the clock) and the mat heard (not silent);
        counted as ``behind`` and ``peeked``. The next frame read carries the exposure over
        the frames peeked at (their time counted as loaded where either frame read is,
        :meth:`~texsense.apps.alerts.ExposureTracker.step`): the exposure and the pipeline's
        state are no longer exactly those of reading every frame."""
        if frame.values.size != self.config.layout.n_elements:
            self._malformed("count", f"a frame of {frame.values.size} values")
            return False
        if not self.monitor.keep_time(frame, now):
            return False
        self._mismatch = None
        self.behind += 1
        self.peeked += 1
        self._heard(now)
        return True

    def _heard(self, now: float) -> None:
        """The mat sent at ``now``: its frame period (the running mean of the gaps between
        its messages, read or skipped)."""
        if self.last_seen is not None:
            gap = max(now - self.last_seen, 0.0)
            self.period_s = gap if self.period_s is None else 0.8 * self.period_s + 0.2 * gap
        self.last_seen = now

    def _count_mismatch(self, got: int, now: float) -> None:
        """Refuse the mat once its frames have had another element count for
        ``refuse_after_s`` and :data:`REFUSE_AFTER_N` messages in a row."""
        n = self.config.layout.n_elements
        run, since, _ = self._mismatch or (0, now, got)
        self._mismatch = (run + 1, since, got)
        if run + 1 < REFUSE_AFTER_N or now - since < self.refuse_after_s:
            return
        self.refused = (
            f"{run + 1} frames in a row over {now - since:.0f} s had {got} values, but the "
            f"mat's layout has {n} elements: refused until admitted again"
        )
        self.state = "refused"
        self.version += 1
        self._event("refused", {"reason": self.refused, "values": got, "elements": n})
        log.warning("mat %s: %s", self.id, self.refused)

    def admit(self) -> Event:
        """Lift a refusal: the mat's next frames are read again (event ``admitted``)."""
        if self.refused is None:
            raise ParameterError(f"mat {self.id} is not refused")
        self.refused, self._mismatch = None, None
        self.state, self.last_wall, self.last_seen = "waiting", None, None
        self.version += 1
        self._event("admitted", {})
        log.warning("mat %s: admitted again", self.id)
        t = self.monitor.clock.last_t or 0.0
        return Event("admitted", t, None, {"mat": self.id})

    def feed(self, frame: Frame, now: float, *, follow: bool = False) -> bool:
        """One frame (from MQTT or a local source); True when it was processed. ``follow``:
        the station is behind and a newer frame of this mat waits: the frame goes through
        the pipeline and the exposure but makes no snapshot (:meth:`Monitor.follow`),
        counted as ``behind``."""
        if frame.values.size != self.config.layout.n_elements:
            self._malformed("count", f"a frame of {frame.values.size} values")
            return False
        if units.quantity_of(frame.unit) != self.config.quantity:
            self._malformed("unit", f"unit {frame.unit!r} is not {self.config.quantity}")
            return False
        self._mismatch = None
        if frame.unit != self.source.unit:
            frame.values = units.convert(frame.values, frame.unit, self.source.unit)
            frame.unit = self.source.unit
        try:
            if follow:
                done = self.monitor.follow(frame, now)
            else:
                done = self.monitor.process(frame, wall=now) is not None
        except Exception as e:  # one mat's failure must not stop the ward: one line, no trace
            self.failed += 1
            self.version += 1
            self.quiet.warn(f"mat {self.id}", "failed", f"frame {frame.seq} could not be "
                            f"processed ({type(e).__name__}: {e})")  # fmt: skip
            return False
        if follow:  # no snapshot: the mat's view changes with the frame after it
            if done:
                self.behind += 1
                self._heard(now)
            return done
        self.version += 1
        if not done:  # off the mat's clock: counted and logged by the monitor
            return False
        self._arrived(now)
        return True

    def _arrived(self, now: float) -> None:
        if self.state == "stale":
            self._event("resumed", {"after_s": round(now - (self.last_seen or now), 2)})
        self._heard(now)
        self.state = "live"
        self.last_wall = now

    def check(self, now: float, read_until: float | None = None) -> bool:
        """Mark the mat stale (and store an event) when it stopped sending, and follow its
        local source's trouble; True if anything changed. ``read_until``: the wall time up to
        which the station has read its inbox (default ``now``): silence is judged there."""
        problem = self._problem(now)
        changed = problem != self.problem
        if changed:
            said = self.local is not None and self.local.problem  # the source said it
            if problem is not None and not said:
                log.warning("mat %s: %s", self.id, problem)
            self.problem = problem
            self.version += 1
        if self.state != "live" or self.last_seen is None or self.period_s is None:
            return changed
        until = now if read_until is None or self.local is not None else read_until
        if until - self.last_seen > max(2.0 * self.period_s, self.min_stale_s):
            self.state = "stale"
            self.version += 1
            self._event("stale", {"silent_s": round(until - self.last_seen, 2)})
            return True
        return changed

    def _problem(self, now: float) -> str | None:
        """What is wrong with a local source: its device's trouble, or its silence."""
        if self.local is None:
            return None
        if self.local.problem:
            return f"{self.local.name}: {self.local.problem}"
        since = now - (self.last_wall or self.created)
        if since >= max(SILENT_S, 2.0 * (self.period_s or 0.0)):
            return f"no frames from {self.local.name} for {since // 10 * 10:.0f} s"
        return None

    # ---------------------------------------------------------------- views
    @property
    def revision(self) -> int:
        """Grows with every visible change of the mat (its own and its monitor's: a frame, an
        acknowledgement on its dashboard)."""
        return self.version + self.monitor.changes

    def view_state(self) -> tuple[str, int]:
        """The state the ward shows (an open alert on a live mat shows as ``alert`` or
        ``acknowledged``) and its urgency (worked out once per revision)."""
        revision = self.revision
        if self._view is None or self._view[0] != revision:
            self._view = (revision, *self._view_state())
        return self._view[1], self._view[2]

    def _view_state(self) -> tuple[str, int]:
        state = self.state
        alert = self.monitor.tracker.open_alert
        if state == "live" and alert is not None:
            state = "alert" if alert.active else "acknowledged"
        latest = self.monitor.latest_head  # (no maps: they are not shown)
        bed = latest.get("bed") if latest and state != "stale" else None
        turn_due = bool(bed and bed["turn_due"])
        return state, max(URGENCY[state], URGENCY["alert"] if turn_due else 0)

    def status(self) -> dict[str, Any]:
        """The mat's state without its maps (what ``GET /api/mats`` and a ward tile show)."""
        latest = self.monitor.latest_head  # (no maps: they are not shown)
        alert = self.monitor.tracker.open_alert
        stats = latest["stats"] if latest else None
        state, urgency = self.view_state()
        bed = latest.get("bed") if latest and state != "stale" else None
        if bed is not None:
            bed = {"side": bed["side"], "since_turn_s": bed["since_turn_s"],
                   "turn_due": bed["turn_due"], "interval_s": bed["interval_s"],
                   "due_in_s": bed["due_in_s"]}  # fmt: skip
        exposure = self.monitor.tracker.exposure_s
        mmhg = float(units.factor("N/cm2", "mmHg"))
        peak = stats["peak_ncm2"] if stats else None
        return {
            "id": self.id,
            "source": self.config.source,
            "quantity": self.config.quantity,
            "elements": self.config.layout.n_elements,
            "frames": self.monitor.frames,
            "messages": self.messages,
            "malformed": self.malformed,
            "skipped": self.monitor.clock.skipped,
            "failed": self.failed,
            "ignored": self.ignored,
            "behind": self.behind,
            "peeked": self.peeked,
            "missed": self.monitor.missed,
            "missed_runs": [list(r) for r in self.monitor.missed_runs],  # [first, last] seq
            "last_error": self.last_error,
            "problem": self.problem,
            "last_frame_wall": self.last_wall,
            "period_s": None if self.period_s is None else round(self.period_s, 3),
            "state": state,
            "refused": self.refused,
            "occupied": bool(stats and (stats["load_N"] or 0.0) > 5.0),  # null: no calibration
            "minutes_since_reposition": round(float(np.max(exposure, initial=0.0)) / 60.0, 1),
            "exposure_s": round(float(np.max(exposure, initial=0.0)), 1),  # the same, finer
            "frame_t": self.monitor.clock.last_t,  # the time of the frame it is at (its clock)
            # what the tile says: "above 32 mmHg for 8.6 min", "peak 45 mmHg"
            "threshold_mmhg": round(self.monitor.tracker.threshold_ncm2 * mmhg, 1),
            "peak_mmhg": None if peak is None else round(peak * mmhg, 1),
            "action": self.monitor.mode.action,
            "mode": self.monitor.mode.name,  # a bed's tile is drawn as a bed, stale or not
            "orientation": self.monitor.layout.orientation,
            "alert": alert.to_dict() if alert is not None else None,
            "urgency": urgency,
            "bed": bed,
        }

    def summary(self, now: float) -> dict[str, Any]:
        """The status with the layout and the latest pressure map (``GET /api/mats/{id}``)."""
        lay = self.config.layout
        latest = self.monitor.latest
        return {
            **self.status(),
            "shape": list(lay.shape) if lay.shape else None,
            "cells": None if lay.cells is None else lay.cells.tolist(),
            "seconds_since_frame": None
            if self.last_wall is None
            else round(now - self.last_wall, 2),
            "pressure": latest["pressure"] if latest else None,
        }

    def tile(self) -> str:
        """The mat's tile on the ward WebSocket (JSON text): the status and the pressure map
        downsampled and quantised (:class:`~texsense.station.tiles.BlockMap`); made once per
        change, whoever asks."""
        revision = self.revision
        if self._tile is not None and self._tile[0] == revision:
            return self._tile[1]

        pressure = self.monitor.last_pressure
        body = {**self.status(), "map": None if pressure is None else self.blocks.encode(pressure)}
        text = json.dumps(body, separators=(",", ":"))
        self._tile = (revision, text)
        return text


class Station:
    """Many mats, one MQTT connection, one event store.

    Parameters
    ----------
    broker : BrokerURL
        Where the mats publish (username/password and TLS pass through to paho).
    mats : list of MatConfig
        The ward's mats.
    topic : str
        The subscription (MQTT topic filter).
    store : EventStore, optional
        Events and sessions (default: SQLite in memory).
    min_stale_s : float
        A mat is stale after two frame periods, but never sooner than this
        (:data:`MIN_STALE_S`).
    refuse_after_s : float
        A mat whose frames have had another element count for this long (and at least
        :data:`REFUSE_AFTER_N` messages in a row) is refused.
    """

    #: The class of its mats (a group's station shows the mats held elsewhere too).
    entry_class: type[MatEntry] = MatEntry

    def __init__(
        self,
        broker: BrokerURL | None,
        mats: list[MatConfig],
        *,
        topic: str = "texsense/+/frames",
        store: EventStore | None = None,
        record_dir: Path | str = "recordings",
        min_stale_s: float = MIN_STALE_S,
        refuse_after_s: float = 10.0,
    ) -> None:
        ids = [check_mat_id(m.id) for m in mats]
        if len(set(ids)) != len(ids):
            raise ParameterError(f"mat ids must be unique, got {ids}")
        self.broker = broker
        self.topic = topic
        self.store = store or EventStore(":memory:")
        self.quiet = Quiet(log)
        entry = self.entry_class
        self.mats = {
            m.id: entry(m, self.store, Path(record_dir), min_stale_s, refuse_after_s, self.quiet)
            for m in mats
        }
        self.unknown: OrderedDict[str, list[float]] = OrderedDict()  # key -> [count, last]
        self.unknown_forgotten = 0
        self.connected = False
        self.connects = 0
        self.refusal: str | None = None  # why the broker refused the station, if it did
        self.started = time.time()
        self._client: Any = None
        self._stopping = False
        self._inbox: Inbox | None = None  # MQTT messages waiting for the loop
        self.serving = 0  # page requests and new viewers being served (they go first)
        self.served_at = -1e9  # when the last of them was served (monotonic s)

    # ---------------------------------------------------------------- MQTT
    def _on_connect(self, client: Any, _u: Any, _f: Any, reason: Any, _p: Any = None) -> None:
        if getattr(reason, "is_failure", False):
            if self.refusal != str(reason):
                log.warning("the broker %s refused the station: %s", self.broker, reason)
            self.refusal = str(reason)
            return
        self.refusal = None
        self.connects += 1
        client.subscribe(self.topic, qos=0)

    def _on_subscribe(self, _client: Any, _u: Any, _mid: Any, reasons: Any, _p: Any = None) -> None:
        """The broker acknowledged the subscription: from now on frames reach the station
        (before it, a frame sent at QoS 0 would be lost), so only now is it connected."""
        if any(getattr(r, "is_failure", False) for r in reasons or ()):
            log.warning("the broker %s refused the subscription to %s", self.broker, self.topic)
            return
        self.connected = True
        log.info("connected to %s, subscribed to %s", self.broker, self.topic)

    def _on_disconnect(self, *_args: Any) -> None:
        if self.connected and not self._stopping:  # a stop is no loss
            log.warning("lost the broker %s; reconnecting", self.broker)
        self.connected = False

    def _on_message(self, _client: Any, _u: Any, msg: Any) -> None:
        if self._inbox is not None:  # paho's thread: into the inbox, handled on the loop
            self._inbox.put(msg.topic, msg.payload)

    def handle(self, topic: str, payload: bytes, now: float | None = None) -> None:
        """One MQTT message (in the event loop)."""
        now = time.time() if now is None else now
        mat = mat_id_of(topic)
        entry = self.mats.get(mat) if mat is not None else None
        if entry is None:
            self._unknown((mat or topic)[:120], now)
            return
        try:
            entry.handle(payload, now)
        except Exception as e:  # a case nobody foresaw: one line, counted, the ward goes on
            entry.failed += 1
            self.quiet.warn(f"mat {entry.id}", "failed", f"message {entry.messages} could not "
                            f"be handled ({type(e).__name__}: {e})")  # fmt: skip

    def _unknown(self, key: str, now: float) -> None:
        """Count a message for an unknown mat (bounded: :data:`UNKNOWN_MAX` keys)."""
        seen = self.unknown.get(key)
        if seen is None:
            self.quiet.warn("station", "unknown", f"frames for an unknown mat {key!r} are "
                            "ignored")  # fmt: skip
            seen = self.unknown[key] = [0, now]
            while len(self.unknown) > UNKNOWN_MAX:
                self.unknown.popitem(last=False)
                self.unknown_forgotten += 1
        self.unknown.move_to_end(key)
        seen[0] += 1
        seen[1] = now

    def forget_unknown(self, now: float) -> None:
        """Forget unknown mats silent for :data:`UNKNOWN_TTL_S`."""
        while self.unknown:
            key, (_count, last) = next(iter(self.unknown.items()))
            if now - last < UNKNOWN_TTL_S:
                break
            del self.unknown[key]
            self.unknown_forgotten += 1

    def open_inbox(self) -> Inbox:
        """The inbox of MQTT messages, handled on the running event loop."""
        self._inbox = Inbox(asyncio.get_running_loop(), self.handle, self.quiet,
                            skip=self.skip, defer=self.pages_first)  # fmt: skip
        return self._inbox

    def pages_first(self) -> bool:
        """Whether the inbox waits for pages: while one is served and :data:`PAGE_GRACE_S`
        after (a page opens in a burst: the page, its scripts and styles, its WebSocket)."""
        return self.serving > 0 or time.monotonic() - self.served_at < PAGE_GRACE_S

    def skip(self, topic: str, payload: bytes, arrived: float) -> bool:
        """Skip a message's full processing (the station is behind and a newer one of its
        topic waits): the frame is followed through the pipeline and the exposure, without a
        snapshot (:meth:`MatEntry.feed`, ``follow``); an unknown topic's is counted. A message
        that waited longer than :data:`FOLLOW_S` is only peeked at for its time
        (:meth:`MatEntry.skim`: the station is far behind, and following every frame would not
        let it catch up). A mat being recorded keeps every frame (False: the message is
        handled)."""
        mat = mat_id_of(topic)
        entry = self.mats.get(mat) if mat is not None else None
        if entry is None:
            self._unknown((mat or topic)[:120], arrived)
            return True
        if entry.monitor.recorder is not None:
            return False
        try:
            entry.handle(payload, arrived, skim=True, peek=time.time() - arrived > FOLLOW_S)
        except Exception as e:  # as in handle: one line, counted, the ward goes on
            entry.failed += 1
            self.quiet.warn(f"mat {entry.id}", "failed", f"message {entry.messages} could not "
                            f"be handled ({type(e).__name__}: {e})")  # fmt: skip
        return True

    def start(self) -> None:
        """Connect (in paho's network thread) from within the running event loop."""
        if self.broker is None:
            return
        self.open_inbox()
        client = mqtt_client(self.broker, f"texsense-station-{id(self)}")
        client.on_connect = self._on_connect
        client.on_subscribe = self._on_subscribe
        client.on_disconnect = self._on_disconnect
        client.on_message = self._on_message
        client.loop_start()
        self._client = client

    def stop(self) -> None:
        """Disconnect and end every mat's session (in one write)."""
        self._stopping = True
        if self._client is not None:
            self._client.disconnect()
            self._client.loop_stop()
            self._client = None
        for entry in self.mats.values():
            entry.monitor.close(end_session=False)
        self.store.end_sessions([e.monitor.session_id for e in self.mats.values()])

    async def consume(self, mat_id: str, source: Source) -> None:
        """Feed a mat from a local source (serial, IIO, replay) until it ends."""
        entry = self.mats[mat_id]
        entry.local = source
        try:
            async for frame in source.frames():
                entry.feed(frame, time.time())
                entry.malformed = max(entry.malformed, source.errors)
        except Exception as e:  # the source gave up: said, and the mat shows it
            log.warning("mat %s: %s stopped: %s", mat_id, source.name, e)
            source.problem = f"stopped: {e}"
        finally:
            source.close()

    async def watch(self, every_s: float = CHECK_S) -> None:
        """Mark mats stale as they stop sending (runs until cancelled)."""
        k = 0
        while True:
            now = time.time()
            self.check_all(now)
            k += 1
            if k % max(1, round(1.0 / every_s)) == 0:
                self.forget_unknown(now)
            await asyncio.sleep(every_s)

    def check_all(self, now: float, mats: Any = None) -> None:
        """Judge the silence of ``mats`` (default all) at what the inbox has read by now."""
        read = now if self._inbox is None else self._inbox.read_until(now)
        for e in self.mats.values() if mats is None else (self.mats[m] for m in mats):
            e.check(now, read)

    async def acknowledge(self, mat_id: str, alert_id: int) -> dict[str, Any]:
        """Acknowledge a mat's alert (the event, JSON-ready)."""
        return self.mats[mat_id].monitor.acknowledge(alert_id).to_dict()

    async def admit(self, mat_id: str) -> dict[str, Any]:
        """Lift a mat's refusal (the event, JSON-ready)."""
        return self.mats[mat_id].admit().to_dict()

    def layers(self) -> list[tuple[Any, dict[str, Any]]]:
        """ASGI middleware the web server adds (with its options)."""
        return []

    # ---------------------------------------------------------------- views
    def summaries(self) -> list[dict[str, Any]]:
        """Every mat, most urgent first (alerts, then stale or refused, then the longest
        time without repositioning)."""
        now = time.time()
        rows = [e.summary(now) for e in self.mats.values()]
        return sorted(rows, key=lambda r: (-r["urgency"], -r["minutes_since_reposition"], r["id"]))

    def header(self) -> dict[str, Any]:
        """The broker, the connection and the unknown mats (the 20 busiest)."""
        busiest = sorted(self.unknown.items(), key=lambda kv: -kv[1][0])[:20]
        inbox, now = self._inbox, time.time()
        return {
            "broker": None if self.broker is None else str(self.broker),
            "connected": self.connected,
            "refusal": self.refusal,
            "topic": self.topic,
            "unknown": {k: int(v[0]) for k, v in busiest},
            "unknown_topics": len(self.unknown),
            "unknown_forgotten": self.unknown_forgotten,
            "dropped": 0 if self._inbox is None else self._inbox.dropped,
            # how far behind the station reads (s) and the frames it skipped to keep up
            "behind_s": 0.0 if inbox is None else round(max(now - inbox.read_until(now), 0.0), 2),
            "skipped": 0 if inbox is None else inbox.skipped,
        }

    def ward(self) -> dict[str, Any]:
        """The whole ward: connection and every mat's summary."""
        return {**self.header(), "wall": time.time(), "mats": self.summaries()}
