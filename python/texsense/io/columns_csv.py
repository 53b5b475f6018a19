"""Column tables in CSV: a header of names, then one row of numbers per sample.

The virtual sensor writes ``time_s,compression_mm,pressure_ncm2,capacitance_pF``; the
hysteresis and drift tools read any such table and pick columns by name.

Examples
--------
>>> import tempfile, os
>>> path = os.path.join(tempfile.mkdtemp(), "t.csv")
>>> _ = write_columns_csv(path, {"time_s": [0.0, 0.1], "pressure_ncm2": [1.5, 2.0]})
>>> read_columns_csv(path)["pressure_ncm2"].tolist()
[1.5, 2.0]
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

from texsense.exceptions import FormatError, ParameterError
from texsense.io._text import is_number, parse_csv_rows, read_lines

__all__ = ["read_columns_csv", "write_columns_csv"]


def write_columns_csv(path: str | Path, columns: Mapping[str, npt.ArrayLike]) -> Path:
    """Write equal-length columns; floats with the shortest text that reads back exactly."""
    path = Path(path)
    if not columns:
        raise ParameterError("no columns to write")
    names = list(columns)
    for name in names:
        if not name or "," in name:
            raise ParameterError(f"bad column name {name!r}")
    arrays = [np.asarray(columns[n], dtype=np.float64).ravel() for n in names]
    length = arrays[0].size
    if any(a.size != length for a in arrays):
        raise ParameterError("all columns must have the same length")
    lines = [",".join(names)]
    lines += [
        ",".join(repr(v) for v in row) for row in zip(*(a.tolist() for a in arrays), strict=True)
    ]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def read_columns_csv(
    path: str | Path, required: Sequence[str] = ()
) -> dict[str, npt.NDArray[np.float64]]:
    """Read a column table; raise :class:`FormatError` naming the line on any bad row, or
    naming the first of the ``required`` columns that is missing."""
    path = Path(path)
    lines = [ln for ln in read_lines(path)]
    while lines and not lines[-1].strip():
        lines.pop()
    start = 0
    while start < len(lines) and lines[start].startswith("#"):
        start += 1
    if start >= len(lines):
        raise FormatError(path, "empty file: expected a header line of column names")
    names = [s.strip() for s in lines[start].split(",")]
    if any(not n for n in names) or len(set(names)) != len(names):
        raise FormatError(path, "header must name every column once", start + 1)
    if all(is_number(n) for n in names):
        raise FormatError(
            path, "the first line holds numbers: a header of names is expected", start + 1
        )
    what = f"{len(names)} values ({', '.join(names)})"
    for name in required:
        if name not in names:
            raise FormatError(path, f"no column {name!r}; columns are {', '.join(names)}")
    data = parse_csv_rows(path, lines[start + 1 :], start + 2, len(names), what)
    return {n: data[:, i].copy() for i, n in enumerate(names)}
