import numpy as np
import pytest

from texsense.apps.posture import centre_of_force
from texsense.exceptions import ParameterError
from texsense.sim.mat import VirtualMat
from texsense.sim.seated import (
    LEANING_BACK,
    POSTURES,
    ReferenceMat,
    Subject,
    back_pressure,
    posture_pressure,
    simulate_session,
)

LAY = VirtualMat.seat().layout


def cof(posture, subject=None):
    p = posture_pressure(LAY, posture, subject or Subject("avg"))
    return centre_of_force(p[None], LAY)[0]


def test_postures_move_the_centre_of_force_the_right_way():
    upright = cof(1)
    assert cof(2)[0] > upright[0] + 0.5  # leaning right: +x
    assert cof(3)[0] < upright[0] - 0.5
    assert cof(15)[1] < upright[1] - 3  # leading edge: towards the front (y = 0)
    assert cof(5)[1] > upright[1]  # leaning back: towards the backrest
    patterns = np.array([posture_pressure(LAY, k, Subject("avg")) for k in POSTURES])
    d = np.linalg.norm(patterns[:, None] - patterns[None], axis=2)
    assert np.all(d[~np.eye(16, dtype=bool)] > 0.3)  # 16 different patterns
    with pytest.raises(ParameterError, match=r"1\.\.16"):
        posture_pressure(LAY, 17, Subject("avg"))


def test_subjects_differ_in_weight_and_placement():
    light, heavy = Subject("a", weight_kg=55), Subject("b", weight_kg=95)
    assert posture_pressure(LAY, 1, heavy).sum() == pytest.approx(
        posture_pressure(LAY, 1, light).sum() * 95 / 55
    )
    shifted = Subject("c", offset_cm=(2.0, 0.0))
    assert cof(1, shifted)[0] - cof(1)[0] == pytest.approx(2.0, abs=0.4)
    a, b = Subject.random(0), Subject.random(1)
    assert a.weight_kg != b.weight_kg and Subject.random(0).weight_kg == a.weight_kg


def test_back_sensor_reads_high_only_when_leaning_back():
    rng = np.random.default_rng(0)
    back = np.array([[back_pressure(k, rng) for _ in range(200)] for k in POSTURES])
    leaning = np.array([k in LEANING_BACK for k in POSTURES])
    assert back[leaning].mean() == pytest.approx(1.8, abs=0.1)
    assert back[~leaning].mean() < 0.15


def test_session_follows_the_thesis_protocol():
    s = simulate_session(Subject.random(2), posture_s=10.0, home_s=5.0, rest_s=60.0, seed=1)
    lab = s.truth.labels
    assert set(np.unique(lab["round"])) == {0, 1, 2, 3}
    for r in (1, 2, 3):  # every posture held in every round
        held = np.unique(lab["posture"][(lab["round"] == r) & lab["hold"]])
        assert held.tolist() == list(POSTURES)
    rest = lab["posture"] == -1  # unloaded before round 3
    assert rest.any() and np.all(s.truth.frames[rest] == 0)
    assert s.truth.times[rest].min() > s.truth.times[lab["round"] == 2].max()
    assert s.reference.layout.n_elements == 1024 and s.reference.layout.shape == (32, 32)
    assert s.capacitance.frames.shape == s.truth.frames.shape == s.failed.shape
    assert np.all(s.capacitance.frames[s.failed] == 0)  # failed readings are 0 pF
    assert s.failed.all(axis=0).sum() == 12  # the thesis's 12 dead elements


def test_reference_mat_has_a_fixed_gain_error_of_about_ten_percent():
    ref = ReferenceMat(seed=3)
    reading = ref.read(np.ones((50, 1024)))
    gain = reading.mean(axis=0)
    assert np.std(gain) == pytest.approx(0.10, abs=0.015)
    np.testing.assert_allclose(gain, ref.gain, atol=0.02)


def test_sessions_are_reproducible_across_processes():
    """The same subject and seed give the same session in any Python process (no use of the
    per-process randomised str hash)."""
    import os
    import subprocess
    import sys

    code = (
        "from texsense.sim.seated import Subject, simulate_session;"
        "s = simulate_session(Subject.random(1), posture_s=4, home_s=2, rest_s=0, rounds=1);"
        "print(float(s.truth.frames.sum()), float(s.capacitance.frames.sum()))"
    )
    outs = set()
    for hashseed in ("1", "2"):
        env = {**os.environ, "PYTHONHASHSEED": hashseed}
        run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
        assert run.returncode == 0, run.stderr
        outs.add(run.stdout)
    assert len(outs) == 1
