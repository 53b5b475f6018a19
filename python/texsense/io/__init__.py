"""Readers and writers for recordings.

:func:`load` opens any supported file or folder and picks the reader by content (not by
extension alone); :func:`save` writes HDF5, wide CSV or Tekscan ASCII by extension or by
``format``. One module per format:

==============  =====================================  ========  ===========
format          what                                   read      write
==============  =====================================  ========  ===========
``hdf5``        texsense recording (``.h5``)           yes       yes
``pmd``         PhysioNet PMD text files (folders)     yes       no
``tekscan``     Tekscan ASCII ``.csv`` / ``.asf``      yes       yes
``xsensor``     XSENSOR CSV export                     yes       no
``pliance``     novel pliance ``.asc``                 yes       no
``wide-csv``    ``time_s,e0,e1,...``                   yes       yes
==============  =====================================  ========  ===========
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from texsense.exceptions import FormatError, ParameterError
from texsense.io.hdf5 import RecordingWriter, read_hdf5, write_hdf5
from texsense.io.pliance import read_pliance
from texsense.io.pmd import is_pmd_path, read_pmd
from texsense.io.tekscan import read_tekscan, write_tekscan
from texsense.io.wide_csv import MAGIC as _WIDE_MAGIC
from texsense.io.wide_csv import read_wide_csv, write_wide_csv
from texsense.io.xsensor import read_xsensor
from texsense.recording import Recording

__all__ = [
    "READERS",
    "WRITERS",
    "RecordingWriter",
    "load",
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
    if not path.exists():
        raise FormatError(path, "no such file or folder")
    if path.is_dir():
        if is_pmd_path(path):
            return "pmd"
        raise FormatError(path, "folder is not a PMD tree (no S1, S2, ... or 1.txt .. 17.txt)")
    with path.open("rb") as fh:
        head = fh.read(8192)
    if head.startswith(_HDF5_SIGNATURE):
        return "hdf5"
    hint = _BINARY_HINTS.get(path.suffix.lower())
    if hint:
        raise FormatError(path, f"this is {hint}")
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff")
    first = text.split("\n", 1)[0].strip()
    if first.startswith("DATA_TYPE") or "Tekscan" in text[:400]:
        return "tekscan"
    if first.startswith("File:") and "FRAME" in text:
        return "xsensor"
    if first.startswith("file name:") and "mat type" in text[:300]:
        return "pliance"
    if first.startswith(_WIDE_MAGIC) or first.startswith("time_s,") or first.startswith("# "):
        return "wide-csv"
    tokens = first.split("\t")
    if len(tokens) >= 2048 and all(t.strip().isdigit() for t in tokens[:2048]):
        return "pmd"
    raise FormatError(
        path,
        "unknown format; texsense reads texsense HDF5, PhysioNet PMD, Tekscan ASCII, "
        "XSENSOR CSV, novel pliance .asc and wide CSV (time_s,e0,e1,...)",
    )


def load(path: str | Path, *, format: str | None = None, **options: Any) -> Recording:
    """Read a recording from any supported file or folder.

    Parameters
    ----------
    path : str or Path
        File or folder.
    format : str, optional
        Force a reader (one of :data:`READERS`); by default the content decides.
    **options
        Passed to the reader (e.g. ``unit=`` for a wide CSV without unit line).

    Examples
    --------
    >>> import texsense
    >>> rec = texsense.load("../shared/data/vendor-formats/iscan_test.csv")
    >>> rec.layout.shape, rec.n_frames
    ((28, 28), 309)
    """
    fmt = format or sniff_format(path)
    if fmt not in READERS:
        raise ParameterError(f"unknown format {fmt!r}; known: {', '.join(READERS)}")
    return READERS[fmt](path, **options)


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
