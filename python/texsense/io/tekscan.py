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
from pathlib import Path

import numpy as np

from texsense import units
from texsense._progress import progress
from texsense.exceptions import FormatError, ParameterError, UnitError
from texsense.io._text import format_float, read_lines
from texsense.layout import Layout
from texsense.recording import Recording

__all__ = ["read_tekscan", "write_tekscan"]

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


def _parse_header(path: Path, lines: list[str]) -> tuple[dict[str, str], dict[str, int], int]:
    header: dict[str, str] = {}
    where: dict[str, int] = {}
    last_key = ""
    for i, raw in enumerate(lines):
        line = raw.strip()
        if line.startswith("ASCII_DATA"):
            return header, where, i + 1
        if not line:
            continue
        m = _KEY.match(line)
        if m and (m.group(2) is not None or line.endswith(":") or last_key != "COMMENTS"):
            last_key = m.group(1)
            header[last_key] = (m.group(2) or "").strip()
            where[last_key] = i + 1
        elif last_key:
            # continuation, e.g. the free text after COMMENTS:
            header[last_key] = (header[last_key] + "\n" + line).strip()
        else:
            raise FormatError(path, f"expected a 'KEY value' header line, found {line!r}", i + 1)
    raise FormatError(path, "no 'ASCII_DATA @@' line: not a Tekscan ASCII export or truncated")


def read_tekscan(path: str | Path) -> Recording:
    """Read a Tekscan ASCII export (``.csv`` or ``.asf``).

    Returns
    -------
    Recording
        Raw counts (``UNITS raw``) or pressure in N/cm² on a ROWS x COLS grid whose 'B' cells
        are empty. Frame times come from each frame line, else from ``SECONDS_PER_FRAME``.

    Raises
    ------
    FormatError
        On a missing key, a frame of the wrong shape, a non-number, a 'B' pattern that
        changes between frames, or a missing ``@@`` end marker; the message names the line.
    """
    path = Path(path)
    lines = read_lines(path)
    header, where, i = _parse_header(path, lines)
    for key in ("ROWS", "COLS"):
        if key not in header:
            raise FormatError(path, f"header lacks {key}")
    try:
        rows, cols = int(header["ROWS"]), int(header["COLS"])
    except ValueError:
        raise FormatError(path, "ROWS and COLS must be integers", where["ROWS"]) from None
    if rows < 1 or cols < 1:
        raise FormatError(path, f"ROWS and COLS must be >= 1, got {rows} x {cols}", where["ROWS"])
    row_cm = _spacing_cm(
        path, where.get("ROW_SPACING", 0), "ROW_SPACING", header.get("ROW_SPACING", "1 cm")
    )
    col_cm = _spacing_cm(
        path, where.get("COL_SPACING", 0), "COL_SPACING", header.get("COL_SPACING", "1 cm")
    )
    spf = 0.0
    if "SECONDS_PER_FRAME" in header:
        try:
            spf = float(header["SECONDS_PER_FRAME"])
        except ValueError:
            raise FormatError(
                path, "SECONDS_PER_FRAME must be a number", where["SECONDS_PER_FRAME"]
            ) from None
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

    frames: list[np.ndarray] = []
    times: list[float] = []
    frame_numbers: list[int] = []
    active: np.ndarray | None = None
    n = len(lines)
    ended = False
    while i < n:
        line = lines[i].strip()
        if not line:
            i += 1
            continue
        if line.startswith("@@"):
            ended = True
            break
        m = _FRAME.match(line)
        if not m:
            raise FormatError(path, f"expected 'Frame <k>' or '@@', found {line[:40]!r}", i + 1)
        number = int(m.group(1))
        fields = [s.strip() for s in (m.group(2) or "").split(",")]
        t = float("nan")
        if fields and fields[0]:
            try:
                t = float(fields[0])
            except ValueError:
                raise FormatError(
                    path, f"frame time must be a number, found {fields[0]!r}", i + 1
                ) from None
        if np.isnan(t):
            t = (number - int(header.get("START_FRAME", "1") or 1)) * spf
        if i + rows >= n:
            raise FormatError(
                path, f"frame {number}: file ends inside the frame (truncated)", i + 1
            )
        block = lines[i + 1 : i + 1 + rows]
        cells = np.empty((rows, cols), dtype=np.float64)
        is_b = np.zeros((rows, cols), dtype=bool)
        for r, text in enumerate(block):
            tokens = [s.strip() for s in text.split(",")]
            if tokens and tokens[-1] == "" and len(tokens) == cols + 1:
                tokens = tokens[:-1]
            if len(tokens) != cols:
                raise FormatError(
                    path,
                    f"frame {number}: expected {cols} comma-separated cells, found {len(tokens)}",
                    i + 2 + r,
                )
            for c, tok in enumerate(tokens):
                if tok == "B":
                    is_b[r, c] = True
                    cells[r, c] = np.nan
                else:
                    try:
                        cells[r, c] = float(tok)
                    except ValueError:
                        raise FormatError(
                            path,
                            f"frame {number}, column {c + 1}: expected a number or 'B', "
                            f"found {tok!r}",
                            i + 2 + r,
                        ) from None
        if active is None:
            active = ~is_b
        elif not np.array_equal(active, ~is_b):
            r, c = np.argwhere(active == is_b)[0]
            raise FormatError(
                path,
                f"frame {number}: the 'B' (no sensel) pattern differs from frame 1 at "
                f"row {r + 1}, column {c + 1}",
                i + 2 + r,
            )
        frames.append(cells[active])
        times.append(t)
        frame_numbers.append(number)
        i += 1 + rows
    if not ended:
        raise FormatError(path, "no closing '@@': the file is truncated", n)
    if active is None:
        raise FormatError(path, "no frames between 'ASCII_DATA @@' and '@@'")
    if not active.any():
        raise FormatError(path, "every cell is 'B': no sensel in the map")
    layout = Layout.grid(rows, cols, pitch_cm=(row_cm, col_cm), active=active)
    values = np.asarray(frames, dtype=np.float64)
    internal = units.INTERNAL_UNIT[quantity]
    if unit != internal:
        values = values * units.factor(unit, internal)
    return Recording(
        values.astype(np.float32),
        np.asarray(times),
        layout,
        quantity=quantity,
        unit=internal,
        labels={"frame_number": np.asarray(frame_numbers, dtype=np.int64)},
        meta={
            "format": "tekscan-ascii",
            "source": str(path),
            "source_unit": unit,
            "header": header,
        },
    )


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
    out: list[str] = []
    for key in order:
        value = header[key]
        if "\n" in value:
            out.append(f"{key}:" if key == "COMMENTS" else key)
            out.extend(value.split("\n"))
        else:
            out.append(f"{key} {value}".rstrip())
    out.append("ASCII_DATA @@")
    out.append("")
    scaled = rec.frames.astype(np.float64) * factor
    cells = rec.layout.cells
    for k in progress(range(rec.n_frames), total=rec.n_frames, desc="writing", unit="frame"):
        out.append(f"Frame {k + 1}, {float(rec.times[k])!r}")
        grid = np.full(rows * cols, "B", dtype=object)
        if factor == 1.0:
            grid[cells] = [format_float(v) for v in rec.frames[k]]
        else:  # float64 text of the scaled value reads back exactly after scaling back
            grid[cells] = [repr(v) if v == v else "nan" for v in scaled[k].tolist()]
        for r in range(rows):
            out.append(",".join(grid[r * cols : (r + 1) * cols]))
        out.append("")
    out.append("@@")
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
    return path
