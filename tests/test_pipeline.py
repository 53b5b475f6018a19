"""Calibration, failure detection, repair methods and the capacitance-to-pressure pipeline."""

import json

import numpy as np
import pytest

from texsense import Layout
from texsense.calibration.workflows import calibrate_mat, material_record
from texsense.compensation.health import FailureDetector, health_report
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.repair import METHODS, Repair
from texsense.compensation.stages import Convert, StageChain, load_chain
from texsense.exceptions import FormatError, ParameterError
from texsense.sim import protocols
from texsense.sim.failures import FailureModel
from texsense.sim.mat import VirtualMat


@pytest.fixture(scope="module")
def mat_setup():
    """A 16-element prototype: calibration recordings, its calibration, and a loaded session."""
    cal_mat = VirtualMat.prototype(16, "textile-3mm", seed=4)
    n = cal_mat.layout.n_elements
    ft = cal_mat.cdc.frame_time_s(n)
    base = cal_mat.scan(np.arange(8) * ft, np.zeros((8, n))).capacitance
    uni = cal_mat.scan((8 + np.arange(8)) * ft, np.full((8, n), 1.0)).capacitance
    m = protocols.run_protocol("calibration", "textile-3mm", seed=9, sample_hz=None)
    material = material_record(m)
    cal = calibrate_mat(material, base, uni, 1.0, 3.0)
    session = VirtualMat.prototype(16, "textile-3mm", seed=4, failures=FailureModel())
    times = np.arange(120) * ft
    load = 1.5 + np.sin(times / 4.0)[:, None] * np.linspace(0.2, 1.0, n)[None, :]
    scan = session.scan(times, np.clip(load, 0, None))
    return cal, material, base, uni, scan


def test_zeroing_and_equilibration_make_the_pressure_right(mat_setup):
    cal, _, _, _, scan = mat_setup
    conv = cal["convert"]
    assert conv.gain_.std() > 0.01  # the elements do differ (electrode area, stray, stiffness)
    n = conv.n_elements
    one_curve = Convert(3.0).set_fitted(
        curve_compression_mm=conv.curve_compression_mm_,
        curve_capacitance_pF=conv.curve_capacitance_pF_,
        offset_pF=np.zeros(n),
        gain=np.ones(n),
    )
    plain = StageChain([one_curve, cal["hysteresis"]])
    truth = scan.pressure.frames
    ok = ~scan.failed & (truth > 0.5)
    lay = scan.capacitance.layout
    errs = []
    for c in (cal, plain):
        p = Pipeline(c, lay, repair=None, drift=False).run(scan.capacitance).frames
        errs.append(np.abs(p[ok] - truth[ok]) / truth[ok])
    assert errs[0].mean() < 0.08
    assert errs[0].mean() < 0.6 * errs[1].mean()  # one curve for all elements is worse


def test_calibration_file_round_trip_and_bad_files(mat_setup, tmp_path):
    from texsense.data.modelfile import envelope

    cal = mat_setup[0]
    path = cal.save(tmp_path / "cal.json")
    back = load_chain(path)
    assert back.id == cal.id and back.to_dict() == cal.to_dict()
    np.testing.assert_array_equal(back["convert"].gain_, cal["convert"].gain_)
    rec = mat_setup[4].capacitance
    np.testing.assert_array_equal(back.reset().run(rec).frames, cal.reset().run(rec).frames)
    d = json.loads(path.read_text())
    content = d["content"]
    convert = next(s for s in content["stages"] if s["stage"] == "convert")
    gains = convert["fitted"]["elements"]["gain"]
    no_elements = json.loads(json.dumps(content))
    next(s for s in no_elements["stages"] if s["stage"] == "convert")["fitted"].pop("elements")
    negative = json.loads(json.dumps(content))
    next(s for s in negative["stages"] if s["stage"] == "convert")["fitted"]["elements"]["gain"] = [
        -1.0
    ] * 16
    gains[0] = 2.0
    cases = {
        "not JSON": "{",
        "format 'other'": json.dumps({"format": "other"}),
        "texsense.chain version 7": json.dumps({**d, "version": 7}),
        "missing field 'fitted.elements.offset_pF'": json.dumps(
            envelope("texsense.chain", no_elements)
        ),
        "was edited after texsense wrote it": json.dumps(d),
        r"gain'.*expected a number in \(0, 1000\]": json.dumps(
            envelope("texsense.chain", negative)
        ),
    }
    for why, text in cases.items():
        bad = tmp_path / "bad.json"
        bad.write_text(text)
        with pytest.raises(FormatError, match=why) as e:
            load_chain(bad)
        assert "bad.json" in str(e.value)


def test_calibration_input_errors(mat_setup):
    _, material, base, uni, _ = mat_setup
    with pytest.raises(ParameterError, match="never reaches"):
        Convert(3.0, 50.0).fit(material, base, uni)
    with pytest.raises(ParameterError, match="no column"):
        Convert(3.0).fit({"compression_mm": material["compression_mm"]}, base, uni)
    with pytest.raises(ParameterError, match="do not respond"):
        Convert(3.0).fit(material, base, base)


def test_detector_finds_each_failure_kind():
    lay = Layout.grid(3, 3)
    base = np.full(9, 2.0)
    det = FailureDetector(lay, stuck_frames=5).fit(base, np.full(9, 6.0))
    rng = np.random.default_rng(0)
    codes = []
    for k in range(30):
        frame = 3.0 + 0.5 * np.sin(k / 3 + np.arange(9)) + rng.normal(0, 1e-3, 9)
        valid = np.ones(9, bool)
        frame[0] = 0.0  # short / break
        frame[1] = 9.0  # beyond the expected range
        if k == 10:
            valid[2] = False  # converter saturated
        frame[4] = 3.3  # stuck while its neighbours move
        if k == 20:
            frame[8] += 3.0  # implausible jump (and back at 21)
        _, measured = det.step(frame, valid, t=float(k))
        assert np.array_equal(measured, valid & (det.codes_ == 0))
        codes.append(det.codes_)
    c = np.array(codes)
    assert np.all(c[:, 0] == 1) and np.all(c[:, 1] == 2)
    assert c[10, 2] == 2 and np.sum(c[:, 2] > 0) == 1
    assert np.all(c[6:, 4] == 3) and np.all(c[:5, 4] == 0)
    assert c[20, 8] == 4 and c[21, 8] == 4 and np.sum(c[:, 8] > 0) == 2
    assert np.all(c[:, [3, 5, 6, 7]] == 0)  # healthy elements are not flagged
    report = health_report(c, np.arange(30.0), lay)
    assert report[0].status == "dead" and report[0].kinds == {"short/break": 30}
    assert report[8].status == "intermittent" and report[8].episodes == 1
    assert report[2].first_failed_s == report[2].last_failed_s == 10.0
    assert report[3].status == "ok" and report[3].first_failed_s is None


def test_detector_on_the_virtual_mat_matches_the_failures(mat_setup):
    cal, *_, scan = mat_setup
    lo, hi = cal["convert"].expected_range_pF()
    det = FailureDetector(scan.capacitance.layout).fit(lo, hi)
    det.run(scan.capacitance)
    codes = det.codes_
    assert scan.failed.any()
    assert np.all(codes[scan.failed] > 0)  # every failure found
    assert np.mean(codes[~scan.failed] > 0) < 0.01  # few false alarms


@pytest.mark.parametrize("method", METHODS)
def test_each_repair_method(method):
    lay = Layout.grid(4, 4)
    rep = Repair(lay, method).fit()
    first = np.full(16, 3.0)
    rep.step(first, np.ones(16, bool), t=0.0)
    frame = np.full(16, 5.0)
    valid = np.ones(16, bool)
    valid[5] = False
    out, measured = rep.step(frame, valid, t=1.0)
    assert measured.tolist() == valid.tolist()
    expected = {"zero": 0.0, "last-value": 3.0}.get(method, 5.0)
    assert out[5] == pytest.approx(expected)
    assert np.all(out[valid] == 5.0)
    # all of an element's neighbours (and every element) failed -> its last value
    out, _ = rep.step(np.zeros(16), np.zeros(16, bool), t=2.0)
    if method == "zero":
        assert np.all(out == 0)
    else:
        np.testing.assert_allclose(out, np.where(valid, 5.0, expected))
        assert np.all(rep.outcome_ == 2)


def test_harmonic_fills_a_cluster_from_its_border_and_neighbour_mean_cannot():
    lay = Layout.grid(5, 5)
    x = np.tile(np.arange(5.0), 5)  # a linear ramp along the columns
    valid = np.ones(25, bool)
    cluster = [6, 7, 8, 11, 12, 13, 16, 17, 18]  # the 3 x 3 centre
    valid[cluster] = False
    nm = Repair(lay, "neighbour-mean").fit()
    nm.step(np.zeros(25), np.ones(25, bool), t=0.0)
    out_nm, _ = nm.step(x, valid, t=1.0)
    out_h, _ = Repair(lay, "harmonic").fit().step(x, valid, t=0.0)
    # the ramp is harmonic: the inpainting reproduces it; eq. 6.14 holds 0 at the centre
    np.testing.assert_allclose(out_h, x, atol=1e-12)
    assert out_nm[12] == 0.0


def test_unknown_repair_method():
    with pytest.raises(ParameterError, match="repair stage's method must be one of"):
        Repair(Layout.grid(2, 2), "magic").fit()


def test_pipeline_streaming_equals_batch_and_repairs_failures(mat_setup):
    cal, *_, scan = mat_setup
    lay = scan.capacitance.layout
    batch = Pipeline(cal, lay, repair="neighbour-mean").run(scan.capacitance)
    stream = Pipeline(cal, lay, repair="neighbour-mean")
    rows = [
        stream.step(scan.capacitance.frames[k], None, scan.capacitance.times[k])[0]
        for k in range(scan.capacitance.n_frames)
    ]
    np.testing.assert_allclose(np.array(rows), batch.frames, rtol=1e-6)  # float32 storage
    assert not np.isnan(batch.frames).any()
    np.testing.assert_array_equal(batch.valid, ~(scan.failed | (~scan.capacitance.valid)))
    assert batch.meta["calibration_id"] == cal.id and batch.meta["software"].startswith("texsense")
    truth = scan.pressure.frames
    sel = truth > 0.5
    raw = Pipeline(cal, lay, hysteresis=False, drift=False, repair=None).run(scan.capacitance)
    err = lambda r: np.nanmean(np.abs(r.frames[sel] - truth[sel]) / truth[sel])  # noqa: E731
    ok = sel & ~scan.failed
    err_ok = lambda r: np.mean(np.abs(r.frames[ok] - truth[ok]) / truth[ok])  # noqa: E731
    assert err_ok(batch) < 0.7 * err_ok(raw)  # hysteresis compensation helps
    assert err(batch) < 0.15


def test_failed_elements_keep_their_hysteresis_state_frozen(mat_setup):
    cal, *_, scan = mat_setup
    rec = scan.capacitance
    lay = rec.layout
    ok = np.ones(rec.frames.shape, bool)
    fail = slice(40, 70)
    ok[fail, 3] = False
    codes_free = Pipeline(cal, lay, detect=False, drift=False, repair=None)
    out = codes_free.run(rec._with(valid=ok))
    assert np.all(np.isnan(out.frames[fail, 3]))
    # element 3 with the failed frames left out entirely gives the same numbers after them
    keep = np.ones(rec.n_frames, bool)
    keep[fail] = False
    short = rec._with(
        frames=rec.frames[keep], times=rec.times[keep], valid=ok[keep],
        element_times=rec.element_times[keep] if rec.element_times is not None else None,
    )  # fmt: skip
    ref = Pipeline(cal, lay, detect=False, drift=False, repair=None).run(short)
    np.testing.assert_allclose(out.frames[70:, 3], ref.frames[40:, 3], rtol=1e-6)


def test_pipeline_errors(mat_setup):
    cal, *_, scan = mat_setup
    with pytest.raises(ParameterError, match="calibration is for 16"):
        Pipeline(cal, Layout.grid(2, 2))
    with pytest.raises(ParameterError, match="unknown repair"):
        Pipeline(cal, scan.capacitance.layout, repair="magic")
    with pytest.raises(ParameterError, match="not pressure"):
        Pipeline(cal, scan.capacitance.layout).run(scan.pressure)


def test_cli_calibrate_process_repair_health(mat_setup, tmp_path, capsys):
    from texsense import load
    from texsense.cli import main
    from texsense.io.columns_csv import write_columns_csv

    cal, material, base, uni, scan = mat_setup
    write_columns_csv(tmp_path / "material.csv", material)
    base.save(tmp_path / "base.h5")
    uni.save(tmp_path / "uni.h5")
    scan.capacitance.save(tmp_path / "raw.h5")
    calf = tmp_path / "cal.json"
    args = ["calibrate", "mat", "--material", str(tmp_path / "material.csv"), "--baseline"]
    args += [str(tmp_path / "base.h5"), "--uniform", str(tmp_path / "uni.h5"), "--pressure", "1"]
    assert main([*args, "--thickness-mm", "3", "-o", str(calf)]) == 0
    chain = load_chain(calf)  # the calibration file is the mat's chain of stages
    assert chain.names == ["detect", "convert", "hysteresis"]
    assert chain.id == cal.id
    out = tmp_path / "p.h5"
    assert (
        main(["process", str(tmp_path / "raw.h5"), "--calibration", str(calf), "-o", str(out)]) == 0
    )
    p = load(out)
    assert p.quantity == "pressure" and p.meta["calibration_id"] == chain.id
    assert not np.isnan(p.frames).any() and (~p.valid).sum() == scan.failed.sum()
    # repair: elements marked invalid in the input get values
    holes = p._with(frames=np.where(p.valid, p.frames, np.nan))
    holes.save(tmp_path / "holes.h5")
    fixed = tmp_path / "fixed.h5"
    assert main(["repair", str(tmp_path / "holes.h5"), "-o", str(fixed), "--method", "idw8"]) == 0
    assert not np.isnan(load(fixed).frames).any()
    capsys.readouterr()
    assert main(["health", str(tmp_path / "raw.h5"), "--calibration", str(calf), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    dead = [e["element"] for e in rep if e["status"] == "dead"]
    assert dead == np.flatnonzero(scan.failed.all(axis=0)).tolist()
    assert main(["health", str(out)]) == 1
    assert "needs capacitance" in capsys.readouterr().err


def test_reference_detector_median_equals_a_brute_force_median():
    """The oracle of tests/test_chain.py (padded-table median, one small row sort per frame)
    against np.median over each element's neighbours, on a full grid and on a grid with
    holes (degrees 0-4)."""
    from reference_pipeline import ReferenceDetector

    rng = np.random.default_rng(5)
    active = rng.random((9, 11)) > 0.3
    for lay in (Layout.grid(8, 7), Layout.grid(9, 11, active=active)):
        det = ReferenceDetector(lay, None, None)
        indptr, indices = lay.neighbours
        for _ in range(10):
            x = rng.random(lay.n_elements)
            expected = np.array(
                [
                    np.median(x[indices[indptr[i] : indptr[i + 1]]])
                    if indptr[i + 1] > indptr[i]
                    else 0.0
                    for i in range(lay.n_elements)
                ]
            )
            np.testing.assert_allclose(det.neighbour_median(x), expected, rtol=0, atol=1e-15)


def test_the_pipeline_follows_the_streaming_contract(mat_setup):
    """step(values, valid, t) with t required (anything more keyword-only, with a default),
    run, reset, parameters from the constructor."""
    import inspect

    cal, *_, scan = mat_setup
    rec = scan.capacitance
    pipe = Pipeline(cal, rec.layout, repair="idw8", drift=False)
    params = pipe.get_params()
    assert list(params) == [
        "chain", "layout", "detect", "hysteresis", "drift", "repair", "capacity",
        "in_use", "in_use_options", "interval",
    ]  # fmt: skip
    assert params["repair"] == "idw8" and params["drift"] is False
    step = inspect.signature(Pipeline.step).parameters
    positional = [p for p in step.values() if p.kind is not inspect.Parameter.KEYWORD_ONLY]
    assert [p.name for p in positional][1:] == ["values", "valid", "t"]
    more = [p for p in step.values() if p.kind is inspect.Parameter.KEYWORD_ONLY]
    assert all(p.default is not inspect.Parameter.empty for p in more)
    assert step["t"].default is inspect.Parameter.empty
    batch = pipe.run(rec)
    pipe.reset()
    rows = [pipe.step(rec.frames[k], rec.valid[k], rec.times[k]) for k in range(rec.n_frames)]
    np.testing.assert_array_equal(np.array([r[0] for r in rows], np.float32), batch.frames)
    np.testing.assert_array_equal(np.array([r[1] for r in rows]), batch.valid)
    with pytest.raises(ParameterError, match="must not decrease"):
        pipe.step(rec.frames[0], None, rec.times[0])
