"""The one registry of file formats: every reader class and every writer declares itself
here, and everything that lists formats reads it (format detection, ``load(format=...)``,
``texsense convert --format``, the errors that name what is known, the table in
docs/formats.md, the conformance tests).

- A **reader** is a :class:`~texsense.io._base.RecordingReader` subclass that sets
  ``format`` (its name), ``what`` (a few words for tables and errors) and ``sniff`` (its rule
  for "this file is mine", from a :class:`Probe` of the file's first 64 KiB); defining the
  class registers it (``__init_subclass__``), in the order of ``sniff_order``.
- A **writer** is a function decorated with :func:`writer`, naming its format, what it is and
  the output suffixes it is chosen for.

A new format is therefore one module in ``texsense/io/`` (the package imports every public
module in it) plus its tests: the conformance suite (tests/readers/test_formats.py) walks
this registry and fails for a reader that has no case there.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from texsense.io._base import RecordingReader

__all__ = ["READER_CLASSES", "WRITERS", "Probe", "WriterEntry", "register_reader", "writer"]


@dataclass(frozen=True)
class Probe:
    """What format detection knows of a file before any reader opens it.

    Attributes
    ----------
    path : Path
        The file or folder.
    head : bytes
        Its first 64 KiB (empty for a folder).
    text : str
        ``head`` decoded (any encoding the text readers accept), or ``""``.
    first : str
        The first line of ``text``, stripped.
    """

    path: Path
    head: bytes = b""
    text: str = ""
    first: str = ""

    @property
    def is_folder(self) -> bool:
        """Whether the probe is of a folder (only readers of folders claim it)."""
        return self.path.is_dir()


#: Reader classes by format name, in sniffing order (filled as the format modules load).
READER_CLASSES: dict[str, type[RecordingReader]] = {}


def register_reader(cls: type[RecordingReader]) -> None:
    """Add a reader class (called by ``RecordingReader.__init_subclass__``)."""
    name = cls.format
    if not cls.what:
        raise TypeError(f"{cls.__name__}: a reader of {name!r} must say what it reads (what=)")
    other = READER_CLASSES.get(name)
    if other is not None and other.__qualname__ != cls.__qualname__:
        raise TypeError(f"{cls.__name__}: the format {name!r} is already {other.__name__}'s")
    READER_CLASSES[name] = cls
    ordered = sorted(READER_CLASSES.items(), key=lambda kv: (kv[1].sniff_order, kv[0]))
    READER_CLASSES.clear()
    READER_CLASSES.update(ordered)


@dataclass(frozen=True)
class WriterEntry:
    """A writer: its format name, what it writes, the output suffixes that choose it and
    the function ``write(rec, path) -> path``."""

    name: str
    what: str
    suffixes: tuple[str, ...]
    write: Callable[..., Path]


#: Writers by format name.
WRITERS: dict[str, WriterEntry] = {}

_F = TypeVar("_F", bound=Callable[..., Any])


def writer(name: str, *, what: str, suffixes: tuple[str, ...]) -> Callable[[_F], _F]:
    """Register the decorated ``write(rec, path) -> Path`` as the writer of format ``name``,
    chosen for an output path ending in one of ``suffixes`` (lower case, with the dot)."""

    def register(fn: _F) -> _F:
        taken = {s: w.name for w in WRITERS.values() for s in w.suffixes if w.name != name}
        clash = sorted(s for s in suffixes if s in taken)
        if clash:
            raise TypeError(f"writer {name!r}: {', '.join(clash)} already choose {taken[clash[0]]}")
        WRITERS[name] = WriterEntry(name, what, tuple(s.lower() for s in suffixes), fn)
        return fn

    return register
