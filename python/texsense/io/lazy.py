"""Recordings read on demand: a texsense HDF5 recording of any length, longer than the memory
budget, opened as a :class:`~texsense.Recording` whose frames stay in the file until they are
indexed (what the monitor's playback plays, docs/monitor.md "Playback").

:func:`texsense.io.open_recording` opens a texsense recording (``.h5``) as a
:class:`LazyRecording`: its
header, its times and its labels are read (one per frame: the timeline a player needs), its
frames and validity are not. ``rec.frames[i]``, ``rec.frames[a:b]``, ``rec.select(...)`` read
the frames asked for (HDF5 reads the chunks that hold them) with the reader's own checks
(unit, impossible readings invalid); short reads go through one cache of blocks of frames
(:data:`CACHE`) shared by every lazy recording and bounded by a quarter of the memory budget
(:mod:`texsense.data.budget`); a long read (a block of statistics) is read straight from the
file and checked against the budget first. What needs all frames at once
(``np.asarray(rec.frames)``, ``rec.to_unit``) reads them all if they fit the budget and
refuses in one line naming the file otherwise.

The text formats (Tekscan, XSENSOR, pliance, CSV, PMD) are read from their start only: for
them :func:`texsense.io.open_recording` reads the whole file, within the budget (one line
refuses a file beyond it).

Examples
--------
>>> import numpy as np, texsense
>>> from texsense.io import open_recording
>>> path = texsense.Recording(np.arange(12.0).reshape(4, 3), [0, 1, 2, 3],
...                           texsense.Layout.grid(1, 3)).save(getfixture("tmp_path") / "a.h5")
>>> rec = open_recording(path)
>>> type(rec).__name__, rec.n_frames, rec.frames[2].tolist(), rec.select(slice(3, 4)).frames
('LazyRecording', 4, [6.0, 7.0, 8.0], array([[ 9., 10., 11.]], dtype=float32))
"""

from __future__ import annotations

import itertools
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np

from texsense.data import budget
from texsense.data.layout import Layout
from texsense.data.recording import Recording
from texsense.exceptions import FormatError
from texsense.io._base import Piece

__all__ = ["CACHE", "CACHE_SHARE", "FrameCache", "LazyRecording"]

#: The share of the memory budget that the cache of frames may hold.
CACHE_SHARE = 0.25
#: Bytes per frame a player holds besides the labels: the times, what a review computes per
#: frame (load, peak, contact area, centre of force, wall clock, usable: 96 bytes) and the
#: page's copy of the times while it is sent (a number in JSON and as a Python float).
TIMELINE_BYTES = 160
#: Frames of times and labels read at a time while opening.
_TIMELINE_BLOCK = 1 << 16
#: A cache block holds at most this share of the cache (a seek reads one or two blocks).
_BLOCK_SHARE = 16


class FrameCache:
    """The blocks of frames read last (least recently used forgotten first), at most
    :data:`CACHE_SHARE` of the memory budget together."""

    def __init__(self) -> None:
        self._blocks: OrderedDict[tuple[int, int], tuple[Piece, int]] = OrderedDict()
        self._lock = threading.Lock()
        self._held = 0

    @staticmethod
    def limit() -> int:
        """The most bytes the cache holds (:data:`CACHE_SHARE` of the budget)."""
        return int(budget.max_memory() * CACHE_SHARE)

    def held(self) -> int:
        """Bytes the cached blocks hold."""
        with self._lock:
            return self._held

    def get(self, key: tuple[int, int]) -> Piece | None:
        """The block ``key`` (a source's token, a block number), if cached."""
        with self._lock:
            found = self._blocks.get(key)
            if found is None:
                return None
            self._blocks.move_to_end(key)
            return found[0]

    def put(self, key: tuple[int, int], piece: Piece) -> None:
        """Keep ``piece``, forgetting the oldest blocks until all fit the limit."""
        size = sum(a.nbytes for a in (piece.values, piece.valid, piece.element_times)
                   if a is not None)  # fmt: skip
        limit = self.limit()
        with self._lock:
            if key in self._blocks:
                return
            while self._blocks and self._held + size > limit:
                _, (_, old) = self._blocks.popitem(last=False)
                self._held -= old
            if size <= limit:
                self._blocks[key] = (piece, size)
                self._held += size

    def forget(self, token: int) -> None:
        """Drop the blocks of one source."""
        with self._lock:
            for key in [k for k in self._blocks if k[0] == token]:
                self._held -= self._blocks.pop(key)[1]


#: The one cache of every lazy recording.
CACHE = FrameCache()
_tokens = itertools.count()


class _Source:
    """One HDF5 recording file: its reader (opened again when closed), its timeline, and the
    frames read in cache blocks of whole HDF5 chunks."""

    def __init__(self, path: Path) -> None:
        from texsense.io.hdf5 import HDF5Reader

        self.path = path
        self.token = next(_tokens)
        self._lock = threading.Lock()
        self._reader: HDF5Reader | None = HDF5Reader(path)
        r = self._reader
        try:
            self.header = r.header
            self.n = int(r.n_frames)
            n_el = self.header.layout.n_elements
            self.row_bytes = n_el * (5 + (8 if self.header.element_times else 0))
            self.times, self.labels = self._timeline(r)
            chunks = r._sets["frames"].chunks
            most = max(1, CACHE.limit() // _BLOCK_SHARE // max(self.row_bytes, 1))
            self.block = int(min(chunks[0] if chunks else 256, most))
        except BaseException:
            r.close()
            raise

    def _timeline(self, r: Any) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Times and labels of every frame, checked against the budget as they come."""
        hint = "its times and labels alone do not fit"
        budget.check(self.n * TIMELINE_BYTES, f"the timeline of {self.n} frames", self.path, hint)
        times: list[np.ndarray] = []
        labels: dict[str, list[np.ndarray]] = {}
        held = self.n * TIMELINE_BYTES
        for t, lab in r.timeline(_TIMELINE_BLOCK):
            times.append(t)
            for k, v in lab.items():
                labels.setdefault(k, []).append(v)
                held += v.nbytes
            budget.check(held, f"the timeline of {self.n} frames", self.path, hint)
        dtypes = r.header.label_dtypes
        t_all = np.concatenate(times) if times else np.zeros(0)
        lab_all = {k: np.concatenate(labels[k]) if k in labels else np.zeros(0, dtype=dt)
                   for k, dt in dtypes.items()}  # fmt: skip
        return t_all, lab_all

    def _read(self, a: int, b: int) -> Piece:
        from texsense.io.hdf5 import HDF5Reader
        from texsense.io.policy import DAMAGED  # (loads h5py, as the reader does)

        with self._lock:
            try:
                if self._reader is None:
                    self._reader = HDF5Reader(self.path)
                    if self._reader.n_frames < self.n:
                        raise FormatError(self.path, "the file changed: it holds fewer frames")
                piece = self._reader.frames_at(a, b)
            except DAMAGED as e:
                raise FormatError(self.path, f"frames {a + 1}..{b} cannot be read ({e})") from None
        et = piece.element_times
        return Piece(piece.values, piece.times, {}, valid=piece.valid,
                     element_times=None if et is None else np.asarray(et, np.float64))  # fmt: skip

    def rows(self, a: int, b: int) -> Piece:
        """Frames ``a:b`` (``0 <= a <= b <= n``): through the cache when they lie in at most
        two of its blocks, else straight from the file within the budget."""
        if b - a > 2 * self.block:
            what = f"frames {a}..{b - 1} of {self.header.layout.n_elements} elements"
            budget.check((b - a) * self.row_bytes, what, self.path)
            return self._read(a, b)
        parts = []
        for k in range(a // self.block, (b - 1) // self.block + 1 if b > a else a // self.block):
            key = (self.token, k)
            piece = CACHE.get(key)
            if piece is None:
                piece = self._read(k * self.block, min(self.n, (k + 1) * self.block))
                CACHE.put(key, piece)
            parts.append(piece)
        if not parts:
            return self._read(a, a)
        lo = a - (a // self.block) * self.block

        def cut(name: str) -> Any:
            arrays = [getattr(p, name) for p in parts]
            if arrays[0] is None:
                return None
            return (np.concatenate(arrays) if len(arrays) > 1 else arrays[0])[lo : lo + b - a]

        return Piece(cut("values"), cut("times"), {}, valid=cut("valid"),
                     element_times=cut("element_times"))  # fmt: skip

    def close(self) -> None:
        """Close the file (read again on demand) and forget its cached blocks."""
        with self._lock:
            if self._reader is not None:
                self._reader.close()
                self._reader = None
        CACHE.forget(self.token)


class _Column:
    """A (frames, elements) array of a :class:`LazyRecording` that reads what is indexed:
    an integer, a slice, integer indices or a boolean mask over frames (then any index over
    the elements)."""

    ndim = 2
    nbytes = 0  # the frames it read are held by the cache (CACHE), counted there

    def __init__(self, owner: LazyRecording, name: str, dtype: Any) -> None:
        self._owner = owner
        self._name = name
        self.dtype = np.dtype(dtype)

    @property
    def shape(self) -> tuple[int, int]:
        return (self._owner._source.n, self._owner.layout.n_elements)

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, index: Any) -> Any:
        if isinstance(index, tuple):  # frames first, then the elements of what was read
            rows, rest = self[index[0]], index[1:]
            return rows[rest] if isinstance(index[0], (int, np.integer)) else rows[:, *rest]
        n = self.shape[0]
        if isinstance(index, (int, np.integer)):
            i = int(index) + (n if index < 0 else 0)
            if not 0 <= i < n:
                raise IndexError(f"frame {int(index)} is out of range 0..{n - 1}")
            return self._owner._rows(i, i + 1)[self._name][0]
        if isinstance(index, slice):
            start, stop, step = index.indices(n)
            if step == 1:
                return self._owner._rows(start, max(start, stop))[self._name]
            index = np.arange(start, stop, step)
        idx = np.asarray(index)
        if idx.dtype == bool:
            idx = np.flatnonzero(idx)
        idx = np.where(idx < 0, idx + n, idx).astype(np.int64)
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise IndexError(f"frame index out of range 0..{n - 1}")
        what = f"{idx.size} frames of {self.shape[1]} elements"
        budget.check(idx.size * self._owner._source.row_bytes, what, self._owner._source.path)
        out = np.empty((idx.size, self.shape[1]), self.dtype)
        for k, i in enumerate(idx):
            out[k] = self._owner._rows(int(i), int(i) + 1)[self._name][0]
        return out

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        """All of it (read within the budget, or a one-line refusal naming the file)."""
        whole = self[:]
        return whole if dtype is None else whole.astype(dtype)

    def astype(self, dtype: Any, **kwargs: Any) -> np.ndarray:
        """All of it as ``dtype`` (see :meth:`__array__`)."""
        return np.asarray(self).astype(dtype, **kwargs)


class LazyRecording(Recording):
    """A :class:`~texsense.Recording` whose ``frames``, ``valid`` and ``element_times`` stay
    in the file until indexed (see the module); ``times``, ``labels``, ``layout`` and
    ``meta`` are in memory. Everything derived from it (``select``, ``to_unit``, ...) is an
    ordinary recording."""

    def __init__(self, source: _Source, layout: Layout, *, repairs: bool = False) -> None:
        # no Recording.__init__: it would read every frame to check them
        h = source.header
        self._source = source
        self._repairs = repairs
        self.layout = layout
        self.quantity = h.quantity
        self.unit = h.unit
        self.times = source.times
        self.labels = source.labels
        self.meta = dict(h.meta)
        self.frames: Any = _Column(self, "frames", np.float32)
        self.valid: Any = _Column(self, "valid", bool)
        self.element_times: Any = (
            _Column(self, "element_times", np.float64) if h.element_times else None
        )

    @classmethod
    def open(cls, path: str | Path) -> LazyRecording:
        """Open a texsense HDF5 recording (its header and timeline are read and checked)."""
        source = _Source(Path(path))
        return cls(source, source.header.layout)

    @property
    def path(self) -> Path:
        """The file the frames are read from."""
        return self._source.path

    def with_repairs(self) -> LazyRecording:
        """The same frames where every finite reading counts as valid (a pressure
        recording's repaired readings: :func:`texsense.apps.review.open_review`)."""
        return LazyRecording(self._source, self.layout, repairs=True)

    def with_layout(self, layout: Layout) -> LazyRecording:
        """The same frames on ``layout`` (same elements: e.g. with an orientation)."""
        if layout.n_elements != self.layout.n_elements:
            raise ValueError("another number of elements")
        return LazyRecording(self._source, layout, repairs=self._repairs)

    def _rows(self, a: int, b: int) -> dict[str, Any]:
        p = self._source.rows(a, b)
        valid = np.isfinite(p.values) if self._repairs else p.valid
        return {"frames": p.values, "valid": valid, "element_times": p.element_times}

    def close(self) -> None:
        """Close the file and forget the cached frames (they are read again if asked for)."""
        self._source.close()
