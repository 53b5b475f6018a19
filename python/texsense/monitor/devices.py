"""The hardware sources of the live monitor: a mat on a serial line (the texsense line
protocol), a Linux IIO capacitance-to-digital converter behind a multiplexer, and frames from
an MQTT broker. Each registers itself with the command line (:class:`~texsense.monitor.sources.
Source`, ``scheme``); what they share (retrying a device that is missing, reading it in a
thread, counting malformed input) is :mod:`texsense.monitor.sources`.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import numpy as np

from texsense.data import units
from texsense.data.layout import Layout
from texsense.data.protocol import (
    Frame,
    ProtocolError,
    parse_announcement,
    parse_mqtt_payload,
    parse_serial_line,
)
from texsense.exceptions import FormatError, ParameterError, shown
from texsense.monitor.sources import RETRY_S, Source, SourceOptions, blocking, reason

__all__ = ["IIOSource", "MQTTSource", "SerialSource"]


class SerialSource(Source):
    """Frames from a serial line in the texsense line protocol
    (:mod:`texsense.data.protocol`). ``port`` is a device (``/dev/ttyACM0``) or any pySerial
    URL (``socket://host:port``, ``loop://``). A port that is missing or refuses is tried
    again every :data:`RETRY_S` s (and said once); so is one that goes away while reading.

    Without a ``layout`` the device must announce its own (a ``#layout`` line, see
    :func:`~texsense.data.protocol.parse_announcement`): the source waits up to
    ``announce_timeout_s`` for it and keeps what else it says (its spacer, ...) in
    ``announced``."""

    name = "serial"
    scheme = "serial"
    argument = "PORT"
    path_kind = "device"
    reads = frozenset({"--grid"})

    @classmethod
    def argument_path(cls, argument: str) -> str:
        """A device's path; a pySerial URL (``socket://``, ``rfc2217://``) is none."""
        return "" if "://" in argument else cls.path_kind

    summary = "a mat on a serial line in the texsense line protocol (a device or pySerial URL)"

    @classmethod
    def from_option(cls, argument: str, options: SourceOptions) -> Source:
        """``serial:PORT`` (``--grid`` only for a device that does not announce its layout)."""
        return cls(argument, options.grid)

    def __init__(
        self,
        port: str,
        layout: Layout | None = None,
        *,
        baudrate: int = 115200,
        opener: Callable[..., Any] | None = None,
        announce_timeout_s: float = 12.0,
    ) -> None:
        super().__init__()
        self.announced: dict[str, Any] = {}
        self.port = port
        self.name = f"serial:{port}"
        if opener is None:
            import serial

            opener = serial.serial_for_url
        self._opener = opener
        self._baudrate = baudrate
        self._dev: Any = None
        self.lines = 0
        if layout is None:  # the device must be there now, to announce its layout
            try:
                self._dev = self._opener(self.port, baudrate=self._baudrate, timeout=0.2)
            except (OSError, ValueError) as e:
                raise ParameterError(
                    f"{self.name}: cannot open it ({reason(e)}); without --grid the device "
                    "must be there to announce its layout"
                ) from None
            layout = self._wait_for_layout(announce_timeout_s)
        else:
            self._open()  # at once: a missing device is said before the server starts
        self.layout = layout

    def _wait_for_layout(self, timeout_s: float) -> Layout:
        """Read lines until the device announces its layout (frames before it are dropped)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                line = self._dev.readline()
            except OSError:
                break
            try:
                got = parse_announcement(line)
            except ProtocolError as e:
                raise ParameterError(f"{self.name}: {e}") from None
            if got is not None:
                layout, self.announced = got
                return layout
        raise ParameterError(
            f"{self.name} announced no layout ('#layout' line) within {timeout_s:g} s: "
            "give the mat's grid with --grid ROWSxCOLS"
        )

    def _open(self) -> bool:
        try:
            self._dev = self._opener(self.port, baudrate=self._baudrate, timeout=0.2)
        except (OSError, ValueError) as e:  # serial.SerialException is an OSError
            self._trouble(f"cannot open it ({reason(e)}); trying again every {RETRY_S:g} s")
            return False
        self._fine()
        return True

    def parse(self, line: bytes) -> Frame | None:
        """One line -> a frame, None (comment, blank, malformed: counted and skipped)."""
        self.lines += 1
        try:
            announced = parse_announcement(line)
            if announced is not None:
                if announced[0].n_elements != self.layout.n_elements:
                    raise ProtocolError(
                        f"the device announces {announced[0].n_elements} elements, "
                        f"expected {self.layout.n_elements}"
                    )
                return None
            return parse_serial_line(line, self.layout.n_elements)
        except ProtocolError as e:
            self._bad(f"line {self.lines}", e)
            return None

    async def frames(self) -> AsyncIterator[Frame]:
        """Frames as lines arrive."""
        while True:
            if self._dev is None and not await blocking(self._open):
                await asyncio.sleep(RETRY_S)
                continue
            try:
                raw = await blocking(self._dev.readline)
            except OSError as e:  # unplugged, or the remote end closed
                self._trouble(f"lost it ({reason(e)}); trying again every {RETRY_S:g} s")
                self.close()
                await asyncio.sleep(RETRY_S)
                continue
            if not raw:
                continue
            frame = self.parse(raw)
            if frame is not None:
                yield frame

    def close(self) -> None:
        """Close the port."""
        dev, self._dev = self._dev, None
        if dev is not None:
            with contextlib.suppress(OSError):
                dev.close()


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
    scheme = "iio"
    argument = "DEVICE_DIR"
    path_kind = "folder"
    reads = frozenset({"--grid", "--sampling-frequency", "--multiplexer", "--capdac-pf"})
    summary = "a Linux IIO AD7745/46 converter behind a multiplexer (needs --grid)"

    @classmethod
    def from_option(cls, argument: str, options: SourceOptions) -> Source:
        """``iio:DEVICE_DIR`` with ``--grid`` and the converter's settings."""
        return cls(
            argument,
            options.need_grid(cls.scheme),
            sampling_frequency=options.sampling_frequency,
            capdac_pF=options.capdac_pF,
            multiplexer=options.multiplexer,
        )

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
        self.layout = layout
        self.name = f"iio:{self.dir}"
        n = layout.n_elements
        self.mux = multiplexer
        self.channels = (
            channels if channels is not None else ([0] if multiplexer else list(range(n)))
        )
        if multiplexer is None and len(self.channels) != n:
            raise ParameterError(f"without a multiplexer, {n} elements need {n} channels")
        if capdac_pF is not None and capdac_pF < 0:
            raise ParameterError(f"capdac_pF must be >= 0, got {capdac_pF}")
        self.settle_s = settle_s
        self._settings = (sampling_frequency, capdac_pF)
        self._scale: dict[int, float] = {}
        self._offset: dict[int, float] = {}
        self.ready = False
        if self.dir.is_dir():  # a device that is there but is not a CDC: an error at once
            self._set_up()
        else:
            self._trouble(f"no such IIO device folder; trying again every {RETRY_S:g} s")

    def _set_up(self) -> None:
        """Check the channels, write the settings, read scale and offset."""
        if not self.dir.is_dir():
            raise FormatError(self.dir, "no such IIO device folder")
        for c in set(self.channels):
            if not (self.dir / f"in_capacitance{c}_raw").is_file():
                raise FormatError(self.dir, f"no in_capacitance{c}_raw (not a CDC, or channel?)")
        sampling_frequency, capdac_pF = self._settings
        if sampling_frequency is not None:
            self._write("sampling_frequency", f"{sampling_frequency:g}")
        self._scale = {
            c: self._number(f"in_capacitance{c}_scale", "in_capacitance_scale", 1.0)
            for c in set(self.channels)
        }
        if capdac_pF is not None:
            for c in set(self.channels):
                counts = round(capdac_pF / self._scale[c])
                self._write(f"in_capacitance{c}_offset", str(counts))
        self._offset = {
            c: self._number(f"in_capacitance{c}_offset", "in_capacitance_offset", 0.0)
            for c in set(self.channels)
        }
        self.ready = True
        self._fine()

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
                    raise FormatError(p, f"not a number: {shown(text, 20)}") from None
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
        """Frames, one full multiplexer cycle each (a missing device is waited for)."""
        seq = 0
        t0 = time.monotonic()
        while True:
            if not self.ready:
                try:
                    await blocking(self._set_up)
                except FormatError as e:
                    self._trouble(f"{e.detail}; trying again every {RETRY_S:g} s")
                    await asyncio.sleep(RETRY_S)
                    continue
            times, values = await blocking(self.read_frame)
            yield Frame(seq, times - t0, values, "pF")
            seq += 1


class MQTTSource(Source):
    """Frames from an MQTT broker (paho-mqtt), topic ``texsense/<mat>/frames`` by default, JSON
    payloads as in :mod:`texsense.data.protocol`."""

    name = "mqtt"
    scheme = "mqtt"
    argument = "HOST[:PORT]"
    reads = frozenset({"--grid"})
    summary = "frames from an MQTT broker, topic texsense/+/frames (needs --grid)"

    @classmethod
    def from_option(cls, argument: str, options: SourceOptions) -> Source:
        """``mqtt:HOST[:PORT]`` with ``--grid``."""
        host, _, port = argument.partition(":")
        try:
            number = int(port or 1883)
        except ValueError:
            raise ParameterError(f"--source mqtt:{argument}: the port must be a number") from None
        if not host or not 0 < number < 65536:
            raise ParameterError(f"--source mqtt:{argument}: expected HOST[:PORT]")
        return cls(host, options.need_grid(cls.scheme), port=number)

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
        try:
            frame = self.handle(msg.payload)
        except Exception as e:  # never end paho's network thread: counted, said once
            self._bad(f"message {self.messages}", e)
            return
        if frame is not None and self._loop is not None:
            with contextlib.suppress(RuntimeError):  # the loop has closed
                self._loop.call_soon_threadsafe(self._put, frame)

    def _put(self, frame: Frame) -> None:
        """Queue a frame; a consumer that lags loses the oldest (counted), never the newest."""
        if self._queue is None:
            return
        if self._queue.full():
            self._queue.get_nowait()
            self._bad(f"message {self.messages}", ProtocolError("the monitor lags: dropped"))
        self._queue.put_nowait(frame)

    def _on_connect(self, client: Any, _u: Any, _f: Any, code: Any, _p: Any = None) -> None:
        if getattr(code, "is_failure", False):
            self._trouble(f"the broker refused the connection ({code}); trying again")
            return
        self._fine()
        client.subscribe(self.topic)

    def _on_connect_fail(self, _client: Any, _userdata: Any) -> None:
        self._trouble(f"cannot connect to the broker; trying again every {RETRY_S:g} s")

    async def frames(self) -> AsyncIterator[Frame]:
        """Frames as messages arrive."""
        import paho.mqtt.client as mqtt

        self._loop = asyncio.get_running_loop()
        self._queue = asyncio.Queue(maxsize=1000)
        client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
        client.on_message = self._on_message
        client.on_connect = self._on_connect
        client.on_connect_fail = self._on_connect_fail
        client.reconnect_delay_set(min_delay=1, max_delay=int(RETRY_S))
        client.connect_async(self.host, self.port)
        client.loop_start()
        self._client = client
        try:
            while True:
                yield await self._queue.get()
        finally:
            client.disconnect()
            client.loop_stop()


# the simulated people (texsense.monitor.virtual) are sources too
