"""Writing files so that nothing is lost: every file texsense writes goes to a temporary name
in the same folder, is flushed to disk and then renamed over the target (an atomic step on
POSIX and Windows). A write that fails (disk full, file-size limit, killed) leaves the
previous file as it was and no half-written file under the target's name.

- :func:`atomic_path` gives a temporary path to hand to a library that opens files itself
  (h5py, matplotlib, joblib); :func:`atomic_open` is the same for an open file object;
  :func:`write_text` and :func:`write_bytes` are the one-liners.
- :func:`check_not_input` refuses an output that is one of the inputs (``process raw.h5 -o
  raw.h5`` would otherwise replace the raw data by its result).
- :func:`unused_name` gives a name that no file has yet (``session.h5``, ``session-2.h5``, ...)
  for recordings that must never overwrite an earlier one.

Examples
--------
>>> import os, tempfile
>>> from pathlib import Path
>>> folder = tempfile.mkdtemp()
>>> target = os.path.join(folder, "model.json")
>>> _ = write_text(target, "old")
>>> try:
...     with atomic_open(target, "w") as f:
...         _ = f.write("half a new fi")
...         raise RuntimeError("killed")
... except RuntimeError:
...     pass
>>> Path(target).read_text()        # the previous file is kept
'old'
>>> sorted(os.listdir(folder))      # and no temporary file is left behind
['model.json']
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from types import ModuleType
from typing import IO, TYPE_CHECKING, Any

from texsense.exceptions import ParameterError, WriteError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "atomic_open",
    "atomic_path",
    "check_not_input",
    "save_figure",
    "unused_name",
    "write_bytes",
    "write_text",
]

_TMP_PREFIX = ".texsense-tmp-"


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(folder: Path) -> None:
    with contextlib.suppress(OSError):  # not every platform/file system lets a folder sync
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | Path, *, suffix: str | None = None) -> Iterator[Path]:
    """A temporary path beside ``path``; on a clean exit it is synced and renamed to ``path``.

    Parameters
    ----------
    path : str or Path
        The file to (re)place. Its folder must exist.
    suffix : str, optional
        The temporary file's suffix (default: ``path``'s own, so that libraries that choose
        a format by extension, like matplotlib, see the right one).

    Raises
    ------
    WriteError
        The write or the rename failed (disk full, no permission, ...): the previous file
        at ``path``, if any, is unchanged and the temporary file is removed.
    """
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise WriteError(target, f"the folder {folder} does not exist")
    if target.is_dir():
        raise WriteError(target, "is a folder, expected a file name")
    fd, tmp_name = tempfile.mkstemp(
        prefix=_TMP_PREFIX + target.name + ".",
        suffix=target.suffix if suffix is None else suffix,
        dir=folder,
    )
    # mkstemp makes the file private (0600): give it the mode the file had, or that a new
    # file gets (0666 less the umask), so that writing safely does not change who may read
    with contextlib.suppress(OSError):
        os.fchmod(fd, _mode_of(target))
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        _fsync_file(tmp)
        os.replace(tmp, target)
    except OSError as e:
        _remove(tmp)
        raise WriteError(target, _reason(e)) from e
    except BaseException:
        _remove(tmp)
        raise
    _fsync_dir(folder)


@contextlib.contextmanager
def atomic_open(
    path: str | Path, mode: str = "w", *, encoding: str | None = "utf-8", newline: str | None = None
) -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path`` for writing (``"w"`` or ``"wb"``); it replaces
    ``path`` only when the block ends without an error (see :func:`atomic_path`)."""
    if mode not in ("w", "wb", "wt"):
        raise ParameterError(f"atomic_open writes whole files: mode 'w' or 'wb', not {mode!r}")
    with atomic_path(path) as tmp:
        if "b" in mode:
            with open(tmp, "wb") as fb:
                yield fb
                fb.flush()
        else:
            with open(tmp, "w", encoding=encoding, newline=newline) as ft:
                yield ft
                ft.flush()


def write_text(path: str | Path, text: str, *, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically; returns the path."""
    with atomic_open(path, "w", encoding=encoding) as f:
        f.write(text)
    return Path(path)


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns the path."""
    with atomic_open(path, "wb") as f:
        f.write(data)
    return Path(path)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_not_input(
    output: str | Path, inputs: Iterable[str | Path], *, what: str = "output"
) -> None:
    """Refuse an output that is one of the inputs (the same file, also through links or
    another spelling of its path).

    Raises
    ------
    ParameterError
        Naming the file: writing it would destroy the input.
    """
    out = Path(output)
    for item in inputs:
        src = Path(item)
        if _same_file(out, src) or out.resolve() == src.resolve():
            raise ParameterError(
                f"the {what} {out} is also an input: writing it would destroy the input; "
                "choose another name"
            )


def unused_name(path: str | Path) -> Path:
    """``path`` if no file has that name, otherwise the first free ``stem-2.ext``,
    ``stem-3.ext``, ... in the same folder (a recording never replaces an earlier one).

    >>> import os, tempfile
    >>> folder = tempfile.mkdtemp()
    >>> first = unused_name(os.path.join(folder, "night.h5")); _ = write_bytes(first, b"")
    >>> unused_name(first).name
    'night-2.h5'
    """
    target = Path(path)
    if not target.exists():
        return target
    k = 2
    while True:
        candidate = target.with_name(f"{target.stem}-{k}{target.suffix}")
        if not candidate.exists():
            return candidate
        k += 1


def _mode_of(target: Path) -> int:
    """The permission bits ``target`` has, or a new file would get (0666 less the umask)."""
    try:
        return target.stat().st_mode & 0o7777
    except OSError:
        pass
    try:  # the umask without changing it (Linux); else the usual 022
        status = Path("/proc/self/status").read_text()
        umask = int(next(ln.split()[1] for ln in status.splitlines() if ln.startswith("Umask")), 8)
    except (OSError, StopIteration, ValueError, IndexError):
        umask = 0o022
    return 0o666 & ~umask


def _remove(path: Path) -> None:
    with contextlib.suppress(OSError):
        path.unlink()


def _reason(e: OSError) -> str:
    text = e.strerror or str(e) or type(e).__name__
    return f"could not write ({text}); the previous file, if any, is unchanged"


def pyplot() -> ModuleType:
    """matplotlib.pyplot on the Agg backend (files only, no window), with TrueType fonts in
    PDFs (their text can be copied): the one place texsense sets matplotlib up."""
    import matplotlib

    matplotlib.use("Agg")
    matplotlib.rcParams["pdf.fonttype"] = 42
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Figure, path: str | Path, **savefig: object) -> Path:
    """Write ``fig`` to ``path`` in the format its extension names (PNG without one), under a
    temporary name that is renamed when complete; returns the path.

    Raises
    ------
    ParameterError
        If matplotlib cannot write the extension's format.
    WriteError
        If the file could not be written (the previous file is kept).
    """
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    if fmt not in fig.canvas.get_supported_filetypes():
        known = ", ".join(sorted(fig.canvas.get_supported_filetypes()))
        raise ParameterError(f"{path}: cannot write a figure as .{fmt}; use one of {known}")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=fmt, **savefig)  # type: ignore[arg-type]
    return path
