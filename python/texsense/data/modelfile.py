"""The one envelope of every model file texsense writes: stage chains (the calibration of a
mat), stages, hysteresis models and drift models.

A file is JSON::

    {"format": "texsense.chain", "version": 2, "software": "texsense 0.1.0",
     "sha256": "<hash of the content>", "content": {...}}

- **read**: :func:`load` gives ``(format, content)`` of a file, or one
  :class:`~texsense.exceptions.FormatError` line naming it and what is wrong (a folder, a
  missing file, a binary or UTF-16 file, text that is not JSON, JSON that is not an object,
  another format or version, a field missing or of the wrong shape: :class:`Fields`);
- **version check**: the formats and versions of :data:`FORMATS` are read as they are; the
  formats of earlier versions go through the one legacy reader (:mod:`texsense.data.legacy`), which
  converts them, and are never written;
- **content hash**: ``sha256`` is the SHA-256 of the content in canonical JSON (sorted keys,
  no spaces). A file whose content does not match it was edited after texsense wrote it and
  is refused; an edit made on purpose is accepted with ``texsense rehash FILE``
  (:func:`rehash`), which writes the hash of the content as it is now;
- **write**: :func:`write` goes through :func:`texsense.data.files.write_text` (a temporary name
  in the same folder, fsync, rename): a failed or killed write keeps the previous file.

Examples
--------
>>> import json, tempfile
>>> from pathlib import Path
>>> path = Path(tempfile.mkdtemp()) / "m.json"
>>> _ = write(path, "texsense.drift", {"gamma": -0.025})
>>> load(path)
('texsense.drift', {'gamma': -0.025})
>>> d = json.loads(path.read_text()); d["content"]["gamma"] = 1e308
>>> _ = path.write_text(json.dumps(d))
>>> try:
...     load(path)
... except Exception as e:
...     print(str(e).split(": ", 1)[1][:38])
was edited after texsense wrote it (it
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable, Collection, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from texsense._core import __version__
from texsense.data import legacy
from texsense.data.files import json_loads, read_regular, write_text
from texsense.exceptions import FormatError

if TYPE_CHECKING:
    from texsense.data.ranges import Kind, Real

__all__ = [
    "FORMATS",
    "Fields",
    "content_hash",
    "envelope",
    "load",
    "read_json",
    "rehash",
    "unpack",
    "write",
]

#: The formats texsense writes, with their present version.
FORMATS: dict[str, int] = {
    "texsense.chain": 2,
    "texsense.stage": 2,
    "texsense.hysteresis": 2,
    "texsense.drift": 1,
}

#: What each format holds, for messages.
_WHAT = {
    "texsense.chain": "a stage chain (a calibration)",
    "texsense.stage": "a stage",
    "texsense.hysteresis": "a hysteresis model",
    "texsense.drift": "a drift model",
}


def _canonical(content: Any) -> bytes:
    return json.dumps(content, sort_keys=True, separators=(",", ":")).encode("utf-8")


def content_hash(content: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of the content in canonical JSON (sorted keys, no spaces); floats
    written by :func:`json.dumps` read back to the same bits, so it survives a round trip."""
    return hashlib.sha256(_canonical(content)).hexdigest()


def envelope(format: str, content: Mapping[str, Any]) -> dict[str, Any]:
    """The file's JSON object for ``content`` of ``format``."""
    if format not in FORMATS:
        raise ValueError(f"unknown model format {format!r}")
    content = dict(content)
    return {
        "format": format,
        "version": FORMATS[format],
        "software": f"texsense {__version__}",
        "sha256": content_hash(content),
        "content": content,
    }


def write(path: str | Path, format: str, content: Mapping[str, Any]) -> Path:
    """Write a model file atomically (a failed write keeps the previous file and raises
    :class:`~texsense.exceptions.WriteError`)."""
    text = json.dumps(envelope(format, content), indent=1)
    return write_text(path, text + "\n")


def read_json(path: str | Path) -> Any:
    """The JSON of a file; anything that is not a readable UTF-8 JSON text raises
    :class:`FormatError` naming the file and what it is instead."""
    path = Path(path)
    if path.is_dir():
        raise FormatError(path, "is a folder, expected a JSON model file")
    try:
        raw = read_regular(path, "a JSON model file")
    except OSError as e:
        raise FormatError(path, f"cannot read: {e.strerror or e}") from None
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")) or (len(raw) > 1 and b"\x00" in raw[:2]):
        raise FormatError(path, "UTF-16 text; texsense model files are UTF-8 (save it as UTF-8)")
    if b"\x00" in raw:
        raise FormatError(path, "a binary file, expected a JSON model file")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise FormatError(path, "not UTF-8 text, expected a JSON model file") from None
    try:
        return json_loads(text)  # a key twice, nested too deeply: not JSON
    except json.JSONDecodeError as e:
        raise FormatError(path, f"not JSON: {e.msg}", line=e.lineno) from None


def _kind(d: Any) -> str:
    if isinstance(d, list):
        return "a JSON list"
    if isinstance(d, dict):
        return "a JSON object"
    return f"a JSON {type(d).__name__}"


def unpack(
    d: Any, source: str | Path, formats: Collection[str] | None = None
) -> tuple[str, dict[str, Any]]:
    """``(format, content)`` of a file's JSON: the present formats with their hash checked,
    earlier ones converted by :func:`texsense.data.legacy.upgrade`; ``formats`` limits what is
    accepted (for the message)."""
    want = " or ".join(_WHAT[f] for f in formats) if formats else "a texsense model file"
    if not isinstance(d, dict):
        raise FormatError(source, f"holds {_kind(d)}, expected {want}")
    fmt, version = d.get("format"), d.get("version")
    if fmt in FORMATS and version == FORMATS[fmt]:
        content = d.get("content")
        if not isinstance(content, dict):
            raise FormatError(source, "missing field 'content' (an object)")
        if d.get("sha256") != content_hash(content):
            raise FormatError(
                source,
                "was edited after texsense wrote it (its content does not match its sha256); "
                f"if the edit is deliberate, accept it with: texsense rehash {source}",
            )
    else:
        upgraded = legacy.upgrade(d, source)
        if upgraded is None:
            if fmt in FORMATS:
                raise FormatError(
                    source,
                    f"{fmt} version {version!r}; this texsense reads version {FORMATS[fmt]} "
                    "and the earlier ones",
                )
            raise FormatError(source, f"format {fmt!r}, expected {want}")
        fmt, content = upgraded
    if formats and fmt not in formats:
        raise FormatError(source, f"holds {_WHAT.get(fmt, fmt)}, expected {want}")
    return fmt, content


def load(path: str | Path, formats: Collection[str] | None = None) -> tuple[str, dict[str, Any]]:
    """``(format, content)`` of a model file (see :func:`unpack`)."""
    return unpack(read_json(path), path, formats)


def rehash(
    path: str | Path, check: Callable[[dict[str, Any]], object] | None = None
) -> tuple[str, str]:
    """Accept a deliberate edit: write the hash of the file's content as it is now (the
    content itself is unchanged). ``check`` gets the new envelope first and raises if the
    content does not read as its format (nothing is written then). Returns the format and
    the new hash."""
    d = read_json(path)
    if not isinstance(d, dict) or d.get("format") not in FORMATS:
        raise FormatError(path, f"holds {_kind(d)} that is not a texsense model file")
    fmt = d["format"]
    if d.get("version") != FORMATS[fmt] or not isinstance(d.get("content"), dict):
        raise FormatError(path, f"not a {fmt} file of version {FORMATS[fmt]}: nothing to re-hash")
    if check is not None:
        check(envelope(fmt, d["content"]))
    write(path, fmt, d["content"])
    return fmt, content_hash(d["content"])


class Fields:
    """Reading a content object with errors that name the file and the field.

    >>> f = Fields({"curve": {"x": [[1, 2], [3]]}}, "cal.json")
    >>> try:
    ...     f.array("curve.x")
    ... except FormatError as e:
    ...     print(e)
    cal.json: field 'curve.x': not a regular array of numbers (rows of different length?)
    """

    def __init__(self, content: Any, source: str | Path, prefix: str = "") -> None:
        self.content = content
        self.source = source
        self.prefix = prefix

    def _name(self, key: str) -> str:
        return f"{self.prefix}{key}"

    def error(self, key: str, what: str) -> FormatError:
        """A FormatError about field ``key``."""
        return FormatError(self.source, f"field {self._name(key)!r}: {what}")

    def get(self, key: str, default: Any = ...) -> Any:
        """The value at a dotted ``key`` (``default`` when missing, else an error)."""
        node = self.content
        for part in key.split("."):
            if not isinstance(node, dict) or part not in node:
                if default is not ...:
                    return default
                raise FormatError(self.source, f"missing field {self._name(key)!r}")
            node = node[part]
        return node

    def sub(self, key: str) -> Fields:
        """The fields of the object at ``key``."""
        value = self.get(key)
        if not isinstance(value, dict):
            raise self.error(key, f"expected an object, got {_kind(value)}")
        return Fields(value, self.source, f"{self._name(key)}.")

    def array(
        self, key: str, ndim: int | None = None, finite: bool = True, within: Real | None = None
    ) -> np.ndarray:
        """A float64 array; ragged rows, strings, a wrong number of dimensions, (with
        ``finite``) NaN and infinities and (with ``within``) an entry outside that range
        (:mod:`texsense.data.ranges`) are errors."""
        value = self.get(key)
        try:
            kind: str = np.asarray(value).dtype.kind
        except (ValueError, TypeError, OverflowError):
            kind = "ragged"
        if kind in ("U", "S", "b"):  # numpy would convert "1.5" and true
            raise self.error(key, "holds text or true/false where numbers belong")
        try:
            if kind not in ("i", "u", "f"):  # ragged rows, null, objects, huge integers
                raise TypeError
            a = np.asarray(value, dtype=np.float64)
        except (ValueError, TypeError, OverflowError):
            raise self.error(
                key, "not a regular array of numbers (rows of different length?)"
            ) from None
        if ndim is not None and a.ndim != ndim:
            raise self.error(key, f"expected {ndim} dimension(s), got shape {a.shape}")
        if finite and not np.all(np.isfinite(a)):
            raise self.error(key, "holds NaN or infinite values")
        if within is not None and a.size:
            out = ~within.holds_array(a)
            if out.any():
                at = np.unravel_index(int(np.argmax(out)), a.shape)
                where = ", ".join(str(int(i)) for i in at)
                raise self.error(
                    key, f"entry [{where}] is {float(a[at])!r}, expected {within.text()}"
                )
        return a

    def number(
        self, key: str, default: Any = ..., finite: bool = True, within: Kind | None = None
    ) -> float:
        """A float (bool and strings are errors; with ``within``, a value outside that range
        too)."""
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, f"expected a number, got {value!r}")
        try:
            v = float(value)
        except OverflowError:
            raise self.error(key, "expected a number, got an integer beyond any float") from None
        if finite and not math.isfinite(v):
            raise self.error(key, f"expected a finite number, got {v}")
        if within is not None and not within.holds(v):
            raise self.error(key, f"expected {within.text()}, got {v!r}")
        return v

    def text(self, key: str, default: Any = ...) -> str:
        """A string."""
        value = self.get(key, default)
        if not isinstance(value, str):
            raise self.error(key, f"expected text, got {value!r}")
        return value
