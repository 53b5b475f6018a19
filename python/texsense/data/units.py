"""Units of texsense and conversions between them.

Inside texsense every quantity has one unit: pressure in N/cm² (the thesis's unit),
capacitance in pF, compression in mm, time in s, force in N, area in cm². Other units are
converted only at the edges (reading, writing, display), and an unknown unit string is
rejected, never guessed.

1 N/cm² = 10 kPa = 75.006 mmHg = 1.4504 psi.

Examples
--------
>>> from texsense.data import units
>>> round(units.convert(32.0, "mmHg", "N/cm2"), 4)
0.4266
>>> units.canonical("kpa")
'kPa'
"""

from __future__ import annotations

from typing import Any, Final, overload

import numpy as np
import numpy.typing as npt

from texsense.exceptions import UnitError

__all__ = [
    "INTERNAL_UNIT",
    "canonical",
    "convert",
    "is_pressure_unit",
    "quantity_of",
]

# mmHg: 133.322387415 Pa (conventional millimetre of mercury); psi: 6894.757293168 Pa.
_MMHG_PA: Final = 133.322387415
_PSI_PA: Final = 6894.757293168

# unit -> (quantity, factor to the internal unit of that quantity)
_UNITS: Final[dict[str, tuple[str, float]]] = {
    "N/cm2": ("pressure", 1.0),
    "kPa": ("pressure", 0.1),
    "Pa": ("pressure", 1e-4),
    "MPa": ("pressure", 100.0),
    "mmHg": ("pressure", _MMHG_PA * 1e-4),
    "psi": ("pressure", _PSI_PA * 1e-4),
    "bar": ("pressure", 10.0),
    "mbar": ("pressure", 0.01),
    "N/mm2": ("pressure", 100.0),
    "g/cm2": ("pressure", 9.80665e-3),
    "kg/cm2": ("pressure", 9.80665),
    "pF": ("capacitance", 1.0),
    "fF": ("capacitance", 1e-3),
    "nF": ("capacitance", 1e3),
    "F": ("capacitance", 1e12),
    "mm": ("length", 1.0),
    "cm": ("length", 10.0),
    "m": ("length", 1000.0),
    "um": ("length", 1e-3),
    "in": ("length", 25.4),
    "s": ("time", 1.0),
    "ms": ("time", 1e-3),
    "min": ("time", 60.0),
    "h": ("time", 3600.0),
    "N": ("force", 1.0),
    "kN": ("force", 1000.0),
    "kgf": ("force", 9.80665),
    "lbf": ("force", 4.4482216152605),
    "cm2": ("area", 1.0),
    "mm2": ("area", 0.01),
    "m2": ("area", 1e4),
    "in2": ("area", 6.4516),
    "ohm": ("resistance", 1.0),
    "kohm": ("resistance", 1e3),
    "count": ("raw", 1.0),
    "1": ("dimensionless", 1.0),
    "%": ("dimensionless", 0.01),
}

# Spellings met in vendor files and by hand -> canonical unit.
_ALIASES: Final[dict[str, str]] = {
    "n/cm^2": "N/cm2",
    "n/cm²": "N/cm2",
    "ncm2": "N/cm2",
    "n/cm2": "N/cm2",
    "kpa": "kPa",
    "pa": "Pa",
    "mpa": "MPa",
    "mmhg": "mmHg",
    "mm hg": "mmHg",
    "psi": "psi",
    "bar": "bar",
    "mbar": "mbar",
    "n/mm2": "N/mm2",
    "n/mm^2": "N/mm2",
    "g/cm2": "g/cm2",
    "g/cm^2": "g/cm2",
    "kg/cm2": "kg/cm2",
    "kg/cm^2": "kg/cm2",
    "pf": "pF",
    "ff": "fF",
    "nf": "nF",
    "f": "F",
    "farad": "F",
    "mm": "mm",
    "millimeters": "mm",
    "millimetres": "mm",
    "cm": "cm",
    "centimeters": "cm",
    "centimetres": "cm",
    "m": "m",
    "meters": "m",
    "metres": "m",
    "um": "um",
    "µm": "um",
    "in": "in",
    "inch": "in",
    "inches": "in",
    "s": "s",
    "sec": "s",
    "secs": "s",
    "seconds": "s",
    "ms": "ms",
    "min": "min",
    "h": "h",
    "n": "N",
    "kn": "kN",
    "kgf": "kgf",
    "lbf": "lbf",
    "cm2": "cm2",
    "cm^2": "cm2",
    "cm²": "cm2",
    "mm2": "mm2",
    "mm^2": "mm2",
    "mm²": "mm2",
    "m2": "m2",
    "in2": "in2",
    "ohm": "ohm",
    "ω": "ohm",
    "kohm": "kohm",
    "raw": "count",
    "count": "count",
    "counts": "count",
    "1": "1",
    "%": "%",
}

#: The internal unit of each quantity.
INTERNAL_UNIT: Final[dict[str, str]] = {
    "pressure": "N/cm2",
    "capacitance": "pF",
    "length": "mm",
    "time": "s",
    "force": "N",
    "area": "cm2",
    "resistance": "ohm",
    "raw": "count",
    "dimensionless": "1",
}


def canonical(unit: str) -> str:
    """Return the canonical spelling of ``unit``.

    Parameters
    ----------
    unit : str
        A unit string such as ``"kPa"``, ``"KPa"``, ``"N/cm^2"`` or ``"centimeters"``.

    Returns
    -------
    str
        The canonical spelling (``"kPa"``, ``"N/cm2"``, ``"cm"``).

    Raises
    ------
    UnitError
        If the unit is not known. Units are never guessed.
    """
    if not isinstance(unit, str):
        raise UnitError(f"unit must be a string, got {type(unit).__name__}")
    key = unit.strip()
    if key in _UNITS:
        return key
    found = _ALIASES.get(key.lower())
    if found is None:
        known = ", ".join(sorted(_UNITS))
        raise UnitError(f"unknown unit {unit!r}; known units: {known}")
    return found


def quantity_of(unit: str) -> str:
    """Return the physical quantity measured in ``unit`` (``"pressure"``, ``"length"``, ...)."""
    return _UNITS[canonical(unit)][0]


def is_pressure_unit(unit: str) -> bool:
    """Return True if ``unit`` is a known pressure unit."""
    try:
        return quantity_of(unit) == "pressure"
    except UnitError:
        return False


def factor(from_unit: str, to_unit: str) -> float:
    """Return the factor ``f`` such that ``value[to_unit] = value[from_unit] * f``.

    Raises
    ------
    UnitError
        If a unit is unknown or the two units measure different quantities.
    """
    q_from, f_from = _UNITS[canonical(from_unit)]
    q_to, f_to = _UNITS[canonical(to_unit)]
    if q_from != q_to:
        raise UnitError(
            f"cannot convert {from_unit!r} ({q_from}) to {to_unit!r} ({q_to}): different quantities"
        )
    return f_from / f_to


@overload
def convert(value: float, from_unit: str, to_unit: str) -> float: ...
@overload
def convert(value: npt.NDArray[Any], from_unit: str, to_unit: str) -> npt.NDArray[np.float64]: ...
@overload
def convert(
    value: float | npt.ArrayLike, from_unit: str, to_unit: str
) -> float | npt.NDArray[np.float64]: ...
def convert(
    value: float | npt.ArrayLike, from_unit: str, to_unit: str
) -> float | npt.NDArray[np.float64]:
    """Convert ``value`` from one unit to another of the same quantity.

    Parameters
    ----------
    value : float or array_like
        The value(s), in ``from_unit``.
    from_unit, to_unit : str
        Unit strings (see :func:`canonical`).

    Returns
    -------
    float or ndarray
        The value(s) in ``to_unit``; a float for a scalar input.

    Examples
    --------
    >>> convert(1.0, "N/cm2", "kPa")
    10.0
    >>> round(convert(1.0, "N/cm2", "psi"), 4)
    1.4504
    """
    f = factor(from_unit, to_unit)
    if isinstance(value, int | float | np.number):
        return float(value) * f
    return np.asarray(value, dtype=np.float64) * f
