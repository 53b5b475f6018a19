"""A file object for h5py that keeps a failed write from HDF5.

HDF5 cannot recover from a write that the operating system refused (a full disk, a file-size
limit): its file stays half-closed and the process crashed when it closed the file at exit
(``texsense convert`` under ``ulimit -f`` ended in a segmentation fault). Written through
:class:`GuardedFile`, HDF5 never sees the failure: the first ``OSError`` is kept, later writes
are dropped, and the writer raises the kept error once HDF5 has closed the file. After the
guard is closed (a writer stopped mid-way, whose HDF5 file object is let go later), what HDF5
still writes is dropped: the file is being discarded.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

from texsense.data.files import check_new

__all__ = ["GuardedFile"]


class GuardedFile(io.RawIOBase):
    """The file h5py writes through (``h5py.File(GuardedFile(path), "w")``): the first
    failed write is kept in :attr:`error` and later writes are dropped.

    Examples
    --------
    >>> import os, tempfile, h5py
    >>> path = os.path.join(tempfile.mkdtemp(), "g.h5")
    >>> guard = GuardedFile(path)
    >>> with h5py.File(guard, "w") as f:
    ...     f["x"] = [1, 2, 3]
    >>> guard.close(); guard.error is None
    True
    """

    def __init__(self, path: Path, *, new: bool = False) -> None:
        super().__init__()
        try:  # new: a file made here (O_EXCL: nothing there, not even a link to nothing)
            self._f = open(path, "x+b" if new else "w+b", buffering=0)  # noqa: SIM115
        except FileExistsError:  # (closed by close())
            check_new(path)
            raise
        self.error: OSError | None = None

    def readable(self) -> bool:
        return True

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, pos: int, whence: int = 0) -> int:
        return pos if self._f.closed else self._f.seek(pos, whence)

    def tell(self) -> int:
        return 0 if self._f.closed else self._f.tell()

    def readinto(self, b: Any) -> int:
        return 0 if self._f.closed else self._f.readinto(b) or 0

    def write(self, b: Any) -> int:
        view = memoryview(b).cast("B")
        if self._f.closed:  # HDF5 letting go of a file whose writer was stopped: discarded
            return len(view)
        if self.error is None:
            try:
                done = 0
                while done < len(view):
                    done += self._f.write(view[done:]) or 0
                return len(view)
            except OSError as e:
                self.error = e
        self._f.seek(len(view), 1)
        return len(view)

    def truncate(self, size: int | None = None) -> int:
        if self._f.closed:
            return 0 if size is None else size
        if self.error is None:
            try:
                return self._f.truncate(size)
            except OSError as e:
                self.error = e
        return self._f.tell() if size is None else size

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self._f.close()
        super().close()
