"""Muscle activity: the high-rate readout, detection on synthetic and simulated sessions, the
command line."""

import json

import numpy as np
import pytest

from texsense.apps.muscle import activation, detect
from texsense.cli import main
from texsense.exceptions import ParameterError
from texsense.sim.muscle import HIGH_RATE_CDC, session


def test_the_high_rate_readout_meets_the_thesis_rate():
    """>= 10 Hz per element on 4 elements, >= 40 conversions a second (thesis §2.1)."""
    frame = HIGH_RATE_CDC.frame_time_s(4)
    assert 1 / frame >= 10 and 4 / frame >= 40


def test_detect_finds_onsets_ignores_short_blips_and_names_bad_input():
    t = np.arange(0, 30, 0.05)
    act = np.zeros_like(t)
    act[(t > 5) & (t < 6)] = 0.5
    act[(t > 10) & (t < 10.1)] = 0.5  # a 0.1 s blip: not a contraction
    act[(t > 20) & (t < 21)] = 0.25
    found = detect(t, act)
    assert found.count == 2 and found.intensity == [1.0, 0.5]
    with pytest.raises(ParameterError, match="threshold"):
        detect(t, act, on_ncm2=0)
    with pytest.raises(ParameterError, match="one length"):
        detect(t[:-1], act)


def test_a_session_through_the_compensation():
    from texsense.calibration.workflows import sleeve_calibration
    from texsense.compensation.pipeline import Pipeline

    s = session(5.0, seed=3)
    rec = s.scan.capacitance
    p = Pipeline(sleeve_calibration(seed=3), rec.layout, repair=None).run(rec)
    found = detect(p.times, activation(p))
    hit = [any(abs(o - t0) < 0.4 for o in found.onsets_s) for t0 in s.onsets_s]
    assert np.mean(hit) >= 0.95
    false = [o for o in found.onsets_s if not any(abs(o - t0) < 0.4 for t0 in s.onsets_s)]
    assert len(false) <= 1
    truth = s.intensity / s.intensity.max()
    got = np.array([found.intensity[int(np.argmin(np.abs(np.array(found.onsets_s) - t0)))]
                    for t0 in s.onsets_s])  # fmt: skip
    assert np.mean(np.abs(got - truth)) < 0.1


def test_cli_simulate_and_detect(tmp_path, capsys):
    assert main(["muscle", "simulate", "--minutes", "3", "-o", str(tmp_path)]) == 0
    capsys.readouterr()
    cal, plot = str(tmp_path / "calibration.json"), str(tmp_path / "m.png")
    args = ["muscle", "detect", str(tmp_path / "sleeve.h5"), "--calibration", cal,
            "--plot", plot, "--json"]  # fmt: skip
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert abs(out["count"] - len(truth["onsets_s"])) <= 1 and (tmp_path / "m.png").exists()
    assert main(["muscle", "detect", str(tmp_path / "sleeve.h5")]) == 1
    assert "needs --calibration" in capsys.readouterr().err
