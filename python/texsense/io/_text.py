"""Helpers shared by the text readers: decoding and number parsing with exact locations."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from texsense.exceptions import FormatError

__all__ = [
    "format_float",
    "is_number",
    "parse_csv_rows",
    "parse_float",
    "parse_floats",
    "read_lines",
]


def read_lines(path: Path) -> list[str]:
    """Read a text file as lines (any of UTF-8 with or without BOM, or Latin-1)."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise FormatError(path, "file not found") from None
    except IsADirectoryError:
        raise FormatError(path, "expected a file, found a folder") from None
    if b"\x00" in raw[:4096]:
        raise FormatError(path, "binary file (NUL bytes), expected a text export")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return text.splitlines()


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


def parse_csv_rows(
    path: Path, rows: list[str], first_line: int, n_columns: int, what: str
) -> np.ndarray:
    """Parse comma-separated rows of exactly ``n_columns`` numbers into an array.

    ``first_line`` is the 1-based line number of ``rows[0]`` in the file; ``what`` describes
    the expected values for the message ("3 comma-separated values").
    """
    data = np.empty((len(rows), n_columns), dtype=np.float64)
    for k, line in enumerate(rows):
        tokens = line.split(",")
        if len(tokens) != n_columns:
            raise FormatError(path, f"expected {what}, found {len(tokens)}", first_line + k)
        try:
            data[k] = [float(t) for t in tokens]
        except ValueError:
            bad = next(t for t in tokens if not is_number(t))
            raise FormatError(
                path, f"expected a number, found {bad.strip()!r}", first_line + k
            ) from None
    return data
