"""Values of state that texsense stored and reads back (a mat's checkpoint, written by another
process, another version or read from a damaged database row): each read as the type it must
have, or one :class:`~texsense.exceptions.ParameterError` naming the place and the value.

A value that only *looks* right is refused here too (a count of ``true``, a time of ``NaN``, a
period of ``[1, 2]``): taken in, it would fail a frame later, far from its cause, or turn every
number after it into NaN.

>>> number({"t": 3}, "t", "frame clock")
3.0
>>> try:
...     whole({"n": 2.0}, "n", "monitor")
... except ValueError as e:
...     print(e)
the stored monitor's n is '2.0', not a whole number >= 0
"""

from __future__ import annotations

import math
from typing import Any

from texsense.exceptions import ParameterError, shown

__all__ = [
    "flag",
    "mapping",
    "number",
    "optional_number",
    "optional_text",
    "optional_whole",
    "texts",
    "whole",
    "wholes",
]

_MISSING = object()


def _get(state: Any, key: str, what: str, default: Any) -> Any:
    if not isinstance(state, dict):
        raise ParameterError(f"the stored {what} is {shown(state)}, not an object")
    if key not in state:
        if default is _MISSING:
            raise ParameterError(f"the stored {what} has no {key}")
        return default
    return state[key]


def mapping(state: Any, key: str, what: str) -> dict[str, Any]:
    """``state[key]``, an object (a part of a state, read by its own ``restore``)."""
    v = _get(state, key, what, _MISSING)
    if not isinstance(v, dict):
        raise ParameterError(f"the stored {what}'s {key} is {shown(v)}, not an object")
    return v


def number(
    state: Any, key: str, what: str, *, lo: float | None = None, default: Any = _MISSING
) -> float:
    """``state[key]`` as a finite float (at least ``lo``)."""
    v = _get(state, key, what, default)
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    if not ok or (lo is not None and v < lo):
        bound = "" if lo is None else f" >= {lo:g}"
        raise ParameterError(f"the stored {what}'s {key} is {shown(v)}, not a finite number{bound}")
    return float(v)


def optional_number(
    state: Any, key: str, what: str, *, lo: float | None = None, default: Any = None
) -> float | None:
    """``state[key]`` as a finite float, or None (also when it is missing)."""
    if _get(state, key, what, default) is None:
        return None
    return number(state, key, what, lo=lo)


def whole(state: Any, key: str, what: str, *, lo: int = 0, default: Any = _MISSING) -> int:
    """``state[key]`` as an int (at least ``lo``)."""
    v = _get(state, key, what, default)
    if not isinstance(v, int) or isinstance(v, bool) or v < lo:
        raise ParameterError(f"the stored {what}'s {key} is {shown(v)}, not a whole number >= {lo}")
    return v


def optional_whole(
    state: Any, key: str, what: str, *, lo: int = 0, default: Any = None
) -> int | None:
    """``state[key]`` as an int, or None (also when it is missing)."""
    if _get(state, key, what, default) is None:
        return None
    return whole(state, key, what, lo=lo)


def optional_text(
    state: Any, key: str, what: str, *, choices: tuple[str, ...] | None = None, default: Any = None
) -> str | None:
    """``state[key]`` as a str (one of ``choices``), or None."""
    v = _get(state, key, what, default)
    if v is None:
        return None
    if not isinstance(v, str) or (choices is not None and v not in choices):
        which = "text" if choices is None else "one of " + ", ".join(choices)
        raise ParameterError(f"the stored {what}'s {key} is {shown(v)}, not {which}")
    return v


def flag(state: Any, key: str, what: str, *, default: Any = _MISSING) -> bool:
    """``state[key]``, ``true`` or ``false``."""
    v = _get(state, key, what, default)
    if not isinstance(v, bool):
        raise ParameterError(f"the stored {what}'s {key} is {shown(v)}, not true or false")
    return v


def texts(state: Any, key: str, what: str, *, default: Any = _MISSING) -> list[str]:
    """``state[key]``, a list of str (``null`` an empty one)."""
    v = _get(state, key, what, default)
    if v is None:
        return []
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
        raise ParameterError(f"the stored {what}'s {key} is {shown(v)}, not a list of texts")
    return v


def wholes(state: Any, key: str, what: str, *, lo: int = 0, hi: int | None = None) -> list[int]:
    """``state[key]``, a list of ints in ``lo .. hi - 1``."""
    v = _get(state, key, what, _MISSING)
    ok = isinstance(v, list) and all(
        isinstance(x, int) and not isinstance(x, bool) and x >= lo and (hi is None or x < hi)
        for x in v
    )
    if not ok:
        span = f">= {lo}" if hi is None else f"in {lo}..{hi - 1}"
        raise ParameterError(f"the stored {what}'s {key} is {shown(v)}, not whole numbers {span}")
    return v
