"""Live frame sources: one async interface for the virtual seat, a replayed recording, a serial
line, Linux IIO capacitance converters and MQTT (docs/monitor.md).

Every source has a ``layout``, a ``quantity`` (``capacitance`` or ``pressure``) and an async
iterator :meth:`Source.frames` yielding :class:`~texsense.data.protocol.Frame` objects with
per-element time stamps. Sources that parse bytes from outside count malformed input in
``errors`` (and log it) and skip it; they never stop on bad input.

Hardware that is missing, refuses or goes away (a serial port that is not there, a TCP device
that refuses, an unplugged USB cable, an IIO device folder that is missing, a broker that is
down) is one line on the console and the source's ``problem`` (shown on the page); the source
tries again every :data:`RETRY_S` s and says so once it works. Device calls that block run in
daemon threads, so a stopping monitor never waits for a device.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import logging
import re
import threading
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from texsense.data.layout import Layout
from texsense.data.protocol import (
    Frame,
)
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

if TYPE_CHECKING:
    from texsense.compensation.stages import StageChain

__all__ = [
    "SOURCES",
    "ReplaySource",
    "Source",
    "SourceOptions",
    "available_sources",
    "open_source",
    "source_help",
]

log = logging.getLogger("texsense.monitor")

#: Seconds between two attempts to open a device that is missing or refuses.
RETRY_S = 2.0


def reason(e: BaseException) -> str:
    """The short reason of an OS or device error: ``No such file or directory``,
    ``Connection refused`` (pyserial nests them in longer texts)."""
    found = re.findall(r"\[Errno \d+\] ([^:\]]+)", str(e))
    if found:
        return str(found[-1]).strip()
    return getattr(e, "strerror", None) or str(e) or type(e).__name__


async def blocking(fn: Callable[..., Any], *args: Any) -> Any:
    """``fn(*args)`` in a daemon thread (a device call that may block): unlike
    ``asyncio.to_thread``, a stopping process never waits for it."""
    loop = asyncio.get_running_loop()
    future: asyncio.Future[Any] = loop.create_future()

    def settle(ok: bool, value: Any) -> None:
        if not future.done():
            future.set_result(value) if ok else future.set_exception(value)

    def work() -> None:
        try:
            result: tuple[bool, Any] = (True, fn(*args))
        except BaseException as e:  # handed to the awaiting coroutine
            result = (False, e)
        with contextlib.suppress(RuntimeError):  # a closed loop: nobody waits any more
            loop.call_soon_threadsafe(settle, *result)

    name = getattr(fn, "__name__", None) or getattr(getattr(fn, "func", None), "__name__", "work")
    threading.Thread(target=work, daemon=True, name=f"texsense-{name}").start()
    return await future


@dataclass(frozen=True)
class SourceOptions:
    """What the command line says of a source besides its name (``--speed``, ``--grid``, the
    IIO converter's settings): each source takes what it needs (:meth:`Source.from_option`)."""

    speed: float = 1.0
    grid: Layout | None = None
    sampling_frequency: float | None = None
    multiplexer: Callable[[int], None] | None = None
    capdac_pF: float | None = None
    loop: bool = True

    def need_grid(self, scheme: str) -> Layout:
        """The grid a source of ``scheme`` cannot work without."""
        if self.grid is None:
            raise ParameterError(f"--source {scheme} needs --grid ROWSxCOLS")
        return self.grid


#: The sources offered on the command line, by scheme (``--source SCHEME[:ARGUMENT]``).
SOURCES: dict[str, type[Source]] = {}

#: The modules whose sources the command line offers (each class registers itself).
SOURCE_MODULES = (
    "texsense.monitor.sources",
    "texsense.monitor.devices",
    "texsense.monitor.virtual",
)


class Source:
    """Base of all sources.

    A subclass that sets ``scheme`` is offered on the command line as ``--source
    SCHEME[:ARGUMENT]`` (``argument`` names what follows the colon, empty for none; ``summary``
    is its help) and builds itself from there with :meth:`from_option`; the help, the error
    for an unknown source and the source contract test read :data:`SOURCES`.
    """

    name = "source"
    layout: Layout
    quantity = "capacitance"
    unit = "pF"
    #: the name on the command line (empty: not offered there, e.g. the station's fed source)
    scheme: ClassVar[str] = ""
    #: what follows ``SCHEME:`` on the command line (empty: nothing)
    argument: ClassVar[str] = ""
    #: one line of help
    summary: ClassVar[str] = ""
    #: what the argument is when it is a path (a kind of :data:`texsense.io.named.PATH_KINDS`:
    #: a file named in a ward file is found beside it); empty: not a path
    path_kind: ClassVar[str] = ""
    #: the command line's source options it reads (``--speed``, ``--grid``, ...): another
    #: one given with it has no effect, and is refused (:mod:`texsense.commands._applies`)
    reads: ClassVar[frozenset[str]] = frozenset()
    #: source seconds per wall second, when the source knows it (a replay's or a virtual
    #: mat's ``--speed``; 0: as fast as possible, not known): the mat's clock starts from it
    rate: float = 1.0

    @classmethod
    def argument_path(cls, argument: str) -> str:
        """The kind of path ``argument`` is (:attr:`path_kind`; empty: none, e.g. a URL)."""
        return cls.path_kind

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("scheme"):
            if cls.scheme in SOURCES and SOURCES[cls.scheme].__qualname__ != cls.__qualname__:
                raise TypeError(f"{cls.__name__}: --source {cls.scheme} is already taken")
            SOURCES[cls.scheme] = cls

    @classmethod
    def from_option(cls, argument: str, options: SourceOptions) -> Source:
        """The source ``--source SCHEME:ARGUMENT`` names, with the command line's options."""
        raise NotImplementedError(f"{cls.__name__} is not offered on the command line")

    @classmethod
    def default_calibration(cls) -> StageChain | None:
        """The calibration the source's mat comes with (a virtual mat's), or None."""
        return None

    def __init__(self) -> None:
        self.errors = 0  # malformed lines / payloads skipped
        self.last_error: str | None = None
        self.problem: str | None = None  # the device is missing, refuses or went away

    def _trouble(self, text: str) -> None:
        """The device is missing or refuses: one console line (again only when the reason
        changes) and the state the page shows."""
        if text != self.problem:
            log.warning("%s: %s", self.name, text)
        self.problem = text

    def _fine(self) -> None:
        if self.problem is not None:
            log.warning("%s: working again", self.name)
        self.problem = None

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
            "problem": self.problem,
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


class ReplaySource(Source):
    """Replay a recording (any readable file or a :class:`Recording`) at ``speed`` times real
    time (0: as fast as possible), optionally looping."""

    name = "replay"
    scheme = "replay"
    argument = "FILE"
    path_kind = "recording"
    reads = frozenset({"--speed"})
    summary = "a recording of any readable format, at --speed times real time"

    @classmethod
    def from_option(cls, argument: str, options: SourceOptions) -> Source:
        """``replay:FILE``."""
        return cls(Path(argument), speed=options.speed, loop=options.loop)

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
        self.rate = self.speed

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


def available_sources() -> dict[str, type[Source]]:
    """Every source the command line offers, by scheme (their modules imported)."""
    for module in SOURCE_MODULES:
        importlib.import_module(module)
    return SOURCES


def source_help() -> str:
    """``virtual | virtual-bed | replay:FILE | ...``, from :data:`SOURCES`."""
    return " | ".join(
        f"{s}:{c.argument}" if c.argument else s for s, c in available_sources().items()
    )


def resolve_spec(spec: str, named_in: str | Path) -> str:
    """``spec`` as named in the file ``named_in`` (a ward file's ``source =``): its path, if
    its source takes one, found by the rule for paths in files (beside ``named_in``) and of
    the kind the source reads (:func:`texsense.io.named.named_path`). Raises
    ``ParameterError`` (the caller names the file and the key)."""
    from texsense.io.named import named_path  # (h5py: with the recordings)

    scheme, _, argument = spec.partition(":")
    cls = available_sources().get(scheme)
    kind = cls.argument_path(argument) if cls is not None and argument else ""
    if not kind:
        return spec
    return f"{scheme}:{named_path(argument, named_in, kind)}"


def open_source(spec: str, options: SourceOptions | None = None) -> Source:
    """The source ``--source`` names (``SCHEME`` or ``SCHEME:ARGUMENT``).

    Raises
    ------
    ParameterError
        For an unknown scheme (naming those known), a missing or unexpected argument, or what
        the source itself refuses.
    """
    scheme, colon, argument = spec.partition(":")
    known = available_sources()
    cls = known.get(scheme)
    if cls is None:
        raise ParameterError(f"unknown source {spec!r}; known: {source_help()}")
    if cls.argument and not argument:
        raise ParameterError(f"--source {scheme} needs {scheme}:{cls.argument}")
    if not cls.argument and colon:
        raise ParameterError(f"--source {scheme} takes nothing after the colon, got {spec!r}")
    return cls.from_option(argument, options or SourceOptions())
