"""Readers and writers for recordings.

:func:`load` opens any supported file or folder and picks the reader by content (not by
extension alone); :func:`open_reader` does the same but returns the format's reader, which
parses the header and then yields the frames in blocks (constant memory, what ``texsense
process`` uses); :func:`save` writes a recording in the format its extension names, always
under a temporary name that is renamed when complete.

One module per format, one reader class each over :class:`texsense.io._base.RecordingReader`,
which declares its name, what it reads and its detection rule; the writers declare themselves
with :func:`texsense.io._registry.writer`. This package imports every public module in its
folder, so a new format is one new module: detection, ``load(format=...)``, ``read_<format>``,
``texsense convert --format``, the errors and the table of docs/formats.md
(:func:`formats_table`) all read the registry:

>>> print(formats_table())  # doctest: +NORMALIZE_WHITESPACE
| format | `format=` | read | write (chosen by the output's extension) |
|---|---|---|---|
| texsense recording (.h5) | `hdf5` | yes | yes: `.h5`, `.hdf5` (exact round trip) |
| Tekscan ASCII .csv / .asf | `tekscan` | yes | yes: `.asf` (exact round trip) |
| XSENSOR CSV export | `xsensor` | yes | no |
| novel pliance .asc | `pliance` | yes | no |
| column table (one element) | `columns-csv` | yes | no (`texsense.io.columns.write_columns`) |
| wide CSV (time_s,e0,e1,...) | `wide-csv` | yes | yes: `.csv` (exact round trip) |
| PhysioNet PMD text files and folders | `pmd` | yes | no |
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from texsense._progress import logger
from texsense.data.files import check_regular, regular_files
from texsense.data.recording import Recording
from texsense.exceptions import FormatError, ParameterError
from texsense.io._base import RecordingReader
from texsense.io._registry import READER_CLASSES, WRITERS, Probe
from texsense.io._text import decode_head, open_binary
from texsense.io.hdf5 import RecordingWriter
from texsense.io.lazy import LazyRecording

__all__ = [
    "READER_CLASSES",
    "WRITERS",
    "LazyRecording",
    "RecordingReader",
    "RecordingWriter",
    "formats_table",
    "load",
    "open_reader",
    "open_recording",
    "read_folder",
    "save",
    "sniff_format",
]

#: Readers that do not write, and where their format is written instead (formats_table).
_WRITTEN_ELSEWHERE = {"columns-csv": "texsense.io.columns.write_columns"}

# Binary vendor files people try to open: a hint instead of a parse error.
_BINARY_HINTS = {
    ".fsx": "a Tekscan binary movie: export it as ASCII (File > Save As ASCII) first",
    ".xsn": "an XSENSOR binary session: export it as CSV first",
    ".mva": "a Tekscan binary movie: export it as ASCII first",
}


def known_formats() -> str:
    """What texsense reads, in words (for errors and help)."""
    return ", ".join(cls.what for cls in READER_CLASSES.values())


def sniff_format(path: str | Path) -> str:
    """Name the format of ``path`` by looking at its content: the first reader in
    :data:`READER_CLASSES` whose ``sniff`` claims it (``"folder"`` for a folder no reader
    claims: :func:`read_folder`).

    Raises
    ------
    FormatError
        If the file or folder matches no known format; the message lists what is known.
    """
    path = Path(path)
    check_regular(path, folder_ok=True)  # no FIFO, device, dangling link: nothing waits
    if path.is_dir():
        probe = Probe(path)
    else:
        with open_binary(path) as fh:
            head = fh.read(1 << 16)
        hint = _BINARY_HINTS.get(path.suffix.lower())
        if hint:
            raise FormatError(path, f"this is {hint}")
        if not head:
            raise FormatError(path, "empty file")
        text = decode_head(head)
        probe = Probe(path, head, text, text.split("\n", 1)[0].strip())
    for name, cls in READER_CLASSES.items():
        if cls.sniff(probe):
            return name
    if probe.is_folder:
        return "folder"
    raise FormatError(path, f"unknown format; texsense reads {known_formats()}")


def formats_table() -> str:
    """The table of formats (docs/formats.md shows it; a test keeps them equal)."""
    rows = ["| format | `format=` | read | write (chosen by the output's extension) |",
            "|---|---|---|---|"]  # fmt: skip
    for name, cls in READER_CLASSES.items():
        w = WRITERS.get(name)
        if w is not None:
            note = w.what.partition("(")[2].rstrip(")")
            written = f"yes: {', '.join(f'`{s}`' for s in w.suffixes)}" + (
                f" ({note})" if note else ""
            )
        elif name in _WRITTEN_ELSEWHERE:
            written = f"no (`{_WRITTEN_ELSEWHERE[name]}`)"
        else:
            written = "no"
        rows.append(f"| {cls.what} | `{name}` | yes | {written} |")
    return "\n".join(rows)


def _reader_function(name: str) -> Callable[..., Recording]:
    """``read_<format>(path, *, accept_truncated=False, **options)``: :func:`load` with that
    format, documented by the reader class."""
    cls = READER_CLASSES[name]

    def read(path: str | Path, *, accept_truncated: bool = False, **options: Any) -> Recording:
        with open_reader(path, format=name, accept_truncated=accept_truncated, **options) as r:
            return r.read()

    read.__name__ = read.__qualname__ = f"read_{name.replace('-', '_')}"
    read.__doc__ = cls.__doc__
    read.__module__ = __name__
    return read


def __getattr__(attr: str) -> Callable[..., Any]:
    """``read_hdf5``, ``read_tekscan``, ... : one per registered reader; ``write_hdf5``, ...:
    the registered writers."""
    if attr.startswith("write_") and attr[len("write_") :].replace("_", "-") in WRITERS:
        return WRITERS[attr[len("write_") :].replace("_", "-")].write
    if attr.startswith("read_"):
        name = attr[len("read_") :].replace("_", "-")
        if name == "table":
            name = "columns-csv"  # the column table's reader has always been read_table
        if name in READER_CLASSES:
            fn = _reader_function(name)
            globals()[attr] = fn
            return fn
    raise AttributeError(f"module 'texsense.io' has no attribute {attr!r}")


def open_reader(
    path: str | Path,
    *,
    format: str | None = None,
    accept_truncated: bool = False,
    **options: Any,
) -> RecordingReader:
    """Open a recording for reading in blocks: its header is parsed, the frames are read by
    ``reader.blocks(frames)`` (or all at once by ``reader.read()``). Close it when done (a
    context manager).

    Parameters
    ----------
    path : str or Path
        File or folder.
    format : str, optional
        Force a reader (one of :data:`READER_CLASSES`); by default the content decides.
    accept_truncated : bool
        Read a file that holds less than it declares (cut short, closed early, datasets of
        different lengths) up to its last complete frame with a warning, instead of refusing
        it (``--accept-truncated`` on the command line).
    **options
        Passed to the reader (e.g. ``unit=`` for a wide CSV without unit line).

    Examples
    --------
    >>> with open_reader("../shared/data/pmd/experiment-i/S1/1.txt") as reader:
    ...     sum(block.n_frames for block in reader.blocks(32))
    82
    """
    fmt = format or sniff_format(path)
    if fmt == "folder":
        raise FormatError(
            path,
            "a folder that is not a PMD tree: this reads one recording at a time (a folder "
            "of recordings: texsense.load, or 'texsense process' as an archive)",
        )
    if fmt not in READER_CLASSES:
        raise ParameterError(f"unknown format {fmt!r}; known: {', '.join(READER_CLASSES)}")
    cls = READER_CLASSES[fmt]
    known = inspect.signature(cls.__init__).parameters
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise ParameterError(f"the {fmt} reader takes no option {', '.join(unknown)}")
    return cls(path, accept_truncated=accept_truncated, **options)


def load(
    path: str | Path,
    *,
    format: str | None = None,
    accept_truncated: bool = False,
    **options: Any,
) -> Recording:
    """Read a recording from any supported file or folder.

    Parameters
    ----------
    path : str or Path
        File or folder.
    format : str, optional
        Force a reader (one of :data:`READER_CLASSES`); by default the content decides.
    accept_truncated : bool
        Read a file cut short up to its last complete frame, with a warning (see
        :func:`open_reader`).
    **options
        Passed to the reader (e.g. ``unit=`` for a wide CSV without unit line).

    Examples
    --------
    >>> import texsense
    >>> rec = texsense.load("../shared/data/vendor-formats/iscan_test.csv")
    >>> rec.layout.shape, rec.n_frames
    ((28, 28), 309)
    """
    if (format or sniff_format(path)) == "folder":
        return read_folder(path, accept_truncated=accept_truncated, **options)
    with open_reader(path, format=format, accept_truncated=accept_truncated, **options) as r:
        return r.read()


def open_recording(path: str | Path, *, apart: bool = False) -> Recording:
    """A recording to play: a texsense HDF5 recording as a
    :class:`~texsense.io.lazy.LazyRecording` (its frames read when indexed: any length), any
    other format read whole (within the memory budget: a file beyond it is refused in one
    line, since the text formats are read from their start only); with ``apart`` that read
    is done in a child process (:func:`texsense.io.apart.load_apart`: a server's threads go
    on while text is parsed)."""
    if sniff_format(path) == "hdf5":
        return LazyRecording.open(path)
    if apart:
        from texsense.io.apart import load_apart  # late: its child process runs load()

        return load_apart(path)
    return load(path)


def read_folder(path: str | Path, *, accept_truncated: bool = False, **options: Any) -> Recording:
    """Every recording in a folder (and its subfolders, in natural order of their paths)
    as one recording, e.g. the folder ``texsense process`` or ``texsense seat-sessions``
    writes: files that are not recordings (``calibration.json``, a report) are passed over;
    a label ``file`` names the file each frame comes from (unless the files have one). Times
    run on: a file whose times would go back (each file starting at 0 s) is shifted to start
    one frame period after the previous one ends.

    Raises
    ------
    FormatError
        If the folder holds no recording, or its recordings differ in layout, quantity, unit
        or label names (the first that differs is named).
    """
    folder = Path(path)
    if not folder.is_dir():
        raise FormatError(folder, "no such folder")
    files = []
    found, passed = regular_files(folder, recursive=True)  # no link out, FIFO, device
    for p, why in passed:
        logger.warning("warning: %s: passed over (%s)", p, why)
    for p in sorted(found, key=_natural):
        try:
            sniff_format(p)
        except FormatError:
            continue
        files.append(p)
    if not files:
        raise FormatError(
            folder,
            "holds no recording texsense reads (and is not a PMD tree: no S1, S2, ... or "
            "1.txt .. 17.txt)",
        )
    parts: list[Recording] = []
    for p in files:
        rec = load(p, accept_truncated=accept_truncated, **options)
        if "file" not in rec.labels:
            name = str(p.relative_to(folder))
            rec = rec.with_labels({**rec.labels, "file": np.full(rec.n_frames, name)})
        first = parts[0] if parts else rec
        unlike = _differs(first, rec)
        if unlike:
            one = "a folder is read as one recording"
            raise FormatError(p, f"{unlike} than {files[0].name}: {one}")
        if parts and rec.n_frames and parts[-1].n_frames:
            rec = _after(parts[-1], rec)
        parts.append(rec)
    return Recording.concatenate(parts)


def _after(previous: Recording, rec: Recording) -> Recording:
    """``rec`` with its times shifted to start one frame period after ``previous`` ends when
    they would go back (files that each start at 0 s); as they are otherwise."""
    end = float(previous.times[-1])
    if rec.times[0] > end:
        return rec
    steps = np.diff(rec.times)
    period = float(np.median(steps)) if steps.size else 1.0
    shift = end + period - float(rec.times[0])
    et = None if rec.element_times is None else rec.element_times + shift
    return Recording(
        rec.frames,
        rec.times + shift,
        rec.layout,
        rec.quantity,
        rec.unit,
        valid=rec.valid,
        element_times=et,
        labels=rec.labels,
        meta=rec.meta,
    )


def _natural(p: Path) -> list[Any]:
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", str(p))]


def _differs(a: Recording, b: Recording) -> str | None:
    if a.layout != b.layout:
        return f"another layout ({b.layout.n_elements} elements)"
    if (a.quantity, a.unit) != (b.quantity, b.unit):
        return f"another quantity ({b.quantity} in {b.unit})"
    if a.labels.keys() != b.labels.keys():
        return f"other labels ({', '.join(sorted(b.labels))})"
    if (a.element_times is None) != (b.element_times is None):
        return "element time stamps present in only some files"
    return None


def format_for_output(path: str | Path) -> str:
    """The writer for an output path, chosen by its extension."""
    suffix = Path(path).suffix.lower()
    for name, w in WRITERS.items():
        if suffix in w.suffixes:
            return name
    known = "; ".join(f"{', '.join(w.suffixes)} ({w.name})" for w in WRITERS.values())
    raise ParameterError(
        f"cannot tell the output format from {Path(path).name!r}: use {known}, or pass the "
        "format explicitly"
    )


def save(rec: Recording, path: str | Path, *, format: str | None = None) -> Path:
    """Write ``rec`` in ``format``, by default the one its extension names
    (:data:`WRITERS`: HDF5 ``.h5``, wide CSV ``.csv``, Tekscan ASCII ``.asf``)."""
    fmt = format or format_for_output(path)
    if fmt not in WRITERS:
        raise ParameterError(f"no writer for {fmt!r}; writable: {', '.join(WRITERS)}")
    return WRITERS[fmt].write(rec, path)


def _load_formats() -> None:
    """Import every public module of this package: each format registers itself."""
    for info in pkgutil.iter_modules(__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"{__name__}.{info.name}")


_load_formats()
