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

And the one way a file is opened for reading: :func:`open_regular` (and :func:`check_regular`
for a library that opens the file by its name itself, such as h5py) accepts a regular file
only. A FIFO, a device, a socket, a dangling link or a loop of links is refused at once in one
line naming the path, and nothing ever waits on a file that does not answer (the open does not
block: a FIFO without a writer would hang a reader for ever); :func:`read_small_text` reads a
small text file (a token, a password) and refuses one larger than it can be (``/dev/zero``).

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
import errno
import os
import signal
import stat
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import ModuleType
from typing import IO, TYPE_CHECKING, Any

from texsense.data import budget
from texsense.data.outside import json_loads, toml_loads
from texsense.exceptions import FormatError, ParameterError, WriteError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "atomic_open",
    "atomic_path",
    "check_new",
    "check_not_input",
    "check_regular",
    "check_writable",
    "json_loads",
    "kept_or_made",
    "made_once",
    "make_folder",
    "open_regular",
    "read_regular",
    "read_small_text",
    "real_path",
    "regular_files",
    "save_figure",
    "signals_held",
    "toml_loads",
    "unused_name",
    "write_bytes",
    "write_text",
]

_TMP_PREFIX = ".texsense-tmp-"


def cache_folder() -> Path:
    """Where texsense keeps what it can make again (trained posture models, the virtual mats'
    calibrations): ``$XDG_CACHE_HOME/texsense``, by default ``~/.cache/texsense``."""
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "texsense"


@contextlib.contextmanager
def made_once(path: str | Path) -> Iterator[bool]:
    """Hold an exclusive lock on the file ``path`` (made if missing) while the block runs, so
    that processes about to make the same cached result (a fit, a trained model) make it one
    after the other: the later ones find it made and read it. Yields whether the lock is held:
    not where the platform has no file locks (Windows) or the lock file cannot be made (a
    read-only cache, whose write is skipped anyway); the block runs all the same. The kernel
    lets go of the lock of a process that dies."""
    try:
        import fcntl  # POSIX only
    except ImportError:
        yield False
        return
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:
        yield False
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield True
    finally:
        os.close(fd)  # lets go of the lock


def kept_or_made(path: Path, read: Callable[[Path], Any], make: Callable[[], Any]) -> Any:
    """What ``read(path)`` finds kept at ``path`` (None: nothing usable), else ``make()`` (which
    keeps it there), made by one process at a time: the others wait (:func:`made_once`)."""
    kept = read(path)
    if kept is not None:
        return kept
    with contextlib.suppress(OSError):  # a folder that cannot be made: make() says so
        path.parent.mkdir(parents=True, exist_ok=True)
    with made_once(path.with_name(path.name + ".lock")):
        kept = read(path)  # made meanwhile by another process
        return kept if kept is not None else make()


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


def _place_error(e: OSError) -> str:
    """What an ``OSError`` of a status asked before a write says, in the words of the errors."""
    if e.errno == errno.ELOOP:
        return "a loop of symbolic links"
    if e.errno == errno.ENAMETOOLONG:
        return "a name too long for the file system"
    return _reason(e)


def _is_file(path: Path) -> bool:
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except OSError:
        return False


def _write_place(target: Path) -> Path:
    """The folder of ``target`` once it is a place a file can be written to: an existing
    folder, and ``target`` nothing or a regular file. Every other place (a NUL in the name, a
    name too long, a loop of links, a file or a missing folder on the way, a folder or a
    device at ``target``) is a :class:`WriteError` naming it, never another ``OSError``."""
    if "\x00" in str(target):
        raise WriteError(target, "a name with a NUL character, which no file system holds")
    folder = target.parent if str(target.parent) else Path(".")
    try:
        folder_mode = os.stat(folder).st_mode
    except (FileNotFoundError, NotADirectoryError):
        on_way = next((p for p in [*reversed(folder.parents), folder] if _is_file(p)), None)
        where = f"{on_way} is a file, not a folder" if on_way is not None else (
            f"the folder {folder} does not exist")  # fmt: skip
        raise WriteError(target, where) from None
    except OSError as e:
        raise WriteError(target, f"the folder {folder}: {_place_error(e)}") from None
    if not stat.S_ISDIR(folder_mode):
        raise WriteError(target, f"{folder} is a file, not a folder")
    try:
        mode: int | None = os.stat(target).st_mode
    except FileNotFoundError:
        mode = None  # a new file (or a link to nothing, which is replaced)
    except OSError as e:
        raise WriteError(target, _place_error(e)) from None
    if mode is not None and stat.S_ISDIR(mode):
        raise WriteError(target, "is a folder, expected a file name")
    if mode is not None and not stat.S_ISREG(mode):
        raise WriteError(target, "is not a regular file (a device, a FIFO, ...): not replaced")
    return folder


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
    folder = _write_place(target)
    mode = _mode_of(target)
    with signals_held() as release:  # a stop signal between the file and the try: no leftover
        try:
            fd, tmp_name = tempfile.mkstemp(
                prefix=_TMP_PREFIX + target.name[:80] + ".",
                suffix=target.suffix if suffix is None else suffix,
                dir=folder,
            )
        except OSError as e:
            raise WriteError(target, _reason(e)) from None
        tmp = Path(tmp_name)
        try:
            release()  # from here a signal's exception removes the temporary file
            # mkstemp makes the file private (0600): give it the mode the file had, or that a
            # new file gets (0666 less the umask): writing safely does not change who may read
            with contextlib.suppress(OSError):
                os.fchmod(fd, mode)
            os.close(fd)
        except BaseException:
            os.close(fd)
            _remove(tmp)
            raise
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


def real_path(path: str | Path) -> Path:
    """``path`` with every link followed; a loop of links is left as it is (``Path.resolve``
    raises RuntimeError on one, which would be a traceback)."""
    return Path(os.path.realpath(path))


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
        if _same_file(out, src) or real_path(out) == real_path(src):
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


_KINDS = (
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def kind_of(mode: int) -> str:
    """What a path's status (``st_mode``) says it is, in the words of errors: ``a folder``,
    ``a file`` (regular), ``a FIFO (named pipe)``, ``a character device``, ..."""
    if stat.S_ISDIR(mode):
        return "a folder"
    return "a file" if stat.S_ISREG(mode) else _kind(mode)


def read_status(path: Path) -> os.stat_result | None:
    """The status of a path to be read, following links; None when nothing is there (or a
    link to nothing). Any other failure is a :class:`~texsense.exceptions.FormatError` naming
    the path and saying why in the words of errors: the one reading of a failed ``stat`` for
    every path texsense reads (:func:`check_regular`, the paths a ward file names)."""
    try:
        return os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as e:
        why = {errno.ELOOP: "a loop of symbolic links",
               errno.ENOTDIR: "a file on the way where a folder should be",
               errno.ENAMETOOLONG: "a name too long for the file system",
               errno.EACCES: "no permission to reach it",
               errno.EPERM: "no permission to reach it"}.get(e.errno or 0)  # fmt: skip
        raise FormatError(path, why or f"cannot be read ({e.strerror or e})") from None


def check_regular(path: str | Path, *, folder_ok: bool = False) -> os.stat_result:
    """The status of ``path`` if it is a regular file (a folder too with ``folder_ok``),
    following links; anything else is a :class:`~texsense.exceptions.FormatError` naming it.

    Only the status is asked (``stat``), which never waits on the file itself.

    >>> check_regular("/dev/null")
    Traceback (most recent call last):
    ...
    texsense.exceptions.FormatError: /dev/null: not a regular file (a character device): ...
    """

    p = Path(path)
    if "\x00" in str(p):
        raise FormatError(p, "a name with a NUL character, which no file has")
    st = read_status(p)
    if st is None:
        missing = "a link to nothing" if os.path.islink(p) else "no such file or folder"
        raise FormatError(p, missing)
    if stat.S_ISDIR(st.st_mode):
        if folder_ok:
            return st
        raise FormatError(p, "expected a file, found a folder")
    if not stat.S_ISREG(st.st_mode):
        raise FormatError(
            p, f"not a regular file ({_kind(st.st_mode)}): texsense reads regular files only"
        )
    return st


def open_regular(path: str | Path) -> IO[bytes]:
    """Open a regular file for reading bytes without ever waiting on it (see
    :func:`check_regular`): the open itself does not block (``O_NONBLOCK``), and the file
    opened is checked again, so that a FIFO put in its place in between is refused too.

    Raises
    ------
    FormatError
        Naming the file: missing, a folder, a FIFO, a device, a dangling link, no permission.
    """

    p = Path(path)
    check_regular(p)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    try:
        fd = os.open(p, flags | getattr(os, "O_CLOEXEC", 0))
    except OSError as e:
        raise FormatError(p, f"cannot be read ({e.strerror or e})") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise FormatError(p, f"not a regular file ({_kind(mode)})")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def check_writable(path: str | Path, what: str, *, folder: bool = False) -> Path:
    """Refuse now, in one :class:`~texsense.exceptions.WriteError` naming ``what``, a place
    where a file (with ``folder``: a folder) cannot be made: a folder or a file in the way,
    no permission, a read-only file system. For a server, which would otherwise find out
    hours later, when it first writes (a recording, an event)."""
    p = Path(path)
    if folder and p.exists() and not p.is_dir():
        raise WriteError(p, f"{what} is a file, expected a folder")
    if not folder and p.is_dir():
        raise WriteError(p, f"{what} is a folder, expected a file name")
    nearest = p if folder and p.is_dir() else (p.parent if str(p.parent) else Path("."))
    if not folder and not nearest.exists():
        raise WriteError(p, f"{what}: the folder {nearest} does not exist")
    while not nearest.exists() and nearest != nearest.parent:
        nearest = nearest.parent
    if not nearest.is_dir():
        raise WriteError(p, f"{what}: {nearest} is a file, expected a folder")
    if not os.access(nearest, os.W_OK | os.X_OK):
        reason = "a read-only file system" if _read_only(nearest) else "no permission"
        raise WriteError(p, f"{what}: cannot write in {nearest} ({reason})")
    return p


def _read_only(folder: Path) -> bool:
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):
        return False


def make_folder(path: str | Path, what: str = "output folder") -> Path:
    """Make the folder ``path`` (and its parents) if it is missing; one
    :class:`~texsense.exceptions.WriteError` naming it when it cannot be (a file in the way,
    no permission, a read-only file system).

    >>> import os, tempfile
    >>> d = tempfile.mkdtemp(); f = write_text(os.path.join(d, "f"), "x")
    >>> make_folder(os.path.join(d, "f", "sub"))
    Traceback (most recent call last):
    ...
    texsense.exceptions.WriteError: .../f/sub: cannot make the output folder (.../f is a file)
    """
    p = Path(path)
    if p.is_dir():
        return p
    blocking = next((q for q in [p, *p.parents] if q.exists() and not q.is_dir()), None)
    if blocking is not None:
        raise WriteError(p, f"cannot make the {what} ({blocking} is a file)")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise WriteError(p, f"cannot make the {what} ({e.strerror or e})") from None
    return p


def regular_files(
    folder: str | Path, *, recursive: bool = False, folders: bool = False
) -> tuple[list[Path], list[tuple[Path, str]]]:
    """The regular files in ``folder`` (and its subfolders with ``recursive``; the subfolders
    themselves with ``folders``), sorted, and what was passed over with why: links that lead
    out of the folder, dangling links, loops of links, FIFOs, devices and sockets, names that
    are not UTF-8 text (a listing of them was a 500 from the monitor). Nothing is
    opened (only the status of each entry is asked), so nothing can wait on an entry that
    does not answer; a subfolder reached through a link is not entered.

    >>> import os, tempfile
    >>> d = tempfile.mkdtemp(); _ = write_text(os.path.join(d, "a.csv"), "x")
    >>> os.symlink("/etc/hostname", os.path.join(d, "out.csv")); os.mkfifo(os.path.join(d, "f"))
    >>> files, skipped = regular_files(d)
    >>> [p.name for p in files], sorted((p.name, why) for p, why in skipped)
    (['a.csv'], [('f', 'a FIFO (named pipe)'), ('out.csv', 'a link out of the folder')])
    """
    root = Path(folder)
    base = Path(os.path.realpath(root))
    files: list[Path] = []
    skipped: list[tuple[Path, str]] = []
    pending = [root]
    while pending:
        current = pending.pop()
        try:
            entries = sorted(os.scandir(current), key=lambda e: e.name)
        except OSError as e:
            skipped.append((current, f"cannot be listed ({e.strerror or e})"))
            continue
        for entry in entries:
            path = Path(entry.path)
            why = _entry_problem(entry, path, base)
            if why == "folder":
                if recursive:
                    pending.append(path)
                if folders:
                    files.append(path)
            elif why:
                skipped.append((path, why))
            else:
                files.append(path)
    return sorted(files), skipped


def _entry_problem(entry: os.DirEntry[str], path: Path, base: Path) -> str | None:
    """None for a regular file inside ``base``, "folder" for a real subfolder, else why the
    entry is passed over."""
    if not entry.name.isascii():
        try:  # a name of bytes that are not UTF-8 (lone surrogates to Python): no page,
            entry.name.encode("utf-8")  # report or file texsense writes can hold it
        except UnicodeEncodeError:
            return "a name that is not UTF-8 text"
    try:
        if entry.is_symlink():
            real = Path(os.path.realpath(path))
            if base != real and base not in real.parents:
                return "a link out of the folder"
            st = os.stat(path)
            if stat.S_ISDIR(st.st_mode):
                return "a link to a folder"
        else:
            st = entry.stat(follow_symlinks=False)
    except FileNotFoundError:
        return "a link to nothing"
    except OSError as e:
        return "a loop of symbolic links" if e.errno == errno.ELOOP else (e.strerror or str(e))
    if stat.S_ISDIR(st.st_mode):
        return "folder"
    if not stat.S_ISREG(st.st_mode):
        return _kind(st.st_mode)
    return None


def check_new(path: str | Path) -> Path:
    """``path`` if nothing is there (not even a link to nothing, which ``exists()`` passes and
    an open follows: a live recording would be made where it points), else the one line of
    every live recorder. ``io._guarded.GuardedFile(new=True)`` creates the file exclusively
    anyway; this says it before a recorder starts."""
    if os.path.lexists(path):
        raise ParameterError(f"{path} exists: recordings are never written over; choose a new name")
    return Path(path)


def read_regular(path: str | Path, what: str) -> bytes:
    """The bytes of a regular file that an option names (a model, a calibration, regions,
    credentials), read without ever waiting on it (:func:`open_regular`) and only when its
    size fits the memory budget (:func:`texsense.data.budget.check`): missing, a folder, a
    FIFO, a device or a file larger than the budget is a
    :class:`~texsense.exceptions.FormatError` naming it (``what`` says what it should have
    been)."""
    p = Path(path)
    with open_regular(p) as f:
        size = os.fstat(f.fileno()).st_size
        budget.check(size, what, p)
        return f.read(size + 1)


def read_small_text(path: str | Path, what: str, limit: int = 65536) -> str:
    """The text of a small UTF-8 file (a token, a password, a settings file) of at most
    ``limit`` bytes; a larger file, a device (``/dev/zero``) or a FIFO is refused in one line
    (``what`` names the option it came from)."""
    p = Path(path)
    try:
        with open_regular(p) as f:
            data = f.read(limit + 1)
    except Exception as e:  # FormatError: one line that names the path
        detail = getattr(e, "detail", str(e))
        raise ParameterError(f"{what} {p}: {detail}") from None
    if len(data) > limit:
        raise ParameterError(f"{what} {p}: larger than {limit} bytes, not a small text file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ParameterError(f"{what} {p}: not UTF-8 text") from None


@contextlib.contextmanager
def signals_held() -> Iterator[Callable[[], None]]:
    """Hold SIGINT and SIGTERM (in the main thread) until the block calls ``release()`` or
    ends; a signal that came meanwhile takes effect at the release."""
    held = {signal.SIGINT, signal.SIGTERM}
    main = threading.current_thread() is threading.main_thread()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held) if main else None
    done = False

    def release() -> None:
        nonlocal done
        if previous is not None and not done:
            done = True
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)

    try:
        yield release
    finally:
        release()


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
    temporary name that is renamed when complete; returns the path. The figure is closed,
    written or not (pyplot keeps every open figure: one left open by a refused output stays
    for the life of the process, and a server's or a test's process collects them).

    Raises
    ------
    ParameterError
        If matplotlib cannot write the extension's format.
    WriteError
        If the file could not be written (the previous file is kept).
    """
    try:
        path = Path(path)
        fmt = path.suffix.lstrip(".").lower() or "png"
        if fmt not in fig.canvas.get_supported_filetypes():
            known = ", ".join(sorted(fig.canvas.get_supported_filetypes()))
            raise ParameterError(f"{path}: cannot write a figure as .{fmt}; use one of {known}")
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=fmt, **savefig)  # type: ignore[arg-type]
        return path
    finally:
        pyplot().close(fig)
