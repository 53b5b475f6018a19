"""One contract for every stage (texsense.compensation.testing.check_stage, in the spirit of
scikit-learn's check_estimator): each stage is checked with the input it reads; the checks have no
special case for any stage."""

from __future__ import annotations

import numpy as np
import pytest

from texsense.calibration.workflows import material_record
from texsense.compensation.drift import split_steps
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import (
    STAGES,
    Convert,
    Drift,
    FailureDetector,
    Hysteresis,
    Linear,
    Repair,
    StageChain,
    load_chain,
    stage_from_dict,
)
from texsense.compensation.testing import check_stage
from texsense.exceptions import FormatError
from texsense.sim import protocols
from texsense.sim.failures import FailureModel
from texsense.sim.mat import VirtualMat
from texsense.sim.seated import Subject, simulate_session


def seat_records():
    """What a user calibrates the virtual seat from: its layout, unloaded and 1 N/cm² scans,
    a test-machine record and held steps of another specimen."""
    mat = VirtualMat.seat(seed=5)
    n = mat.layout.n_elements
    ft = mat.cdc.frame_time_s(n)
    base = mat.scan(np.arange(10) * ft, np.zeros((10, n))).capacitance
    uni = VirtualMat.seat(seed=5).scan((11 + np.arange(10)) * ft, np.ones((10, n))).capacitance
    material = material_record(
        protocols.run_protocol("calibration", "textile-3mm", seed=11, sample_hz=None)
    )
    st = protocols.run_protocol("steps", "textile-3mm", seed=11, sample_hz=10)
    steps = split_steps(st.times, st.labels["pressure_ncm2"], st.labels["compression_mm"])
    return mat, base, uni, material, steps


@pytest.fixture(scope="module")
def world():
    """For each stage: a new stage, how to fit it, and a recording of what it reads (the
    previous stage's output on a virtual-seat session with failures)."""
    mat, base, uni, material, steps = seat_records()
    lay = mat.layout
    n = lay.n_elements
    cases = {
        "detect": (FailureDetector(lay, stuck_frames=8), lambda s: s.fit(base)),
        "convert": (Convert(3.0, 1.0), lambda s: s.fit(material, base, uni)),
        "linear": (
            Linear("capacitance", "pF", "capacitance", "pF", 40.0),
            lambda s: s.fit(np.full(n, 0.5), np.linspace(0.9, 1.1, n)),
        ),
        "hysteresis": (
            Hysteresis(),
            lambda s: s.fit(material["compression_mm"], material["pressure_ncm2"]),
        ),
        "drift": (Drift(), lambda s: s.fit(steps)),
        "repair": (Repair(lay, "harmonic"), lambda s: s.fit()),
    }
    session = simulate_session(
        Subject.random(3), mat=VirtualMat.seat(seed=5, failures=FailureModel()),
        rounds=1, rest_s=10.0, posture_s=8.0,
    ).capacitance.select(slice(0, 120))  # fmt: skip
    chain = StageChain.fit_mat(material, base, uni, 1.0, 3.0, steps=steps)
    detected = chain["detect"].reset().run(session)  # validity from detection
    inputs = {"detect": session, "convert": detected, "linear": detected}
    inputs["hysteresis"] = chain["convert"].reset().run(detected)
    inputs["drift"] = chain["hysteresis"].reset().run(inputs["hysteresis"])
    inputs["repair"] = inputs["drift"]
    return {"cases": cases, "inputs": inputs, "chain": chain, "session": session}


def test_every_registered_stage_has_a_case(world):
    """A stage class that names itself is in STAGES; this suite needs a case for it."""
    missing = sorted(set(STAGES) - set(world["cases"]))
    assert not missing, f"stages without a contract case here: {missing}"
    assert {"detect", "convert", "linear", "hysteresis", "drift", "repair"} <= set(STAGES)


def test_a_stage_name_is_taken_once():
    from texsense.compensation.stage import Stage

    with pytest.raises(TypeError, match="is Drift's"):
        type("Other", (Stage,), {"name": "drift"})


@pytest.mark.parametrize("name", sorted(STAGES))
def test_the_stage_contract(world, name):
    stage, fit = world["cases"][name]
    rec = world["inputs"][name]
    assert rec.valid.mean() > 0.5 and (name == "detect" or (~rec.valid).any())
    check_stage(stage, fit, rec)


def test_repair_fills_invalid_readings_and_keeps_them_marked(world):
    stage, fit = world["cases"]["repair"]
    rec = world["inputs"]["repair"]
    out = fit(stage).reset().run(rec)
    bad = ~rec.valid
    assert bad.any() and np.isfinite(out.frames[bad]).mean() > 0.95
    np.testing.assert_array_equal(out.valid, rec.valid)
    np.testing.assert_array_equal(out.frames[~bad], rec.frames[~bad])


def test_bad_stage_files_name_the_problem(tmp_path):
    with pytest.raises(FormatError, match="a stage must be a JSON object"):
        stage_from_dict([])
    with pytest.raises(FormatError, match="unknown stage 'magic'"):
        stage_from_dict({"stage": "magic"})
    with pytest.raises(FormatError, match=r"field 'params': unknown parameters \['x'\]"):
        stage_from_dict({"stage": "drift", "params": {"x": 1}})
    with pytest.raises(FormatError, match=r"missing field 'fitted\.model'"):
        stage_from_dict({"stage": "hysteresis", "params": {}, "fitted": {}})
    (tmp_path / "b.json").write_bytes(b"\x89HDF\r\n\x00\x00")
    with pytest.raises(FormatError, match="binary"):
        load_chain(tmp_path / "b.json")


def test_the_chain_the_pipeline_and_the_stages_give_the_same_numbers(world, tmp_path):
    """The chain's file round trip; the compiled pipeline equals the chain run stage after
    stage in Python, to the bit, batch and streaming."""
    chain = world["chain"]
    assert chain.names == ["detect", "convert", "hysteresis", "drift"]
    loaded = load_chain(chain.save(tmp_path / "mat.chain.json"))
    assert loaded.to_dict() == chain.to_dict() and loaded.id == chain.id
    rec = world["session"]
    by_stages = loaded.reset().run(rec)
    compiled = Pipeline(loaded, rec.layout, repair=None).run(rec)
    np.testing.assert_array_equal(compiled.valid, by_stages.valid)
    np.testing.assert_array_equal(compiled.frames, by_stages.frames)
    # ... and with a repair stage at the end of the chain
    repaired = StageChain([*loaded.stages, Repair(rec.layout, "idw8").fit()])
    expected = repaired.reset().run(rec)
    got = Pipeline(loaded, rec.layout, repair="idw8").run(rec)
    np.testing.assert_array_equal(got.frames, expected.frames)
    # streaming through the chain
    loaded.reset()
    rows = [loaded.step(rec.frames[k], rec.valid[k], rec.times[k])[0] for k in range(20)]
    np.testing.assert_array_equal(np.array(rows, np.float32), by_stages.frames[:20])


def test_a_qlv_drift_runs_the_same_in_the_pipeline_and_stage_by_stage(world):
    """A drift that relaxes the elastic response of the input (QLV, level 'backbone'):
    the compiled pipeline (Compensation with a level curve) equals the chain run stage
    after stage, batch and streaming."""
    from texsense.compensation.drift import DriftModel, log_kernel
    from texsense.compensation.stages import Drift

    chain = world["chain"]
    hyst = chain["hysteresis"].model_
    qlv = DriftModel(-0.02, log_kernel(), level="backbone", backbone=hyst.backbone_curve())
    qlv_chain = StageChain([*chain.without("drift").stages, Drift.of(qlv)])
    rec = world["session"]
    by_stages = qlv_chain.reset().run(rec)
    compiled = Pipeline(qlv_chain, rec.layout, repair=None).run(rec)
    np.testing.assert_array_equal(compiled.valid, by_stages.valid)
    np.testing.assert_array_equal(compiled.frames, by_stages.frames)
    plain = chain.reset().run(rec)
    ok = by_stages.valid & plain.valid
    assert np.nanmax(np.abs(by_stages.frames[ok] - plain.frames[ok])) > 1e-4
    qlv_chain.reset()
    rows = [qlv_chain.step(rec.frames[k], rec.valid[k], rec.times[k])[0] for k in range(20)]
    np.testing.assert_array_equal(np.array(rows, np.float32), by_stages.frames[:20])


def test_a_chain_checks_what_flows_from_stage_to_stage(world):
    chain = world["chain"]
    with pytest.raises(ValueError, match="the hysteresis stage reads compression"):
        StageChain([chain["detect"], chain["hysteresis"]])
    assert chain.without("drift").names == ["detect", "convert", "hysteresis"]
    assert chain.reads == ("capacitance", "pF") and chain.gives == ("pressure", "N/cm2")
