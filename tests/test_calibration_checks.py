"""The checks of what a mat calibration is made from (texsense.calibration.checks)."""

import numpy as np
import pytest

from texsense import Layout, Recording
from texsense.calibration.checks import (
    check_gains,
    check_material,
    check_recordings,
    parse_pressure,
    record_thickness_mm,
)
from texsense.calibration.workflows import material_record
from texsense.exceptions import ParameterError
from texsense.sim import protocols


@pytest.mark.parametrize(
    "text, ncm2", [("1", 1.0), ("10kPa", 1.0), ("75 mmHg", 1.0), ("2 N/cm2", 2.0), (0.5, 0.5)]
)
def test_pressures_with_units(text, ncm2):
    assert parse_pressure(text) == pytest.approx(ncm2, rel=1e-3)


@pytest.mark.parametrize("text", ["", "abc", "-1", "0", "1 pF", "1 furlong", "nan"])
def test_bad_pressures_say_what(text):
    with pytest.raises(ParameterError, match="pressure"):
        parse_pressure(text)


@pytest.mark.parametrize("spacer", ["textile-3mm", "textile-6mm", "foam-9mm", "bouc-wen-6mm"])
def test_the_record_tells_its_spacers_thickness(spacer):
    """eq. 2.1 fitted to a record of the simulator (not built from eq. 2.1's form): within
    the ±35 % the check allows, a little low (the permittivity grows with compression)."""
    rec = material_record(protocols.run_protocol("calibration", spacer, seed=3, sample_hz=None))
    thickness = float(spacer.split("-")[-1].removesuffix("mm"))
    assert 0.8 < record_thickness_mm(rec) / thickness < 1.05


def test_a_record_of_another_spacer_is_refused_with_its_thickness():
    rec = material_record(protocols.run_protocol("calibration", "textile-6mm", sample_hz=None))
    found = check_material(rec, 3.0, 1.0, "m6.csv")
    assert [f.level for f in found] == ["refuse"] and "thicker spacer" in found[0].text
    thin = material_record(protocols.run_protocol("calibration", "textile-3mm", sample_hz=None))
    found = check_material(thin, 6.0, 1.0, "m3.csv")
    assert [f.level for f in found] == ["refuse"] and "about 2.7 mm" in found[0].text
    assert check_material(thin, 3.0, 1.0, "m3.csv") == []
    found = check_material(thin, 3.0, 75.0, "m3.csv")  # 75 mmHg meant
    assert "75 mmHg" in found[0].text and found[0].level == "refuse"


def _mat(values, n_frames=10, drift=0.0):
    lay = Layout.grid(4, 4, pitch_cm=2.0)
    frames = np.tile(np.asarray(values, float), (n_frames, 1))
    frames += np.linspace(0, drift, n_frames)[:, None]
    return Recording(frames, np.arange(n_frames) * 1.0, lay, "capacitance", "pF")


def test_recordings_checked_for_length_swaps_silent_elements_and_settling():
    zero = _mat(np.full(16, 3.0))
    loaded = np.full(16, 4.0)
    assert check_recordings(zero, _mat(loaded)) == []
    assert "holds 3 frames" in check_recordings(zero, _mat(loaded, 3))[0].text
    assert "swapped" in check_recordings(_mat(loaded), zero)[0].text
    two_silent = loaded.copy()
    two_silent[[5, 9]] = 3.05
    (found,) = check_recordings(zero, _mat(two_silent))
    assert found.level == "warn" and "2 of 16" in found.text
    assert "e5 (row 2, column 2)" in found.text
    half = loaded.copy()
    half[:8] = 3.0
    (found,) = check_recordings(zero, _mat(half))
    assert found.level == "refuse" and "did not cover the mat" in found.text
    (found,) = check_recordings(zero, _mat(loaded, drift=0.3))
    assert found.level == "warn" and "not steady" in found.text
    assert "(20 % of the load response, 1.15 pF)" in found.text
    # a load that barely moved the mat: the creep said in times, not in thousands of percent
    creeping_zero = _mat(np.full(16, 3.85), drift=0.3)
    found = check_recordings(creeping_zero, _mat(np.full(16, 4.002)))
    steady = [f.text for f in found if "steady" in f.text]
    assert steady and "times the load response, 0.00" in steady[0], found


def test_gains_far_from_one_are_said():
    assert check_gains(np.full(8, 1.1), "x") == []
    assert "2.30 x" in check_gains(np.full(8, 2.3), "x")[0].text


def test_the_edge_a_hand_presses_on():
    """The orientation step of the wizard and the page: a press near an edge names it."""
    from texsense.calibration.checks import edge_of_press

    lay = Layout.grid(10, 6, pitch_cm=2.0)
    zero = np.full(lay.n_elements, 3.0)
    for (row, col), edge in (((0, 3), "top"), ((9, 2), "bottom"), ((5, 0), "left"),
                             ((4, 5), "right")):  # fmt: skip
        press = zero.copy()
        press[lay.element_at(row, col)] += 1.5
        assert edge_of_press(press, zero, lay) == edge
    with pytest.raises(ParameterError, match="no element rose"):
        edge_of_press(zero, zero, lay)
