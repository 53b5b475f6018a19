"""Fits that come out the same every time, made once.

Identifying a Preisach model (eq. 4.15-4.22, with the cross-validated choice of its
smoothing) takes seconds of CPU, and a calibration made from a spacer preset fits the same
record every time: once for the preset's drift stage and once more in the mat's chain, in
every ``calibrate``, every calibration panel, every virtual mat. The fit is a pure function
of its inputs and of texsense's code, so :func:`remembered` keys its result (a JSON-able
content, e.g. :meth:`HysteresisModel.to_content`) by a digest of both and keeps it in this
process and in :func:`~texsense.data.files.cache_folder` (``fit-<kind>-<digest>.json``).
Another version of the code (:func:`code_digest`) or other inputs give another key, so a
kept result is never one the current code would not make. A kept file that cannot be read
is made again, and a cache that cannot be written is skipped, each said in the log.
``TEXSENSE_NO_FIT_CACHE=1`` turns it off (every fit made).
"""

from __future__ import annotations

import copy
import functools
import hashlib
import json
import logging
import os
from collections import OrderedDict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from texsense.data.files import cache_folder, json_loads, kept_or_made, write_text

__all__ = ["code_digest", "remembered"]

log = logging.getLogger("texsense.fitcache")
T = TypeVar("T")

#: Contents kept in this process (the newest; each a few hundred kB at most).
IN_MEMORY = 16
_memory: OrderedDict[str, Any] = OrderedDict()


@functools.cache
def code_digest() -> str:
    """A digest of this texsense's code (every Python file of the package and the compiled
    core): what one version made is read by that version only."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for path in sorted([*root.rglob("*.py"), *root.glob("_core*.so"), *root.glob("_core*.pyd")]):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _key(kind: str, parts: Sequence[Any]) -> str:
    digest = hashlib.sha256(f"{code_digest()}\0{kind}".encode())
    for part in parts:
        if isinstance(part, np.ndarray):
            a = np.ascontiguousarray(part)
            digest.update(f"\0array {a.dtype.str} {a.shape}\0".encode())
            digest.update(a.tobytes())
        else:
            digest.update(b"\0json ")
            digest.update(json.dumps(part, sort_keys=True).encode())
    return digest.hexdigest()[:24]


def remembered(
    kind: str, parts: Sequence[Any], make: Callable[[], Any], build: Callable[[Any], T]
) -> T:
    """``build(make())``, where ``make()`` gives a JSON-able content; or ``build`` of what
    ``make()`` gave before for the same ``kind``, ``parts`` (arrays and JSON-able values:
    every input of the fit) and code. ``build`` gets a copy of its own on every call; a
    kept content it refuses (a :class:`ValueError`, e.g. a damaged file) is made again."""
    if os.environ.get("TEXSENSE_NO_FIT_CACHE"):
        return build(make())
    key = f"{kind}-{_key(kind, parts)}"
    if key in _memory:
        _memory.move_to_end(key)
        return build(copy.deepcopy(_memory[key]))
    path = cache_folder() / f"fit-{key}.json"

    def fit() -> tuple[T]:
        content = make()
        built = build(copy.deepcopy(content))
        try:
            write_text(path, json.dumps(content))
        except OSError as e:
            log.warning("not kept (%s): %s", path, e)
        _keep(key, content)
        return (built,)

    # one process makes it, the others wait and read it
    return kept_or_made(path, lambda p: _read(p, key, build), fit)[0]


def _read(path: Path, key: str, build: Callable[[Any], T]) -> tuple[T] | None:
    """``(build(content),)`` of the content kept at ``path``, or None (none kept, or one that
    cannot be read: said in the log, to be made again)."""
    if not path.is_file():
        return None
    try:
        content = json_loads(path.read_text(encoding="utf-8"))
        built = build(content)
    except (OSError, ValueError) as e:
        log.warning("making again: %s: %s", path, e)
        return None
    _keep(key, copy.deepcopy(content))
    return (built,)


def _keep(key: str, content: Any) -> None:
    _memory[key] = content
    while len(_memory) > IN_MEMORY:
        _memory.popitem(last=False)
