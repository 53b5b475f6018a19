"""A virtual device behind a real serial line: a virtual mat's capacitance, served in the
texsense serial line protocol (:mod:`texsense.data.protocol`) on a pseudo-terminal, so
that everything a real mat goes through — the serial port, the line protocol, the recorder,
the calibration, the monitor — can be run and tested without hardware (docs/calibration.md).

The device announces itself first (and again before a frame, at most four times a second, for
a reader that opens the port later) with a comment line that a reader of the protocol may use
instead of ``--grid``::

    #layout {"device": "texsense virtual seat", "spacer": "textile-3mm", "elements": 96, ...}

then writes one ``F,...`` line per frame, paced to the converter's frame time (1.6 s for the
96-element seat on one AD7745, 1.06 s for the 64 x 32 bed on 32 converters) divided by
``speed``. What lies on the mat is chosen by ``load``:

- ``empty``: nothing (what zeroing records);
- ``uniform:P``: P N/cm² on every element (what equilibration records: a bladder or a plate);
- ``person``: a virtual person (the seat: the 16 postures of thesis §6.2 in turn; the bed: a
  night of lying positions, :mod:`texsense.sim.bed`).

The mat is the simulator's (:class:`~texsense.sim.mat.VirtualMat`), not built from the
compensation's models. With ``truth`` the true pressure of every frame is recorded too.

Examples
--------
>>> dev = VirtualDevice("seat", load="uniform:1.5", seed=3)
>>> dev.layout.n_elements, dev.spacer, round(dev.frame_s, 2)
(96, 'textile-3mm', 1.6)
>>> t, pressure, line = next(dev.frames())
>>> float(pressure.max()), line.startswith("F,0,")
(1.5, True)
"""

from __future__ import annotations

import contextlib
import os
import queue
import select
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from texsense.data.layout import Layout
from texsense.data.protocol import format_serial_line, layout_announcement
from texsense.exceptions import ParameterError
from texsense.sim.bed import BED_CONVERTERS, Sleeper, bed_mat, night_frames, night_plan
from texsense.sim.mat import VirtualMat
from texsense.sim.seated import SEAT_FAILURES, Subject, posture_pressure

__all__ = ["LOADS", "MATS", "VirtualDevice", "parse_load"]

#: The mats a virtual device can be.
MATS = ("seat", "bed")
#: What can lie on it (``uniform:P`` with P in N/cm²).
LOADS = ("empty", "uniform:P", "person")
#: Seconds between two announcements of the layout: the longest a reader that opens the port
#: waits for one (1 s before: half a second on average of every `texsense record` and monitor
#: started on a device; a line of ~300 bytes four times a second is nothing on the line).
ANNOUNCE_EVERY_S = 0.25


def parse_load(text: str) -> tuple[str, float]:
    """``empty`` -> ("empty", 0), ``uniform:1.5`` -> ("uniform", 1.5), ``person`` ->
    ("person", 0); anything else is a :class:`ParameterError` naming what is allowed."""
    if text in ("empty", "person"):
        return text, 0.0
    kind, _, value = text.partition(":")
    if kind == "uniform":
        try:
            p = float(value)
        except ValueError:
            p = float("nan")
        if np.isfinite(p) and 0 <= p <= 100:
            return "uniform", p
        raise ParameterError(f"--load uniform:P needs a pressure 0-100 N/cm², got {value!r}")
    raise ParameterError(f"--load must be one of {', '.join(LOADS)}, got {text!r}")


class VirtualDevice:
    """A virtual mat and its readout as a serial device.

    Parameters
    ----------
    mat : {"seat", "bed"}
        The thesis's 96-element seat (15 x 16 checkerboard, 2.07 cm) or the 64 x 32 bed mat.
    load : str
        ``empty``, ``uniform:P`` (N/cm²) or ``person`` (see the module docstring).
    seed : int
        The physical mat (element spread, stray capacitance) and the person.
    failures : bool
        Elements fail at the rates the thesis measured on its seat (off: a new mat).
    speed : float
        Simulated seconds per wall-clock second (1: real time).
    """

    def __init__(
        self,
        mat: str = "seat",
        *,
        load: str = "empty",
        seed: int = 0,
        failures: bool = False,
        speed: float = 1.0,
    ) -> None:

        if mat not in MATS:
            raise ParameterError(f"--mat must be one of {', '.join(MATS)}, got {mat!r}")
        if not (np.isfinite(speed) and 0 < speed <= 1000):
            raise ParameterError(f"speed must lie in (0, 1000], got {speed}")
        self.mat_name = mat
        self.load, self.pressure = parse_load(load)
        self.seed, self.speed = int(seed), float(speed)
        if mat == "seat":
            self.mat = VirtualMat.seat(seed=seed, failures=SEAT_FAILURES if failures else None)
            self.frame_s = self.mat.cdc.frame_time_s(self.mat.layout.n_elements)
        else:
            self.mat = bed_mat(seed=seed, failures=failures)
            self.frame_s = self.mat.cdc.frame_time_s(self.mat.layout.n_elements, BED_CONVERTERS)
        self.frames_sent = 0
        self.dropped = 0
        self._lock = threading.Lock()
        self._load_version = 0

    @property
    def layout(self) -> Layout:
        """Where the elements are."""
        return self.mat.layout

    @property
    def spacer(self) -> str:
        """The spacer preset of every element (what ``calibrate mat --material`` wants)."""
        return self.mat.spacer_name

    def announcement(self) -> str:
        """The ``#layout`` line (without newline)."""
        return layout_announcement(
            self.layout,
            device=f"texsense virtual {self.mat_name}",
            spacer=self.spacer,
            frame_s=round(self.frame_s, 6),
            load=self.load if self.load != "uniform" else f"uniform:{self.pressure:g}",
        )

    def set_load(self, text: str) -> None:
        """Change what lies on the mat from the next frame on (``empty``, ``uniform:P``,
        ``person``; thread-safe: ``texsense simulate device`` calls it for each line typed on
        its standard input). A bad load is a :class:`ParameterError`; the load stays."""
        kind, pressure = parse_load(text)
        with self._lock:
            self.load, self.pressure = kind, pressure
            self._load_version += 1

    def _pressures(self, rng: np.random.Generator) -> Iterator[tuple[float, np.ndarray]]:
        """(time, true pressure) of every frame, endless; the load may change between two
        frames (:meth:`set_load`), time goes on."""
        n = self.layout.n_elements
        t, version, person = 0.0, -1, None
        while True:
            with self._lock:
                kind, pressure, changed = self.load, self.pressure, version != self._load_version
                version = self._load_version
            if kind != "person":
                person = None
                yield t, np.full(n, pressure)
            else:
                if person is None or changed:
                    walk = self._seated if self.mat_name == "seat" else self._lying
                    person = walk(rng, t)
                _, p = next(person)
                yield t, p
            t += self.frame_s

    def _seated(self, rng: np.random.Generator, t: float) -> Iterator[tuple[float, np.ndarray]]:
        subject = Subject.random(self.seed, seed=101)
        while True:
            posture = int(rng.integers(1, 17))
            take = rng.normal(0.0, 0.5, 2)
            end = t + 90.0 * rng.uniform(0.7, 1.3)
            while t < end:
                jitter = tuple(take + rng.normal(0.0, 0.15, 2))
                yield t, posture_pressure(self.layout, posture, subject, jitter)
                t += self.frame_s

    def _lying(self, rng: np.random.Generator, t: float) -> Iterator[tuple[float, np.ndarray]]:
        sleeper = Sleeper.random(self.seed, seed=202)

        def plan() -> Iterator[tuple[str, float]]:
            while True:
                yield from night_plan(rng, 8, 1800.0, out_every=0)

        for f in night_frames(sleeper, plan(), rng, frame_s=self.frame_s, t0=t):
            yield f.t, f.pressure

    def frames(self) -> Iterator[tuple[float, np.ndarray, str]]:
        """(time s, true pressure N/cm², protocol line) of every frame, endless, unpaced."""
        rng = np.random.default_rng([self.seed, 7])
        for seq, (t, p) in enumerate(self._pressures(rng)):
            scan = self.mat.scan(np.array([t]), p[None, :])
            cap = scan.capacitance
            assert cap.element_times is not None  # a scan times every element
            values = np.where(cap.valid[0], cap.frames[0], np.nan).astype(np.float64)
            t0_us = round(float(cap.element_times[0, 0]) * 1e6)
            offsets = cap.element_times[0] - cap.element_times[0, 0]
            dt_us = round(float(offsets[-1]) / max(len(offsets) - 1, 1) * 1e6)
            yield t, p, format_serial_line(seq, t0_us, dt_us, values)

    def serve(
        self,
        link: str | Path,
        *,
        stop: threading.Event | None = None,
        truth: str | Path | None = None,
        max_frames: int | None = None,
    ) -> None:
        """Serve frames on a new pseudo-terminal whose path is ``link`` (a symbolic link to
        ``/dev/pts/N``, made here and removed at the end) until ``stop`` is set or
        ``max_frames`` were produced. A reader that is slower than the device, or absent,
        loses frames (counted in ``dropped``), as behind a real UART; the device never
        waits for it."""
        link = Path(link)
        if link.exists() or link.is_symlink():
            raise ParameterError(f"{link} exists: the device's link must be a new path")
        stop = stop or threading.Event()
        # the truth's file first: refused (it exists), it leaves no link or terminal behind
        recorder = _TruthRecorder(truth, self.layout) if truth else None
        master, slave = os.openpty()
        _raw(slave)
        os.symlink(os.ttyname(slave), link)
        lines: queue.Queue[str] = queue.Queue(maxsize=2)
        writer = threading.Thread(target=_write_lines, args=(master, lines, stop), daemon=True)
        writer.start()
        try:
            self._produce(lines, stop, recorder, max_frames)
        finally:
            stop.set()
            writer.join(timeout=2)
            if recorder is not None:
                recorder.close()
            with contextlib.suppress(OSError):
                link.unlink()
            for fd in (master, slave):
                with contextlib.suppress(OSError):
                    os.close(fd)

    def _produce(
        self,
        lines: queue.Queue[str],
        stop: threading.Event,
        recorder: _TruthRecorder | None,
        max_frames: int | None,
    ) -> None:
        start = time.monotonic()
        last_announce = -np.inf
        for k, (t, p, line) in enumerate(self.frames()):
            if stop.is_set() or (max_frames is not None and k >= max_frames):
                return
            now = time.monotonic()
            if now - last_announce >= ANNOUNCE_EVERY_S:
                self._offer(lines, self.announcement())
                last_announce = now
            if not self._offer(lines, line):
                self.dropped += 1
            self.frames_sent += 1
            if recorder is not None:
                recorder.append(t, p)
            delay = start + (t + self.frame_s) / self.speed - time.monotonic()
            if delay > 0 and stop.wait(delay):
                return

    @staticmethod
    def _offer(lines: queue.Queue[str], line: str) -> bool:
        try:
            lines.put_nowait(line)
            return True
        except queue.Full:
            return False

    def info(self) -> dict[str, Any]:
        """What the command prints when it starts."""
        shape = self.layout.shape
        return {
            "mat": self.mat_name,
            "elements": self.layout.n_elements,
            "grid": None if shape is None else f"{shape[0]}x{shape[1]}",
            "spacer": self.spacer,
            "frame_s": self.frame_s,
            "load": self.load if self.load != "uniform" else f"uniform:{self.pressure:g}",
        }


def _raw(fd: int) -> None:
    """No echo, no line-ending translation: the pty passes bytes as a USB serial port does."""
    import termios
    import tty

    tty.setraw(fd, termios.TCSANOW)


def _write_lines(master: int, lines: queue.Queue[str], stop: threading.Event) -> None:
    """Write queued lines to the pty's master side; a line is written whole or, if the
    reader does not drain the port within 2 s, abandoned at the next stop check."""

    while not stop.is_set():
        try:
            line = lines.get(timeout=0.1)
        except queue.Empty:
            continue
        data = (line + "\n").encode("ascii")
        while data and not stop.is_set():
            _, ready, _ = select.select([], [master], [], 0.2)
            if not ready:
                continue
            try:
                written = os.write(master, data)
            except OSError:
                return
            data = data[written:]


class _TruthRecorder:
    """The true pressure of every served frame, in a crash-safe HDF5 recording."""

    def __init__(self, path: str | Path, layout: Layout) -> None:
        from texsense.io.hdf5 import RecordingWriter

        self.writer = RecordingWriter(
            path,
            layout,
            "pressure",
            "N/cm2",
            meta={"source": "texsense simulate device (true pressure)"},
            flush_interval_s=1.0,
        )

    def append(self, t: float, p: np.ndarray) -> None:
        self.writer.append(p, [t])

    def close(self) -> None:
        self.writer.close()
