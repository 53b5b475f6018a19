"""HDF5 recordings: the texsense on-disk format (schema version 1).

The schema is documented in ``docs/data-model.md`` so that h5py alone can read a file::

    /                      attrs: format="texsense.recording", version=1, quantity, unit,
                                  meta (JSON text), software="texsense <version>"
    /frames                float32 (T, N), chunked, gzip, growable along T
    /times                 float64 (T,), s
    /valid                 bool (T, N)
    /element_times         float64 (T, N), s                         (only if present)
    /labels/<name>         (T,) numbers or UTF-8 strings
    /layout                attrs: kind ("grid" | "points"), rows, cols, pitch_cm (grid only)
    /layout/xy_cm          float64 (N, 2)
    /layout/size_cm        float64 (N, 2)
    /layout/area_cm2       float64 (N,)
    /layout/cells          int64 (N,)                                 (grid only)
    /layout/neighbours_indptr, /layout/neighbours_indices   int64
    /layout/names          UTF-8 strings (N,)                         (only if present)
    /layout/regions/<name> int64 element indices

:class:`RecordingWriter` appends frames while recording and flushes them to disk, so that a
process that is killed leaves a readable file holding everything flushed before.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

from texsense import units
from texsense._core import __version__
from texsense._progress import logger
from texsense.exceptions import FormatError, ParameterError
from texsense.layout import Layout
from texsense.recording import Recording

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "HDF5Chunks",
    "RecordingWriter",
    "read_hdf5",
    "write_hdf5",
]

FORMAT_NAME = "texsense.recording"
FORMAT_VERSION = 1
_STR = h5py.string_dtype("utf-8")


def _software() -> str:

    return f"texsense {__version__}"


def _chunk_rows(n_elements: int) -> int:
    # about 256 KiB of float32 per chunk
    return int(max(1, min(4096, 65536 // max(1, n_elements))))


def _write_layout(group: h5py.Group, layout: Layout) -> None:
    group.attrs["kind"] = layout.kind
    if layout.shape is not None and layout.cells is not None:
        group.attrs["rows"], group.attrs["cols"] = layout.shape
        group.create_dataset("cells", data=layout.cells)
    if layout.pitch_cm is not None:
        group.attrs["pitch_cm"] = np.asarray(layout.pitch_cm, dtype=np.float64)
    group.create_dataset("xy_cm", data=layout.xy_cm)
    group.create_dataset("size_cm", data=layout.size_cm)
    group.create_dataset("area_cm2", data=layout.area_cm2)
    indptr, indices = layout.neighbours
    group.create_dataset("neighbours_indptr", data=indptr)
    group.create_dataset("neighbours_indices", data=indices)
    if layout.names is not None:
        group.create_dataset("names", data=np.array(layout.names, dtype=object), dtype=_STR)
    regions = group.create_group("regions")
    for name, members in layout.regions.items():
        regions.create_dataset(name, data=members)


def _read_layout(group: h5py.Group) -> Layout:
    shape = None
    cells = None
    if group.attrs.get("kind") == "grid":
        shape = (int(group.attrs["rows"]), int(group.attrs["cols"]))
        cells = group["cells"][()]
    pitch = None
    if "pitch_cm" in group.attrs:
        pitch = tuple(float(v) for v in group.attrs["pitch_cm"])
    names = None
    if "names" in group:
        names = list(group["names"].asstr()[()])
    regions = {k: v[()] for k, v in group["regions"].items()} if "regions" in group else {}
    return Layout(
        group["xy_cm"][()],
        group["size_cm"][()],
        area_cm2=group["area_cm2"][()],
        shape=shape,
        cells=cells,
        pitch_cm=pitch,  # type: ignore[arg-type]
        neighbours=(group["neighbours_indptr"][()], group["neighbours_indices"][()]),
        names=names,
        regions=regions,
    )


def _label_dtype(values: np.ndarray) -> Any:
    return _STR if values.dtype.kind == "U" else values.dtype


class RecordingWriter:
    """Append frames to an HDF5 recording while it is being made.

    Every :meth:`append` writes the frames into growable datasets; the file is flushed to disk
    at most ``flush_interval_s`` after the last flush (0: after every append), so a killed
    process loses at most that interval.

    Parameters
    ----------
    path : str or Path
        The file to create (overwritten if it exists).
    layout : Layout
        Element layout.
    quantity, unit : str
        What the frames hold.
    meta : mapping, optional
        JSON-able provenance.
    element_times : bool
        Whether per-element time stamps will be appended.
    flush_interval_s : float
        Longest time between flushes.
    compress : bool
        gzip the frames. Off by default for live recording: a process killed while HDF5
        rewrites a compressed chunk can leave the whole chunk unreadable, while an
        uncompressed chunk is rewritten in place with the same bytes for the rows already
        there. ``write_hdf5`` (one write, then close) compresses; ``texsense convert`` compacts
        a live recording afterwards.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from texsense import Layout, load
    >>> path = os.path.join(tempfile.mkdtemp(), "live.h5")
    >>> with RecordingWriter(path, Layout.grid(2, 2), "pressure", "N/cm2") as w:
    ...     w.append(np.ones((3, 4)), times=[0.0, 0.1, 0.2])
    >>> load(path).n_frames
    3
    """

    def __init__(
        self,
        path: str | Path,
        layout: Layout,
        quantity: str,
        unit: str,
        *,
        meta: dict[str, Any] | None = None,
        element_times: bool = False,
        flush_interval_s: float = 0.0,
        compress: bool = False,
    ) -> None:
        # Validate quantity/unit/meta by building an empty recording.
        probe = Recording(
            np.zeros((0, layout.n_elements)), [], layout, quantity, unit, meta=meta or {}
        )
        self.path = Path(path)
        self.n_elements = layout.n_elements
        self.flush_interval_s = float(flush_interval_s)
        self._last_flush = time.monotonic()
        self._file = h5py.File(self.path, "w")
        f = self._file
        f.attrs["format"] = FORMAT_NAME
        f.attrs["version"] = FORMAT_VERSION
        f.attrs["quantity"] = probe.quantity
        f.attrs["unit"] = probe.unit
        f.attrs["meta"] = json.dumps(probe.meta)
        f.attrs["software"] = _software()
        f.attrs["open"] = 1  # cleared by close(): a file still open was interrupted
        n = layout.n_elements
        rows = _chunk_rows(n)
        comp = {"compression": "gzip", "compression_opts": 4, "shuffle": True} if compress else {}
        f.create_dataset(
            "frames", (0, n), np.float32, maxshape=(None, n), chunks=(rows, max(n, 1)), **comp
        )
        f.create_dataset("times", (0,), np.float64, maxshape=(None,), chunks=(max(rows, 256),))
        f.create_dataset(
            "valid", (0, n), bool, maxshape=(None, n), chunks=(rows, max(n, 1)), **comp
        )
        if element_times:
            f.create_dataset(
                "element_times",
                (0, n),
                np.float64,
                maxshape=(None, n),
                chunks=(rows, max(n, 1)),
                **comp,
            )
        f.create_group("labels")
        _write_layout(f.create_group("layout"), layout)
        f.flush()
        self.n_frames = 0

    def append(
        self,
        frames: npt.ArrayLike,
        times: npt.ArrayLike,
        *,
        valid: npt.ArrayLike | None = None,
        element_times: npt.ArrayLike | None = None,
        labels: Mapping[str, npt.ArrayLike] | None = None,
    ) -> None:
        """Append one frame (N,) or a block of frames (k, N) with their time stamps."""
        f = self._file
        fr = np.asarray(frames, dtype=np.float32)
        if fr.ndim == 1:
            fr = fr[None, :]
        k = fr.shape[0]
        if fr.shape != (k, self.n_elements):
            raise ParameterError(
                f"append: expected frames of {self.n_elements} elements, got shape {fr.shape}"
            )
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        if t.shape != (k,):
            raise ParameterError(f"append: expected {k} time stamps, got {t.shape}")
        v = np.ones_like(fr, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
        v = v.reshape(k, self.n_elements)
        has_et = "element_times" in f
        if has_et != (element_times is not None):
            raise ParameterError(
                "append: element_times must be given exactly when the writer was opened "
                "with element_times=True"
            )
        labels = labels or {}
        label_group = f["labels"]
        if self.n_frames > 0 and set(labels) != set(label_group):
            raise ParameterError(
                f"append: labels {sorted(labels)} differ from the first append's "
                f"{sorted(label_group)}"
            )
        start, stop = self.n_frames, self.n_frames + k
        for name, values in labels.items():
            arr = np.atleast_1d(np.asarray(values))
            if arr.shape != (k,):
                raise ParameterError(f"append: label {name!r} needs {k} values")
            if name not in label_group:
                label_group.create_dataset(
                    name, (0,), _label_dtype(arr), maxshape=(None,), chunks=(256,)
                )
            ds = label_group[name]
            ds.resize((stop,))
            ds[start:stop] = arr.astype(object) if arr.dtype.kind == "U" else arr
        for name, data in (("frames", fr), ("valid", v), ("times", t)):
            ds = f[name]
            ds.resize(stop, axis=0)
            ds[start:stop] = data
        if has_et:
            ds = f["element_times"]
            ds.resize(stop, axis=0)
            ds[start:stop] = np.asarray(element_times, dtype=np.float64).reshape(k, -1)
        self.n_frames = stop
        now = time.monotonic()
        if now - self._last_flush >= self.flush_interval_s:
            f.flush()
            self._last_flush = now

    def flush(self) -> None:
        """Write everything appended so far to disk."""
        self._file.flush()
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Flush and close the file."""
        if self._file.id.valid:
            self._file.attrs["open"] = 0
            self._file.flush()
            self._file.close()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_hdf5(rec: Recording, path: str | Path) -> Path:
    """Write ``rec`` to ``path`` (HDF5, schema version 1) and return the path."""
    path = Path(path)
    with RecordingWriter(
        path,
        rec.layout,
        rec.quantity,
        rec.unit,
        meta=rec.meta,
        element_times=rec.element_times is not None,
        compress=True,
    ) as w:
        if rec.n_frames:
            w.append(
                rec.frames,
                rec.times,
                valid=rec.valid,
                element_times=rec.element_times,
                labels=rec.labels,
            )
        else:
            for name, values in rec.labels.items():
                w._file["labels"].create_dataset(
                    name, (0,), _label_dtype(values), maxshape=(None,), chunks=(256,)
                )
    return path


def _open(path: Path) -> h5py.File:
    try:
        return h5py.File(path, "r")
    except OSError as e:
        if "already open for write" in str(e):
            # A writer was killed while the file was in SWMR mode: the data are consistent,
            # only the "open for writing" flag is left. Reading in SWMR mode is safe.
            return h5py.File(path, "r", libver="latest", swmr=True)
        raise FormatError(path, f"not a readable HDF5 file ({e})") from None


def _read_prefix(ds: h5py.Dataset, n: int) -> tuple[np.ndarray, int]:
    """Read the first ``n`` rows of ``ds``; if a chunk is unreadable (a write was killed
    halfway), return the rows before it and how many there are."""
    try:
        return ds[:n], n
    except OSError:
        pass
    rows = ds.chunks[0] if ds.chunks else 1
    parts = []
    got = 0
    while got < n:
        stop = min(n, got + rows)
        try:
            parts.append(ds[got:stop])
        except OSError:
            break
        got = stop
    empty = ds[:0]
    return (np.concatenate(parts) if parts else empty), got


def read_hdf5(path: str | Path) -> Recording:
    """Read a texsense HDF5 recording.

    Raises
    ------
    FormatError
        If the file is not HDF5, not a texsense recording, of an unknown schema version, or
        lacks a required dataset.
    """
    path = Path(path)
    with _open(path) as f:
        fmt = f.attrs.get("format")
        if fmt != FORMAT_NAME:
            raise FormatError(
                path, f"HDF5 file is not a texsense recording (format attribute is {fmt!r})"
            )
        version = int(f.attrs.get("version", -1))
        if version != FORMAT_VERSION:
            raise FormatError(
                path,
                f"unknown texsense recording version {version}; this texsense reads "
                f"version {FORMAT_VERSION}",
            )
        try:
            # A writer killed between two dataset resizes can leave them one block apart,
            # and one killed while writing a compressed chunk leaves that chunk unreadable:
            # only the frames readable in every dataset are complete.
            sets = {k: f[k] for k in ("frames", "times", "valid", "element_times") if k in f}
            sets.update({f"labels/{k}": v for k, v in f["labels"].items()})
            n = min(ds.shape[0] for ds in sets.values())
            data = {}
            for key, ds in sets.items():
                arr, readable = _read_prefix(ds, n)
                data[key] = arr
                n = min(n, readable)
            if int(f.attrs.get("open", 0)):
                # interrupted while recording: rows whose time stamp was not written yet
                # read as 0 and end the complete part
                t_all = data["times"][:n]
                bad = np.nonzero(~(np.diff(t_all) > 0))[0]
                if bad.size:
                    n = int(bad[0]) + 1
            lost = min(ds.shape[0] for ds in sets.values()) - n
            frames, times, valid = (data[k][:n] for k in ("frames", "times", "valid"))
            element_times = data["element_times"][:n] if "element_times" in data else None
            labels = {}
            for name, ds in f["labels"].items():
                values = data[f"labels/{name}"][:n]
                labels[name] = (
                    np.array([v.decode() if isinstance(v, bytes) else v for v in values], dtype=str)
                    if ds.dtype.kind == "O"
                    else values
                )
            layout = _read_layout(f["layout"])
            quantity = str(f.attrs["quantity"])
            unit = units.canonical(str(f.attrs["unit"]))
            meta = json.loads(f.attrs.get("meta", "{}"))
        except KeyError as e:
            raise FormatError(path, f"missing dataset or attribute: {e}") from None
    if lost:
        logger.warning(
            "%s: %d frame(s) at the end were unreadable (interrupted write) and are left out",
            path,
            lost,
        )
        meta = {**meta, "recovered": {"frames_read": int(n), "frames_unreadable": int(lost)}}
    return Recording(
        frames,
        times,
        layout,
        quantity,
        unit,
        valid=valid,
        element_times=element_times,
        labels=labels,
        meta=meta,
    )


class HDF5Chunks:
    """Read a texsense HDF5 recording a block of frames at a time (constant memory).

    The header (layout, quantity, unit, meta, label names) is read on opening; iterating
    yields :class:`Recording` blocks of at most ``frames`` frames. A file left open by an
    interrupted writer is read whole by :func:`read_hdf5` instead (its recovery needs the
    time stamps of every frame) and yielded in blocks.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from texsense import Layout, Recording
    >>> path = os.path.join(tempfile.mkdtemp(), "r.h5")
    >>> _ = write_hdf5(Recording(np.ones((10, 4)), np.arange(10.0), Layout.grid(2, 2)), path)
    >>> with HDF5Chunks(path, frames=4) as chunks:
    ...     [block.n_frames for block in chunks]
    [4, 4, 2]
    """

    def __init__(self, path: str | Path, frames: int = 4096) -> None:
        if frames < 1:
            raise ParameterError(f"frames per block must be >= 1, got {frames}")
        self.path = Path(path)
        self.frames = int(frames)
        self._file = _open(self.path)
        f = self._file
        try:
            if f.attrs.get("format") != FORMAT_NAME:
                raise FormatError(self.path, "HDF5 file is not a texsense recording")
            if int(f.attrs.get("version", -1)) != FORMAT_VERSION:
                raise FormatError(
                    self.path, f"unknown texsense recording version {f.attrs.get('version')}"
                )
            self.layout = _read_layout(f["layout"])
            self.quantity = str(f.attrs["quantity"])
            self.unit = units.canonical(str(f.attrs["unit"]))
            self.meta = json.loads(f.attrs.get("meta", "{}"))
            self.label_names = sorted(f["labels"])
            self.has_element_times = "element_times" in f
            keys = ["frames", "times", "valid"] + (
                ["element_times"] if self.has_element_times else []
            )
            sets = [f[k] for k in keys] + [f["labels"][k] for k in self.label_names]
            self.n_frames = min(ds.shape[0] for ds in sets)
            self._interrupted = bool(int(f.attrs.get("open", 0)))
        except KeyError as e:
            self.close()
            raise FormatError(self.path, f"missing dataset or attribute: {e}") from None
        except Exception:
            self.close()
            raise

    def __iter__(self) -> Iterator[Recording]:
        if self._interrupted:
            whole = read_hdf5(self.path)
            for a in range(0, whole.n_frames, self.frames):
                yield whole.select(slice(a, a + self.frames))
            return
        f = self._file
        for a in range(0, self.n_frames, self.frames):
            b = min(self.n_frames, a + self.frames)
            labels = {}
            for name in self.label_names:
                ds = f["labels"][name]
                values = ds[a:b]
                labels[name] = (
                    np.array([v.decode() if isinstance(v, bytes) else v for v in values], dtype=str)
                    if ds.dtype.kind == "O"
                    else values
                )
            yield Recording(
                f["frames"][a:b],
                f["times"][a:b],
                self.layout,
                self.quantity,
                self.unit,
                valid=f["valid"][a:b],
                element_times=f["element_times"][a:b] if self.has_element_times else None,
                labels=labels,
                meta=self.meta,
            )

    def close(self) -> None:
        """Close the file."""
        if self._file.id.valid:
            self._file.close()

    def __enter__(self) -> HDF5Chunks:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
