"""What a reader accepts: the one policy for opening an HDF5 file, wherever texsense opens one
(the ``hdf5`` reader behind the command line, the monitor's playback and the Python API, and
the archive's check of an earlier output).

An HDF5 file can point outside itself: a dataset stored in another file (external storage),
a link into another HDF5 file (external link), a virtual dataset assembled from other files,
a filter that loads a plugin. Read naively, a file that does any of this makes texsense read
a file the user never named (a recording whose frames are the bytes of some text file on the
machine). :func:`open_hdf5` therefore checks every object of the file before anything is read
from it, and accepts only:

- a regular file (:func:`texsense.data.files.check_regular`: no FIFO, device, dangling link);
- hard links (a soft link or an external link is refused, wherever it is);
- groups and datasets (no committed datatypes or other objects);
- datasets stored in the file itself (contiguous, chunked or compact; no external storage, no
  virtual dataset), with the filters of :data:`FILTERS` only, of the dtypes of
  :data:`DTYPE_KINDS` (numbers, booleans, strings; no complex, compound, reference or
  variable-length arrays), whose chunks fit the memory budget
  (:mod:`texsense.data.budget`);
- at most :data:`MAX_OBJECTS` objects.

Anything else is a :class:`~texsense.exceptions.FormatError` that names the file and the
dataset, in one line.

Examples
--------
>>> import os, tempfile, h5py, numpy as np
>>> folder = tempfile.mkdtemp()
>>> path = os.path.join(folder, "ext.h5")
>>> with h5py.File(path, "w") as f:
...     f["x"] = np.arange(3.0)
...     f["y"] = h5py.ExternalLink("/etc/other.h5", "/x")
>>> try:
...     open_hdf5(path)
... except FormatError as e:
...     print(e.detail.split(":")[0])
/y is an external link (to /x in /etc/other.h5)
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from h5py import h5d, h5z

from texsense.data import budget
from texsense.data.files import check_regular
from texsense.data.outside import lone_surrogate
from texsense.exceptions import FormatError, ParameterError, shown

__all__ = [
    "DAMAGED",
    "DTYPE_KINDS",
    "FILTERS",
    "MAX_OBJECTS",
    "check_hdf5",
    "check_strings",
    "check_text",
    "link_name",
    "named",
    "open_hdf5",
    "text_of",
]

#: The filters a dataset may use (all built into HDF5 or h5py: no plugin is ever loaded).
FILTERS = {
    h5z.FILTER_DEFLATE: "gzip",
    h5z.FILTER_SHUFFLE: "shuffle",
    h5z.FILTER_FLETCHER32: "fletcher32",
    h5z.FILTER_LZF: "lzf",
}
#: The dtypes a dataset may have (numpy kinds): bool, integers, floats, strings (fixed or
#: variable length; h5py reads variable-length strings as objects).
DTYPE_KINDS = {"b": "bool", "i": "integer", "u": "integer", "f": "float", "S": "string"}
#: What h5py raises when a file's storage is damaged: an OSError, or a RuntimeError for a
#: flipped byte in a B-tree ("wrong B-tree signature"), which was a traceback: every read
#: of a file's content catches both and says the file is damaged, in one line naming it.
DAMAGED = (OSError, RuntimeError)
#: The most objects (groups, datasets) a file may hold; a recording has a few dozen.
MAX_OBJECTS = 100_000
_LAYOUTS = {h5d.CONTIGUOUS: "contiguous", h5d.CHUNKED: "chunked", h5d.COMPACT: "compact"}


def open_hdf5(path: str | Path) -> h5py.File:
    """Open an HDF5 file for reading under the policy of this module.

    Raises
    ------
    FormatError
        Naming the file (and the dataset): not a regular file, not HDF5, or holding something
        the policy refuses.
    """
    p = Path(path)
    check_regular(p)
    try:
        f = h5py.File(p, "r")
    except OSError as e:
        if "already open for write" not in str(e):
            raise FormatError(p, f"not a readable HDF5 file ({e})") from None
        # A writer was killed while the file was in SWMR mode: the data are consistent,
        # only the "open for writing" flag is left. Reading in SWMR mode is safe.
        try:
            f = h5py.File(p, "r", libver="latest", swmr=True)
        except Exception as e2:
            raise FormatError(p, f"not a readable HDF5 file ({e2})") from None
    except Exception as e:  # h5py raises others for some damaged files
        raise FormatError(p, f"not a readable HDF5 file ({type(e).__name__}: {e})") from None
    try:
        check_hdf5(f, p)
    except BaseException:
        f.close()
        raise
    return f


def check_hdf5(f: h5py.File, path: Path) -> None:
    """Check every object of an open file against the policy (see the module)."""
    for count, (name, obj) in enumerate(_walk(f, path), 1):
        if count > MAX_OBJECTS:
            raise FormatError(path, f"holds more than {MAX_OBJECTS} objects: not a recording")
        if isinstance(obj, h5py.Dataset):
            _check_dataset(obj, name, path)
        elif not isinstance(obj, h5py.Group):
            raise FormatError(path, f"{name} is a {type(obj).__name__}, not a group or dataset")


def _walk(group: h5py.Group, path: Path, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """Every object below ``group`` reached by hard links; any other link is refused before
    it is followed."""
    try:
        names = list(group.keys())
    except (OSError, RuntimeError, KeyError, ValueError) as e:
        raise FormatError(path, f"the group {prefix or '/'} cannot be read ({e})") from None
    for key in names:
        name = f"{prefix}/{key}"
        try:
            link = group.get(key, getlink=True)
        except (OSError, RuntimeError, KeyError, ValueError) as e:
            raise FormatError(path, f"the link {name} cannot be read ({e})") from None
        if isinstance(link, h5py.ExternalLink):
            raise FormatError(
                path,
                f"{name} is an external link (to {link.path} in {link.filename}): texsense "
                "reads only what is stored in the file itself",
            )
        if isinstance(link, h5py.SoftLink):
            raise FormatError(path, f"{name} is a soft link (to {link.path}): a recording has none")
        if not isinstance(link, h5py.HardLink):
            raise FormatError(path, f"{name} is a link of an unknown kind")
        try:
            obj = group[key]
        except (OSError, RuntimeError, KeyError, ValueError) as e:
            raise FormatError(path, f"{name} cannot be opened ({e})") from None
        yield name, obj
        if isinstance(obj, h5py.Group):
            yield from _walk(obj, path, name)


def _check_dataset(ds: h5py.Dataset, name: str, path: Path) -> None:
    try:
        dcpl = ds.id.get_create_plist()
        layout = dcpl.get_layout()
        external = dcpl.get_external_count()
        filters = [dcpl.get_filter(i)[0] for i in range(dcpl.get_nfilters())]
        dtype = ds.dtype
        chunks = ds.chunks
    except (OSError, RuntimeError, ValueError, TypeError) as e:
        raise FormatError(path, f"the dataset {name} cannot be read ({e})") from None
    if layout == h5d.VIRTUAL:
        raise FormatError(
            path, f"the dataset {name} is virtual (made of other files): texsense reads only "
            "what is stored in the file itself",
        )  # fmt: skip
    if external:
        raise FormatError(
            path, f"the dataset {name} is stored in another file (external storage): "
            "texsense reads only what is stored in the file itself",
        )  # fmt: skip
    if layout not in _LAYOUTS:
        raise FormatError(path, f"the dataset {name} has an unknown storage layout ({layout})")
    unknown = [f for f in filters if f not in FILTERS]
    if unknown:
        raise FormatError(
            path, f"the dataset {name} uses filter {unknown[0]}; texsense reads "
            f"{', '.join(FILTERS.values())} only",
        )  # fmt: skip
    _check_dtype(dtype, name, path)
    if chunks is not None:
        budget.check(
            math.prod(chunks) * max(dtype.itemsize, 1), f"one chunk of the dataset {name}", path
        )


def _check_dtype(dtype: Any, name: str, path: Path) -> None:
    if dtype.kind in DTYPE_KINDS:
        return
    if dtype.kind == "O" and h5py.check_string_dtype(dtype) is not None:
        return
    what = {"c": "complex numbers", "V": "a compound or opaque type", "U": "a string"}.get(
        dtype.kind, f"the type {dtype}"
    )
    if h5py.check_vlen_dtype(dtype) is not None:
        what = "variable-length arrays"
    elif h5py.check_ref_dtype(dtype) is not None:
        what = "object references"
    raise FormatError(
        path,
        f"the dataset {name} holds {what}; texsense reads numbers, booleans and strings only",
    )


def link_name(name: str, k: int) -> str:
    """The HDF5 link name under which a region or label called ``name`` (the ``k``-th) is
    stored: the name itself when HDF5 can hold it as a link name, else ``#k`` (a slash makes
    a path, ``.`` is the group itself); the name is kept in the attribute ``name`` either
    way (:func:`named`)."""
    plain = name and name not in (".", "..") and "/" not in name and not name.startswith("#")
    return name if plain else f"#{k}"


def text_of(value: Any) -> str:
    """A text an HDF5 file holds (an attribute, a string of a dataset) as Unicode text: bytes
    that are not UTF-8, which h5py gives as bytes or, in an attribute, as a string with lone
    surrogates (``surrogateescape``) that no UTF-8 file or page can hold, become U+FFFD."""
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    text = str(value)
    if not text.isascii():
        text = text.encode("utf-8", "surrogateescape").decode("utf-8", "replace")
    return text


def named(group: h5py.Group) -> dict[str, Any]:
    """The members of a group of regions or labels by their names (the attribute ``name``
    if there is one, as :func:`link_name` stores them; else the link name)."""
    out: dict[str, Any] = {}
    for key, obj in group.items():
        out[text_of(obj.attrs.get("name", key))] = obj
    return out


def check_json(value: Any, what: str = "the recording's metadata") -> str:
    """The JSON text of ``value`` (a recording's metadata, its layout) for a file, checked as
    every reader reads it back (:func:`texsense.data.outside.json_loads`): a text holding a
    lone surrogate, which ``json.dumps`` writes as an ASCII escape a reader then refuses, is a
    :class:`~texsense.exceptions.ParameterError` before anything is written. Every JSON text
    a writer writes goes through it."""
    bad = lone_surrogate(value)
    if bad is not None:
        raise ParameterError(f"{what} holds {shown(bad)}, which is not Unicode text")
    return json.dumps(value, separators=(",", ":"))


def check_text(value: str, what: str) -> str:
    """``value`` if HDF5 can store it as UTF-8 and give it back (no NUL, which ends a string
    there, no lone surrogate); a :class:`~texsense.exceptions.ParameterError` naming
    ``what`` before anything is written otherwise."""
    if "\x00" in value:
        raise ParameterError(f"{what} {shown(value)} holds a NUL character, which HDF5 cannot keep")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise ParameterError(f"{what} {shown(value)} is not valid Unicode text") from None
    return value


def check_strings(ds: h5py.Dataset, rows: slice = slice(None)) -> None:
    """Before ``ds[rows]`` of a dataset of variable-length strings: every string's declared
    length, read from its stored descriptor (the length's 4 bytes, then the global heap's
    address and index), is at most the file's size. HDF5 allocates and clears a string's
    declared length before it reads the string: a flipped byte in a length declared up to
    4 GiB, which took 4 GiB of memory and ~3 s before HDF5 found that the string in the heap
    does not match. Raises an OSError (one of :data:`DAMAGED`: the caller says that the file
    is damaged, as for any damaged read). Checked where the descriptors lie plainly in the
    file: contiguous storage and chunks stored without a filter (in a compressed chunk a
    flipped byte fails the decompression; a compact dataset's few lie in its header)."""
    info = h5py.check_string_dtype(ds.dtype)
    if info is None or info.length is not None or ds.size == 0:
        return
    fcpl = ds.file.id.get_create_plist()
    size = 4 + fcpl.get_sizes()[0] + 4
    first, stop, _ = rows.indices(ds.shape[0]) if ds.ndim else (0, 1, 1)
    spans = []  # (address, bytes) of the stored descriptors of ``rows``
    dcpl = ds.id.get_create_plist()
    if dcpl.get_layout() == h5d.CONTIGUOUS and ds.id.get_offset() is not None:
        row = size * (ds.size // max(ds.shape[0], 1) if ds.ndim else 1)
        spans.append((ds.id.get_offset() + first * row, max(stop - first, 0) * row))
    elif dcpl.get_layout() == h5d.CHUNKED:
        along, filters = ds.chunks[0], dcpl.get_nfilters()
        chunks = (
            [ds.id.get_chunk_info_by_coord((k * along,)) for k in
             range(first // along, -(-stop // along))] if ds.ndim == 1 else
            [ds.id.get_chunk_info(i) for i in range(ds.id.get_num_chunks())]
        )  # fmt: skip
        spans += [(c.byte_offset, c.size) for c in chunks if c.byte_offset is not None and
                  all(c.filter_mask >> i & 1 for i in range(filters))]  # fmt: skip
    if not spans:
        return
    with open(ds.file.filename, "rb") as f:
        end = f.seek(0, 2)
        for at, n in spans:
            f.seek(fcpl.get_userblock() + at)  # addresses count from the end of a user block
            raw = f.read(n // size * size)
            lengths = np.frombuffer(raw, "<u4").reshape(-1, size // 4)[:, 0] if size % 4 == 0 \
                else np.array([int.from_bytes(raw[i : i + 4], "little")
                               for i in range(0, len(raw), size)])  # fmt: skip
            if lengths.size and int(lengths.max()) > end:
                raise OSError(f"a string of {ds.name} declares {int(lengths.max())} bytes, more "
                              f"than the file's {end}")  # fmt: skip
