"""The one legacy reader (texsense.data.legacy) on the model files the code wrote before the
one-calibration refactor (tests/fixtures/models, made by make_fixtures.py at commit 41db87f):
every file loads, as a chain, and gives the numbers that code gave."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from texsense import Layout, Recording
from texsense.compensation.hysteresis import HysteresisModel
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import FailureDetector, Repair, load_chain, load_stage
from texsense.exceptions import FormatError

HERE = Path(__file__).parent / "fixtures" / "models"


@pytest.fixture(scope="module")
def expected():
    d = np.load(HERE / "expected.npz")
    layout = Layout.from_dict(json.loads(str(d["layout"])))
    raw = Recording(
        d["frames"], d["times"], layout, "capacitance", "pF", valid=d["valid"],
        element_times=d["element_times"],
    )  # fmt: skip
    return d, raw


@pytest.mark.parametrize(
    ("name", "stages"),
    [
        ("calibration-v1-mat", ["convert", "hysteresis", "drift"]),
        ("calibration-v1-mat-nodrift", ["convert", "hysteresis"]),
        ("chain-v1", ["detect", "convert", "hysteresis", "drift"]),
    ],
)
def test_mat_calibrations_of_the_first_round_give_the_same_pressure(expected, name, stages):
    d, raw = expected
    key = {"calibration-v1-mat": "mat", "calibration-v1-mat-nodrift": "mat_nodrift"}.get(
        name, "chain"
    )
    chain = load_chain(HERE / f"{name}.json")
    assert chain.names == stages
    out = Pipeline(chain, raw.layout, repair="neighbour-mean").run(raw)
    np.testing.assert_array_equal(out.valid, d[f"{key}_valid"])
    np.testing.assert_array_equal(out.frames, d[f"{key}_pressure"])
    # the stages one after the other give the same (the first round's StageChain.run rounded
    # to float32 between stages: 1e-5 off)
    by_stages = chain.reset().run(raw)
    if key == "chain":
        np.testing.assert_allclose(
            by_stages.frames, d["chain_stages_pressure"], rtol=1e-5, atol=1e-5
        )


def test_a_linear_calibration_is_a_chain_of_one_linear_stage(expected):
    d, raw = expected
    chain = load_chain(HERE / "calibration-v1-linear.json")
    assert chain.names == ["linear"] and chain.gives == ("capacitance", "pF")
    assert chain["linear"].full_scale == 4095.0
    out = Pipeline(chain, raw.layout, repair="neighbour-mean").run(raw)
    np.testing.assert_array_equal(out.frames, d["linear_values"])
    np.testing.assert_array_equal(out.valid, d["linear_valid"])


def test_hysteresis_models_with_and_without_drift(expected):
    d, _ = expected
    u, t = d["hysteresis_input"], d["hysteresis_times"]
    model = HysteresisModel.load(HERE / "hysteresis-v1.json")
    np.testing.assert_array_equal(model.predict(u), d["hysteresis_output"])
    assert model.method_ == "lsq+thesis-prior" and model.method == "auto"
    with pytest.raises(FormatError, match="holds a stage chain"):
        HysteresisModel.load(HERE / "hysteresis-v1-drift.json")
    chain = load_chain(HERE / "hysteresis-v1-drift.json")  # the model with its drift stage
    assert chain.names == ["hysteresis", "drift"]
    got = chain._arrays(u[:, None], None, t)[0][:, 0]
    np.testing.assert_array_equal(got, d["hysteresis_drift_output"])


def test_stage_files_of_version_1(expected):
    _, raw = expected
    detect = load_stage(HERE / "stage-v1-detect.json")
    assert isinstance(detect, FailureDetector) and detect.layout == raw.layout
    repair = load_stage(HERE / "stage-v1-repair.json")
    assert isinstance(repair, Repair) and repair.method == "idw8" and repair.is_fitted()
    for name in ("convert", "hysteresis", "drift"):
        stage = load_stage(HERE / f"stage-v1-{name}.json")
        assert stage.name == name and stage.is_fitted()


def test_earlier_formats_are_read_never_written(tmp_path):
    chain = load_chain(HERE / "calibration-v1-mat.json")
    d = json.loads(chain.save(tmp_path / "now.json").read_text())
    assert (d["format"], d["version"]) == ("texsense.chain", 2) and "sha256" in d
    assert load_chain(tmp_path / "now.json").to_dict() == chain.to_dict()


def test_an_edited_first_round_calibration_is_refused(tmp_path):
    d = json.loads((HERE / "calibration-v1-mat.json").read_text())
    d["elements"]["offset_pF"][3] = 1.25  # an edit within the offsets' bounds
    (tmp_path / "edited.json").write_text(json.dumps(d))
    with pytest.raises(FormatError, match="was edited after texsense wrote it"):
        load_chain(tmp_path / "edited.json")
    del d["id"]  # the first round's way to accept an edit
    (tmp_path / "accepted.json").write_text(json.dumps(d))
    assert load_chain(tmp_path / "accepted.json")["convert"].offset_pF_[3] == 1.25
    d["elements"]["offset_pF"][3] = 1e308  # accepted as an edit, refused as an offset
    (tmp_path / "huge.json").write_text(json.dumps(d))
    with pytest.raises(FormatError, match=r"offset_pF'.*1e\+308, expected a number in"):
        load_chain(tmp_path / "huge.json")
    d = json.loads((HERE / "calibration-v1-mat.json").read_text())
    (tmp_path / "kind.json").write_text(json.dumps({**d, "kind": "magic"}))
    with pytest.raises(FormatError, match="unknown calibration kind 'magic'"):
        load_chain(tmp_path / "kind.json")
    del d["id"]
    (tmp_path / "missing.json").write_text(json.dumps({**d, "curve": None}))
    with pytest.raises(FormatError, match=r"missing field 'fitted\.curve\.compression_mm'"):
        load_chain(tmp_path / "missing.json")
