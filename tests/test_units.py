import numpy as np
import pytest

from texsense.data import units
from texsense.exceptions import UnitError


@pytest.mark.parametrize(
    ("unit", "expected"),
    [("kPa", 10.0), ("mmHg", 75.006), ("psi", 1.4504), ("Pa", 1e4), ("N/cm2", 1.0)],
)
def test_one_newton_per_square_centimetre(unit, expected):
    assert units.convert(1.0, "N/cm2", unit) == pytest.approx(expected, rel=1e-4)


def test_round_trip_and_arrays():
    x = np.array([0.0, 0.5, 3.2])
    back = units.convert(units.convert(x, "N/cm2", "mmHg"), "mmHg", "N/cm2")
    np.testing.assert_allclose(back, x, rtol=1e-15)


@pytest.mark.parametrize(
    ("spelling", "canonical"),
    [("KPa", "kPa"), ("N/cm^2", "N/cm2"), ("centimeters", "cm"), ("raw", "count"), ("mm2", "mm2")],
)
def test_vendor_spellings(spelling, canonical):
    assert units.canonical(spelling) == canonical


def test_unknown_unit_is_rejected_not_guessed():
    with pytest.raises(UnitError, match="unknown unit 'kpascal'"):
        units.canonical("kpascal")
    with pytest.raises(UnitError, match="different quantities"):
        units.convert(1.0, "kPa", "mm")
    with pytest.raises(UnitError):
        units.canonical(3)  # type: ignore[arg-type]


def test_quantities():
    assert units.quantity_of("mmHg") == "pressure"
    assert units.quantity_of("pF") == "capacitance"
    assert units.is_pressure_unit("psi")
    assert not units.is_pressure_unit("pF")
    assert not units.is_pressure_unit("bogus")
    assert units.convert(2.0, "pF", "fF") == pytest.approx(2000.0)
    assert units.convert(1.0, "in", "cm") == pytest.approx(2.54)
