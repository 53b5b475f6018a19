"""XSENSOR CSV exports (frame blocks).

Layout of the file: a header (``File:``, ``Units:``, ``Threshold:``), then per frame a block
``FRAME,<k>``, ``Date,<yyyy Mon dd>``, ``Time,<hh:mm:ss.fff>``, one ``SENSOR,<name>`` block per
sensor (``Rows``, ``Columns``, ``Sensel Width (cm)``, ``Sensel Height (cm)``, statistics,
``SENSELS`` and Rows lines of Columns values) and optional ``GROUP`` blocks (region
statistics). Lines of commas only are separators.

Several sensors (for example a left and a right insole) become one grid layout, side by side
with two empty columns between them, and one named region per sensor. The vendor's per-frame
statistics ``Est. Load (N)``, ``Contact Area (cm²)``, ``Peak Pressure`` and
``Average Pressure`` are kept as labels ``vendor_load_N_s<i>``, ``vendor_contact_area_cm2_s<i>``,
``vendor_peak_ncm2_s<i>`` and ``vendor_mean_ncm2_s<i>`` (i = sensor number from 1), useful
to cross-check :mod:`texsense.apps.stats`. GROUP blocks are skipped (their cell membership is not
exported), but their ``Cells`` count is checked against their ``SENSELS`` values.

The export says nothing of its length, but every frame repeats the first frame's blocks: a
frame cut short at the end of the file (the file cut in half, a last line without its line
end) is refused or, with ``accept_truncated``, left out and reported.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from texsense.data import units
from texsense.data.layout import Layout
from texsense.exceptions import FormatError, UnitError, shown
from texsense.io._base import FrameRow, Header, RecordingReader, check_declared_size
from texsense.io._registry import Probe
from texsense.io._text import Line, TextLines, is_number, parse_float

__all__ = ["XSensorReader"]

_GAP = 2  # empty columns between two sensors in the combined grid
# statistic -> (label prefix, is a pressure in the file's unit)
_VENDOR_STATS = {
    "Est. Load (N)": ("vendor_load_N", False),
    "Contact Area (cm²)": ("vendor_contact_area_cm2", False),
    "Peak Pressure": ("vendor_peak_ncm2", True),
    "Average Pressure": ("vendor_mean_ncm2", True),
}


def _fields(line: str) -> list[str]:
    text = line.rstrip(" \t,")
    if not text:
        return []
    parts = [p.strip() for p in text.split(",")]
    while parts and parts[-1] == "":
        parts.pop()
    return parts


@dataclass
class _Block:
    """A SENSOR or GROUP block of one frame."""

    kind: str
    name: str
    rows: int = 0
    cols: int = 0
    width_cm: float = 0.0
    height_cm: float = 0.0
    cells: int | None = None  # GROUP: how many values its SENSELS hold
    stats: dict[str, float] = field(default_factory=dict)
    values: np.ndarray | None = None
    complete: bool = False

    def signature(self) -> tuple[object, ...]:
        return (self.kind, self.name, self.rows, self.cols, self.width_cm, self.height_cm)


@dataclass
class _Frame:
    number: int
    line: int
    date: str = ""
    stamp: datetime | None = None
    blocks: list[_Block] = field(default_factory=list)

    def sensors(self) -> list[_Block]:
        return [b for b in self.blocks if b.kind == "SENSOR"]

    @property
    def when(self) -> datetime:
        """The time stamp (every frame that passes ``XSensorReader._complete`` has one)."""
        if self.stamp is None:
            raise RuntimeError(f"frame {self.number} has no Time line")
        return self.stamp


class XSensorReader(RecordingReader):
    """Read an XSENSOR CSV export.

    Parameters
    ----------
    path : str or Path
        The export.
    accept_truncated : bool
        Read an export whose last frame was cut short without it (with a warning) instead
        of refusing it.

    Returns
    -------
    Recording
        Pressure in N/cm² (converted from the file's ``Units:``), frames timed from each
        frame's ``Time`` field relative to the first frame. Values that are not a number,
        infinite or negative are invalid readings.
    """

    format = "xsensor"
    what = "XSENSOR CSV export"
    sniff_order = 20

    @classmethod
    def sniff(cls, probe: Probe) -> bool:
        """A ``File:`` first line and ``FRAME`` blocks."""
        return probe.first.startswith("File:") and "FRAME" in probe.text

    def _read_header(self) -> Header:
        path = self.path
        self._lines = TextLines(path)
        unit = None
        for line in self.lines:
            f = _fields(line.text)
            if f and f[0] == "FRAME":
                self.lines.push(line)
                break
            if f and f[0] == "Units:":
                value = f[1] if len(f) > 1 else ""
                try:
                    unit = units.canonical(value)
                except UnitError:
                    raise FormatError(
                        path, f"Units: unknown unit {value!r} (never guessed)", line.number
                    ) from None
        if unit is None:
            raise FormatError(path, "no 'Units:' line: not an XSENSOR CSV export?")
        first = self._next_frame()
        if first is None:
            raise FormatError(path, self._shortfall or "no FRAME blocks found")
        self._first = first
        sensors = first.sensors()
        if not sensors:
            raise FormatError(path, f"frame {first.number} has no SENSOR block", first.line)
        self._t0 = first.when
        layout, self._members = _layout(path, sensors)
        self._signature = [b.signature() for b in first.blocks]
        to_ncm2 = units.factor(unit, "N/cm2")
        self._stats = [
            (si, stat, f"{label}_s{si + 1}", to_ncm2 if is_pressure else 1.0)
            for si, s in enumerate(sensors)
            for stat, (label, is_pressure) in _VENDOR_STATS.items()
            if stat in s.stats
        ]
        dtypes = {"frame_number": np.int64, **{name: np.float64 for _, _, name, _ in self._stats}}
        return Header(
            layout,
            "pressure",
            "N/cm2",
            {
                "format": "xsensor-csv",
                "source": str(path),
                "source_unit": unit,
                "sensors": [s.name for s in sensors],
                "start_time": first.when.isoformat(),
            },
            source_unit=unit,
            label_dtypes=dtypes,
        )

    def _next_frame(self) -> _Frame | None:
        """The next frame, complete; None at the end of the file or at a cut (noted)."""
        start = self.lines.next_nonblank(",")
        if start is None:
            return None
        f = _fields(start.text)
        if f[0] != "FRAME":
            raise FormatError(
                self.path, f"expected 'FRAME,<number>', found {shown(start.text)}", start.number
            )
        try:
            frame = _Frame(int(f[1] if len(f) > 1 else ""), start.number)
        except ValueError:
            raise FormatError(
                self.path,
                f"FRAME: expected a frame number, found {(f[1:] or [''])[0]!r}",
                start.number,
            ) from None
        block: _Block | None = None
        while True:
            line = self.lines.peek()
            if line is None or (
                line.text.lstrip().startswith("FRAME") and _fields(line.text)[:1] == ["FRAME"]
            ):
                break
            next(self.lines)
            if not line.ended:
                self._cut(
                    f"truncated: the file ends in the middle of line {line.number}, inside "
                    f"frame {frame.number}"
                )
                return None
            block = self._line(frame, block, line)
        return self._complete(frame, at_end=line is None)

    def _line(self, frame: _Frame, block: _Block | None, line: Line) -> _Block | None:
        """Take one line of a frame; returns the block now open."""
        f = _fields(line.text)
        if not f:
            return block
        key, value = f[0], (f[1] if len(f) > 1 else "")
        if key == "Date":
            frame.date = value
        elif key == "Time":
            frame.stamp = _stamp(self.path, line, frame.date, value)
        elif key in ("SENSOR", "GROUP"):
            block = _Block(key, value)
            frame.blocks.append(block)
        elif block is None:
            pass
        elif key in ("Rows", "Columns", "Cells"):
            try:
                count = int(value)
            except ValueError:
                raise FormatError(
                    self.path, f"{key}: expected an integer, found {value!r}", line.number
                ) from None
            check_declared_size(self.path, f"{key},{count}", count, 2, line.number)
            setattr(block, {"Rows": "rows", "Columns": "cols", "Cells": "cells"}[key], count)
        elif key.startswith("Sensel Width"):
            block.width_cm = parse_float(self.path, line.number, value, "Sensel Width (cm)")
        elif key.startswith("Sensel Height"):
            block.height_cm = parse_float(self.path, line.number, value, "Sensel Height (cm)")
        elif key == "SENSELS":
            self._sensels(block, line)
        elif block.kind == "SENSOR":
            for prefix in _VENDOR_STATS:
                if key.startswith(prefix) and value:
                    block.stats[prefix] = parse_float(self.path, line.number, value, key)
        return block

    def _sensels(self, block: _Block, at: Line) -> None:
        """The SENSELS values of a block: Rows x Columns for a sensor, Cells for a group."""
        if block.kind == "GROUP":
            want = block.cells
        elif block.rows < 1 or block.cols < 1:
            raise FormatError(
                self.path, f"SENSELS of {block.name!r} before its Rows/Columns", at.number
            )
        else:
            want = block.rows * block.cols
        if want is None:
            return  # a group without a Cells count: its values are skipped like other lines
        check_declared_size(self.path, f"{block.kind} {block.name!r}", want, 2, at.number)
        values: list[float] = []
        while len(values) < want:
            line = self.lines.peek()
            if line is None or not line.ended:
                return  # cut: the block stays incomplete
            row = _fields(line.text)
            if row and not is_number(row[0]):
                return  # the next key: fewer values than declared (checked by the frame)
            next(self.lines)
            if not row:
                continue
            if block.kind == "SENSOR" and len(row) != block.cols:
                raise FormatError(
                    self.path,
                    f"sensor {block.name!r}: expected {block.cols} "
                    f"values per SENSELS row, found {len(row)}",
                    line.number,
                )
            r = len(values) // max(block.cols, 1) + 1
            values += [parse_float(self.path, line.number, tok, f"SENSELS row {r}") for tok in row]
        block.values = (
            np.asarray(values[:want]).reshape(block.rows, block.cols)
            if block.kind == "SENSOR"
            else None
        )
        block.complete = len(values) == want

    def _complete(self, frame: _Frame, at_end: bool) -> _Frame | None:
        """Check a frame against the first; a shortfall in the last frame is a cut."""
        problem = ""
        if frame.stamp is None:
            problem = "has no Time line"
        elif (
            hasattr(self, "_signature") and [b.signature() for b in frame.blocks] != self._signature
        ):
            problem = "has other SENSOR/GROUP blocks than the first frame"
        else:
            short = [b for b in frame.blocks if not b.complete and (b.kind == "SENSOR" or b.cells)]
            if short:
                problem = f"has too few SENSELS values in {short[0].kind} {short[0].name!r}"
        if not problem:
            return frame
        if at_end:
            self._cut(f"truncated: the last frame ({frame.number}, line {frame.line}) {problem}")
            return None
        raise FormatError(self.path, f"frame {frame.number} {problem}", frame.line)

    def _frames(self) -> Iterator[FrameRow]:
        frame: _Frame | None = self._first
        n = self.header.layout.n_elements
        while frame is not None:
            values = np.empty(n)
            for s, members in zip(frame.sensors(), self._members, strict=True):
                values[members] = s.values.ravel()  # type: ignore[union-attr]
            sensors = frame.sensors()
            labels: dict[str, float] = {"frame_number": frame.number}
            for si, stat, name, scale in self._stats:
                labels[name] = sensors[si].stats.get(stat, np.nan) * scale
            t = (frame.when - self._t0).total_seconds()
            yield FrameRow(values, t, frame.line, labels)
            frame = self._next_frame()


def _stamp(path: Path, line: Line, date_text: str, value: str) -> datetime:
    try:
        return datetime.strptime(f"{date_text} {value}", "%Y %b %d %H:%M:%S.%f")
    except ValueError:
        raise FormatError(
            path,
            f"expected 'Date,yyyy Mon dd' and 'Time,hh:mm:ss.fff', found {date_text!r} {value!r}",
            line.number,
        ) from None


def _layout(path: Path, sensors: list[_Block]) -> tuple[Layout, list[np.ndarray]]:
    """One grid for all sensors, side by side with _GAP empty columns, a region each."""
    sizes = {(s.width_cm, s.height_cm) for s in sensors}
    if len(sizes) != 1:
        raise FormatError(path, "sensors with different sensel sizes are not supported")
    width_cm, height_cm = sizes.pop()
    rows = max(s.rows for s in sensors)
    cols = sum(s.cols for s in sensors) + _GAP * (len(sensors) - 1)
    active = np.zeros((rows, cols), dtype=bool)
    offsets = []
    c0 = 0
    for s in sensors:
        active[: s.rows, c0 : c0 + s.cols] = True
        offsets.append(c0)
        c0 += s.cols + _GAP
    layout = Layout.grid(rows, cols, pitch_cm=(height_cm, width_cm), active=active, neighbour_gap=0)
    cell_to_element = np.full(rows * cols, -1)
    cell_to_element[layout.cells] = np.arange(layout.n_elements)
    regions: dict[str, np.ndarray] = {}
    for s, off in zip(sensors, offsets, strict=True):
        cells = (np.arange(s.rows)[:, None] * cols + off + np.arange(s.cols)[None, :]).ravel()
        regions[s.name] = cell_to_element[cells]
    return layout.with_regions(regions), [regions[s.name] for s in sensors]
