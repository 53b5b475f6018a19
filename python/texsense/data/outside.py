"""Texts that come from outside parsed so that every way they are not what they claim is a
``ValueError``: :func:`json_loads` (nested too deeply, a key twice) and :func:`toml_loads`
(nested too deeply, an integer of thousands of digits). Re-exported by
:mod:`texsense.data.files`, the module of every file texsense reads or writes."""

from __future__ import annotations

import json
import re
import sys
import tomllib
from typing import Any

from texsense.exceptions import shown

__all__ = ["json_loads", "lone_surrogate", "toml_loads"]


class _DuplicateKeyError(ValueError):
    """A key met twice in one JSON object (raised inside the parser, said by json_loads)."""

    def __init__(self, key: str) -> None:
        super().__init__(key)
        self.key = key


class _BeyondFloatError(ValueError):
    """A JSON integer no float holds (raised inside the parser, said by json_loads)."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self.text = text


def _whole(text: str) -> int:
    """A JSON integer, if a float can hold it (beyond, every reader that takes it as a real
    number raised ``OverflowError``; thousands of digits, Python's own ``ValueError``)."""
    if len(text.lstrip("-")) > 310 or abs(value := int(text)) > sys.float_info.max:
        raise _BeyondFloatError(text)
    return value


#: a surrogate: written as a JSON escape (``\\udcff``) or already in the text (an HDF5
#: attribute h5py decoded with ``surrogateescape``)
_SURROGATE = re.compile(r"\\u[dD][89a-fA-F][0-9a-fA-F]{2}|[\ud800-\udfff]")
_SURROGATE_BYTES = re.compile(rb"\\u[dD][89a-fA-F][0-9a-fA-F]{2}")


def lone_surrogate(value: Any) -> str | None:
    """The first text (a key or a value) of a parsed JSON document that holds a lone
    surrogate, which no UTF-8 file, page or HDF5 attribute can hold, or None."""
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, str):
            if not item.isascii() and _SURROGATE.search(item):
                return item
        elif isinstance(item, dict):
            stack.extend(item.keys())
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
    return None


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    d: dict[str, Any] = {}
    for key, value in pairs:
        if key in d:
            raise _DuplicateKeyError(key)
        d[key] = value
    return d


def json_loads(text: str | bytes | bytearray) -> Any:
    """``json.loads`` of text that came from outside (a file, an attribute, a label, a
    message, a request body): every way it is not JSON is a ``ValueError``
    (:class:`json.JSONDecodeError`), also

    - text nested deeper than the parser's recursion, which ``json`` raises as a
      ``RecursionError`` (a few kB of ``[`` would otherwise be a traceback, a 500, or the end
      of a device's reading thread);
    - an integer beyond any float (``1`` and 400 zeros), which every reader that takes it as
      a real number raised as ``OverflowError`` (a regions file, a recording's alert
      settings: a traceback);
    - a text holding a lone surrogate (``"\\udcff"``), which no UTF-8 file, page or HDF5
      attribute can hold (a report of it was a ``UnicodeEncodeError`` traceback);
    - an object with a key twice (``{"gain": 1, "gain": 1e9}``), which ``json`` takes
      silently, keeping the last: what one reader of the text sees would not be what another
      sees (a hash, a viewer, another parser keeping the first).

    >>> json_loads('{"a": 1, "a": 2}')
    Traceback (most recent call last):
    ...
    json.decoder.JSONDecodeError: the key 'a' twice in one object: line 1 column 10 (char 9)
    """
    try:
        doc = json.loads(text, object_pairs_hook=_unique_keys, parse_int=_whole)
    except RecursionError:
        doc = text if isinstance(text, str) else ""
        raise json.JSONDecodeError("nested too deeply", doc, 0) from None
    except _BeyondFloatError as e:
        doc = text if isinstance(text, str) else bytes(text).decode("utf-8", "replace")
        raise json.JSONDecodeError(
            f"a number of {len(e.text)} digits, beyond any real number",
            doc,
            max(doc.find(e.text), 0),
        ) from None
    except _DuplicateKeyError as e:
        doc = text if isinstance(text, str) else bytes(text).decode("utf-8", "replace")
        marks = [m.start() for m in re.finditer(re.escape(json.dumps(e.key)) + r"\s*:", doc)]
        pos = marks[1] if len(marks) > 1 else 0  # the second time (best effort: escapes)
        raise json.JSONDecodeError(
            f"the key {shown(e.key, 80)} twice in one object", doc, pos
        ) from None
    escape = (
        _SURROGATE.search(text) if isinstance(text, str) else _SURROGATE_BYTES.search(bytes(text))
    )
    if escape and (bad := lone_surrogate(doc)) is not None:
        raw = text if isinstance(text, str) else bytes(text).decode("utf-8", "replace")
        escaped = bad.encode("utf-8", "backslashreplace").decode("ascii", "replace")
        raise json.JSONDecodeError(
            f"the text '{escaped[:60]}' holds a lone surrogate: not Unicode text", raw, 0
        )
    return doc


def toml_loads(raw: bytes) -> dict[str, Any]:
    """The TOML document of a file's bytes (UTF-8, a byte-order mark allowed): every way it is
    not TOML is a ``ValueError`` (``tomllib.TOMLDecodeError``, ``UnicodeDecodeError``), also
    arrays or inline tables nested deeper than ``tomllib`` recurses (a ``RecursionError``) and
    an integer of more digits than Python converts (a bare ``ValueError`` from ``int``)."""
    text = raw.decode("utf-8-sig")
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise ValueError("nested too deeply") from None
    except tomllib.TOMLDecodeError:
        raise
    except ValueError as e:  # int(): "Exceeds the limit (4300 digits) ..."
        raise ValueError(str(e).split(";")[0]) from None
