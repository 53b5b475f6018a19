"""HDF5 recordings: the texsense on-disk format (schema version 1).

The schema is documented in ``docs/data-model.md`` so that h5py alone can read a file::

    /                      attrs: format="texsense.recording", version=1, quantity, unit,
                                  meta (JSON text), software="texsense <version>",
                                  open (1 while written), live (1: appendable recording)
    /frames                float32 (T, N), chunked, gzip, growable along T
    /times                 float64 (T,), s
    /valid                 bool (T, N)
    /element_times         float64 (T, N), s                         (only if present)
    /lower, /upper         float32 (T, N): the bound of every value   (only with bounds)
    /labels/<name>         (T,) numbers or UTF-8 strings, attr name (as for regions)
    /layout                attrs: kind ("grid" | "points"), rows, cols, pitch_cm (grid only),
                                  orientation (JSON, edge -> label; only if declared)
    /layout/xy_cm          float64 (N, 2)
    /layout/size_cm        float64 (N, 2)
    /layout/area_cm2       float64 (N,)
    /layout/cells          int64 (N,)                                 (grid only)
    /layout/neighbours_indptr, /layout/neighbours_indices   int64
    /layout/names          UTF-8 strings (N,)                         (only if present)
    /layout/regions/<name> int64 element indices, attr name (a name HDF5 cannot hold as a
                           link name, "left/heel", is stored as "#<k>" with its name here)

:class:`RecordingWriter` appends frames while recording and flushes them to disk, so that a
process that is killed leaves a readable file holding everything flushed before (``live``).
:func:`write_hdf5` writes a whole recording under a temporary name and renames it when
complete; a file it did not finish (``open`` still 1, ``live`` 0) is refused by the reader.
Writes go through a file object that keeps HDF5 from ever seeing a failed write (a full disk,
a file-size limit): HDF5 then crashed the process when closing; now the writer raises the
``OSError`` once HDF5 is done, and the previous file is kept.

:class:`HDF5Reader` reads a file a block of frames at a time (:mod:`texsense.io._base`).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

from texsense._core import __version__
from texsense._progress import logger
from texsense.data import budget, units
from texsense.data.files import atomic_path, json_loads, signals_held
from texsense.data.layout import Layout
from texsense.data.recording import Recording
from texsense.exceptions import FormatError, ParameterError
from texsense.io._base import Header, Piece, RecordingReader, plausible
from texsense.io._guarded import GuardedFile
from texsense.io._registry import Probe, writer
from texsense.io.policy import (
    DAMAGED,
    check_json,
    check_strings,
    check_text,
    link_name,
    named,
    open_hdf5,
    text_of,
)

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "HDF5Reader",
    "RecordingWriter",
    "read_bounds",
    "write_hdf5",
]

#: The first bytes of every HDF5 file.
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
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
    if layout.orientation:
        group.attrs["orientation"] = check_json(layout.orientation, "the layout's orientation")
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
    for k, (name, members) in enumerate(layout.regions.items()):
        ds = regions.create_dataset(link_name(name, k), data=members)
        ds.attrs["name"] = name


def _check_texts(layout: Layout, probe: Recording) -> str:
    """Every text HDF5 is to keep, checked before the file is made (a writer that cannot
    represent something refuses before writing); returns the metadata's JSON text, the one
    the file keeps."""
    for name in layout.names or ():
        check_text(name, "element name")
    for name in layout.regions:
        check_text(name, "region name")
    meta = check_json(probe.meta)
    for value in (probe.quantity, probe.unit, meta):
        check_text(value, "the recording's metadata")
    return meta


def _whole(ds: h5py.Dataset) -> Any:
    """All of a dataset of the layout, once the memory budget has seen its declared size (a
    few compressed bytes can declare gigabytes)."""
    if not isinstance(ds, h5py.Dataset):
        raise TypeError(f"{ds.name} is not a dataset")
    itemsize = 64 if ds.dtype.kind == "O" else ds.dtype.itemsize
    budget.check(ds.size * itemsize, f"the dataset {ds.name}", ds.file.filename)
    check_strings(ds)
    return ds[()]


def _read_layout(group: h5py.Group) -> Layout:
    shape = None
    cells = None
    if group.attrs.get("kind") == "grid":
        shape = (group.attrs["rows"], group.attrs["cols"])  # whole numbers: checked by Layout
        cells = _whole(group["cells"])
    pitch = None
    if "pitch_cm" in group.attrs:
        pitch = tuple(float(v) for v in group.attrs["pitch_cm"])
    names = None
    if "names" in group:
        names = [_text(v) for v in _whole(group["names"]).ravel()]
    regions = {}
    for key, ds in group["regions"].items() if "regions" in group else ():
        regions[_text(ds.attrs.get("name", key))] = _whole(ds)
    orientation = None
    if "orientation" in group.attrs:
        orientation = json_loads(_text(group.attrs["orientation"]))
    return Layout(
        _whole(group["xy_cm"]),
        _whole(group["size_cm"]),
        area_cm2=_whole(group["area_cm2"]),
        shape=shape,
        cells=cells,
        pitch_cm=pitch,  # type: ignore[arg-type]
        neighbours=(_whole(group["neighbours_indptr"]), _whole(group["neighbours_indices"])),
        names=names,
        regions=regions,
        orientation=orientation,
    )


_text = text_of  # every text of the file (bytes not UTF-8 become U+FFFD)


def _label_dtype(values: np.ndarray) -> Any:
    return _STR if values.dtype.kind == "U" else values.dtype


class RecordingWriter:
    """Append frames to an HDF5 recording while it is being made.

    Readings that every reader finds impossible (not a number, infinite, a negative pressure,
    beyond any sensor: :func:`texsense.io._base.impossible`) are written as invalid.

    Every :meth:`append` writes the frames into growable datasets; the file is flushed to disk
    at most ``flush_interval_s`` after the last flush (0: after every append), so a killed
    process loses at most that interval.

    Parameters
    ----------
    path : str or Path
        The file to create: a live one refuses a path where anything is (never written over:
        :func:`texsense.io._guarded.check_new`); ``live=False`` (a temporary name) overwrites.
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
    live : bool
        A live recording (the default): a file left open by a killed writer is read up to its
        last flushed frame. False for a file written in one go (under a temporary name, see
        :func:`write_hdf5`): a reader refuses such a file if it was not closed.

    Raises
    ------
    OSError
        From :meth:`append`, :meth:`flush` or :meth:`close` when the disk refused a write (the
        file is then incomplete; :meth:`close` still releases it).

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
        live: bool = True,
        bounds: bool = False,
    ) -> None:
        # Validate quantity/unit/meta by building an empty recording.
        probe = Recording(
            np.zeros((0, layout.n_elements)), [], layout, quantity, unit, meta=meta or {}
        )
        self.path = Path(path)
        self.n_elements = layout.n_elements
        self.quantity = probe.quantity
        self.flush_interval_s = float(flush_interval_s)
        self._last_flush = time.monotonic()
        meta_text = _check_texts(layout, probe)
        self._label_keys: dict[str, str] = {}
        self._guard = GuardedFile(self.path, new=live)  # live: a new file (never written over)
        try:
            self._file = h5py.File(self._guard, "w")
            self._create(layout, probe, meta_text, element_times, compress, live)
            if bounds:  # the lower and upper maps of every value (issue 37)
                for name in ("lower", "upper"):
                    self._file.create_dataset(name, (0, self.n_elements), np.float32,
                                              **self._grow)  # fmt: skip
        except BaseException:
            self.close()
            raise
        self.n_frames = 0

    def _create(
        self,
        layout: Layout,
        probe: Recording,
        meta_text: str,
        element_times: bool,
        compress: bool,
        live: bool,
    ) -> None:
        f = self._file
        f.attrs["format"] = FORMAT_NAME
        f.attrs["version"] = FORMAT_VERSION
        f.attrs["quantity"] = probe.quantity
        f.attrs["unit"] = probe.unit
        f.attrs["meta"] = meta_text
        f.attrs["software"] = _software()
        f.attrs["open"] = 1  # cleared by close(): a file still open was interrupted
        f.attrs["live"] = int(live)
        n = layout.n_elements
        rows = _chunk_rows(n)
        comp = {"compression": "gzip", "compression_opts": 4, "shuffle": True} if compress else {}
        grow = {"maxshape": (None, n), "chunks": (rows, max(n, 1))}
        self._grow = {**grow, **comp}
        f.create_dataset("frames", (0, n), np.float32, **grow, **comp)
        f.create_dataset("times", (0,), np.float64, maxshape=(None,), chunks=(max(rows, 256),))
        f.create_dataset("valid", (0, n), bool, **grow, **comp)
        if element_times:
            f.create_dataset("element_times", (0, n), np.float64, **grow, **comp)
        f.create_group("labels")
        _write_layout(f.create_group("layout"), layout)
        self.flush()

    def _check(self) -> None:
        if self._guard.error is not None:
            raise self._guard.error

    def append(
        self,
        frames: npt.ArrayLike,
        times: npt.ArrayLike,
        *,
        valid: npt.ArrayLike | None = None,
        element_times: npt.ArrayLike | None = None,
        labels: Mapping[str, npt.ArrayLike] | None = None,
        lower: npt.ArrayLike | None = None,
        upper: npt.ArrayLike | None = None,
    ) -> None:
        """Append one frame (N,) or a block of frames (k, N) with their time stamps (and,
        for a writer with ``bounds``, the lower and upper maps)."""
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
        # what every reader will find impossible is written as invalid (a compensated
        # pressure below zero, say): the file says what it holds, and reading it warns of nothing
        v = v.reshape(k, self.n_elements) & plausible(fr, self.quantity)
        has_et = "element_times" in f
        if has_et != (element_times is not None):
            raise ParameterError(
                "append: element_times must be given exactly when the writer was opened "
                "with element_times=True"
            )
        start, stop = self.n_frames, self.n_frames + k
        if ("lower" in f) != (lower is not None and upper is not None):
            raise ParameterError("append: lower and upper go with a writer opened with bounds")
        self._append_labels(labels or {}, start, stop)
        if lower is not None and upper is not None:
            for name, data in (("lower", lower), ("upper", upper)):
                ds = f[name]
                ds.resize(stop, axis=0)
                ds[start:stop] = np.asarray(data, dtype=np.float32).reshape(k, self.n_elements)
        for name, data in (("frames", fr), ("valid", v), ("times", t)):
            ds = f[name]
            ds.resize(stop, axis=0)
            ds[start:stop] = data
        if has_et:
            ds = f["element_times"]
            ds.resize(stop, axis=0)
            ds[start:stop] = np.asarray(element_times, dtype=np.float64).reshape(k, -1)
        self.n_frames = stop
        if time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()
        self._check()

    def _append_labels(self, labels: Mapping[str, npt.ArrayLike], start: int, stop: int) -> None:
        keys = self._label_keys
        if self.n_frames > 0 and set(labels) != set(keys):
            raise ParameterError(
                f"append: labels {sorted(labels)} differ from the first append's {sorted(keys)}"
            )
        arrays = {name: np.atleast_1d(np.asarray(values)) for name, values in labels.items()}
        for name, arr in arrays.items():
            if arr.shape != (stop - start,):
                raise ParameterError(f"append: label {name!r} needs {stop - start} values")
            check_text(name, "label name")
            if arr.dtype.kind == "U":
                for value in np.unique(arr):
                    check_text(str(value), f"a value of the label {name!r}")
        for name, arr in arrays.items():
            if name not in keys:
                self.add_label(name, arr.dtype)
            ds = self._file["labels"][keys[name]]
            ds.resize((stop,))
            ds[start:stop] = arr.astype(object) if arr.dtype.kind == "U" else arr

    def update_meta(self, extra: Mapping[str, Any]) -> None:
        """Add ``extra`` to the file's ``meta`` (e.g. a state known only at the end: the
        in-use drift correction)."""
        meta = json_loads(self._file.attrs["meta"])
        meta.update(extra)
        self._file.attrs["meta"] = check_json(meta)

    def add_label(self, name: str, dtype: Any) -> None:
        """Create the (empty) label ``name`` of ``dtype`` (strings: a numpy ``U`` dtype)."""
        check_text(name, "label name")
        key = self._label_keys[name] = link_name(name, len(self._label_keys))
        h5type = _STR if np.dtype(dtype).kind == "U" else dtype
        ds = self._file["labels"].create_dataset(key, (0,), h5type, maxshape=(None,), chunks=(256,))
        ds.attrs["name"] = name

    def flush(self) -> None:
        """Write everything appended so far to disk."""
        self._file.flush()
        self._last_flush = time.monotonic()
        self._check()

    def close(self) -> None:
        """Mark the file complete, flush and close it (the file is released also when a
        write failed; then the kept ``OSError`` is raised)."""
        f = getattr(self, "_file", None)
        with signals_held():  # a stop signal waits until the file is closed, not half-closed
            if f is not None and f.id.valid:
                if self._guard.error is None:
                    f.attrs["open"] = 0
                f.close()
            if not self._guard.closed:
                self._guard.close()
        self._check()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_bounds(
    path: str | Path, frames: slice | None = None
) -> tuple[np.ndarray, np.ndarray] | None:
    """The lower and upper maps of a processed recording (``process --interval``), or None
    when it has none; ``frames`` picks some of them."""
    path = Path(path)
    with open_hdf5(path) as f:  # (the one policy: every object checked, no link followed)
        if "lower" not in f or "upper" not in f:
            return None
        sel = slice(None) if frames is None else frames
        n = f["times"].shape[0]
        if f["lower"].shape[0] != n or f["upper"].shape[0] != n:
            raise FormatError(path, "the lower and upper maps do not cover every frame")
        return np.asarray(f["lower"][sel], np.float32), np.asarray(f["upper"][sel], np.float32)


@writer("hdf5", what="texsense recording (exact round trip)", suffixes=(".h5", ".hdf5"))
def write_hdf5(rec: Recording, path: str | Path) -> Path:
    """Write ``rec`` to ``path`` (HDF5, schema version 1) and return the path.

    The file is written under a temporary name in the same folder and renamed when complete
    (:func:`texsense.data.files.atomic_path`): a write that fails or is killed leaves the previous
    file, and a failure raises :class:`~texsense.exceptions.WriteError`.
    """
    path = Path(path)
    with (
        atomic_path(path) as tmp,
        RecordingWriter(
            tmp,
            rec.layout,
            rec.quantity,
            rec.unit,
            meta=rec.meta,
            element_times=rec.element_times is not None,
            compress=True,
            live=False,
        ) as w,
    ):
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
                w.add_label(name, values.dtype)
    return path


#: What each dataset of a recording may hold (numpy kinds).
_KINDS = {"frames": "iuf", "times": "iuf", "element_times": "iuf", "valid": "biu"}
_KIND_WORDS = {"iuf": "real numbers", "biu": "booleans"}


def _readable_rows(ds: h5py.Dataset, n: int) -> int:
    """How many of the first ``n`` rows of ``ds`` can be read: a writer killed while HDF5
    rewrote a compressed chunk leaves that chunk (at the end) unreadable."""
    rows = ds.chunks[0] if ds.chunks else max(n, 1)
    stop = n
    while stop > 0:
        start = (stop - 1) // rows * rows
        try:
            ds[start:stop]
            return stop
        except DAMAGED:
            stop = start
    return 0


def _held_rows(ds: h5py.Dataset) -> int | None:
    """Rows of ``ds`` for which the file holds storage (None: cannot tell): a dataset that
    declares more rows than that was not written (or its length was damaged)."""
    shape = ds.shape
    if not shape or shape[0] == 0:
        return 0
    try:
        if ds.chunks is None:
            row = ds.dtype.itemsize * math.prod(shape[1:])
            return ds.id.get_storage_size() // row if row and ds.dtype.kind != "O" else None
        bands = math.prod(-(-s // c) for s, c in zip(shape[1:], ds.chunks[1:], strict=True))
        return ds.id.get_num_chunks() // max(bands, 1) * ds.chunks[0]
    except (AttributeError, ValueError, TypeError, *DAMAGED):
        return None


def _labels(group: h5py.Group, a: int, b: int) -> dict[str, np.ndarray]:
    labels = {}
    for name, ds in named(group).items():
        check_strings(ds, slice(a, b))
        values = ds[a:b]
        labels[name] = (
            np.array([_text(v) for v in values], dtype=str) if ds.dtype.kind in "OS" else values
        )
    return labels


class HDF5Reader(RecordingReader):
    """Read a texsense HDF5 recording.

    Parameters
    ----------
    path : str or Path
        The file.
    accept_truncated : bool
        Read a damaged or unfinished file up to the frames that every dataset holds (with a
        warning) instead of refusing it.

    Raises
    ------
    FormatError
        If the file is not HDF5, not a texsense recording, of an unknown schema version,
        lacks a required dataset, or holds less than it declares.
    """

    format = "hdf5"
    what = "texsense recording (.h5)"
    sniff_order = 0

    @classmethod
    def sniff(cls, probe: Probe) -> bool:
        """HDF5's signature."""
        return probe.head.startswith(HDF5_SIGNATURE)

    #: the frames as stored (up to float64) and as float32, their validity, a mask
    bytes_per_value = 15

    def _expected_frames(self) -> int | None:
        return self.n_frames  # what every dataset holds (a shortfall is refused before)

    def _read_header(self) -> Header:
        self._file = open_hdf5(self.path)
        try:
            return self._header(self._file)
        except FormatError:  # names the file and what already
            raise
        except (KeyError, ValueError, TypeError, *DAMAGED) as e:
            raise FormatError(self.path, f"damaged or incomplete recording: {e}") from None

    def _header(self, f: h5py.File) -> Header:
        path = self.path
        fmt = f.attrs.get("format")
        if fmt != FORMAT_NAME:
            raise FormatError(
                path, f"HDF5 file is not a texsense recording (format attribute is {fmt!r})"
            )
        version = int(f.attrs.get("version", -1))
        if version != FORMAT_VERSION:
            raise FormatError(
                path,
                f"unknown texsense recording version {version}; this "
                f"texsense reads version {FORMAT_VERSION}",
            )
        try:
            meta = json_loads(_text(f.attrs.get("meta", "{}")))
        except (json.JSONDecodeError, TypeError) as e:
            raise FormatError(path, f"the attribute 'meta' is not JSON ({e})") from None
        if not isinstance(meta, dict):
            raise FormatError(path, "the attribute 'meta' is not a JSON object")
        for key in ("frames", "times", "valid", "layout", "labels"):
            if key not in f:
                raise FormatError(path, f"missing dataset or group '/{key}'")
        try:
            layout = _read_layout(f["layout"])
        except (KeyError, ValueError, TypeError, ParameterError) as e:
            raise FormatError(path, f"/layout is damaged: {e}") from None
        self._sets = self._datasets(f, layout.n_elements)
        n = self._complete_frames(f)
        if "recovered" in self._state:
            meta = {**meta, "recovered": self._state["recovered"]}
        self.n_frames = self._known_complete = n
        return Header(
            layout,
            _text(f.attrs["quantity"]),
            units.canonical(_text(f.attrs["unit"])),
            meta,
            declared_frames=max(ds.shape[0] for ds in self._sets.values()),
            label_dtypes={
                k: (str if ds.dtype.kind in "OS" else ds.dtype)
                for k, ds in named(f["labels"]).items()
            },
            element_times="element_times" in f,
        )

    def _datasets(self, f: h5py.File, n: int) -> dict[str, h5py.Dataset]:
        sets = {k: f[k] for k in ("frames", "times", "valid", "element_times") if k in f}
        sets.update({f"labels/{k}": v for k, v in named(f["labels"]).items()})
        for key, ds in sets.items():
            if not isinstance(ds, h5py.Dataset):
                raise FormatError(self.path, f"/{key} is not a dataset")
            kinds = _KINDS.get(key)
            if kinds is not None and ds.dtype.kind not in kinds:
                raise FormatError(
                    self.path, f"/{key} holds {ds.dtype} values, expected {_KIND_WORDS[kinds]}"
                )
            per_frame = (n,) if key in ("frames", "valid", "element_times") else ()
            if ds.shape[1:] != per_frame or not ds.shape:
                raise FormatError(
                    self.path,
                    f"/{key} has shape {ds.shape}, expected "
                    f"(frames{', ' + str(n) if per_frame else ''})",
                )
        return sets

    def _complete_frames(self, f: h5py.File) -> int:
        """How many frames every dataset holds; notes a shortfall or a recovery."""
        lengths = {k: ds.shape[0] for k, ds in self._sets.items()}
        n, longest = min(lengths.values()), max(lengths.values())
        self._state: dict[str, Any] = {}
        if not int(f.attrs.get("open", 0)):
            held = {k: _held_rows(ds) for k, ds in self._sets.items()}
            short = {k: h for k, h in held.items() if h is not None and h < lengths[k]}
            if n != longest:
                counts = ", ".join(f"{k} {v}" for k, v in lengths.items())
                self._cut(f"the datasets differ in length ({counts}): the file is damaged")
            elif short:
                k, h = next(iter(short.items()))
                self._cut(
                    f"/{k} declares {lengths[k]} frames but holds data for at most {h}: "
                    "the file is damaged"
                )
                n = min(n, *short.values())
            return n
        if not int(f.attrs.get("live", 1)):
            self._cut(
                "the file was not finished by its writer (it is still marked open: "
                "the write was interrupted)"
            )
        return self._recover(n)

    def _recover(self, n: int) -> int:
        """A file left open: the frames readable in every dataset, up to where the time
        stamps stop increasing (rows whose time stamp was not written yet read as 0)."""
        for ds in self._sets.values():
            held = _held_rows(ds)
            n = min(n, _readable_rows(ds, n if held is None else min(n, held)))
        t_all = self._sets["times"][:n]
        bad = np.nonzero(~(np.diff(t_all) > 0))[0]
        complete = int(bad[0]) + 1 if bad.size else n
        lost = min(ds.shape[0] for ds in self._sets.values()) - complete
        if lost:
            self._state["recovered"] = {"frames_read": complete, "frames_unreadable": int(lost)}
        if self._shortfall is None:
            unreadable = f"; {lost} frame(s) at the end were unreadable and are left out"
            logger.warning(
                "warning: %s: the recording was not closed by its recorder (interrupted); "
                "read the %d frame(s) written before%s",
                self.path,
                complete,
                unreadable if lost else "",
            )
        return complete

    def _piece(self, a: int, b: int, labels: bool = False) -> Piece:
        """Frames ``a:b`` as stored (HDF5 reads the chunks that hold them, nothing else)."""
        sets = self._sets
        return Piece(
            sets["frames"][a:b],
            sets["times"][a:b],
            _labels(self._file["labels"], a, b) if labels else {},
            valid=sets["valid"][a:b],
            element_times=sets["element_times"][a:b] if "element_times" in sets else None,
        )

    def timeline(self, frames: int = 1 << 16) -> Iterator[tuple[np.ndarray, dict[str, Any]]]:
        """The times (s) and labels of every frame, ``frames`` at a time, without reading a
        frame (times checked as :meth:`blocks` checks them): what a player needs over the
        whole recording before it seeks (:mod:`texsense.io.lazy`)."""
        for a in range(0, self.n_frames, frames):
            b = min(self.n_frames, a + frames)
            try:
                t = np.asarray(self._sets["times"][a:b], dtype=np.float64)
                labels = _labels(self._file["labels"], a, b)
            except DAMAGED as e:
                raise FormatError(self.path, f"frames {a + 1}..{b} cannot be read ({e})") from None
            self.frames_read = a
            self._check_times(Piece(np.zeros((b - a, 0), np.float32), t, labels))
            yield t, labels
        self.frames_read = self.n_frames
        self._times.finish()

    def _pieces(self) -> Iterator[Piece]:
        for a in range(0, self.n_frames, self._block):
            b = min(self.n_frames, a + self._block)
            try:
                yield self._piece(a, b, labels=True)
            except DAMAGED as e:
                self._cut(f"frames {a + 1}..{b} cannot be read ({e}): the file is damaged")
                return

    def close(self) -> None:
        """Close the file."""
        f = getattr(self, "_file", None)
        if f is not None and f.id.valid:
            f.close()
