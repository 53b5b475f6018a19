"""Exceptions raised by texsense.

Errors at the edges (files, lines, parameters) carry one clear message that names *where*
(file, line, field) and *what was expected*. The compiled core's error variants map one to
one onto the classes re-exported here.
"""

from __future__ import annotations

from pathlib import Path

from texsense._core import NeighbourIndexError, ParameterError, ShapeError

__all__ = [
    "FormatError",
    "NeighbourIndexError",
    "NotFittedError",
    "ParameterError",
    "ShapeError",
    "UnitError",
    "WriteError",
    "shown",
]


def shown(value: object, limit: int = 40) -> str:
    """A value as an error message shows it: quoted (``repr``, so that control characters
    and quotes are seen as what they are), and when longer than ``limit`` characters cut
    with the cut said, so that a cut value is never taken for the value itself.

    >>> shown("x")
    "'x'"
    >>> shown(10**30, 20)
    "'10000000000000000000'... (31 characters)"
    """
    text = str(value)
    if len(text) <= limit:
        return repr(text)
    return f"{text[:limit]!r}... ({len(text)} characters)"


class UnitError(ValueError):
    """A unit string is unknown or does not fit the quantity."""


class NotFittedError(RuntimeError):
    """A model was used before ``fit`` was called."""


class FormatError(ValueError):
    """A file does not follow its format.

    Parameters
    ----------
    path : str or Path
        The file (or folder) being read.
    message : str
        What was found and what was expected.
    line : int, optional
        1-based line number where the problem is, if it is line oriented.
    """

    def __init__(self, path: str | Path, message: str, line: int | None = None) -> None:
        self.path = Path(path)
        self.line = line
        self.detail = message
        where = f"{self.path}" if line is None else f"{self.path}, line {line}"
        super().__init__(f"{where}: {message}")


class WriteError(OSError):
    """A file could not be written (disk full, no permission, a folder in the way, ...).

    The write went to a temporary name (see :mod:`texsense.data.files`), so the previous file at
    ``path`` is unchanged.

    Parameters
    ----------
    path : str or Path
        The file that was to be written.
    message : str
        Why it failed.
    """

    def __init__(self, path: str | Path, message: str) -> None:
        self.path = Path(path)
        self.detail = message
        super().__init__(f"{self.path}: {message}")

    def __str__(self) -> str:
        return f"{self.path}: {self.detail}"
