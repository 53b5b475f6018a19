"""The ward station's engine: many mats over one MQTT connection, each with its own layout,
calibration, pipeline state, exposure and reposition alerts (docs/station.md).

A mat publishes its frames to ``<prefix>/<mat id>/frames`` with the payload of
:mod:`texsense.monitor.protocol`. The station subscribes to one topic filter (default
``texsense/+/frames``; ``--mats 'ward3/+/frames'`` lets several stations split a site without
any coordination of their own: the broker routes). Every mat is a
:class:`~texsense.monitor.live.Monitor` fed by the station; what the station adds per mat:

- **arrival**: messages, malformed payloads (counted per mat and skipped), the frame period
  (running mean of arrival gaps);
- **stale**: a mat that has not sent for two of its frame periods (checked every 20 ms;
  ``min_stale_s`` can set a floor for mats with jittery links) is marked stale and an event
  is stored with how long it was silent; its next frame marks it live again;
- **refused**: a mat whose frames do not match its layout (another number of elements) is
  refused with an event that says both counts; the other mats go on;
- **connection**: the MQTT client reconnects by itself when the broker goes away and comes
  back, and subscribes again.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from texsense import units
from texsense.bed import BedWatch
from texsense.exceptions import ParameterError
from texsense.layout import Layout
from texsense.monitor.alerts import Event, ExposureTracker
from texsense.monitor.live import Monitor
from texsense.monitor.protocol import Frame, ProtocolError, parse_mqtt_payload
from texsense.monitor.sources import Source
from texsense.monitor.store import EventStore
from texsense.station.broker import BrokerURL, mqtt_client

__all__ = ["MatConfig", "MatEntry", "Station", "mat_id_of"]

log = logging.getLogger("texsense.station")

#: Urgency order of a mat's state on the ward page (highest first).
URGENCY = {"alert": 4, "stale": 3, "refused": 3, "acknowledged": 2, "live": 1, "waiting": 0}


def mat_id_of(topic: str) -> str | None:
    """The mat id of a frames topic (``.../<mat id>/frames``), None for other topics."""
    parts = topic.split("/")
    if len(parts) < 2 or parts[-1] != "frames" or not parts[-2]:
        return None
    return parts[-2]


@dataclass
class MatConfig:
    """One mat of the ward: its id (the topic segment before ``/frames``), layout, calibration
    (a stage chain or mat calibration; None for a mat that sends pressure), where its
    frames come from (``mqtt``, or a local source built by the command line) and, for a bed,
    its side model and turning schedule."""

    id: str
    layout: Layout
    calibration: Any = None
    quantity: str = "capacitance"
    source: str = "mqtt"
    reposition_min: float = 20.0
    extra: dict[str, Any] = field(default_factory=dict)
    #: A bed mat: the turning schedule on the side ``posture_model`` reports, and at-risk
    #: regions (:class:`texsense.bed.BedWatch`); the model's labels must be sides.
    bed: bool = False
    posture_model: Any = None
    turn_every_min: float = 120.0


class _FedSource(Source):
    """The Source a mat's Monitor sees: frames are handed to it by the station."""

    def __init__(self, config: MatConfig) -> None:
        super().__init__()
        self.layout = config.layout
        self.quantity = config.quantity
        self.unit = "pF" if config.quantity == "capacitance" else "N/cm2"
        self.name = f"mat {config.id} ({config.source})"

    def frames(self) -> AsyncIterator[Frame]:  # pragma: no cover - never iterated
        raise NotImplementedError("the station hands frames to the monitor")


class MatEntry:
    """One mat's state in the station."""

    def __init__(
        self, config: MatConfig, store: EventStore, record_dir: Path, min_stale_s: float
    ) -> None:
        from texsense.pipeline import Pipeline

        self.config = config
        self.id = config.id
        self.source = _FedSource(config)
        pipeline = None
        if config.quantity == "capacitance":
            if config.calibration is None:
                raise ParameterError(f"mat {config.id}: a capacitance mat needs a calibration")
            pipeline = Pipeline(config.calibration, config.layout)
        tracker = ExposureTracker(config.layout, reposition_min=config.reposition_min)
        bed = None
        if config.bed:
            if config.posture_model is None:
                raise ParameterError(f"mat {config.id}: a bed needs a side model (model = ...)")
            bed = BedWatch(config.layout, interval_min=config.turn_every_min)
        self.monitor = Monitor(
            self.source,
            pipeline=pipeline,
            tracker=tracker,
            posture_model=config.posture_model,
            store=store,
            record_dir=record_dir / config.id,
            bed=bed,
        )
        self.min_stale_s = min_stale_s
        self.messages = 0
        self.malformed = 0
        self.ignored = 0
        self.last_error: str | None = None
        self.last_wall: float | None = None
        self.period_s: float | None = None
        self.state = "waiting"
        self.refused: str | None = None

    # ---------------------------------------------------------------- messages
    def _event(self, kind: str, detail: dict[str, Any]) -> None:
        t = self.monitor.latest["t"] if self.monitor.latest else 0.0
        self.monitor._events([Event(kind, t, None, {"mat": self.id, **detail})])

    def handle(self, payload: bytes, now: float) -> bool:
        """One message; True when it gave a frame."""
        if self.refused is not None:
            self.ignored += 1
            return False
        self.messages += 1
        n = self.config.layout.n_elements
        try:
            frame = parse_mqtt_payload(payload, n)
        except ProtocolError as e:
            got = _value_count(payload)
            if got is not None and got != n:
                self.refused = (
                    f"frames of {got} values, but the mat's layout has {n} elements: refused"
                )
                self.state = "refused"
                self._event("refused", {"reason": self.refused})
                log.warning("mat %s: %s", self.id, self.refused)
                return False
            self.malformed += 1
            self.source.errors += 1
            self.last_error = str(e)
            self.source.last_error = f"message {self.messages}: {e}"
            return False
        return self.feed(frame, now)

    def feed(self, frame: Frame, now: float) -> bool:
        """One frame (from MQTT or a local source); True when it was processed."""
        if frame.values.size != self.config.layout.n_elements:
            self.malformed += 1
            self.last_error = f"a frame of {frame.values.size} values"
            return False
        if units.quantity_of(frame.unit) != self.config.quantity:
            self.malformed += 1
            self.last_error = f"unit {frame.unit!r} is not {self.config.quantity}"
            return False
        if frame.unit != self.source.unit:
            frame.values = units.convert(frame.values, frame.unit, self.source.unit)
            frame.unit = self.source.unit
        self.monitor.process(frame)
        self._arrived(now)
        return True

    def _arrived(self, now: float) -> None:
        if self.last_wall is not None:
            gap = now - self.last_wall
            self.period_s = gap if self.period_s is None else 0.8 * self.period_s + 0.2 * gap
        if self.state == "stale":
            self._event("resumed", {"after_s": round(now - (self.last_wall or now), 2)})
        self.state = "live"
        self.last_wall = now

    def check_stale(self, now: float) -> bool:
        """Mark the mat stale (and store an event) when it stopped sending; True if it just
        became stale."""
        if self.state != "live" or self.last_wall is None or self.period_s is None:
            return False
        if now - self.last_wall > max(2.0 * self.period_s, self.min_stale_s):
            self.state = "stale"
            self._event("stale", {"silent_s": round(now - self.last_wall, 2)})
            return True
        return False

    # ---------------------------------------------------------------- views
    def summary(self, now: float) -> dict[str, Any]:
        """What the ward tile and ``GET /api/mats`` show."""
        latest = self.monitor.latest
        alert = self.monitor.tracker.open_alert
        exposure = self.monitor.tracker.exposure_map()
        stats = latest["stats"] if latest else None
        state = self.state
        if state == "live" and alert is not None:
            state = "alert" if alert.active else "acknowledged"
        bed = latest.get("bed") if latest and state != "stale" else None
        if bed is not None:
            bed = {"side": bed["side"], "since_turn_s": bed["since_turn_s"],
                   "turn_due": bed["turn_due"], "interval_s": bed["interval_s"]}  # fmt: skip
        turn_due = bool(bed and bed["turn_due"])
        return {
            "id": self.id,
            "source": self.config.source,
            "quantity": self.config.quantity,
            "elements": self.config.layout.n_elements,
            "shape": list(self.config.layout.shape) if self.config.layout.shape else None,
            "cells": None
            if self.config.layout.cells is None
            else self.config.layout.cells.tolist(),
            "frames": self.monitor.frames,
            "messages": self.messages,
            "malformed": self.malformed,
            "ignored": self.ignored,
            "last_error": self.last_error,
            "last_frame_wall": self.last_wall,
            "seconds_since_frame": None
            if self.last_wall is None
            else round(now - self.last_wall, 2),
            "period_s": None if self.period_s is None else round(self.period_s, 3),
            "state": state,
            "refused": self.refused,
            "occupied": bool(stats and stats["load_N"] > 5.0),
            "minutes_since_reposition": round(float(np.nanmax(exposure, initial=0.0)) / 60.0, 1),
            "alert": alert.to_dict() if alert is not None else None,
            "pressure": latest["pressure"] if latest else None,
            "urgency": max(URGENCY[state], URGENCY["alert"] if turn_due else 0),
            "bed": bed,
        }


def _value_count(payload: bytes) -> int | None:
    """How many values a payload carries, if it is a JSON object with a list of values."""
    try:
        d = json.loads(payload)
    except (ValueError, UnicodeDecodeError):
        return None
    if isinstance(d, dict) and isinstance(d.get("values"), list):
        return len(d["values"])
    return None


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
        A mat is stale after two frame periods, but never sooner than this.
    """

    def __init__(
        self,
        broker: BrokerURL | None,
        mats: list[MatConfig],
        *,
        topic: str = "texsense/+/frames",
        store: Any = None,
        record_dir: Path | str = "recordings",
        min_stale_s: float = 0.0,
    ) -> None:
        ids = [m.id for m in mats]
        if len(set(ids)) != len(ids):
            raise ParameterError(f"mat ids must be unique, got {ids}")
        self.broker = broker
        self.topic = topic
        self.store = store or EventStore(":memory:")
        self.mats = {m.id: MatEntry(m, self.store, Path(record_dir), min_stale_s) for m in mats}
        self.unknown: dict[str, int] = {}
        self.connected = False
        self.connects = 0
        self.started = time.time()
        self._client: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._subscribers: set[asyncio.Queue[str]] = set()

    # ---------------------------------------------------------------- MQTT
    def _on_connect(self, client: Any, _u: Any, _f: Any, reason: Any, _p: Any = None) -> None:
        if getattr(reason, "is_failure", False):
            log.warning("broker refused the connection: %s", reason)
            return
        self.connected = True
        self.connects += 1
        client.subscribe(self.topic, qos=0)
        log.info("connected to %s, subscribed to %s", self.broker, self.topic)

    def _on_disconnect(self, *_args: Any) -> None:
        self.connected = False
        log.warning("lost the broker %s; reconnecting", self.broker)

    def _on_message(self, _client: Any, _u: Any, msg: Any) -> None:
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self.handle, msg.topic, msg.payload)

    def handle(self, topic: str, payload: bytes) -> None:
        """One MQTT message (in the event loop)."""
        mat = mat_id_of(topic)
        entry = self.mats.get(mat) if mat is not None else None
        if entry is None:
            key = mat or topic
            self.unknown[key] = self.unknown.get(key, 0) + 1
            if self.unknown[key] == 1:
                log.warning("frames for an unknown mat %r (topic %s) are ignored", key, topic)
            return
        try:
            if entry.handle(payload, time.time()):
                self._changed()
        except Exception:  # one mat's failure must not stop the ward
            log.exception("mat %s: a frame could not be processed", entry.id)
            entry.malformed += 1

    def start(self) -> None:
        """Connect (in paho's network thread) from within the running event loop."""
        if self.broker is None:
            return
        self._loop = asyncio.get_running_loop()
        client = mqtt_client(self.broker, f"texsense-station-{id(self)}")
        client.on_connect = self._on_connect
        client.on_disconnect = self._on_disconnect
        client.on_message = self._on_message
        client.loop_start()
        self._client = client

    def stop(self) -> None:
        """Disconnect and end every mat's session."""
        if self._client is not None:
            self._client.disconnect()
            self._client.loop_stop()
            self._client = None
        for entry in self.mats.values():
            entry.monitor.close()

    async def consume(self, mat_id: str, source: Source) -> None:
        """Feed a mat from a local source (serial, IIO, replay) until it ends."""
        entry = self.mats[mat_id]
        try:
            async for frame in source.frames():
                if entry.feed(frame, time.time()):
                    self._changed()
                entry.malformed = max(entry.malformed, source.errors)
        finally:
            source.close()

    async def watch(self, every_s: float = 0.02) -> None:
        """Mark mats stale as they stop sending (runs until cancelled)."""
        while True:
            now = time.time()
            if any([e.check_stale(now) for e in self.mats.values()]):
                self._changed()
            await asyncio.sleep(every_s)

    # ---------------------------------------------------------------- views
    def summaries(self) -> list[dict[str, Any]]:
        """Every mat, most urgent first (alerts, then stale or refused, then the longest
        time without repositioning)."""
        now = time.time()
        rows = [e.summary(now) for e in self.mats.values()]
        return sorted(rows, key=lambda r: (-r["urgency"], -r["minutes_since_reposition"], r["id"]))

    def subscribe(self) -> asyncio.Queue[str]:
        """A queue that receives the ward (JSON text) after every change, at most 5 times a
        second; a slow viewer gets the newest."""
        q: asyncio.Queue[str] = asyncio.Queue(maxsize=2)
        self._subscribers.add(q)
        return q

    def unsubscribe(self, q: asyncio.Queue[str]) -> None:
        """Stop sending to ``q``."""
        self._subscribers.discard(q)

    def _changed(self) -> None:
        self._dirty = True

    async def publish(self, every_s: float = 0.2) -> None:
        """Send the ward to the viewers whenever it changed (runs until cancelled)."""
        self._dirty = True
        while True:
            if self._dirty and self._subscribers:
                self._dirty = False
                text = json.dumps(self.ward(), separators=(",", ":"))
                for q in self._subscribers:
                    if q.full():
                        q.get_nowait()
                    q.put_nowait(text)
            await asyncio.sleep(every_s)

    def ward(self) -> dict[str, Any]:
        """The whole ward: connection and every mat's summary."""
        return {
            "broker": None if self.broker is None else str(self.broker),
            "connected": self.connected,
            "topic": self.topic,
            "unknown": self.unknown,
            "wall": time.time(),
            "mats": self.summaries(),
        }
