"""Compression stockings: RAL-GZ 387 classes, the report of a strip, a day's virtual wear
through the compensation, and the command line."""

import json

import numpy as np
import pytest

from texsense import Layout, Recording
from texsense.apps.stocking import compression_class, report
from texsense.cli import main
from texsense.exceptions import ParameterError
from texsense.sim.stocking import LEGS, design, truth_mmhg, wear


def test_classes_of_ral_gz_387_and_the_gaps_between():
    assert [compression_class(v) for v in (18, 21, 23, 32, 34, 46, 49, 80)] == [
        "I", "I", "II", "II", "III", "III", "IV", "IV",
    ]  # fmt: skip
    assert compression_class(17.9) == "below I"
    assert compression_class(22.0) == "between I and II"
    assert compression_class(47.5) == "between III and IV"


def test_laplace_law_and_the_design_profile():
    """P = T / r: the same tension presses twice as hard on half the radius; the design
    gives each class its middle pressure at B on every leg size."""
    for leg in LEGS.values():
        p0 = truth_mmhg(design("II", leg), leg, 0.0)
        assert p0[0] == pytest.approx(27.5) and np.all(np.diff(p0) < 0)
        p8 = truth_mmhg(design("II", leg), leg, 8.0)
        assert p8[0] == pytest.approx(27.5 * 0.97)  # 3 % relaxation of the knit in 8 h
    leg = LEGS["medium"]
    t = design("I", leg)
    half = type(leg)(tuple(c / 2 for c in leg.circumference_cm))
    np.testing.assert_allclose(truth_mmhg(t, half, 0.0), 2 * truth_mmhg(t, leg, 0.0))


def test_report_of_a_pressure_strip_and_its_errors():
    lay = Layout.points([[0, 12], [0, 24], [0, 34], [0, 44]], names=["B", "B1", "C", "D"])
    times = np.arange(0, 2 * 3600 + 1, 60.0)
    mmhg = np.array([30.0, 24.0, 20.0, 15.0]) - (times[:, None] / 3600) * 2.0
    rec = Recording(mmhg / 75.00615, times, lay, "pressure", "N/cm2")
    rep = report(rec)
    assert rep.hours == [1.0, 2.0]
    # the mean of the last 10 minutes before each mark
    window = times[(times > 3000) & (times <= 3600)]
    assert rep.mmhg[0, 0] == pytest.approx(30 - 2 * np.mean(window) / 3600, abs=0.01)
    assert rep.classes() == ["II", "II"]
    assert rep.gradient[0, 0] == pytest.approx(22.1 / 28.1, abs=0.01)
    assert json.loads(json.dumps(rep.to_dict()))["class"] == ["II", "II"]
    with pytest.raises(ParameterError, match="named B, B1, C, D"):
        report(rec._with(layout=Layout.points([[0, 0]] * 4)))
    with pytest.raises(ParameterError, match="not capacitance"):
        report(rec._with(quantity="capacitance", unit="pF"))


def test_a_days_wear_is_read_right_only_with_drift_compensation():
    from texsense.calibration.workflows import strip_calibration
    from texsense.compensation.pipeline import Pipeline
    from texsense.data.units import convert

    times, truth, scan = wear("II", LEGS["medium"], hours=8.0)
    cal = strip_calibration()
    rec = scan.capacitance
    comp = Pipeline(cal, rec.layout, repair=None).run(rec)
    raw = Pipeline(cal, rec.layout, hysteresis=False, drift=False, repair=None).run(rec)
    late = times > times[-1] - 600
    true_b = float(np.mean(convert(truth[late, 0], "N/cm2", "mmHg")))
    got = report(comp, raw)
    assert abs(got.mmhg[-1, 0] - true_b) < 1.5 and got.classes()[-1] == "II"
    assert got.uncompensated_mmhg[-1, 0] > true_b + 5 and got.classes(True)[-1] == "III"


def test_cli_simulate_and_report(tmp_path, capsys):
    assert main(["stocking", "simulate", "--class", "I", "--hours", "2", "-o", str(tmp_path)]) == 0
    capsys.readouterr()
    assert main(["stocking", "report", str(tmp_path / "strip.h5"), "--calibration",
                 str(tmp_path / "calibration.json"), "--json"]) == 0  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert out["class"] == ["I", "I"] and out["points"] == ["B", "B1", "C", "D"]
    assert main(["stocking", "report", str(tmp_path / "strip.h5")]) == 1
    assert "needs --calibration" in capsys.readouterr().err
