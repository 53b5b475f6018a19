"""One contract for every stage (in the spirit of scikit-learn's parametrize_with_checks):
each check runs on every stage of texsense.stages with the input it reads."""

from __future__ import annotations

import numpy as np
import pytest

from texsense.exceptions import FormatError, NotFittedError
from texsense.pipeline import Pipeline
from texsense.sim import protocols
from texsense.sim.failures import FailureModel
from texsense.sim.mat import VirtualMat
from texsense.sim.seated import Subject, simulate_session
from texsense.stages import (
    STAGES,
    Convert,
    Detect,
    Drift,
    Hysteresis,
    Repair,
    StageChain,
    load_chain,
    stage_from_dict,
)
from texsense.workflows import material_record


def seat_records():
    """What a user calibrates the virtual seat from: its layout, unloaded and 1 N/cm² scans,
    a test-machine record and held steps of another specimen."""
    from texsense.drift import split_steps

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
    """Fitted stages of the virtual seat and, for each, a recording of what it reads (the
    previous stage's output on a session with failures)."""
    mat, base, uni, material, steps = seat_records()
    fits = {
        "detect": lambda: Detect(mat.layout, stuck_frames=8).fit(base),
        "convert": lambda: Convert(3.0, 1.0).fit(material, base, uni),
        "hysteresis": lambda: Hysteresis().fit(
            material["compression_mm"], material["pressure_ncm2"]
        ),
        "drift": lambda: Drift().fit(steps),
        "repair": lambda: Repair(mat.layout, "harmonic").fit(),
    }
    session = simulate_session(
        Subject.random(3), mat=VirtualMat.seat(seed=5, failures=FailureModel()),
        rounds=1, rest_s=10.0, posture_s=8.0,
    ).capacitance.select(slice(0, 120))  # fmt: skip
    fitted = {k: f() for k, f in fits.items()}
    inputs = {"detect": session, "convert": session}
    inputs["hysteresis"] = fitted["convert"].reset().run(session)
    inputs["drift"] = fitted["hysteresis"].reset().run(inputs["hysteresis"])
    inputs["repair"] = fitted["detect"].reset().run(session)  # validity from detection
    inputs["repair"] = inputs["drift"]._with(valid=inputs["drift"].valid & inputs["repair"].valid)
    for s in fitted.values():
        s.reset()
    fresh = {
        "detect": lambda: Detect(mat.layout, stuck_frames=8),
        "convert": lambda: Convert(3.0, 1.0),
        "hysteresis": lambda: Hysteresis(),
        "drift": lambda: Drift(),
        "repair": lambda: Repair(mat.layout, "harmonic"),
    }
    return {"fits": fits, "fitted": fitted, "inputs": inputs, "fresh": fresh, "layout": mat.layout}


NAMES = sorted(STAGES)


def same(a, b, rtol=0.0, atol=None):
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    atol = (1e-9 if rtol else 0.0) if atol is None else atol
    np.testing.assert_allclose(a, b, rtol=rtol, atol=atol, equal_nan=True)


@pytest.mark.parametrize("name", NAMES)
def test_constructor_stores_parameters_and_fit_returns_self(world, name):
    stage = world["fresh"][name]()
    params = stage._params()
    assert not stage.is_fitted()
    assert not [k for k in vars(stage) if k.endswith("_") and not k.startswith("_")]
    with pytest.raises(NotFittedError):
        stage.run(world["inputs"][name])
    fitted = world["fits"][name]()
    assert type(fitted) is type(stage) and fitted.is_fitted()
    learned = [k for k in vars(fitted) if k.endswith("_") and not k.startswith("_")]
    assert learned, "what fit learns ends in _"
    assert fitted._params() == params  # fit does not change the parameters


@pytest.mark.parametrize("name", NAMES)
def test_streaming_equals_batch(world, name):
    stage, rec = world["fitted"][name], world["inputs"][name]
    batch = stage.reset().run(rec)
    stage.reset()
    rows = [stage.step(rec.frames[k], rec.valid[k], rec.times[k]) for k in range(rec.n_frames)]
    values = np.array([r[0] for r in rows])
    valid = np.array([r[1] for r in rows])
    np.testing.assert_array_equal(valid, batch.valid)
    same(values.astype(np.float32), batch.frames)
    assert batch.valid.sum() > 0.5 * batch.valid.size


@pytest.mark.parametrize("name", [n for n in NAMES if n != "repair"])
def test_an_invalid_reading_leaves_the_state_untouched(world, name):
    """Element 7 fails for frames 40-59: afterwards it continues as if those frames had
    not been recorded at all (time passes); the failed readings are marked invalid. (The
    repair stage fills invalid readings instead: next test.)"""
    stage, rec = world["fitted"][name], world["inputs"][name]
    gap = slice(40, 60)
    valid = rec.valid.copy()
    valid[gap, 7] = False
    frames = rec.frames.copy()
    frames[gap, 7] = np.nan if name != "detect" else frames[gap, 7]
    with_gap = stage.reset().run(rec._with(frames=frames, valid=valid))
    assert not with_gap.valid[gap, 7].any()
    keep = np.ones(rec.n_frames, bool)
    keep[gap] = False
    without = stage.reset().run(rec.select(keep))
    same(with_gap.frames[60:, 7], without.frames[40:, 7], rtol=1e-6)
    np.testing.assert_array_equal(with_gap.valid[60:, 7], without.valid[40:, 7])


def test_repair_fills_invalid_readings_and_keeps_them_marked(world):
    stage, rec = world["fitted"]["repair"], world["inputs"]["repair"]
    out = stage.reset().run(rec)
    bad = ~rec.valid
    assert bad.any() and np.isfinite(out.frames[bad]).mean() > 0.95
    np.testing.assert_array_equal(out.valid, rec.valid)
    np.testing.assert_array_equal(out.frames[~bad], rec.frames[~bad])


@pytest.mark.parametrize("name", NAMES)
def test_save_load_round_trip_and_reset(world, name, tmp_path):
    stage, rec = world["fitted"][name], world["inputs"][name]
    first = stage.reset().run(rec)
    again = stage.reset().run(rec)  # reset: the same stream again
    same(first.frames, again.frames)
    path = stage.save(tmp_path / f"{name}.json")
    loaded = type(stage).load(path)
    assert type(loaded) is type(stage) and loaded.to_dict() == stage.to_dict()
    same(loaded.run(rec).frames, first.frames)
    d = stage.to_dict()
    assert d["format"] == "texsense.stage" and d["version"] == 1 and d["stage"] == name


def test_bad_stage_files_name_the_problem(tmp_path):
    with pytest.raises(FormatError, match=r"not a texsense\.stage"):
        stage_from_dict({"format": "x"})
    with pytest.raises(FormatError, match="unknown stage 'magic'"):
        stage_from_dict({"format": "texsense.stage", "version": 1, "stage": "magic"})
    with pytest.raises(FormatError, match="version 9"):
        stage_from_dict({"format": "texsense.stage", "version": 9, "stage": "drift"})
    with pytest.raises(FormatError, match="hysteresis stage: bad or missing field"):
        stage_from_dict(
            {"format": "texsense.stage", "version": 1, "stage": "hysteresis", "fitted": {}}
        )
    (tmp_path / "b.json").write_bytes(b"\x89HDF\r\n")
    with pytest.raises(FormatError, match="binary"):
        load_chain(tmp_path / "b.json")


def test_a_mat_calibration_is_one_chain_of_stages(world, tmp_path):
    """The chain's file round trip; the compiled pipeline equals the stages run one after
    the other; a first-round calibration file loads as the same chain."""
    from texsense.workflows import calibrate_mat

    _, base, uni, material, steps = seat_records()
    chain = StageChain.fit_mat(material, base, uni, 1.0, 3.0, steps=steps)
    assert [s.name for s in chain.stages] == ["detect", "convert", "hysteresis", "drift"]
    loaded = load_chain(chain.save(tmp_path / "mat.chain.json"))
    assert loaded.to_dict() == chain.to_dict()
    rec = world["inputs"]["detect"]
    by_stages = loaded.reset().run(rec)
    compiled = Pipeline(loaded.calibration(), rec.layout, repair=None).run(rec)
    np.testing.assert_array_equal(compiled.valid, by_stages.valid)
    # stages hand float32 recordings on: compression rounded to 1e-7 between two stages
    same(compiled.frames, by_stages.frames, rtol=1e-5, atol=1e-6)
    # the first-round file of the same calibration loads as the same chain
    old = calibrate_mat(material, base, uni, 1.0, 3.0, steps=steps)
    old.save(tmp_path / "old.json")
    from_old = load_chain(tmp_path / "old.json", layout=rec.layout)
    assert [s.name for s in from_old.stages] == ["detect", "convert", "hysteresis", "drift"]
    assert from_old.calibration().id == old.id
    same(from_old.reset().run(rec).frames, by_stages.frames)
