"""Helpers shared by the text readers: a line source that streams any text export (UTF-8 with
or without BOM, Latin-1, UTF-16 with BOM) one line at a time and knows whether the last line
was cut, and number parsing whose errors name the file, the line and what was expected."""

from __future__ import annotations

import codecs
import io
import math
from collections.abc import Iterator
from pathlib import Path
from typing import IO, NamedTuple

import numpy as np

from texsense.data import budget
from texsense.data.files import open_regular
from texsense.exceptions import FormatError

__all__ = [
    "Line",
    "TextLines",
    "decode_head",
    "format_float",
    "is_number",
    "open_binary",
    "parse_csv_row",
    "parse_float",
    "parse_floats",
]

#: A line longer than this is not a text export (a binary file without NUL bytes, say).
MAX_LINE_BYTES = 64 << 20
#: Memory one byte of a line may take once the line is split into its fields (a field of one
#: character is a Python string of ~50 bytes and a pointer): a line may hold at most the memory
#: budget over this (:mod:`texsense.data.budget`). A 26 MB header of 3 million element names
#: took 540 MB under a budget of 64 MiB (harden12).
LINE_COST = 32


def max_line_bytes() -> int:
    """The longest line a text export may have: :data:`MAX_LINE_BYTES`, or less under a
    smaller memory budget."""
    return int(max(4096, min(MAX_LINE_BYTES, budget.max_memory() // LINE_COST)))


UTF16_BOMS = (codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)


class Line(NamedTuple):
    """One line of a text file: its 1-based number, its text without the line end, and
    whether it had a line end (only the last line of a file can lack one: a file cut in the
    middle of a line)."""

    number: int
    text: str
    ended: bool = True


def open_binary(path: Path) -> IO[bytes]:
    """Open ``path`` for reading bytes (:func:`texsense.data.files.open_regular`: a regular
    file only, without waiting on it); a missing file, a folder, a FIFO, a device, a dangling
    link or no permission is a :class:`FormatError` naming the file."""
    return open_regular(path)


def decode_head(head: bytes) -> str:
    """The text of the first bytes of a file, for sniffing its format (UTF-16 by its BOM)."""
    if head.startswith(UTF16_BOMS):
        return head[: len(head) // 2 * 2].decode("utf-16", errors="replace")
    return head.decode("utf-8", errors="replace").lstrip("\ufeff")


class TextLines:
    """The lines of a text file, read one at a time (constant memory).

    The encoding is chosen once from the start of the file: UTF-16 by its byte-order mark,
    otherwise each line is UTF-8 (a BOM is dropped) or, if it is not valid UTF-8, Latin-1.
    NUL bytes without a UTF-16 BOM mean a binary file: :class:`FormatError`.

    Iterating yields :class:`Line` tuples; :meth:`peek` looks at the next line without taking
    it. Use as a context manager (or call :meth:`close`).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> path = Path(tempfile.mkdtemp()) / "t.txt"
    >>> _ = path.write_bytes(b"a,1\\r\\nb,2")
    >>> with TextLines(path) as lines:
    ...     list(lines)
    [Line(number=1, text='a,1', ended=True), Line(number=2, text='b,2', ended=False)]
    """

    def __init__(self, path: str | Path, *, skip: int = 0) -> None:
        self.path = Path(path)
        self._longest = max_line_bytes()
        self._raw = open_binary(self.path)
        head = self._raw.read(4096)
        self._raw.seek(0)
        self._text: io.TextIOWrapper | None = None
        if head.startswith(UTF16_BOMS):
            self._text = io.TextIOWrapper(
                self._raw, encoding="utf-16", errors="replace", newline=""
            )
        elif b"\x00" in head:
            self._raw.close()
            raise FormatError(
                self.path,
                "binary file (NUL bytes), expected a text export (UTF-8, Latin-1 or "
                "UTF-16 with a byte-order mark)",
            )
        self.number = 0
        self._pending: list[Line] = []
        for _ in range(skip):
            if self._next_line() is None:
                break

    def _next_line(self) -> Line | None:
        if self._text is not None:
            text = self._text.readline(self._longest)
            if not text:
                return None
            ended = text.endswith(("\n", "\r"))
            self._check_length(len(text), ended)
            text = text.rstrip("\r\n")
        else:
            raw = self._raw.readline(self._longest)
            if not raw:
                return None
            ended = raw.endswith(b"\n")
            body = raw.rstrip(b"\r\n")
            self._check_length(len(raw), ended)
            try:
                text = body.decode("utf-8")
            except UnicodeDecodeError:
                text = body.decode("latin-1")
            if self.number == 0:
                text = text.lstrip("\ufeff")
        self.number += 1
        return Line(self.number, text, ended)

    def _check_length(self, size: int, ended: bool) -> None:
        if size >= self._longest and not ended:
            raise FormatError(
                self.path,
                f"a line longer than {budget.human(self._longest)}: not a text export (the "
                f"longest line is 1/{LINE_COST} of the memory budget, ${budget.ENV}, "
                f"at most {MAX_LINE_BYTES >> 20} MiB)",
                self.number + 1,
            )

    def __iter__(self) -> TextLines:
        return self

    def __next__(self) -> Line:
        if self._pending:
            return self._pending.pop()
        line = self._next_line()
        if line is None:
            raise StopIteration
        return line

    def peek(self) -> Line | None:
        """The next line without taking it (None at the end of the file)."""
        if not self._pending:
            line = self._next_line()
            if line is None:
                return None
            self._pending.append(line)
        return self._pending[-1]

    def data_lines(self, what: str = "the frames") -> Iterator[Line]:
        """The remaining lines that hold something: empty lines at the end are skipped, an
        empty line followed by more data is a :class:`FormatError` naming it."""
        blank: int | None = None
        for line in self:
            if not line.text.strip():
                blank = blank or line.number
                continue
            if blank is not None:
                raise FormatError(self.path, f"an empty line inside {what}", blank)
            yield line

    def push(self, line: Line) -> None:
        """Put ``line`` back: the next line taken is ``line``."""
        self._pending.append(line)

    def next_nonblank(self, blank: str = "") -> Line | None:
        """The next line that holds more than whitespace and the characters in ``blank``
        (None at the end of the file)."""
        for line in self:
            if line.text.strip().strip(blank).strip():
                return line
        return None

    def close(self) -> None:
        """Close the file."""
        self._raw.close()

    def __enter__(self) -> TextLines:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def parse_float(path: Path, line_no: int, token: str, what: str) -> float:
    """Parse one number; on failure name the file, line and what was expected."""
    try:
        return float(token)
    except ValueError:
        raise FormatError(path, f"expected a number for {what}, found {token!r}", line_no) from None


def parse_floats(path: Path, line_no: int, tokens: list[str], count: int, what: str) -> np.ndarray:
    """Parse exactly ``count`` numbers from ``tokens`` (empty tokens are errors)."""
    if len(tokens) != count:
        raise FormatError(path, f"expected {count} values for {what}, found {len(tokens)}", line_no)
    try:
        return np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not is_number(t))
        raise FormatError(path, f"expected a number in {what}, found {bad!r}", line_no) from None


def is_number(token: str) -> bool:
    """True if ``token`` parses as a float."""
    try:
        float(token)
    except ValueError:
        return False
    return True


def format_float(value: float, dtype: type = np.float32) -> str:
    """Shortest text that reads back to exactly ``value`` in ``dtype`` ("nan" for NaN)."""
    if math.isnan(value):
        return "nan"
    text = np.format_float_positional(dtype(value), unique=True, trim="-")
    return text


def parse_csv_row(path: Path, line: Line, n_columns: int, what: str) -> list[float]:
    """One comma-separated row of exactly ``n_columns`` numbers."""
    tokens = line.text.split(",")
    if len(tokens) != n_columns:
        raise FormatError(path, f"expected {what}, found {len(tokens)}", line.number)
    try:
        return [float(t) for t in tokens]
    except ValueError:
        bad = next(t for t in tokens if not is_number(t))
        raise FormatError(path, f"expected a number, found {bad.strip()!r}", line.number) from None
