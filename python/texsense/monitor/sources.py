"""Live frame sources: one async interface for the virtual seat, a replayed recording, a serial
line, Linux IIO capacitance converters and MQTT (docs/monitor.md).

Every source has a ``layout``, a ``quantity`` (``capacitance`` or ``pressure``) and an async
iterator :meth:`Source.frames` yielding :class:`~texsense.monitor.protocol.Frame` objects with
per-element time stamps. Sources that parse bytes from outside count malformed input in
``errors`` (and log it) and skip it; they never stop on bad input.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import AsyncIterator, Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from texsense import units
from texsense.exceptions import FormatError, ParameterError
from texsense.layout import Layout
from texsense.monitor.protocol import Frame, ProtocolError, parse_mqtt_payload, parse_serial_line
from texsense.recording import Recording
from texsense.sim.bed import BED_CONVERTERS, Sleeper, bed_mat, night_frames, night_plan
from texsense.sim.mat import VirtualMat
from texsense.sim.seated import POSTURES, SEAT_FAILURES, Subject, posture_pressure

__all__ = [
    "IIOSource",
    "MQTTSource",
    "ReplaySource",
    "SerialSource",
    "Source",
    "VirtualBedSource",
    "VirtualSeatSource",
]

log = logging.getLogger("texsense.monitor")


class Source:
    """Base of all sources."""

    name = "source"
    layout: Layout
    quantity = "capacitance"
    unit = "pF"

    def __init__(self) -> None:
        self.errors = 0  # malformed lines / payloads skipped
        self.last_error: str | None = None

    def _bad(self, where: str, e: Exception) -> None:
        self.errors += 1
        self.last_error = f"{where}: {e}"
        if self.errors <= 10 or self.errors % 1000 == 0:
            log.warning(
                "%s: skipped malformed input (%d so far) at %s: %s",
                self.name,
                self.errors,
                where,
                e,
            )

    def frames(self) -> AsyncIterator[Frame]:
        """Frames as they arrive."""
        raise NotImplementedError

    def info(self) -> dict[str, Any]:
        """What the status endpoint shows."""
        return {
            "name": self.name,
            "quantity": self.quantity,
            "unit": self.unit,
            "elements": self.layout.n_elements,
            "errors": self.errors,
            "last_error": self.last_error,
        }

    def close(self) -> None:
        """Release the device."""


async def _pace(start_wall: float, sim_t: float, speed: float) -> None:
    """Sleep until wall time catches up with simulated time ``sim_t`` at ``speed``."""
    if speed <= 0:  # as fast as possible
        await asyncio.sleep(0)
        return
    delay = start_wall + sim_t / speed - time.monotonic()
    await asyncio.sleep(max(delay, 0.0))


class VirtualSeatSource(Source):
    """A simulated person on the 96-element textile seat (thesis §6.2) read through the
    virtual sensor: hysteresis, drift, noise and failing elements (SEAT_FAILURES).

    The person takes the 16 postures in a random order, holding each ``hold_s`` (± 30 %),
    and stands up for ``away_s`` after every ``postures_per_sitting`` postures. ``speed`` runs
    simulated time faster than the wall clock (the seat gives a frame every 1.6 s).
    """

    name = "virtual seat"

    def __init__(
        self,
        *,
        speed: float = 1.0,
        seed: int = 0,
        hold_s: float = 90.0,
        postures_per_sitting: int = 20,
        away_s: float = 120.0,
    ) -> None:

        super().__init__()
        if speed < 0 or hold_s <= 0 or away_s < 0 or postures_per_sitting < 1:
            raise ParameterError("speed >= 0, hold_s > 0, away_s >= 0, postures >= 1 required")
        self.mat = VirtualMat.seat(seed=5, failures=SEAT_FAILURES)
        self.layout = self.mat.layout
        self.subject = Subject.random(seed, seed=101)
        self.speed, self.hold_s, self.away_s = float(speed), float(hold_s), float(away_s)
        self.per_sitting = int(postures_per_sitting)
        self._rng = np.random.default_rng(seed)
        self.frame_s = self.mat.cdc.frame_time_s(self.layout.n_elements)
        self.posture = 0  # the true posture now (0: nobody seated)
        self.failed: np.ndarray = np.zeros(self.layout.n_elements, bool)

    def _plan(self) -> list[tuple[float, int]]:
        """(duration, posture) segments of one sitting and the break after it."""
        postures = self._rng.integers(1, 17, self.per_sitting)
        out = [(self.hold_s * self._rng.uniform(0.7, 1.3), int(p)) for p in postures]
        return [*out, (self.away_s, 0)]

    async def frames(self) -> AsyncIterator[Frame]:
        """Endless frames, paced to ``speed``."""
        n = self.layout.n_elements
        start = time.monotonic()
        t, seq = 0.0, 0
        while True:
            for duration, posture in self._plan():
                take = self._rng.normal(0.0, 0.5, 2)
                end = t + duration
                while t < end:
                    self.posture = posture
                    if posture:
                        jitter = tuple(take + self._rng.normal(0.0, 0.15, 2))
                        p = posture_pressure(self.layout, posture, self.subject, jitter)
                    else:
                        p = np.zeros(n)
                    scan = self.mat.scan(np.array([t]), p[None, :])
                    self.failed = scan.failed[0]
                    cap = scan.capacitance
                    assert cap.element_times is not None  # a scan times every element
                    await _pace(start, t, self.speed)
                    yield Frame(seq, cap.element_times[0].copy(), cap.frames[0].astype(float))
                    seq += 1
                    t += self.frame_s

    def info(self) -> dict[str, Any]:
        """Status, with the simulated truth (the posture's name now, None when away)."""
        truth = POSTURES[self.posture] if self.posture else None
        return {**super().info(), "speed": self.speed, "true_posture": truth}


class VirtualBedSource(Source):
    """A simulated person on the virtual 64 x 32 bed mat (:func:`texsense.sim.bed.bed_mat`:
    textile spacer, failing elements, 32 converters in parallel: a frame about every second):
    lying positions of every
    side and their variants in a random order, each held ``hold_s`` times 0.3-2.2 (the
    default: 18 min to 2 h 12 min, so a 2 h turning schedule is sometimes overrun), turning
    for a few seconds between them, sitting up after every 5 positions and out of bed for
    ``away_s`` after every ``positions_per_stay``."""

    name = "virtual bed"

    def __init__(
        self,
        *,
        speed: float = 1.0,
        seed: int = 0,
        hold_s: float = 3600.0,
        positions_per_stay: int = 8,
        away_s: float = 300.0,
    ) -> None:

        super().__init__()
        if speed < 0 or hold_s <= 0 or away_s < 0 or positions_per_stay < 1:
            raise ParameterError("speed >= 0, hold_s > 0, away_s >= 0, positions >= 1 required")
        self.mat = bed_mat()
        self.layout = self.mat.layout
        self.speed, self.hold_s, self.away_s = float(speed), float(hold_s), float(away_s)
        self.per_stay = int(positions_per_stay)
        self._rng = np.random.default_rng(seed)
        self.sleeper = Sleeper.random(seed, seed=202)
        self.frame_s = self.mat.cdc.frame_time_s(self.layout.n_elements, BED_CONVERTERS)
        self.position: str | None = None
        self.side: str | None = None

    def _plan(self) -> Iterator[tuple[str, float]]:

        while True:
            yield from night_plan(
                self._rng, self.per_stay, self.hold_s, out_every=self.per_stay,
                away_s=self.away_s, spread=(0.3, 2.2),
            )  # fmt: skip

    async def frames(self) -> AsyncIterator[Frame]:
        """Endless frames, paced to ``speed``."""
        start = time.monotonic()
        turn_s = min(6.0, self.hold_s / 3)
        plan = self._plan()
        frames = night_frames(self.sleeper, plan, self._rng, frame_s=self.frame_s, turn_s=turn_s)
        for seq, f in enumerate(frames):
            self.position = None if f.position == "out" else f.position
            self.side = None if f.side == "out" else f.side
            cap = self.mat.scan(np.array([f.t]), f.pressure[None, :]).capacitance
            assert cap.element_times is not None  # a scan times every element
            await _pace(start, f.t, self.speed)
            yield Frame(seq, cap.element_times[0].copy(), cap.frames[0].astype(float))

    def info(self) -> dict[str, Any]:
        """Status, with the simulated truth (the position and side now, None when out of
        bed)."""
        return {
            **super().info(),
            "speed": self.speed,
            "true_position": self.position,
            "true_side": self.side,
        }


class ReplaySource(Source):
    """Replay a recording (any readable file or a :class:`Recording`) at ``speed`` times real
    time (0: as fast as possible), optionally looping."""

    name = "replay"

    def __init__(
        self, recording: Recording | str | Path, *, speed: float = 1.0, loop: bool = False
    ) -> None:
        super().__init__()
        if isinstance(recording, (str, Path)):
            from texsense.io import load

            self.name = f"replay {Path(recording).name}"
            recording = load(recording)
        if recording.n_frames == 0:
            raise ParameterError("the recording has no frames to replay")
        if recording.quantity not in ("capacitance", "pressure"):
            raise ParameterError(
                f"cannot monitor {recording.quantity!r} data ({recording.unit}): the monitor "
                "needs capacitance (with a calibration) or pressure"
            )
        if speed < 0:
            raise ParameterError(f"speed must be >= 0, got {speed}")
        self.rec = recording
        self.layout = recording.layout
        self.quantity, self.unit = recording.quantity, recording.unit
        self.speed, self.loop = float(speed), loop

    async def frames(self) -> AsyncIterator[Frame]:
        """The recording's frames, paced, looping if asked."""
        rec = self.rec
        times = np.asarray(rec.times, dtype=np.float64)
        et = rec.element_times
        span = float(times[-1] - times[0]) + (
            float(np.median(np.diff(times))) if times.size > 1 else 1.0
        )
        start, offset, seq = time.monotonic(), 0.0, 0
        while True:
            for k in range(rec.n_frames):
                t = times[k] - times[0] + offset
                await _pace(start, t, self.speed)
                element_times = (
                    (et[k] - times[0] + offset) if et is not None else np.full(rec.n_elements, t)
                )
                values = np.where(rec.valid[k], rec.frames[k], np.nan).astype(np.float64)
                yield Frame(seq, element_times, values, rec.unit)
                seq += 1
            if not self.loop:
                return
            offset += span


class SerialSource(Source):
    """Frames from a serial line in the texsense line protocol
    (:mod:`texsense.monitor.protocol`). ``port`` is a device (``/dev/ttyACM0``) or any pySerial
    URL (``socket://host:port``, ``loop://``)."""

    name = "serial"

    def __init__(
        self,
        port: str,
        layout: Layout,
        *,
        baudrate: int = 115200,
        opener: Callable[..., Any] | None = None,
    ) -> None:
        super().__init__()
        self.layout = layout
        self.port = port
        self.name = f"serial {port}"
        if opener is None:
            import serial

            opener = serial.serial_for_url
        self._dev = opener(port, baudrate=baudrate, timeout=0.2)
        self.lines = 0

    def parse(self, line: bytes) -> Frame | None:
        """One line -> a frame, None (comment, blank, malformed: counted and skipped)."""
        self.lines += 1
        try:
            return parse_serial_line(line, self.layout.n_elements)
        except ProtocolError as e:
            self._bad(f"line {self.lines}", e)
            return None

    async def frames(self) -> AsyncIterator[Frame]:
        """Frames as lines arrive."""
        while True:
            raw = await asyncio.to_thread(self._dev.readline)
            if not raw:
                continue
            frame = self.parse(raw)
            if frame is not None:
                yield frame

    def close(self) -> None:
        """Close the port."""
        self._dev.close()


class IIOSource(Source):
    """A Linux IIO capacitance-to-digital converter (AD7745/AD7746 driver) read through sysfs,
    with a multiplexer in front of it selecting one element at a time.

    Capacitance of channel ``c`` = (``in_capacitance<c>_raw`` + ``in_capacitance<c>_offset``)
    x ``in_capacitance<c>_scale`` (the IIO convention; the ad7746 driver's scale, 8.192 pF /
    2^24 = 0.000000488, gives pF). ``multiplexer`` is called with the element index before each
    reading (e.g. a function setting GPIO lines); without one the source reads the converter's
    channels as the elements. ``capdac_pF`` sets the CAPDAC once at start: the ad7746 driver
    exposes it as the channel's ``offset`` (in counts; it keeps the nearest of its 127 steps
    of about 21/127 pF, read back before use). ``sampling_frequency`` (Hz) is written to the
    device's ``sampling_frequency`` (the driver picks its nearest filter rate).
    """

    name = "iio"

    def __init__(
        self,
        device: str | Path,
        layout: Layout,
        *,
        channels: list[int] | None = None,
        multiplexer: Callable[[int], None] | None = None,
        sampling_frequency: float | None = None,
        capdac_pF: float | None = None,
        settle_s: float = 0.0,
    ) -> None:
        super().__init__()
        self.dir = Path(device)
        if not self.dir.is_dir():
            raise FormatError(self.dir, "no such IIO device folder")
        self.layout = layout
        self.name = f"iio {self.dir.name}"
        n = layout.n_elements
        self.mux = multiplexer
        self.channels = (
            channels if channels is not None else ([0] if multiplexer else list(range(n)))
        )
        if multiplexer is None and len(self.channels) != n:
            raise ParameterError(f"without a multiplexer, {n} elements need {n} channels")
        self.settle_s = settle_s
        for c in set(self.channels):
            if not (self.dir / f"in_capacitance{c}_raw").is_file():
                raise FormatError(self.dir, f"no in_capacitance{c}_raw (not a CDC, or channel?)")
        if sampling_frequency is not None:
            self._write("sampling_frequency", f"{sampling_frequency:g}")
        self._scale = {
            c: self._number(f"in_capacitance{c}_scale", "in_capacitance_scale", 1.0)
            for c in set(self.channels)
        }
        if capdac_pF is not None:
            if capdac_pF < 0:
                raise ParameterError(f"capdac_pF must be >= 0, got {capdac_pF}")
            for c in set(self.channels):
                counts = round(capdac_pF / self._scale[c])
                self._write(f"in_capacitance{c}_offset", str(counts))
        self._offset = {
            c: self._number(f"in_capacitance{c}_offset", "in_capacitance_offset", 0.0)
            for c in set(self.channels)
        }

    def _write(self, name: str, value: str) -> None:
        path = self.dir / name
        try:
            path.write_text(value)
        except OSError as e:
            raise FormatError(path, f"cannot write {value!r}: {e.strerror}") from None

    def _number(self, name: str, shared: str, default: float) -> float:
        for n in (name, shared):
            p = self.dir / n
            if p.is_file():
                text = p.read_text().strip()
                try:
                    return float(text)
                except ValueError:
                    raise FormatError(p, f"not a number: {text[:20]!r}") from None
        return default

    def read_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """Read every element once (blocking): times (s, monotonic) and capacitance (pF)."""
        n = self.layout.n_elements
        values, times = np.full(n, np.nan), np.empty(n)
        for i in range(n):
            c = self.channels[0] if self.mux else self.channels[i]
            if self.mux:
                self.mux(i)
                if self.settle_s:
                    time.sleep(self.settle_s)
            path = self.dir / f"in_capacitance{c}_raw"
            times[i] = time.monotonic()
            try:
                raw = float(path.read_text().strip())
                values[i] = (raw + self._offset[c]) * self._scale[c]
            except (OSError, ValueError) as e:
                self._bad(f"{path.name} (element {i + 1})", e)
        return times, values

    async def frames(self) -> AsyncIterator[Frame]:
        """Frames, one full multiplexer cycle each."""
        seq = 0
        t0 = time.monotonic()
        while True:
            times, values = await asyncio.to_thread(self.read_frame)
            yield Frame(seq, times - t0, values, "pF")
            seq += 1


class MQTTSource(Source):
    """Frames from an MQTT broker (paho-mqtt), topic ``texsense/<mat>/frames`` by default, JSON
    payloads as in :mod:`texsense.monitor.protocol`."""

    name = "mqtt"

    def __init__(
        self,
        host: str,
        layout: Layout,
        *,
        port: int = 1883,
        topic: str = "texsense/+/frames",
        quantity: str = "capacitance",
    ) -> None:
        super().__init__()
        self.layout, self.host, self.port, self.topic = layout, host, port, topic
        self.quantity = quantity
        self.unit = "pF" if quantity == "capacitance" else "N/cm2"
        self.name = f"mqtt {host}:{port} {topic}"
        self.messages = 0
        self._queue: asyncio.Queue[Frame] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._client: Any = None

    def handle(self, payload: bytes) -> Frame | None:
        """One message -> a frame (None: malformed, counted and skipped)."""
        self.messages += 1
        try:
            frame = parse_mqtt_payload(payload, self.layout.n_elements)
        except ProtocolError as e:
            self._bad(f"message {self.messages}", e)
            return None

        if units.quantity_of(frame.unit) != self.quantity:
            self._bad(f"message {self.messages}", ProtocolError(f"unit {frame.unit!r}"))
            return None
        if frame.unit != self.unit:
            frame.values = units.convert(frame.values, frame.unit, self.unit)
            frame.unit = self.unit
        return frame

    def _on_message(self, _client: Any, _userdata: Any, msg: Any) -> None:
        frame = self.handle(msg.payload)
        if frame is not None and self._loop is not None and self._queue is not None:
            self._loop.call_soon_threadsafe(self._queue.put_nowait, frame)

    async def frames(self) -> AsyncIterator[Frame]:
        """Frames as messages arrive."""
        import paho.mqtt.client as mqtt

        self._loop = asyncio.get_running_loop()
        self._queue = asyncio.Queue(maxsize=1000)
        client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
        client.on_message = self._on_message
        client.on_connect = lambda c, *_: c.subscribe(self.topic)
        client.connect_async(self.host, self.port)
        client.loop_start()
        self._client = client
        try:
            while True:
                yield await self._queue.get()
        finally:
            client.loop_stop()
            client.disconnect()
