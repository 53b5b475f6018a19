"""novel pliance ASCII exports (``.asc``).

The file holds a short header (``file name``, ``mat type``, ``time per frame``, ``pressure
values in <unit>``), a table ``time[secs]`` + one column per sensor number with one frame per
line, the rows ``MPP`` and ``MVP`` (per-sensor peak and mean over the recording, skipped), a
table ``time[secs] force[N] x[cm] y[cm]`` (the vendor's total force and centre of pressure
per time step, ``-`` when unloaded), and the sensor geometry: ``sensor`` numbers, the corner
coordinates ``x[0..3]``/``y[0..3]``, the centres ``x[c]``/``y[c]`` and ``area`` (cm²).

Sensors become a points layout named by their sensor numbers, with the exported centres
(pliance's coordinates, as exported), sizes from the corners and the exported areas. The
vendor's force and centre of pressure at each frame time become the labels
``vendor_force_N``, ``vendor_cop_x_cm`` and ``vendor_cop_y_cm`` (NaN where the export has
``-``).

The layout is at the end of the file, so the header is read in one pass over the whole file
(keeping only the geometry and the vendor's force table, three numbers per time step), and the
frames in a second pass. A file cut anywhere before its geometry table is refused (nothing
can be read without the layout).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from texsense.data import units
from texsense.data.layout import Layout
from texsense.exceptions import FormatError, UnitError
from texsense.io._base import FrameRow, Header, RecordingReader
from texsense.io._registry import Probe
from texsense.io._text import Line, TextLines, parse_float, parse_floats

__all__ = ["PlianceReader"]

_UNIT = re.compile(r"pressure values in\s+(\S+)", re.IGNORECASE)
_PERIOD = re.compile(r"time per frame \[secs\]:\s*([0-9.eE+-]+)")
_GEOMETRY = ("x[c]", "y[c]", "area", "x[0]", "y[0]", "x[2]", "y[2]")


def _find(lines: TextLines, predicate: Any, what: str, path: Path) -> Line:
    for line in lines:
        if predicate(line.text):
            return line
    raise FormatError(path, f"{what} not found (truncated or not a pliance export?)")


def _first_token_is_time(text: str) -> bool | None:
    """True for a frame row, None for a blank line, False for anything else."""
    tokens = text.split(None, 1)
    if not tokens:
        return None
    try:
        float(tokens[0])
    except ValueError:
        return False
    return True


class PlianceReader(RecordingReader):
    """Read a novel pliance ASCII export.

    Parameters
    ----------
    path : str or Path
        The export.
    accept_truncated : bool
        Accepted for a uniform interface; a pliance export cut short has lost its geometry
        table and cannot be read.

    Returns
    -------
    Recording
        Pressure in N/cm² on a points layout (one element per pliance sensor); values that
        are not a number, infinite or negative are invalid readings.
    """

    format = "pliance"
    what = "novel pliance .asc"
    sniff_order = 30

    @classmethod
    def sniff(cls, probe: Probe) -> bool:
        """A ``file name:`` first line and a ``mat type`` near the top."""
        return probe.first.startswith("file name:") and "mat type" in probe.text[:300]

    def _read_header(self) -> Header:
        path = self.path
        with TextLines(path) as lines:
            head: list[str] = []

            def is_table(s: str) -> bool:
                head.append(s)
                return s.strip().startswith("time[secs]") and "force" not in s

            table = _find(
                lines,
                is_table,
                "the 'time[secs] <sensor numbers>' table header",
                path,
            )
            unit = _unit(path, "\n".join(head[:10]))
            self.sensors = table.text.split()[1:]
            if not self.sensors:
                raise FormatError(path, "the frame table names no sensors", table.number)
            self._first_row = table.number
            for line in lines:  # the frame rows, read again by _frames
                if _first_token_is_time(line.text) is False:
                    break
            _find(lines, lambda s: "force[N]" in s, "the 'time[secs] force[N]' table", path)
            self._vendor, sensor_row = self._force_table(lines)
            if sensor_row is None:
                sensor_row = _find(
                    lines,
                    lambda s: s.split()[:1] == ["sensor"],
                    "the 'sensor' geometry table",
                    path,
                )
            layout = self._geometry(lines, sensor_row)
        meta: dict[str, Any] = {
            "format": "pliance-asc",
            "source": str(path),
            "source_unit": unit,
            "header_lines": [s for s in head[:-1] if s.strip()],
        }
        period = _PERIOD.search("\n".join(head[:10]))
        if period:
            meta["time_per_frame_s"] = float(period.group(1))
        return Header(
            layout,
            "pressure",
            "N/cm2",
            meta,
            source_unit=unit,
            label_dtypes=dict.fromkeys(
                ("vendor_force_N", "vendor_cop_x_cm", "vendor_cop_y_cm"), np.float64
            ),
        )

    def _force_table(self, lines: TextLines) -> tuple[dict[float, tuple[float, ...]], Line | None]:
        """The vendor's force and centre of pressure per time step, and the 'sensor' row if
        it ended the table."""
        vendor: dict[float, tuple[float, ...]] = {}
        for line in lines:
            tokens = line.text.split()
            if not tokens:
                continue
            if tokens[0] == "sensor":
                return vendor, line
            if len(tokens) != 4:
                return vendor, None
            t = parse_float(self.path, line.number, tokens[0], "time")
            vendor[round(t, 4)] = tuple(
                float("nan")
                if tok == "-"
                else parse_float(self.path, line.number, tok, "force table")
                for tok in tokens[1:]
            )
        return vendor, None

    def _geometry(self, lines: TextLines, sensor_row: Line) -> Layout:
        path, n = self.path, len(self.sensors)
        if sensor_row.text.split()[1:] != self.sensors:
            raise FormatError(
                path,
                "the geometry table lists other sensors than the frame table",
                sensor_row.number,
            )
        rows: dict[str, tuple[int, np.ndarray]] = {}
        for line in lines:
            tokens = line.text.split()
            if len(tokens) == n + 1:
                rows[tokens[0]] = (
                    line.number,
                    parse_floats(path, line.number, tokens[1:], n, tokens[0]),
                )
        for needed in _GEOMETRY:
            if needed not in rows:
                raise FormatError(path, f"geometry row {needed!r} is missing")
        xy = np.column_stack([rows["x[c]"][1], rows["y[c]"][1]])
        corners_x = np.array([rows[f"x[{c}]"][1] for c in range(4) if f"x[{c}]" in rows])
        corners_y = np.array([rows[f"y[{c}]"][1] for c in range(4) if f"y[{c}]" in rows])
        size = np.column_stack([np.ptp(corners_x, axis=0), np.ptp(corners_y, axis=0)])
        area = rows["area"][1]
        if not (np.all(area > 0) and np.all(size > 0)):
            raise FormatError(
                path, "sensor areas and corner extents must be positive", rows["area"][0]
            )
        return Layout.points(xy, size_cm=size, area_cm2=area, names=self.sensors)

    def _frames(self) -> Iterator[FrameRow]:
        n = len(self.sensors)
        missing = (np.nan, np.nan, np.nan)
        count = 0
        with TextLines(self.path, skip=self._first_row) as lines:
            for line in lines:
                kind = _first_token_is_time(line.text)
                if kind is None:
                    continue
                if kind is False:
                    break  # MPP / MVP rows end the frame table
                tokens = line.text.split()
                t = float(tokens[0])
                values = parse_floats(
                    self.path, line.number, tokens[1:], n, "a frame (one value per sensor)"
                )
                f, x, y = self._vendor.get(round(t, 4), missing)
                labels = {"vendor_force_N": f, "vendor_cop_x_cm": x, "vendor_cop_y_cm": y}
                yield FrameRow(values, t, line.number, labels)
                count += 1
        if not count:
            raise FormatError(self.path, "the frame table holds no frames", self._first_row + 1)


def _unit(path: Path, head: str) -> str:
    m = _UNIT.search(head)
    if not m:
        raise FormatError(path, "no 'pressure values in <unit>' line in the header")
    try:
        unit = units.canonical(m.group(1))
    except UnitError:
        raise FormatError(path, f"unknown pressure unit {m.group(1)!r} (never guessed)") from None
    if units.quantity_of(unit) != "pressure":
        raise FormatError(path, f"'pressure values in {m.group(1)}' is not a pressure unit")
    return unit
