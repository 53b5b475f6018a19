"""Tekscan ASCII exports (I-Scan ``.csv``, F-Scan ``.asf``): reader and writer.

The file is a header of ``KEY value`` lines up to ``ASCII_DATA @@``, then frames: a line
``Frame k[, time_s, , date, , , Raw Sum=, , sum]`` followed by ROWS lines of COLS
comma-separated values, where ``B`` marks a cell without a sensel. The data end with ``@@``.

Every header key is kept in ``meta["header"]``. 'B' cells become empty cells of the grid
layout. ``ROW_SPACING``/``COL_SPACING`` may be in mm, cm or inches. ``UNITS raw`` gives raw
counts; a pressure unit (``KPa``, ``PSI``, ``mmHg``, ...) is converted to N/cm².
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from texsense._progress import progress
from texsense.data import units
from texsense.data.files import atomic_open
from texsense.data.layout import Layout
from texsense.data.recording import Recording
from texsense.exceptions import FormatError, ParameterError, UnitError, shown
from texsense.io._base import FrameRow, Header, RecordingReader, check_declared_size
from texsense.io._registry import Probe, writer
from texsense.io._text import Line, TextLines, format_float

__all__ = ["TekscanReader", "write_tekscan"]

_KEY = re.compile(r"^([A-Z][A-Z0-9_]*):?(?:\s+(.*))?$")
_FRAME = re.compile(r"^Frame\s+(\d+)\s*(?:,(.*))?$")
# Units as Tekscan spells them -> texsense units.
_TEKSCAN_UNIT = {"kpa": "kPa", "psi": "psi", "mmhg": "mmHg", "raw": "count", "n/cm2": "N/cm2"}


def _spacing_cm(path: Path, line_no: int, key: str, value: str) -> float:
    parts = value.split()
    try:
        number = float(parts[0])
        unit = parts[1] if len(parts) > 1 else "mm"
        cm = float(units.convert(number, unit, "cm"))
    except (IndexError, ValueError, UnitError) as e:
        raise FormatError(
            path,
            f"{key}: expected '<number> <mm|centimeters|inches>', found {value!r} ({e})",
            line_no,
        ) from None
    if not cm > 0:
        raise FormatError(path, f"{key}: spacing must be positive, found {value!r}", line_no)
    return cm


def _parse_header(path: Path, lines: TextLines) -> tuple[dict[str, str], dict[str, int]]:
    """Header keys up to ``ASCII_DATA @@`` and the line of each."""
    header: dict[str, str] = {}
    where: dict[str, int] = {}
    last_key = ""
    for raw in lines:
        line = raw.text.strip()
        if line.startswith("ASCII_DATA"):
            return header, where
        if not line:
            continue
        m = _KEY.match(line)
        if m and (m.group(2) is not None or line.endswith(":") or last_key != "COMMENTS"):
            last_key = m.group(1)
            header[last_key] = (m.group(2) or "").strip()
            where[last_key] = raw.number
        elif last_key:
            # continuation, e.g. the free text after COMMENTS:
            header[last_key] = (header[last_key] + "\n" + line).strip()
        else:
            raise FormatError(
                path, f"expected a 'KEY value' header line, found {shown(line)}", raw.number
            )
    raise FormatError(path, "no 'ASCII_DATA @@' line: not a Tekscan ASCII export or truncated")


def _header_unit(path: Path, header: dict[str, str], where: dict[str, int]) -> tuple[str, str]:
    """(quantity, unit in the file) from ``UNITS``."""
    unit_text = header.get("UNITS", "raw").strip()
    unit = _TEKSCAN_UNIT.get(unit_text.lower())
    if unit is None:
        try:
            unit = units.canonical(unit_text)
        except UnitError:
            raise FormatError(
                path, f"UNITS: unknown unit {unit_text!r} (never guessed)", where.get("UNITS")
            ) from None
    quantity = units.quantity_of(unit)
    if quantity not in ("pressure", "raw", "force"):
        raise FormatError(
            path, f"UNITS: {unit_text!r} is not a pressure, force or raw unit", where.get("UNITS")
        )
    return quantity, unit


def _header_int(path: Path, header: dict[str, str], where: dict[str, int], key: str) -> int | None:
    if key not in header:
        return None
    try:
        return int(header[key])
    except ValueError:
        raise FormatError(
            path, f"{key} must be an integer, found {header[key]!r}", where[key]
        ) from None


class TekscanReader(RecordingReader):
    """Read a Tekscan ASCII export (``.csv`` or ``.asf``).

    Parameters
    ----------
    path : str or Path
        The export.
    accept_truncated : bool
        Read an export that was cut or closed early up to its last complete frame (with a
        warning) instead of refusing it.

    Returns
    -------
    Recording
        Raw counts (``UNITS raw``) or pressure in N/cm² on a ROWS x COLS grid whose 'B' cells
        are empty. Frame times come from each frame line, else from ``SECONDS_PER_FRAME``.
        Cells that are not a number, infinite or negative are invalid readings.

    Raises
    ------
    FormatError
        On a missing key, a frame of the wrong shape, a non-number, a 'B' pattern that
        changes between frames, times that go back, or a file cut short (no ``@@``, fewer
        frames than ``START_FRAME``/``END_FRAME`` declare); the message names the line.
    """

    format = "tekscan"
    what = "Tekscan ASCII .csv / .asf"
    sniff_order = 10

    @classmethod
    def sniff(cls, probe: Probe) -> bool:
        """A ``DATA_TYPE`` first line, or Tekscan named near the top."""
        return probe.first.startswith("DATA_TYPE") or "Tekscan" in probe.text[:400]

    non_negative = frozenset({"raw"})

    def _read_header(self) -> Header:
        path = self.path
        self._lines = TextLines(path)
        header, where = _parse_header(path, self.lines)
        for key in ("ROWS", "COLS"):
            if key not in header:
                raise FormatError(path, f"header lacks {key}")
        try:
            rows, cols = int(header["ROWS"]), int(header["COLS"])
        except ValueError:
            raise FormatError(path, "ROWS and COLS must be integers", where["ROWS"]) from None
        if rows < 1 or cols < 1:
            raise FormatError(
                path, f"ROWS and COLS must be >= 1, got {rows} x {cols}", where["ROWS"]
            )
        check_declared_size(path, f"ROWS x COLS = {rows} x {cols}", rows * cols, 2, where["ROWS"])
        self.rows, self.cols = rows, cols
        row_cm, col_cm = (
            _spacing_cm(path, where.get(k, 0), k, header.get(k, "1 cm"))
            for k in ("ROW_SPACING", "COL_SPACING")
        )
        self.spf = 0.0
        if "SECONDS_PER_FRAME" in header:
            try:
                self.spf = float(header["SECONDS_PER_FRAME"])
            except ValueError:
                raise FormatError(
                    path, "SECONDS_PER_FRAME must be a number", where["SECONDS_PER_FRAME"]
                ) from None
        quantity, unit = _header_unit(path, header, where)
        start = _header_int(path, header, where, "START_FRAME")
        end = _header_int(path, header, where, "END_FRAME")
        self.start_frame = start if start is not None else 1
        self.end_frame = end
        declared = end - self.start_frame + 1 if end is not None else None
        # the first frame gives the 'B' pattern, hence the layout
        self.ended = False
        first = self._next_frame()
        if first is None:
            if self._shortfall is None:
                raise FormatError(path, "no frames between 'ASCII_DATA @@' and '@@'")
            raise FormatError(path, f"{self._shortfall}, before its first frame was complete")
        self._first, self.active = first, ~first[1]
        if not self.active.any():
            raise FormatError(path, "every cell is 'B': no sensel in the map")
        internal = units.INTERNAL_UNIT[quantity]
        return Header(
            Layout.grid(rows, cols, pitch_cm=(row_cm, col_cm), active=self.active),
            quantity,
            internal,
            {"format": "tekscan-ascii", "source": str(path), "source_unit": unit, "header": header},
            source_unit=unit,
            declared_frames=declared,
            label_dtypes={"frame_number": np.int64},
        )

    def _next_frame(self) -> tuple[np.ndarray, np.ndarray, float, int, int] | None:
        """(cells, 'B' mask, time, frame number, line) of the next frame; None at ``@@``
        (``self.ended``) or at a cut (noted)."""
        line = self.lines.next_nonblank()
        if line is None:
            self._cut("truncated: no closing '@@' after the last complete frame")
            return None
        text = line.text.strip()
        if text.startswith("@@"):
            self.ended = True
            return None
        m = _FRAME.match(text)
        if not m:
            self._bad_line(line, f"expected 'Frame <k>' or '@@', found {shown(text)}")
            return None
        number = int(m.group(1))
        t = _frame_time(self.path, line, m.group(2))
        if np.isnan(t):
            t = (number - self.start_frame) * self.spf
        found = self._cells(number, line.number)
        return None if found is None else (*found, t, number, line.number)

    def _cells(self, number: int, frame_line: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The ROWS x COLS values and 'B' mask of frame ``number`` (None at a cut, noted)."""
        cells = np.empty((self.rows, self.cols), dtype=np.float64)
        is_b = np.zeros((self.rows, self.cols), dtype=bool)
        for r in range(self.rows):
            line = next(self.lines, None)
            if line is None or not line.ended:
                self._cut(f"truncated: the file ends inside frame {number} (line {frame_line})")
                return None
            tokens = [s.strip() for s in line.text.split(",")]
            if tokens and tokens[-1] == "" and len(tokens) == self.cols + 1:
                tokens = tokens[:-1]
            if len(tokens) != self.cols:
                raise FormatError(
                    self.path,
                    f"frame {number}: expected {self.cols} "
                    f"comma-separated cells, found {len(tokens)}",
                    line.number,
                )
            for c, tok in enumerate(tokens):
                if tok == "B":
                    is_b[r, c], cells[r, c] = True, np.nan
                    continue
                try:
                    cells[r, c] = float(tok)
                except ValueError:
                    raise FormatError(
                        self.path,
                        f"frame {number}, column {c + 1}: expected a number or 'B', found {tok!r}",
                        line.number,
                    ) from None
        return cells, is_b

    def _frames(self) -> Iterator[FrameRow]:
        frame: tuple[np.ndarray, np.ndarray, float, int, int] | None = self._first
        first: list[int] = []  # the first two frame numbers: the export's step
        last = 0
        while frame is not None:
            cells, is_b, t, number, line = frame
            if not np.array_equal(is_b, ~self.active):
                r, c = np.argwhere(self.active == is_b)[0]
                raise FormatError(
                    self.path,
                    f"frame {number}: the 'B' (no sensel) pattern differs "
                    f"from frame 1 at row {r + 1}, column {c + 1}",
                    line + 1 + r,
                )
            if self.end_frame is not None and number > self.end_frame:
                raise FormatError(
                    self.path, f"frame {number} is beyond END_FRAME {self.end_frame}", line
                )
            yield FrameRow(cells[self.active], t, line, {"frame_number": number})
            first, last = [*first, number][:2], number
            frame = self._next_frame()
        self._check_end(first, last)

    def _check_end(self, first: list[int], last: int) -> None:
        """After ``@@`` the last frame must be END_FRAME (an export of every k-th frame
        steps by k): a file closed early is a shortfall."""
        end = self.end_frame
        if not self.ended or end is None or not first or last >= end:
            return
        step = max(1, first[1] - first[0]) if len(first) == 2 else 1
        self._cut(
            f"truncated: END_FRAME is {end}, '@@' came after frame {last} "
            f"({(end - last) // step} missing)"
        )


def _frame_time(path: Path, line: Line, rest: str | None) -> float:
    fields = [s.strip() for s in (rest or "").split(",")]
    if fields and fields[0]:
        try:
            return float(fields[0])
        except ValueError:
            raise FormatError(
                path, f"frame time must be a number, found {fields[0]!r}", line.number
            ) from None
    return float("nan")


@writer("tekscan", what="Tekscan ASCII (exact round trip)", suffixes=(".asf",))
def write_tekscan(rec: Recording, path: str | Path, *, unit: str | None = None) -> Path:
    """Write ``rec`` as a Tekscan ASCII export readable by :func:`read_tekscan`.

    Parameters
    ----------
    rec : Recording
        A grid recording of raw counts, pressure or force.
    path : str or Path
        Output file (``.csv`` or ``.asf``).
    unit : str, optional
        Unit to write: ``"kPa"`` (default for pressure), ``"psi"``, ``"mmHg"``, ``"N/cm2"``.

    Notes
    -----
    Written: grid shape, 'B' for empty cells, spacing in cm, frame times (exactly), values
    with the shortest text that reads back to the same float32. Header keys from
    ``rec.meta["header"]`` (a Tekscan file read earlier) are kept. Not written: the validity
    mask, labels and per-element times (Tekscan ASCII has no place for them).
    """
    path = Path(path)
    if rec.layout.shape is None or rec.layout.cells is None:
        raise ParameterError("write_tekscan: needs a grid layout (Tekscan maps are matrices)")
    if rec.quantity not in ("pressure", "raw", "force"):
        raise ParameterError(f"write_tekscan: cannot write {rec.quantity} (pressure, force, raw)")
    if rec.n_frames == 0:
        raise ParameterError(
            "write_tekscan: a Tekscan export cannot hold a recording without frames (its "
            "readers take the grid's empty cells from the first frame)"
        )
    if unit is None:
        unit = {"pressure": "kPa", "raw": "count", "force": "N"}[rec.quantity]
    unit = units.canonical(unit)
    factor = units.factor(rec.unit, unit)
    rows, cols = rec.layout.shape
    if rec.layout.pitch_cm is None:
        raise ParameterError("write_tekscan: the grid layout has no pitch")
    row_cm, col_cm = rec.layout.pitch_cm
    tek_unit = {"kPa": "KPa", "count": "raw", "psi": "PSI"}.get(unit, unit)
    header = {str(k): str(v) for k, v in dict(rec.meta.get("header", {})).items()}
    period = rec.frame_period_s
    header.update(
        {
            "ROWS": str(rows),
            "COLS": str(cols),
            "ROW_SPACING": f"{row_cm!r} centimeters",
            "COL_SPACING": f"{col_cm!r} centimeters",
            "SENSEL_AREA": f"{row_cm * col_cm!r} cm2",
            "SECONDS_PER_FRAME": repr(period if np.isfinite(period) else 0.0),
            "START_FRAME": "1",
            "END_FRAME": str(rec.n_frames),
            "UNITS": tek_unit,
        }
    )
    header.setdefault("DATA_TYPE", "MOVIE")
    order = ["DATA_TYPE"] + [k for k in header if k != "DATA_TYPE"]
    scaled = rec.frames.astype(np.float64) * factor if factor != 1.0 else None
    with atomic_open(path, "w", encoding="utf-8") as out:
        for key in order:
            value = header[key]
            if "\n" in value:
                out.write((f"{key}:" if key == "COMMENTS" else key) + "\n")
                out.write("\n".join(value.split("\n")) + "\n")
            else:
                out.write(f"{key} {value}".rstrip() + "\n")
        out.write("ASCII_DATA @@\n\n")
        for k in progress(range(rec.n_frames), total=rec.n_frames, desc="writing", unit="frame"):
            out.write(_frame_text(rec, k, scaled))
        out.write("@@\n")
    return path


def _frame_text(rec: Recording, k: int, scaled: np.ndarray | None) -> str:
    """Frame ``k`` as Tekscan text: the frame line, ROWS lines of cells, an empty line."""
    rows, cols = rec.layout.shape  # type: ignore[misc]
    grid = np.full(rows * cols, "B", dtype=object)
    if scaled is None:
        grid[rec.layout.cells] = [format_float(v) for v in rec.frames[k]]
    else:  # float64 text of the scaled value reads back exactly after scaling back
        grid[rec.layout.cells] = [repr(v) if v == v else "nan" for v in scaled[k].tolist()]
    lines = [f"Frame {k + 1}, {float(rec.times[k])!r}"]
    lines += [",".join(grid[r * cols : (r + 1) * cols]) for r in range(rows)]
    return "\n".join(lines) + "\n\n"
