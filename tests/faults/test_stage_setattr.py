"""A stage's parameters stay within their declared ranges after construction (harden15): a
parameter set as an attribute (``stage.gain = -5``) is checked by the same
``ranges.check_params`` as the constructor's (``ranges.Checked.__setattr__``, under every
stage and the hysteresis model), for every stage x every declared parameter x every value
beyond its range; and a gain that is in ``[-1e15, 1e15]`` but whose reciprocal overflows
(1e-300, a denormal) is out of range (``Real.least``), in the stage and in ``--gain``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from texsense import Layout
from texsense.commands._options import RANGES
from texsense.compensation.health import FailureDetector
from texsense.compensation.hysteresis import HysteresisModel
from texsense.compensation.hysteresis._model import RANGES as MODEL
from texsense.compensation.stages import STAGES, Convert, Drift, Hysteresis, Linear, Repair
from texsense.compensation.stages.convert import _LINEAR_GAIN
from texsense.data.ranges import RangeError
from texsense.exceptions import ParameterError

LAY = Layout.grid(2, 2)
MAKE = {
    "detect": lambda: FailureDetector(LAY),
    "repair": lambda: Repair(LAY, "idw8"),
    "convert": lambda: Convert(2.0),
    "linear": lambda: Linear("capacitance", "pF", "pressure", "N/cm2", full_scale=10.0),
    "hysteresis": lambda: Hysteresis(),
    "drift": lambda: Drift(),
    "hysteresis model": lambda: HysteresisModel(),
}
#: the declared ranges of each (the model's table is its module's RANGES)
RANGES_OF = {**{name: cls.ranges for name, cls in STAGES.items()}, "hysteresis model": MODEL}


def _cases(which: str):
    for name, ranges in RANGES_OF.items():
        for key, kind in ranges.items():
            for value in kind.beyond() if which == "beyond" else kind.edges():
                yield pytest.param(name, key, value, id=f"{name}.{key}={value!r}"[:80])


def test_every_stage_is_made_here():
    assert set(MAKE) == set(RANGES_OF)


def set_beyond(name: str, key: str, value: object) -> str | None:
    """What went wrong setting ``key`` of a new ``name`` to ``value`` beyond its range (None:
    refused in one line naming the parameter, the value kept)."""
    stage = MAKE[name]()
    before = getattr(stage, key)
    try:
        setattr(stage, key, value)
    except RangeError as e:
        if e.key != key or "\n" in str(e) or getattr(stage, key) is not before:
            return f"unclear: {e}"
        return None
    return "taken"


@pytest.mark.parametrize(("name", "key", "value"), list(_cases("beyond")))
def test_a_parameter_set_beyond_its_range_is_refused(name, key, value):
    assert set_beyond(name, key, value) is None


@pytest.mark.parametrize(("name", "key", "value"), list(_cases("edges")))
def test_a_parameter_set_within_its_range_is_taken(name, key, value):
    stage = MAKE[name]()
    setattr(stage, key, value)
    assert getattr(stage, key) is value


@pytest.mark.parametrize("gain", [1e-300, -1e-300, 5e-324, 1e-13])
def test_a_gain_whose_reciprocal_overflows_is_out_of_range(gain):
    with pytest.raises(ParameterError, match="gain of element 1"):
        Linear("capacitance", "pF").fit(np.zeros(2), np.array([1.0, gain]))
    stage = Linear("capacitance", "pF").fit(np.zeros(2), np.array([1.0, 1e-12]))
    out = stage.step(np.full(2, 1e15), None, 0.0)[0]
    assert np.all(np.isfinite(out)) and math.isclose(out[1], 1e27)


def test_the_gain_option_takes_what_the_stage_takes():
    for gain in (0.0, 5e-324, 1e-300, -1e-300, 1e-13, 1e-12, -1e-12, 1.0, 1e15, 2e15):
        assert RANGES["--gain"].holds(gain) == _LINEAR_GAIN.holds(gain), gain
