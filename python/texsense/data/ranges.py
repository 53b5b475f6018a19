"""The declared range of a model's parameters, and the one check of them.

Every stage of a calibration (:class:`texsense.compensation.stage.Stage`) declares, next to
its constructor, the kind and range of each parameter in a table (``Stage.ranges``: a
:class:`Kind` by parameter name); the stage's constructor checks its parameters against it
with :func:`check_params`, so a stage made from Python keywords, from a command's options
or from a model file (which calls the constructor) is checked by the same function. A value
out of range is one :class:`RangeError` line naming the stage, the parameter, the value and
the range; a model file's reader turns it into a ``FormatError`` naming the file and the
field ``params.KEY``. The fitted arrays a file carries are read with their bounds by
:meth:`texsense.data.modelfile.Fields.array` (``within=``, a :class:`Real`).

Infinite values are refused unless a range includes them by name (``-inf`` where it means
"no limit": the detector's ``min_pF`` and ``stuck_floor_pF``, its ``jump_pF``); NaN is never
in a range. :func:`texsense.compensation.stages.ranges_table` lists every stage's table
(docs/pipeline.md, "Ranges").

Examples
--------
>>> table = {"grid": Whole(2, 2000), "floor": Real(-INF, 1e6, unit="pF", note="-inf: none")}
>>> check_params("the detect stage", table, {"grid": 100, "floor": -INF})
>>> try:
...     check_params("the detect stage", table, {"grid": 100, "floor": float("nan")})
... except RangeError as e:
...     print(e.key, "|", e)
floor | the detect stage's floor must be a number in [-inf, 1e+06] pF (-inf: none), got nan
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from texsense.data import units
from texsense.exceptions import ParameterError, UnitError, shown

__all__ = [
    "INF",
    "Checked",
    "Instance",
    "Kind",
    "Maybe",
    "OneOf",
    "RangeError",
    "Real",
    "Text",
    "UnitOf",
    "Whole",
    "check_params",
    "shown_value",
]

INF = math.inf


class RangeError(ParameterError):
    """A parameter outside its declared range; ``key`` names the parameter."""

    def __init__(self, message: str, key: str) -> None:
        super().__init__(message)
        self.key = key


def shown_value(value: Any) -> str:
    """A value as a range error shows it: numbers as Python writes them (``nan``, ``-inf``,
    ``1e+300``), anything else quoted with its type."""
    if isinstance(value, float | np.floating):
        return repr(float(value))
    if isinstance(value, int | np.integer) and not isinstance(value, bool):
        return repr(int(value)) if abs(int(value)) < 10**30 else shown(value)
    if isinstance(value, str):
        return shown(value)
    return f"{type(value).__name__} {shown(value)}"


def _number(value: Any) -> float | None:
    """``value`` as a float when it is a real number (not a bool, not text), else None."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        return None
    try:
        return float(value)
    except OverflowError:  # an int beyond any float
        return None


class Kind:
    """A parameter's kind and range: :meth:`holds` a value, says itself in :meth:`text`,
    and gives values at its ends (:meth:`edges`, accepted) and just beyond them
    (:meth:`beyond`, refused) for the tests."""

    def holds(self, value: Any) -> bool:
        """Whether ``value`` is of this kind and within the range."""
        raise NotImplementedError

    def text(self) -> str:
        """The range in words."""
        raise NotImplementedError

    def edges(self) -> list[Any]:
        """Values at the ends of the range (in it)."""
        return []

    def beyond(self) -> list[Any]:
        """Values just outside the range, and of other kinds."""
        return []


def _g(x: float) -> str:
    return "inf" if x == INF else "-inf" if x == -INF else f"{x:g}"


@dataclass(frozen=True)
class Real(Kind):
    """A real number in ``[lo, hi]`` (``lo_open``/``hi_open``: the end excluded). An
    infinite end that is not open is a value of the range (``-inf`` in ``[-inf, 5]``:
    say what it means in ``note``); NaN never is."""

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False
    unit: str = ""
    note: str = ""
    nonzero: bool = False
    #: the least magnitude of a value other than 0 (a gain divided by: 1e-300 is in
    #: ``[-1e15, 1e15]`` but its reciprocal overflows), 0: none
    least: float = 0.0

    def _in(self, v: float) -> bool:
        if v != v:
            return False
        above = v > self.lo if self.lo_open else v >= self.lo
        below = v < self.hi if self.hi_open else v <= self.hi
        tiny = v != 0 and abs(v) < self.least
        return above and below and not (self.nonzero and v == 0) and not tiny

    def _in_ends(self, v: float) -> bool:
        return Real(self.lo, self.hi, self.lo_open, self.hi_open)._in(v)

    def holds(self, value: Any) -> bool:
        v = _number(value)
        return v is not None and self._in(v)

    def holds_array(self, a: np.ndarray) -> np.ndarray:
        """Element-wise :meth:`holds` of a float array."""
        with np.errstate(invalid="ignore"):
            above = a > self.lo if self.lo_open else a >= self.lo
            below = a < self.hi if self.hi_open else a <= self.hi
        tiny = (a != 0) & (np.abs(a) < self.least)
        return above & below & ((a != 0) if self.nonzero else True) & ~tiny  # NaN: False

    def text(self) -> str:
        left, right = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
        ends = f"{left}{_g(self.lo)}, {_g(self.hi)}{right}"
        unit = f" {self.unit}" if self.unit else ""
        note = f" ({self.note})" if self.note else ""
        least = f", of magnitude at least {self.least:g}" if self.least else ""
        return f"a number in {ends}{', not 0' if self.nonzero else ''}{least}{unit}{note}"

    def edges(self) -> list[Any]:
        lo = math.nextafter(self.lo, self.hi) if self.lo_open else self.lo
        hi = math.nextafter(self.hi, self.lo) if self.hi_open else self.hi
        return [lo, hi]

    def beyond(self) -> list[Any]:
        out: list[Any] = [math.nan, "1.0", True, [1.0], *([0.0] if self.nonzero else [])]
        if self.least:  # a magnitude below the least, within [lo, hi]
            out += [
                v for v in (self.least / 2, -self.least / 2, 1e-300, 5e-324) if self._in_ends(v)
            ]
        for end, is_open, away in ((self.lo, self.lo_open, -INF), (self.hi, self.hi_open, INF)):
            if math.isinf(end) and not is_open:
                continue  # nothing lies beyond an infinite end
            out.append(end if is_open else math.nextafter(end, away))
            if not math.isinf(end):
                out.append(away)
                out.append(away * 1e300 if abs(end) < 1e299 else away)
        return out


@dataclass(frozen=True)
class Whole(Kind):
    """A whole number in ``[lo, hi]`` (an ``int``; a file's ``20.0`` is read as 20)."""

    lo: int
    hi: int

    def holds(self, value: Any) -> bool:
        if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
            return False
        return self.lo <= int(value) <= self.hi

    def text(self) -> str:
        return f"a whole number in [{self.lo}, {self.hi}]"

    def edges(self) -> list[Any]:
        return [self.lo, self.hi]

    def beyond(self) -> list[Any]:
        return [self.lo - 1, self.hi + 1, 10**30, 2.5, math.nan, math.inf, "2", True]


@dataclass(frozen=True)
class OneOf(Kind):
    """One of a set of names."""

    values: tuple[str, ...]

    def holds(self, value: Any) -> bool:
        return isinstance(value, str) and value in self.values

    def text(self) -> str:
        return "one of " + ", ".join(self.values)

    def edges(self) -> list[Any]:
        return list(self.values)

    def beyond(self) -> list[Any]:
        return ["", "no-such-name", self.values[0].upper() + "!", 1.0, None]


@dataclass(frozen=True)
class UnitOf(Kind):
    """A unit texsense knows (:func:`texsense.data.units.canonical`)."""

    def holds(self, value: Any) -> bool:
        if not isinstance(value, str):
            return False
        try:
            units.canonical(value)
        except UnitError:
            return False
        return True

    def text(self) -> str:
        return "a unit texsense knows (pF, mm, N/cm2, kPa, ...)"

    def beyond(self) -> list[Any]:
        return ["", "furlong", 1.0]


@dataclass(frozen=True)
class Text(Kind):
    """A text of 1 to ``longest`` characters (a name)."""

    longest: int = 200

    def holds(self, value: Any) -> bool:
        return isinstance(value, str) and 0 < len(value) <= self.longest

    def text(self) -> str:
        return f"a text of 1 to {self.longest} characters"

    def beyond(self) -> list[Any]:
        return ["", "x" * (self.longest + 1), 1.0]


@dataclass(frozen=True)
class Maybe(Kind):
    """``None`` (what it means in ``meaning``) or a value of ``kind``."""

    kind: Kind
    meaning: str

    def holds(self, value: Any) -> bool:
        return value is None or self.kind.holds(value)

    def text(self) -> str:
        return f"{self.kind.text()}, or None ({self.meaning})"

    def edges(self) -> list[Any]:
        return [None, *self.kind.edges()]

    def beyond(self) -> list[Any]:
        return [v for v in self.kind.beyond() if v is not None]


@dataclass(frozen=True)
class Instance(Kind):
    """An object of a class that checks itself (a ``Layout``: its own family's checks)."""

    cls: type

    def holds(self, value: Any) -> bool:
        return isinstance(value, self.cls)

    def text(self) -> str:
        return f"a {self.cls.__name__}"


def check_params(what: str, table: Mapping[str, Kind], values: Mapping[str, Any]) -> None:
    """Check ``values`` (parameter by name) against the declared ``table`` of ``what`` (``"the
    detect stage"``): the first value outside its range is a :class:`RangeError` naming
    ``what``, the parameter, the value and the range. A parameter without a declared range
    is a ``TypeError`` (a programming error, found by the tests)."""
    for key, value in values.items():
        kind = table.get(key)
        if kind is None:
            raise TypeError(f"{what} declares no range for its parameter {key!r}")
        if not kind.holds(value):
            raise RangeError(f"{what}'s {key} must be {kind.text()}, got {shown_value(value)}", key)


class Checked:
    """An object whose parameters are declared in :attr:`ranges` (a stage, the hysteresis
    model): checked by :func:`check_params` when made (:meth:`check_all`, which the
    constructor ends with), and each one set after that (``stage.gain = -5``) is checked by the
    same function before it is taken, so the object never holds a value outside its range.

    >>> class Gain(Checked):
    ...     ranges = {"gain": Real(0.0, 10.0, lo_open=True)}
    ...     def __init__(self, gain: float) -> None:
    ...         self.gain = gain
    ...         self.check_all()
    >>> g = Gain(2.0)
    >>> try:
    ...     g.gain = -5
    ... except RangeError as e:
    ...     print(e, "| kept:", g.gain)
    the object's gain must be a number in (0, 10], got -5 | kept: 2.0
    """

    #: the kind and range of every parameter, by name
    ranges: ClassVar[Mapping[str, Kind]] = {}

    def _what(self) -> str:
        return "the object"

    def _params(self) -> dict[str, Any]:
        """The parameters by name (a stage's: its constructor's arguments)."""
        return {k: getattr(self, k) for k in type(self).ranges}

    def check_all(self) -> None:
        """Check every parameter (:meth:`_params`) against :attr:`ranges` as it is now; from
        here on each one set is checked before it is taken."""
        check_params(self._what(), type(self).ranges, self._params())
        object.__setattr__(self, "_params_checked", True)

    def __setattr__(self, key: str, value: Any) -> None:
        if key in type(self).ranges and self.__dict__.get("_params_checked"):
            check_params(self._what(), type(self).ranges, {key: value})
        super().__setattr__(key, value)
