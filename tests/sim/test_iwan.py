"""The third spacer law (Iwan bank of Jenkins elements, python/texsense/sim/iwan.py)."""

import numpy as np
import pytest

from texsense.exceptions import ParameterError
from texsense.sensor.materials import PRESETS, IwanMaterial
from texsense.sim.spacer import Spacer


def test_loading_passes_p50_and_loops_run_clockwise():
    sp = Spacer.preset("iwan-6mm")
    t = np.linspace(0, 120, 2401)
    e = 3.0 * np.concatenate([np.linspace(0, 1, 1200), np.linspace(1, 0.3, 1201)])
    r = sp.drive_displacement(t, e)
    p = r.pressure_ncm2[:, 0]
    assert p[1199] == pytest.approx(PRESETS["iwan-6mm"].p50_ncm2, rel=0.05)  # 50 % at p50
    up = np.interp(2.0, e[:1200], p[:1200])
    down = np.interp(2.0, e[1200:][::-1], p[1200:][::-1])
    assert up > down > 0  # loading above unloading: a spacer's clockwise loop


def test_ramps_agree_with_displacement_control():
    a, b = Spacer.preset("iwan-6mm"), Spacer.preset("iwan-6mm")
    bank = a._bank
    rate, dt = 0.01, 0.05
    e, p, _, done = bank.ramp_until(dt, rate, 2.0, 100000)
    assert done and p[-1] >= 2.0 > p[-2]
    times = np.concatenate([[0.0], dt * np.arange(1, e.size + 1)])
    r = b.drive_displacement(times, np.concatenate([[0.0], e]) * 6.0)
    np.testing.assert_allclose(r.pressure_ncm2[1:, 0], p, rtol=1e-9, atol=1e-12)


def test_minor_loops_are_not_congruent():
    """The springs stiffen with compression: the same compression loop is steeper higher up."""

    def loop_rise(centre):
        sp = Spacer.preset("iwan-6mm")
        top = centre + 0.2
        e = np.concatenate(
            [np.linspace(0, top, 200), np.linspace(top, centre, 50), np.linspace(centre, top, 50)]
        )
        p = sp.drive_displacement(np.linspace(0, 60, e.size), e).pressure_ncm2[:, 0]
        return p[-1] - p[-50]

    assert loop_rise(3.0) > 2.0 * loop_rise(1.5)


def test_bad_parameters_and_relaxation():
    with pytest.raises(ParameterError):
        Spacer(IwanMaterial("bad", 6.0, 2.3, elements=((1.0, -0.1),)))
    sp = Spacer.preset("iwan-6mm")
    t = np.concatenate([np.linspace(0, 10, 101), 10 + np.geomspace(0.1, 3600, 60)])
    e = np.minimum(t / 10, 1.0) * 3.0
    p = sp.drive_displacement(t, e).pressure_ncm2[:, 0]
    assert p[-1] < p[100]  # a held compression loses pressure (the sliders relax)
