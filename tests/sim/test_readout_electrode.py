import numpy as np
import pytest

from texsense.exceptions import ParameterError
from texsense.sensor.electrode import Electrode, permittivity, wet_factor
from texsense.sensor.readout import CAPDAC_LSB_PF, CDC, NOISE_AF_RMS
from texsense.sim.failures import FailureModel


def test_permittivity_matches_fig_3_17():
    assert permittivity(0.0) == pytest.approx(1.14)
    assert permittivity(0.7) == pytest.approx(1.6)
    assert np.all(np.diff(permittivity(np.linspace(0, 0.8, 20))) > 0)


def test_wet_spacer_matches_fig_3_18_and_dries():
    assert wet_factor(0.0, 0.00275) == pytest.approx(1.19, abs=0.005)
    assert wet_factor(0.7, 0.00275) == pytest.approx(1.25, abs=0.005)
    e = Electrode()
    dry, wet = e.capacitance_pF(6.0, 1.0), e.capacitance_pF(6.0, 1.0, water_fraction=0.00275)
    assert 1.15 < (wet - e.stray_pF) / (dry - e.stray_pF) < 1.25


def test_element_capacitance_in_the_thesis_range():
    # 2 x 2 cm electrodes: 2.5-8 pF on the 3 mm spacer between unloaded and 70 % (§3.1)
    c = Electrode(side_cm=2.0).capacitance_pF(3.0, [0.0, 2.1])
    assert 2.4 < c[0] < 2.7 and 7.5 < c[1] < 8.2
    assert np.all(np.diff(Electrode().capacitance_pF(6.0, np.linspace(0, 5, 30))) > 0)


def test_electrode_errors():
    with pytest.raises(ParameterError, match="thickness must be > 0"):
        Electrode().capacitance_pF(0.0, 0.0)
    with pytest.raises(ParameterError, match=r"compression must lie in \[0, 3.0\)"):
        Electrode().capacitance_pF(3.0, 3.5)
    with pytest.raises(ParameterError, match="side"):
        Electrode(side_cm=-1)


def test_cdc_codes_resolution_and_saturation():
    cdc = CDC(capdac_pF=5.0, noise_scale=0.0, cp1_pF=0, cp2_pF=0)
    rng = np.random.default_rng(0)
    c = np.array([cdc.capdac_effective_pF, 3.0, 7.5, 20.0, -1.0])
    codes, measured, saturated = cdc.convert(c, rng)
    assert codes[0] == 0x800000
    assert saturated.tolist() == [False, False, False, True, True]
    np.testing.assert_allclose(measured[:3], c[:3], atol=4.096 / 2**23)
    assert cdc.capdac_effective_pF == pytest.approx(round(5.0 / CAPDAC_LSB_PF) * CAPDAC_LSB_PF)


def test_cdc_noise_and_parasitics():
    rng = np.random.default_rng(1)
    cdc = CDC(rate_hz=9.1)
    _, m, _ = cdc.convert(np.full(20000, 4.0), rng)
    assert np.std(m) * 1e6 == pytest.approx(NOISE_AF_RMS[9.1], rel=0.2)  # aF
    # 100-150 pF to the shield changes a 3-8 pF reading by < 0.1 % (§3.5)
    assert CDC(cp1_pF=150).parasitic_offset_pF / 3.0 < 1e-3


def test_multiplexed_frame_time():
    assert CDC().frame_time_s(96) == pytest.approx(1.6, abs=0.01)  # thesis §6.2.1
    assert CDC().frame_time_s(96, converters=4) == pytest.approx(0.4, abs=0.01)
    with pytest.raises(ParameterError, match="rate_hz"):
        CDC(rate_hz=100.0)


def test_failures_permanent_share_and_pressure_correlation():
    rng = np.random.default_rng(2)
    t = np.arange(0, 1800, 1.6)
    p = np.zeros((t.size, 200))
    p[:, 100:] = 3.0  # half loaded
    f = FailureModel().simulate(t, p, rng)
    permanent = f.all(axis=0)
    assert permanent.sum() == 25  # 12 / 96 of 200
    intermittent = f[:, ~permanent].mean(axis=0)
    loaded = ~permanent[100:]
    assert (
        intermittent[-loaded.sum() :].mean() > 3 * intermittent[: (~permanent[:100]).sum()].mean()
    )
    assert not FailureModel.none().simulate(t, p, rng).any()


def test_failures_reproduce_the_thesis_session_share():
    """50-57 % of the elements fail at least once in a seat session (§6.5.2.5)."""
    rng = np.random.default_rng(3)
    t = np.arange(0, 3 * 16 * 40, 1.6)  # 3 rounds of 16 postures, 40 s each
    shares = []
    for seed in range(5):
        r = np.random.default_rng(seed)
        base = np.clip(r.gamma(1.5, 0.9, 96), 0, 6)  # loaded and unloaded elements of a seat
        p = base[None, :] * (1 + 0.3 * np.sin(t[:, None] / 60 + r.uniform(0, 6, 96)))
        shares.append(FailureModel().simulate(t, p, rng).any(axis=0).mean())
    assert 0.50 <= np.mean(shares) <= 0.57, shares


def test_failure_model_errors():
    with pytest.raises(ParameterError):
        FailureModel(permanent_fraction=1.5)
    with pytest.raises(ParameterError, match="pressure must be"):
        FailureModel().simulate([0, 1], np.zeros((3, 2)), np.random.default_rng())
