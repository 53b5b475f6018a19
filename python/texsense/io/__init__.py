"""Readers and writers for recordings.

:func:`load` opens any supported file or folder and picks the reader by content (not by
extension alone); :func:`open_reader` does the same but returns the format's reader, which
parses the header and then yields the frames in blocks (constant memory, what ``texsense
process`` uses); :func:`save` writes HDF5, wide CSV or Tekscan ASCII by extension or by
``format``, always under a temporary name that is renamed when complete. One module per
format, one reader class each over :class:`texsense.io._base.RecordingReader`:

===============  =====================================  ========  ===========
format           what                                   read      write
===============  =====================================  ========  ===========
``hdf5``         texsense recording (``.h5``)           yes       yes
``pmd``          PhysioNet PMD text files (folders)     yes       no
``tekscan``      Tekscan ASCII ``.csv`` / ``.asf``      yes       yes
``xsensor``      XSENSOR CSV export                     yes       no
``pliance``      novel pliance ``.asc``                 yes       no
``wide-csv``     ``time_s,e0,e1,...``                   yes       yes
``columns-csv``  a column table (one element)           yes       no (``io.columns``)
===============  =====================================  ========  ===========
"""

from __future__ import annotations

import inspect
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
from texsense.io._text import decode_head, open_binary
from texsense.io.columns_csv import TableReader, is_columns_csv, read_table
from texsense.io.hdf5 import HDF5Reader, RecordingWriter, read_hdf5, write_hdf5
from texsense.io.pliance import PlianceReader, read_pliance
from texsense.io.pmd import PMDReader, is_pmd_path, read_pmd
from texsense.io.tekscan import TekscanReader, read_tekscan, write_tekscan
from texsense.io.wide_csv import MAGIC as _WIDE_MAGIC
from texsense.io.wide_csv import WideCSVReader, read_wide_csv, write_wide_csv
from texsense.io.xsensor import XSensorReader, read_xsensor

__all__ = [
    "READERS",
    "READER_CLASSES",
    "WRITERS",
    "RecordingReader",
    "RecordingWriter",
    "load",
    "open_reader",
    "read_folder",
    "read_hdf5",
    "read_pliance",
    "read_pmd",
    "read_tekscan",
    "read_wide_csv",
    "read_xsensor",
    "save",
    "sniff_format",
    "write_hdf5",
    "write_tekscan",
    "write_wide_csv",
]

READERS: dict[str, Callable[..., Recording]] = {
    "hdf5": read_hdf5,
    "pmd": read_pmd,
    "tekscan": read_tekscan,
    "xsensor": read_xsensor,
    "pliance": read_pliance,
    "wide-csv": read_wide_csv,
    "columns-csv": read_table,
}

READER_CLASSES: dict[str, type[RecordingReader]] = {
    "hdf5": HDF5Reader,
    "pmd": PMDReader,
    "tekscan": TekscanReader,
    "xsensor": XSensorReader,
    "pliance": PlianceReader,
    "wide-csv": WideCSVReader,
    "columns-csv": TableReader,
}

WRITERS: dict[str, Callable[..., Path]] = {
    "hdf5": write_hdf5,
    "wide-csv": write_wide_csv,
    "tekscan": write_tekscan,
}

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
# Binary vendor files people try to open: a hint instead of a parse error.
_BINARY_HINTS = {
    ".fsx": "a Tekscan binary movie: export it as ASCII (File > Save As ASCII) first",
    ".xsn": "an XSENSOR binary session: export it as CSV first",
    ".mva": "a Tekscan binary movie: export it as ASCII first",
}


def sniff_format(path: str | Path) -> str:
    """Name the format of ``path`` by looking at its content.

    Raises
    ------
    FormatError
        If the file or folder matches no known format; the message lists what is known.
    """
    path = Path(path)
    check_regular(path, folder_ok=True)  # no FIFO, device, dangling link: nothing waits
    if path.is_dir():
        return "pmd" if is_pmd_path(path) else "folder"  # a folder of recordings: read_folder
    with open_binary(path) as fh:
        head = fh.read(1 << 16)
    if head.startswith(_HDF5_SIGNATURE):
        return "hdf5"
    hint = _BINARY_HINTS.get(path.suffix.lower())
    if hint:
        raise FormatError(path, f"this is {hint}")
    if not head:
        raise FormatError(path, "empty file")
    text = decode_head(head)
    first = text.split("\n", 1)[0].strip()
    if first.startswith("DATA_TYPE") or "Tekscan" in text[:400]:
        return "tekscan"
    if first.startswith("File:") and "FRAME" in text:
        return "xsensor"
    if first.startswith("file name:") and "mat type" in text[:300]:
        return "pliance"
    if is_columns_csv(path):
        return "columns-csv"
    if first.startswith(_WIDE_MAGIC) or first.startswith("time_s,") or first.startswith("# "):
        return "wide-csv"
    tokens = [t for t in first.strip().split("\t") if t.strip()]
    if len(tokens) == 2048 and sum(t.strip().isdigit() for t in tokens) >= 1024:
        return "pmd"  # (a few impossible counts, "nan" or "1.5", are the reader's to judge)
    raise FormatError(
        path,
        "unknown format; texsense reads texsense HDF5, PhysioNet PMD, Tekscan ASCII, "
        "XSENSOR CSV, novel pliance .asc and wide CSV (time_s,e0,e1,...)",
    )


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
        Force a reader (one of :data:`READERS`); by default the content decides.
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
    parts = []
    for p in files:
        rec = load(p, accept_truncated=accept_truncated, **options)
        if "file" not in rec.labels:
            name = str(p.relative_to(folder))
            rec = rec.with_labels({**rec.labels, "file": np.full(rec.n_frames, name)})
        first = parts[0] if parts else rec
        why = _differs(first, rec)
        if why:
            raise FormatError(p, f"{why} than {files[0].name}: a folder is read as one recording")
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
    if suffix in (".h5", ".hdf5"):
        return "hdf5"
    if suffix in (".asf",):
        return "tekscan"
    if suffix == ".csv":
        return "wide-csv"
    raise ParameterError(
        f"cannot tell the output format from {Path(path).name!r}: use .h5, .csv (wide CSV) "
        "or .asf (Tekscan ASCII), or pass the format explicitly"
    )


def save(rec: Recording, path: str | Path, *, format: str | None = None) -> Path:
    """Write ``rec`` as HDF5 (``.h5``), wide CSV (``.csv``) or Tekscan ASCII (``.asf``)."""
    fmt = format or format_for_output(path)
    if fmt not in WRITERS:
        raise ParameterError(f"no writer for {fmt!r}; writable: {', '.join(WRITERS)}")
    return WRITERS[fmt](rec, path)
