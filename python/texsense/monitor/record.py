"""Recording raw frames from any live source, with no calibration (``texsense record``,
docs/calibration.md): what zeroing, equilibration and a check of a new mat need; and the
monitor's recorder (:class:`Recorder`: the source's readings, the pressure, and the clinical
labels of :mod:`texsense.apps.clinical`).

:func:`record` reads a :class:`~texsense.monitor.sources.Source` until ``duration_s`` of
frame time or ``max_frames`` frames, or until it is stopped, and appends every frame to a
crash-safe HDF5 recording (flushed every :data:`FLUSH_S` s, so a killed recorder keeps all
but the last second). Frames pass the mat's :class:`~texsense.monitor.clock.FrameClock`
first, so a glitching time stamp never makes a recording whose times go backwards, and a time
no clock has (not a number, beyond 1e12 s) never one that no reader reads back; such frames
(the latter said in one line naming the source), gaps in the frame counter and malformed
lines count as dropped.
"""

from __future__ import annotations

import asyncio
import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from texsense.apps.clinical import EVENTS_LABEL, POSTURE_LABEL, WALL_LABEL, encode_events
from texsense.data.files import check_new, make_folder, unused_name
from texsense.data.protocol import Frame
from texsense.exceptions import ParameterError
from texsense.monitor.clock import FrameClock, Quiet
from texsense.monitor.sources import Source

log = logging.getLogger("texsense.monitor")

__all__ = [
    "FLUSH_S",
    "RecordStats",
    "Recorder",
    "record",
    "recording_paths",
    "unused_recording_name",
]

#: Longest time between two flushes: a killed recorder loses at most this.
FLUSH_S = 0.5
#: A source that has sent nothing for this long is said to be silent.
SILENT_S = 10.0


@dataclass
class RecordStats:
    """What a recording got: frames written, frames dropped (gaps in the frame counter,
    malformed lines, frames off the mat's clock), frame time spanned, wall time taken."""

    frames: int = 0
    dropped: int = 0
    span_s: float = 0.0
    wall_s: float = 0.0
    first_t: float | None = None
    silent: bool = False
    notes: list[str] = field(default_factory=list)

    @property
    def rate_hz(self) -> float:
        """Frames per second of frame time."""
        return (self.frames - 1) / self.span_s if self.frames > 1 and self.span_s > 0 else 0.0

    def line(self) -> str:
        """The progress line: frames, rate, dropped."""
        return (
            f"{self.frames} frames, {self.span_s:.1f} s, {self.rate_hz:.2f} frames/s, "
            f"{self.dropped} dropped"
        )


def _writer(path: Path, source: Source, meta: dict[str, Any]) -> Any:
    from texsense.io.hdf5 import RecordingWriter

    return RecordingWriter(
        path,
        source.layout,
        source.quantity,
        source.unit,
        meta=meta,
        element_times=True,
        flush_interval_s=FLUSH_S,
    )


async def record(
    source: Source,
    path: str | Path,
    *,
    duration_s: float | None = None,
    max_frames: int | None = None,
    meta: dict[str, Any] | None = None,
    on_progress: Callable[[RecordStats], None] | None = None,
    stop: asyncio.Event | None = None,
) -> RecordStats:
    """Record ``source`` to the new HDF5 file ``path`` (refused if it exists).

    Parameters
    ----------
    source : Source
        Any live source (virtual, replay, serial, IIO, MQTT).
    path : str or Path
        The recording to write; never an existing file.
    duration_s : float, optional
        Stop once the frames span this many seconds of their own time.
    max_frames : int, optional
        Stop after this many frames.
    meta : dict, optional
        Provenance to store (the source's name is added).
    on_progress : callable, optional
        Called with the stats after every frame and every second without one.
    stop : asyncio.Event, optional
        Set it to end the recording (Ctrl-C does the same through cancellation).

    Returns
    -------
    RecordStats
        What was recorded; the file holds every frame counted in ``frames``.
    """

    path = check_new(path)
    if duration_s is not None and not duration_s > 0:
        raise ParameterError(f"--duration must be > 0 s, got {duration_s}")
    if max_frames is not None and max_frames < 1:
        raise ParameterError(f"--frames must be >= 1, got {max_frames}")
    stats = RecordStats()
    info = {"source": source.name, "recorded_by": "texsense record", "started_at": time.time()}
    info.update(getattr(source, "announced", {}) or {})
    info.update(meta or {})
    writer = _writer(path, source, info)
    stop = stop or asyncio.Event()
    start = time.monotonic()
    try:
        frames = _frames_until(source, stop, stats, on_progress)
        await _consume(frames, writer, source, stats, duration_s, max_frames, on_progress)
    finally:
        stats.wall_s = time.monotonic() - start
        writer.close()
        source.close()
    return stats


async def _frames_until(
    source: Source,
    stop: asyncio.Event,
    stats: RecordStats,
    on_progress: Callable[[RecordStats], None] | None,
) -> Any:
    """The source's frames until ``stop``; says (once) when the source falls silent."""
    iterator = source.frames().__aiter__()
    last = time.monotonic()
    pending: asyncio.Task[Any] | None = None
    try:
        while not stop.is_set():
            if pending is None:
                pending = asyncio.ensure_future(iterator.__anext__())
            done, _ = await asyncio.wait({pending}, timeout=1.0)
            if not done:
                stats.silent = time.monotonic() - last >= SILENT_S
                if on_progress is not None:
                    on_progress(stats)
                continue
            task, pending = pending, None
            try:
                frame = task.result()
            except StopAsyncIteration:
                return
            last = time.monotonic()
            stats.silent = False
            yield frame
    finally:
        if pending is not None:
            pending.cancel()


async def _consume(
    frames: Any,
    writer: Any,
    source: Source,
    stats: RecordStats,
    duration_s: float | None,
    max_frames: int | None,
    on_progress: Callable[[RecordStats], None] | None,
) -> None:
    clock = FrameClock(rate=source.rate)
    quiet = Quiet(log)
    errors_before = source.errors
    last_seq: int | None = None
    async for frame in frames:
        verdict, t, _jump = clock.place_frame(frame)
        if verdict == "unclocked":  # a time no clock has: refused, counted, said once
            source.errors += 1
            errors_before = source.errors
            stats.dropped += 1
            quiet.warn(source.name, "unclocked", f"refused frame {frame.seq}: {clock.fault}")
            continue
        if verdict in ("ahead", "backwards"):
            stats.dropped += 1
            continue
        if last_seq is not None and frame.seq > last_seq + 1:
            stats.dropped += frame.seq - last_seq - 1
        last_seq = frame.seq
        shift = t - frame.t
        values = np.asarray(frame.values, dtype=np.float64)
        valid = np.isfinite(values)
        writer.append(
            np.where(valid, values, 0.0)[None, :],
            times=[t],
            valid=valid[None, :],
            element_times=(frame.element_times + shift)[None, :],
        )
        stats.frames += 1
        stats.first_t = t if stats.first_t is None else stats.first_t
        stats.span_s = t - stats.first_t
        stats.dropped += source.errors - errors_before
        errors_before = source.errors
        if on_progress is not None:
            on_progress(stats)
        if max_frames is not None and stats.frames >= max_frames:
            return
        if duration_s is not None and stats.span_s >= duration_s:
            return


def recording_paths(folder: Path, name: str, quantity: str, calibrated: bool = True) -> list[Path]:
    """The files of a recording named ``name``: ``<name>-raw.h5`` and, for capacitance
    through a calibration, the pressure ``<name>.h5``."""
    paths = [folder / f"{name}-raw.h5"]
    if quantity == "capacitance" and calibrated:
        return [*paths, folder / f"{name}.h5"]
    return paths


def unused_recording_name(folder: Path, name: str, quantity: str, calibrated: bool = True) -> str:
    """``name``, or the first ``name-2``, ``name-3``, ... none of whose files exist
    (:func:`texsense.data.files.unused_name` on each file of the recording)."""
    k = 1
    while True:
        candidate = name if k == 1 else f"{name}-{k}"
        paths = recording_paths(folder, candidate, quantity, calibrated)
        if all(unused_name(p) == p for p in paths):
            return candidate
        k += 1


class Recorder:
    """Crash-safe HDF5 recording of one session: the source's readings (``<name>-raw.h5``,
    re-processable) and, for capacitance sources through a calibration, the pressure
    (``<name>.h5``), both flushed at least every :data:`FLUSH_S` s."""

    def __init__(
        self,
        folder: Path,
        name: str,
        source: Source,
        meta: dict[str, Any],
        *,
        calibrated: bool = True,
        posture: bool = False,
        bounds: bool = False,
    ) -> None:
        from texsense.io.hdf5 import RecordingWriter

        make_folder(folder, "recordings folder")
        lay = source.layout
        self.paths = recording_paths(folder, name, source.quantity, calibrated)
        taken = [p.name for p in self.paths if os.path.lexists(p)]  # a link to nothing too
        if taken:  # never write over an earlier recording
            raise ParameterError(f"a recording named {name!r} exists already ({taken[0]})")
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
        if len(self.paths) > 1:
            self._pressure = RecordingWriter(
                self.paths[1],
                lay,
                "pressure",
                "N/cm2",
                meta=meta,
                element_times=True,
                flush_interval_s=FLUSH_S,
                bounds=bounds,
            )
        self.frames = 0
        self.posture = posture
        #: events raised since the last frame was written: they go with the next one
        self.pending: list[dict[str, Any]] = []

    def append(
        self,
        frame: Frame,
        pressure: np.ndarray,
        measured: np.ndarray,
        wall: float,
        posture: str | None = None,
        bounds: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """Append one frame (raw values and pressure) with its labels: the wall clock when it
        arrived, the events raised since the last frame, the posture shown
        (:mod:`texsense.apps.clinical`), and its bounds (lower, upper) for a recorder made
        with ``bounds``. ``pressure`` is the pressure shown, written as given (NaN as 0): an
        empty element's estimate just below zero is 0 already (the monitor's ``no_negative``);
        a lower bound below zero is written as 0."""
        t = [frame.t]
        et = frame.element_times[None, :]
        valid = np.isfinite(frame.values)[None, :]
        labels: dict[str, Any] = {
            WALL_LABEL: [wall],
            EVENTS_LABEL: np.array([encode_events(self.pending)], dtype=object).astype(str),
        }
        if self.posture:
            labels[POSTURE_LABEL] = np.array([posture or ""]).astype(str)
        self._raw.append(
            np.nan_to_num(frame.values)[None, :],
            times=t,
            valid=valid,
            element_times=et,
            labels=labels,
        )
        if self._pressure is not None:
            # the pressure is the one shown, an empty element's estimate already 0 (the
            # monitor's no_negative); what is left to clip is the lower bound (no pressure is
            # below zero)
            lower = None if bounds is None else np.maximum(np.nan_to_num(bounds[0]), 0)
            self._pressure.append(
                np.nan_to_num(pressure)[None, :],
                times=t,
                valid=measured[None, :],
                element_times=et,
                labels=labels,
                lower=None if lower is None else lower[None, :],
                upper=None if bounds is None else np.nan_to_num(bounds[1])[None, :],
            )
        self.pending = []
        self.frames += 1

    def close(self, extra_meta: dict[str, Any] | None = None) -> None:
        """Finish the files (``extra_meta``: what is known only at the end, e.g. the in-use
        drift correction's state)."""
        if extra_meta:
            self._raw.update_meta(extra_meta)
            if self._pressure is not None:
                self._pressure.update_meta(extra_meta)
        self._raw.close()
        if self._pressure is not None:
            self._pressure.close()
