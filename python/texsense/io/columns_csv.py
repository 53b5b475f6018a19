"""Column tables in CSV: a header of names, then one row of numbers per sample.

The virtual sensor writes ``time_s,compression_mm,pressure_ncm2,capacitance_pF``; the
hysteresis and drift tools read any such table and pick columns by name. texsense writes a
first line ``# rows: N``, so a table cut at a line end is noticed; a last row cut mid-line is
noticed in any table. A table has no validity mask: numbers that are not finite are read as
they are and counted in one warning line; finite values beyond any sensor (beyond their
quantity's ceiling, :data:`texsense.io._base.CEILING`, as every recording reader marks them
impossible) are read as not a number and counted in another (:meth:`ColumnsReader._values`,
which every row passes, read in a block or on its own line).

Examples
--------
>>> import tempfile, os
>>> path = os.path.join(tempfile.mkdtemp(), "t.csv")
>>> _ = write_columns_csv(path, {"time_s": [0.0, 0.1], "pressure_ncm2": [1.5, 2.0]})
>>> read_columns_csv(path)["pressure_ncm2"].tolist()
[1.5, 2.0]
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

from texsense._progress import logger
from texsense.data import units
from texsense.data.files import atomic_open
from texsense.data.layout import Layout
from texsense.data.recording import QUANTITIES
from texsense.data.times import TimeCheck
from texsense.exceptions import FormatError, ParameterError, UnitError
from texsense.io._base import CEILING, CEILING_OTHER, BlockReader, Header, Piece, RecordingReader
from texsense.io._registry import Probe
from texsense.io._text import (
    UTF16_BOMS,
    Line,
    TextLines,
    decode_head,
    is_number,
    open_binary,
    parse_csv_row,
)

__all__ = [
    "ColumnsReader",
    "TableReader",
    "ceiling_of_column",
    "column_name",
    "is_columns_csv",
    "read_columns_csv",
    "unit_of_column",
    "write_columns_csv",
]


#: Column-name suffix of each unit (``compression_mm``, ``pressure_ncm2``, ``capacitance_pF``).
SUFFIXES: dict[str, str] = {
    "mm": "mm",
    "N/cm2": "ncm2",
    "kPa": "kpa",
    "N": "n",
    "pF": "pF",
    "s": "s",
    "mmHg": "mmhg",
}


def column_name(quantity: str, unit: str) -> str:
    """The column of a recording's values: ``capacitance`` in ``pF`` -> ``capacitance_pF``."""
    suffix = SUFFIXES.get(unit, "".join(c for c in unit if c.isalnum()).lower())
    return f"{quantity}_{suffix}" if suffix else quantity


def unit_of_column(name: str) -> str | None:
    """The unit a column's suffix names (``pressure_ncm2`` -> ``N/cm2``), or None."""
    low = name.lower()
    for unit, suffix in SUFFIXES.items():
        if low.endswith("_" + suffix.lower()):
            return unit
    return None


def _header(path: Path) -> tuple[list[str], list[str]]:
    """The ``#`` lines and the names of the first other line of a text file."""
    with open_binary(path) as fh:
        head = fh.read(1 << 14)
    if b"\0" in head and not head.startswith(UTF16_BOMS):
        return [], []  # binary (UTF-16 text has NUL bytes too, after its byte-order mark)
    comments, names = [], []
    for line in decode_head(head).splitlines():
        if line.startswith("#"):
            comments.append(line)
        elif line.strip():
            names = [s.strip() for s in line.split(",")]
            break
    return comments, names


def is_columns_csv(path: str | Path, names: Sequence[str] = ()) -> bool:
    """Whether ``path`` is a column table rather than a recording: texsense's ``# rows:``
    line; a header that holds every column the caller ``names`` (``--input field_oe
    --output moment_emu``: whoever names columns reads a table, whatever else the header
    holds); or a header of names that does not start with ``time_s`` followed by element
    columns (a wide CSV), or whose every other column names a unit (``force_n``). A file
    that says it is a texsense wide CSV is one."""
    path = Path(path)
    if not path.is_file():
        return False
    comments, header = _header(path)
    if any(c.startswith("# rows:") for c in comments):
        return True
    if any(c.startswith("# texsense wide-csv") for c in comments) or len(header) < 2:
        return False
    if any(is_number(n) for n in header):
        return False  # numbers, not names: a PMD or other data line
    if names and all(n in header for n in names):
        return True
    if header[0] != "time_s":
        return True
    return all(unit_of_column(n) is not None for n in header[1:])


def write_columns_csv(path: str | Path, columns: Mapping[str, npt.ArrayLike]) -> Path:
    """Write equal-length columns; floats with the shortest text that reads back exactly.

    The first line declares the row count (``# rows: N``); the file is written to a temporary
    name and renamed (:mod:`texsense.data.files`).
    """
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
    with atomic_open(path, "w", encoding="utf-8") as out:
        out.write(f"# rows: {length}\n" + ",".join(names) + "\n")
        for start in range(0, length, _WRITE_ROWS):  # each column's texts made at once
            texts = [list(map(repr, a[start : start + _WRITE_ROWS].tolist())) for a in arrays]
            out.write("".join(",".join(row) + "\n" for row in zip(*texts, strict=True)))
    return path


#: Rows made into text at a time by :func:`write_columns_csv` (bounded memory, few calls).
_WRITE_ROWS = 16384


class ColumnsReader(BlockReader):
    """A column table read a block of rows at a time.

    Parameters
    ----------
    path : str or Path
        The table.
    required : sequence of str
        Columns that must be there (the first missing one is named in the error).
    accept_truncated : bool
        Read a table cut short (fewer rows than ``# rows:`` declares, a last row cut mid-line)
        up to its last complete row, with a warning.
    """

    format = "columns-csv"

    def __init__(
        self, path: str | Path, required: Sequence[str] = (), *, accept_truncated: bool = False
    ) -> None:
        super().__init__(path, accept_truncated=accept_truncated)
        self._lines = TextLines(self.path)
        try:
            self.names, self.declared_rows = self._read_header(required)
        except BaseException:
            self.close()
            raise
        self.rows_read = 0
        self.not_finite = 0
        self.beyond = 0  # finite values beyond any sensor, read as not a number
        self._ceilings = np.array([ceiling_of_column(name) for name in self.names])
        # the time column is checked as every recording's times are (texsense.data.times)
        self._time_column = self.names.index("time_s") if "time_s" in self.names else None
        self._times = TimeCheck(self.path)
        n = len(self.names)
        self._what = f"{n} values ({', '.join(self.names)})"  # what a row holds, for errors

    def _read_header(self, required: Sequence[str]) -> tuple[list[str], int | None]:
        path, declared = self.path, None
        while (line := self.lines.peek()) is not None and line.text.startswith("#"):
            next(self.lines)
            key, _, value = line.text[1:].partition(":")
            if key.strip() == "rows":
                try:
                    declared = int(value)
                except ValueError:
                    raise FormatError(
                        path, f"rows: expected a count, found {value.strip()!r}", line.number
                    ) from None
        head = self.lines.next_nonblank()
        if head is None:
            raise FormatError(path, "empty file: expected a header line of column names")
        names = [s.strip() for s in head.text.split(",")]
        if any(not n for n in names) or len(set(names)) != len(names):
            raise FormatError(path, "header must name every column once", head.number)
        if all(is_number(n) for n in names):
            raise FormatError(
                path, "the first line holds numbers: a header of names is expected", head.number
            )
        for name in required:
            if name not in names:
                raise FormatError(path, f"no column {name!r}; columns are {', '.join(names)}")
        return names, declared

    def _row_blocks(self, rows: int) -> Iterator[npt.NDArray[np.float64]]:
        """The table's rows as (k, columns) arrays of ``rows`` rows, the last one of fewer."""
        held: list[Line] = []
        lines = self.lines.data_lines("the table")
        while True:
            try:
                line = next(lines)
            except StopIteration:
                break
            except FormatError:  # an empty line inside: a bad line before it is named first
                if held:
                    self._parse(held)
                raise
            if not line.ended:  # only the last line: cut or whole, decided on its own
                done = self._parse(held) if held else np.empty((0, len(self.names)))
                last = self._last_row(line)
                if last is not None:
                    done = np.vstack([done, last])
                if len(done):
                    yield done
                return
            held.append(line)
            if len(held) == rows:
                yield self._parse(held)
                held = []
        if held:
            yield self._parse(held)

    def _parse(self, lines: list[Line]) -> npt.NDArray[np.float64]:
        """Complete lines as one array: every line's commas counted, then every number read by
        ``float`` at once (the same tokens and the same ``float`` as :func:`parse_csv_row`);
        anything amiss is found again line by line, for the error that names its line."""
        n = len(self.names)
        texts = [line.text for line in lines]
        if all(t.count(",") == n - 1 for t in texts):
            try:
                values = list(map(float, ",".join(texts).split(",")))
            except ValueError:
                pass
            else:
                data = np.array(values, dtype=np.float64).reshape(len(lines), n)
                return self._values(data, [line.number for line in lines])
        for line in lines:
            parse_csv_row(self.path, line, n, self._what)  # raises for the first bad line
        raise AssertionError("unreachable: a block that failed parses line by line")

    def _last_row(self, line: Line) -> npt.NDArray[np.float64] | None:
        """A last line without its line end: the table's last row (a (1, columns) array), or
        its cut-off part."""
        if self.declared_rows is not None:
            self._cut(f"truncated: the file ends in the middle of line {line.number}")
            return None
        try:
            row = parse_csv_row(self.path, line, len(self.names), self._what)
        except FormatError:
            self._cut(f"truncated: the file ends in the middle of line {line.number}")
            return None
        return self._values(np.array([row], dtype=np.float64), [line.number])

    def blocks(self, rows: int = 65536) -> Iterator[dict[str, npt.NDArray[np.float64]]]:
        """Yield the table as {column: array} blocks of ``rows`` rows (the last one after the
        table's end was checked: a table cut short raises before it, unless accepted)."""
        tail = None  # a last block of fewer rows waits for the table's end to be checked
        for data in self._row_blocks(rows):
            if len(data) < rows:
                tail = data
            else:
                yield self._block(data)
        count = 0 if tail is None else len(tail)
        declared, total = self.declared_rows, self.rows_read + count
        if declared is not None and self._shortfall is None and total < declared:
            self._cut(
                f"truncated: '# rows: {declared}' but the file holds "
                f"{total} ({declared - total} missing)"
            )
        self._finish_cut(total, "row")
        self._times.finish()
        if tail is not None:
            yield self._block(tail)
        if self.not_finite:
            logger.warning(
                "warning: %s: %d value(s) are not finite numbers", self.path, self.not_finite
            )
        if self.beyond:
            logger.warning(
                "warning: %s: %d value(s) beyond any sensor, read as not a number",
                self.path,
                self.beyond,
            )

    def _values(self, data: npt.NDArray[np.float64], lines: list[int]) -> npt.NDArray[np.float64]:
        """Rows as read (a block at once, or a line on its own; ``lines``: their line
        numbers): the one place where values that are not finite are counted and finite values
        beyond their column's ceiling (:func:`ceiling_of_column`) are counted and read as not a
        number, in place, and where the ``time_s`` column is checked as every recording's
        times are (:class:`~texsense.data.times.TimeCheck`: a number, not going back, on a
        clock's scale; one :class:`FormatError` naming the line and the time)."""
        if self._time_column is not None:
            self._times.block(data[:, self._time_column], np.asarray(lines, dtype=np.int64))
        self.not_finite += int(np.count_nonzero(~np.isfinite(data)))
        with np.errstate(invalid="ignore"):  # NaN and inf stay as they are (counted above)
            beyond = np.isfinite(data) & (np.abs(data) > self._ceilings)
        if beyond.any():
            self.beyond += int(np.count_nonzero(beyond))
            data[beyond] = np.nan
        return data

    def _block(self, data: npt.NDArray[np.float64]) -> dict[str, npt.NDArray[np.float64]]:
        self.rows_read += len(data)
        return {n: data[:, i].copy() for i, n in enumerate(self.names)}

    def read(self) -> dict[str, npt.NDArray[np.float64]]:
        """The whole table as {column: array}."""
        parts = list(self.blocks())
        if not parts:
            return {n: np.zeros(0) for n in self.names}
        return {n: np.concatenate([p[n] for p in parts]) for n in self.names}


def read_columns_csv(
    path: str | Path, required: Sequence[str] = (), *, accept_truncated: bool = False
) -> dict[str, npt.NDArray[np.float64]]:
    """Read a column table; raise :class:`FormatError` naming the line on any bad row, or
    naming the first of the ``required`` columns that is missing, or (unless
    ``accept_truncated``) a table cut short."""
    with ColumnsReader(path, required, accept_truncated=accept_truncated) as reader:
        return reader.read()


def ceiling_of_column(name: str) -> float:
    """The greatest magnitude a column's values can have: :data:`texsense.io._base.CEILING`
    of the quantity its unit names (``pressure_ncm2``: 1e5 N/cm²), the ceiling of every other
    quantity for a column without one (``c0``, ``field_oe``), none for a time column
    (``time_s``: its times are checked by :class:`~texsense.data.times.TimeCheck`).

    >>> ceiling_of_column("pressure_ncm2"), ceiling_of_column("c0"), ceiling_of_column("time_s")
    (100000.0, 1000000000000000.0, inf)
    """
    if unit_of_column(name) == "s":
        return float(np.inf)
    found = _quantity_of_column(name)
    return CEILING.get(found[0], CEILING_OTHER) if found else CEILING_OTHER


def _quantity_of_column(name: str) -> tuple[str, str] | None:
    """(quantity, unit) of a column whose suffix names a unit (``_model`` aside), or None."""
    unit = unit_of_column(name.removesuffix("_model"))
    if unit is None or unit == "s":
        return None
    try:
        kind = units.quantity_of(unit)
    except UnitError:
        return None
    quantity = name.split("_", 1)[0]
    if QUANTITIES.get(quantity) != kind:
        quantity = next((q for q, k in QUANTITIES.items() if k == kind), "")
    return (quantity, unit) if quantity else None


class TableReader(RecordingReader):
    """A column table as a one-element recording (see :class:`TableReader`)."""

    format = "columns-csv"
    what = "column table (one element)"
    sniff_order = 40

    @classmethod
    def sniff(cls, probe: Probe) -> bool:
        """A header of column names (see :func:`is_columns_csv`)."""
        return bool(probe.text) and is_columns_csv(probe.path)

    def _read_header(self) -> Header:
        self._table = ColumnsReader(self.path, accept_truncated=self.accept_truncated)
        names = self._table.names
        found = [(n, q) for n in names if n != "time_s" and (q := _quantity_of_column(n))]
        if not found:
            raise FormatError(
                self.path,
                f"no column names a unit (e.g. pressure_ncm2, capacitance_pF): {', '.join(names)}",
            )
        self._values, (quantity, unit) = found[-1]
        labels = [n for n in names if n not in ("time_s", self._values)]
        # the values column first, as write_columns (texsense.io.columns) writes it
        meta = {
            "format": "columns-csv",
            "source": str(self.path),
            "columns": [self._values, *labels],
        }
        return Header(
            Layout.grid(1, 1, pitch_cm=1.0),
            quantity,
            unit,
            meta,
            declared_frames=self._table.declared_rows,
            label_dtypes=dict.fromkeys(labels, np.float64),
        )

    def _pieces(self) -> Iterator[Piece]:
        row = 0
        for block in self._table.blocks(self._block if self._block < 1 << 30 else 65536):
            n = block[self._values].size
            times = block.get("time_s", np.arange(row, row + n, dtype=np.float64))
            row += n
            labels = {k: block[k] for k in self.header.label_dtypes}
            yield Piece(block[self._values][:, None], times, labels)

    def close(self) -> None:
        """Release the table."""
        table = getattr(self, "_table", None)
        if table is not None:
            table.close()
