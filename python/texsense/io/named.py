"""The one rule for a path named inside a file (a ward file's ``layout``, ``calibration``,
``model``, a source's file, folder or device): relative to the folder of the file that names
it, and of the kind its key reads (docs/station.md, "Paths in a ward file")."""

from __future__ import annotations

import stat
from pathlib import Path

from texsense.data.files import kind_of, read_status
from texsense.exceptions import FormatError, ParameterError
from texsense.io import sniff_format

__all__ = ["PATH_KINDS", "named_path"]


#: What a path named in a file may have to be (:func:`named_path`), in the words of errors.
PATH_KINDS = {
    "file": "a file",
    "folder": "a folder",
    "recording": "a recording (a file, or a folder of a format such as PhysioNet PMD)",
    "device": "a device (or a link to one)",
}


def named_path(value: str, named_in: str | Path, kind: str) -> Path:
    """The path ``value`` that the file ``named_in`` names (a ward file's ``layout``,
    ``calibration``, ``model``, a source's file, folder or device), by the one rule for paths
    inside files: relative to the folder of the file that names it (absolute as it is, ``~``
    the home folder), never to the folder the program runs in; checked to be of ``kind``
    (:data:`PATH_KINDS`): a file where a file is expected (not a folder, FIFO or device), a
    folder where a folder is, a recording (a file, or a folder a reader knows: not any folder
    tree), a device where one is (when it exists: not a file or folder).

    Raises
    ------
    ParameterError
        Saying what was found and what was expected (the caller names the file and key).
    """
    if kind not in PATH_KINDS:
        raise ParameterError(f"unknown kind of path {kind!r}; known: {', '.join(PATH_KINDS)}")
    if not value or "\x00" in value:
        raise ParameterError(f"{value!r} is no path")
    path = Path(value).expanduser()
    if not path.is_absolute():
        path = Path(named_in).parent / path
    want = PATH_KINDS[kind]
    try:
        st = read_status(path)
    except FormatError as e:
        raise ParameterError(str(e)) from None
    if st is None:
        if kind == "device":
            return path  # the source says it is missing (a device may come later)
        raise ParameterError(f"{path}: no such {'folder' if kind == 'folder' else 'file'}")
    mode = st.st_mode
    folder = stat.S_ISDIR(mode)
    found = kind_of(mode)
    fits = {"folder": folder, "device": stat.S_ISCHR(mode), "file": stat.S_ISREG(mode),
            "recording": stat.S_ISREG(mode) or folder}[kind]  # fmt: skip
    if not fits:
        raise ParameterError(f"{path}: expected {want}, found {found}")
    if folder and kind == "recording":
        try:
            fmt = sniff_format(path)
        except FormatError as e:
            raise ParameterError(e.detail) from None
        if fmt == "folder":
            raise ParameterError(f"{path}: expected {want}, found a folder that is none")
    return path
