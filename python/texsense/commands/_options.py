"""Options that several commands share, and the range of every numeric option.

Every numeric option of every command has a declared range in :data:`RANGES` (by the
option's name, or by ``"COMMAND --option"`` where one name means different things in
different commands). :func:`check_numbers` gives each such option a type that refuses, with
argparse's one line and exit 2, a value that is not a finite number or lies outside the
range (``--refuse-after -5``, ``--frames nan``, ``--virtual-mats 1e9``); an option without a
declared range is a programming error, found by the tests (tests/faults/test_families.py).

Examples
--------
>>> RANGES["--reposition-min"].check(3.0, "--reposition-min")
Traceback (most recent call last):
...
ValueError: --reposition-min must lie in 5..120, got 3
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from texsense.data.outside import lone_surrogate
from texsense.exceptions import ParameterError

__all__ = [
    "RANGES",
    "Range",
    "add_accept_truncated",
    "check_numbers",
    "check_words",
    "nonempty",
    "numeric_options",
    "refuse_replacing",
]

ACCEPT_TRUNCATED_HELP = (
    "read a recording that holds less than it declares (an export cut short or closed early, "
    "a last frame cut mid-line, an HDF5 file whose datasets differ in length) up to its last "
    "complete frame, with one warning line saying how much is missing, instead of refusing it"
)


def add_accept_truncated(p: argparse.ArgumentParser) -> None:
    """Add ``--accept-truncated`` (``args.accept_truncated``) to a command that reads
    recordings."""
    p.add_argument("--accept-truncated", action="store_true", help=ACCEPT_TRUNCATED_HELP)


def refuse_replacing(path: Path, replace: bool) -> None:
    """A calibration file is not written over without ``--replace`` (a monitor may be using
    it; the mat's readings would change without a word). Only a calibration *file* is kept
    so: a folder or a device in the way is the writer's one-line error."""
    if path.is_file() and not replace:
        raise ParameterError(
            f"{path} exists: a calibration is not replaced without --replace "
            "(or write it to another name)"
        )


@dataclass(frozen=True)
class Range:
    """Where a numeric option's values may lie: ``lo`` and ``hi`` (None: unbounded), each
    included unless ``lo_open`` / ``hi_open``; ``nonzero`` excludes 0, ``least`` a magnitude
    below it other than 0 (a value divided by: a gain of 1e-300). Every value must also be
    finite."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    nonzero: bool = False
    least: float = 0.0

    def text(self) -> str:
        """The range in words: ``> 0``, ``>= 1``, ``5..120``."""
        if self.lo is not None and self.hi is not None and not (self.lo_open or self.hi_open):
            least = f", of magnitude at least {self.least:g}" if self.least else ""
            return f"{self.lo:g}..{self.hi:g}" + (", not 0" if self.nonzero else "") + least
        parts = []
        if self.lo is not None:
            parts.append(f"{'>' if self.lo_open else '>='} {self.lo:g}")
        if self.hi is not None:
            parts.append(f"{'<' if self.hi_open else '<='} {self.hi:g}")
        if self.nonzero:
            parts.append("not 0")
        return " and ".join(parts) or "finite"

    def holds(self, value: float) -> bool:
        """Whether ``value`` lies in the range (and is finite)."""
        if not math.isfinite(value) or (self.nonzero and value == 0):
            return False
        if value != 0 and abs(value) < self.least:
            return False
        if self.lo is not None and (value <= self.lo if self.lo_open else value < self.lo):
            return False
        return not (self.hi is not None and (value >= self.hi if self.hi_open else value > self.hi))

    def check(self, value: float, name: str) -> float:
        """``value`` if it lies in the range, else a ValueError naming ``name``."""
        if not self.holds(value):
            verb = "be" if self.text()[0] in "<>f" else "lie in"
            raise ValueError(f"{name} must {verb} {self.text()}, got {value:g}")
        return value


_POSITIVE = Range(0.0, lo_open=True)
_COUNT = Range(1, 1_000_000)
_SEED = Range(0, 2**32 - 1)
_PORT = Range(1, 65535)
_MINUTES = Range(0.0, 7 * 24 * 60, lo_open=True)  # up to a week

#: The range of every numeric option: by name, or by "COMMAND --option" (sub-commands
#: included: "hysteresis fit --grid").
RANGES: dict[str, Range] = {
    # recordings, processing, plots
    "--frame": Range(0, 2**62),
    "--chunk-frames": _COUNT,
    "export mcu --capacity": Range(4, 1 << 16),  # Preisach turning points (Pipeline's range)
    "--workers": Range(1, 1024),
    "--every": Range(1, 1_000_000),
    "stocking report --every": Range(0.0, 24 * 365, lo_open=True),
    "--duration": Range(0.0, 3.2e7, lo_open=True),  # s, up to a year
    "--frames": _COUNT,
    "calibrate wizard --frames": Range(3, 100_000),
    # the virtual sensor, the test machine, simulations
    "--seed": _SEED,
    "--mat-seed": _SEED,
    "--sample-hz": Range(0.0, 1e6, lo_open=True),
    "--speed": Range(0.0, 1e6),  # monitor, record, replay: 0 is "as fast as possible"
    "simulate --speed": Range(0.0, 1e6, lo_open=True),  # platen mm/min, or times real time
    "station --speed": Range(0.0, 1e6, lo_open=True),
    "calibrate wizard --speed": Range(0.0, 1e6, lo_open=True),
    "--max": Range(0.0, 1e4, lo_open=True),  # N/cm²
    "--p3": Range(0.0, 1e4, lo_open=True),
    "--cycles": Range(1, 100_000),
    "--hold": Range(0.0, 3.2e7),
    "--sessions": Range(1, 1000),
    "--rounds": Range(1, 1000),
    "--rest-s": Range(0.0, 3.2e7),
    "--minutes": _MINUTES,
    "--hours": Range(0.0, 24 * 365, lo_open=True),
    # design rules
    "--thickness-mm": Range(0.0, 100.0, lo_open=True),
    "--electrode-cm": Range(0.0, 1000.0, lo_open=True),
    "--target-pf": Range(0.0, 1e6, lo_open=True),
    "--rows": Range(1, 4096),
    "--cols": Range(1, 4096),
    "--spacing-mm": Range(0.0, 1e4, lo_open=True),
    "--line-distance-mm": Range(0.0, 1e4, lo_open=True),
    "--update-hz": Range(0.0, 1e6, lo_open=True),
    "--converters": Range(1, 4096),
    # models and their fits
    "--grid": Range(2, 2000),
    "--cells": Range(1, 2000),
    "--smoothing": Range(0.0, 1e12),  # the hysteresis stage's range (data.ranges)
    "--folds": Range(2, 100),
    "--rest-rate": Range(0.0, 1e12, lo_open=True),  # the drift stage's
    "--drift-rest-rate": Range(0.0, 1e12, lo_open=True),
    "--offset": Range(-1e15, 1e15),
    "--gain": Range(-1e15, 1e15, nonzero=True, least=1e-12),  # the linear stage's gain
    "--full-scale": Range(0.0, 1e15, lo_open=True),  # the linear stage's
    "--c": _POSITIVE,
    "--pool": Range(1, 256),
    "--window": Range(0.0, 3.2e7, lo_open=True),
    "--range": _POSITIVE,
    "--interval": Range(0.0, 1.0, lo_open=True, hi_open=True),  # a bound's level (issue 37)
    # devices
    "--sampling-frequency": Range(0.0, 1e7, lo_open=True),
    "--capdac-pf": Range(0.0, 1e4),
    "--wait-s": Range(0.0, 86400.0, lo_open=True),
    # the monitor, the station, alerts
    "--port": _PORT,
    "--threshold": Range(0.0, 1e4, lo_open=True),  # mmHg (monitor, report)
    "muscle detect --threshold": Range(0.0, 1e4, lo_open=True),  # N/cm²
    "--reposition-min": Range(5.0, 120.0),  # texsense.apps.alerts.REPOSITION_RANGE_MIN
    "--offload-min": Range(0.0, 7 * 24 * 60),
    "--turn-every": _MINUTES,
    "--virtual-mats": Range(0, 1000),
    "--refuse-after": Range(0.0, 86400.0, lo_open=True),
    "--stale-after": Range(0.0, 3600.0),  # s: the station's floor before a mat is stale
    "--virtual-beds": Range(0, 500),  # at most every second one of --virtual-mats
    "--checkpoint-every": Range(0.0, 3600.0, lo_open=True),  # a group's checkpoints, s
    "station --workers": Range(1, 64),  # a group member's worker processes
    "simulate --count": Range(1, 1000),  # simulate mats: as many as --virtual-mats
    "simulate --beds": Range(0, 500),
}


def range_of(command: str, option: str) -> Range | None:
    """The declared range of ``option`` in ``command`` (sub-command words included)."""
    return RANGES.get(f"{command} {option}", RANGES.get(option))


def numeric_options(
    parser: argparse.ArgumentParser, command: str = ""
) -> Iterator[tuple[str, argparse.Action]]:
    """(command words, action) of every option of ``parser`` and its sub-commands that takes
    a number (``type=int`` or ``type=float``, checked or not)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from numeric_options(sub, f"{command} {name}".strip())
        elif action.type in (int, float) or isinstance(action.type, _Checked):
            yield command, action


class _Checked:
    """An argparse type: a number of ``kind`` within ``allowed``."""

    def __init__(self, kind: Callable[[str], float], allowed: Range, name: str) -> None:
        self.kind, self.allowed, self.name = kind, allowed, name
        self.__name__ = f"{kind.__name__} ({allowed.text()})"  # argparse's "invalid ... value"

    def __call__(self, text: str) -> float:
        try:
            value = self.kind(text)
        except (ValueError, OverflowError):
            raise argparse.ArgumentTypeError(
                f"expected {'an integer' if self.kind is int else 'a number'}, got {text!r}"
            ) from None
        try:
            return self.allowed.check(value, "the value")
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None


def check_numbers(parser: argparse.ArgumentParser, command: str = "") -> None:
    """Give every numeric option of ``parser`` (and its sub-commands) its declared range.

    Raises
    ------
    LookupError
        An option without a range in :data:`RANGES` (a programming error).
    """
    for cmd, action in numeric_options(parser, command):
        if isinstance(action.type, _Checked):
            continue
        name = action.option_strings[-1] if action.option_strings else action.dest
        allowed = range_of(cmd, name)
        if allowed is None:
            raise LookupError(f"texsense {cmd} {name}: no range declared in RANGES")
        assert action.type is int or action.type is float  # (numeric_options chose it)
        action.type = _Checked(action.type, allowed, name)


def nonempty(text: str) -> str:
    """An argparse type: a word that is not empty (nor only spaces). An empty path reads as
    the current folder (``texsense process ""`` would process the folder it runs in), and an
    empty text as the option left out (``--unit ""``, ``--broker ""``, ``--group ""``,
    ``--orientation ""``): taken and ignored, the user would believe it acted. Nor a NUL
    character, which no name holds, nor bytes that are not UTF-8 text."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty value: give one, or leave the option out")
    if "\0" in text:  # (no file name holds one: os.stat raised ValueError)
        raise argparse.ArgumentTypeError(f"a NUL character in {text!r}")
    if not text.isascii() and lone_surrogate(text) is not None:
        # bytes that are not UTF-8 (Python keeps them as lone surrogates): the name would go
        # into a UTF-8 file, report, figure or page, which cannot hold it (was a traceback)
        shown_text = text.encode("utf-8", "surrogateescape").decode("utf-8", "replace")
        raise argparse.ArgumentTypeError(
            f"{shown_text!r} is not UTF-8 text (rename the file, or give another name)"
        )
    return text


def _path(text: str) -> Path:
    return Path(nonempty(text))


_path.__name__ = "path"  # argparse's "invalid path value"


def check_words(parser: argparse.ArgumentParser) -> None:
    """Give every argument of ``parser`` (and its sub-commands) that takes a path
    (``type=Path``) or a text (no type, no choices) the type that refuses an empty word, with
    argparse's one line and exit 2."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                check_words(sub)
        elif action.type is Path:
            action.type = _path
        elif action.type is None and action.nargs != 0 and not action.choices:
            action.type = nonempty
