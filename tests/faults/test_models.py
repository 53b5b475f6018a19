"""Faults of the model files (issue 28): a failed or killed write keeps the previous model or
calibration; a model that is a folder, binary, UTF-16, ``[]`` or ragged is one clear line; a
hand-edited chain calibration is refused, and accepted only deliberately."""

from __future__ import annotations

import hashlib
import json
import resource
import sys
from pathlib import Path

import numpy as np
import pytest

from faults._families import batch, one_line
from faults.conftest import assert_clear_error, run_cli
from texsense.calibration.workflows import material_record
from texsense.io.columns_csv import write_columns_csv
from texsense.sim import protocols
from texsense.sim.mat import VirtualMat

#: a Python that dies of SIGXFSZ when a file grows past the limit, as a process killed in
#: the middle of a write does (Python itself ignores the signal and gets EFBIG instead)
_KILLABLE = (
    "import signal, sys; signal.signal(signal.SIGXFSZ, signal.SIG_DFL); "
    "from texsense.cli import main; sys.exit(main(sys.argv[1:]))"
)


def _limit_file_size(n_bytes: int):
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (n_bytes, n_bytes))

    return apply


def _killable_cli(*args: str, limit: int):
    import subprocess

    proc = subprocess.run(
        [sys.executable, "-c", _KILLABLE, *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=_limit_file_size(limit),
    )
    return proc.returncode, proc.stdout, proc.stderr


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A 4 x 4 mat's calibration inputs (:func:`calibration_inputs`)."""
    return calibration_inputs(tmp_path_factory.mktemp("models"))


def calibration_inputs(d: Path) -> Path:
    """A 4 x 4 mat's calibration inputs in ``d``: material record, unloaded and uniform
    recordings, and a recording to process."""
    mat = VirtualMat.prototype(16, "textile-3mm", seed=4)
    n, ft = 16, mat.cdc.frame_time_s(16)
    mat.scan(np.arange(8) * ft, np.zeros((8, n))).capacitance.save(d / "base.h5")
    mat.scan((8 + np.arange(8)) * ft, np.ones((8, n))).capacitance.save(d / "uniform.h5")
    mat.scan((20 + np.arange(20)) * ft, np.full((20, n), 1.5)).capacitance.save(d / "raw.h5")
    material = material_record(
        protocols.run_protocol("calibration", "textile-3mm", seed=9, sample_hz=None)
    )
    write_columns_csv(d / "material.csv", material)
    return d


def _calibrate(d, out, *extra):
    return [
        "calibrate", "mat", "--material", d / "material.csv", "--baseline", d / "base.h5",
        "--uniform", d / "uniform.h5", "--pressure", "1", "--thickness-mm", "3", "-o", out,
        *extra,
    ]  # fmt: skip


def _fit(d, out):
    return ["hysteresis", "fit", d / "material.csv", "-o", out, "--cells", "10", "--smoothing",
            "1e-3"]  # fmt: skip


@pytest.fixture(scope="module")
def written(inputs):
    """A calibration and a hysteresis model written by the commands, to be replaced."""
    rc, _, err = run_cli(*_calibrate(inputs, inputs / "mat.json"))
    assert rc == 0, err
    rc, _, err = run_cli(*_fit(inputs, inputs / "model.json"))
    assert rc == 0, err
    return inputs


def _leftovers(folder, name):
    """Files that look like a half-written ``name`` (the target itself excluded)."""
    return [
        p.name
        for p in folder.iterdir()
        if p.name != name and p.name.startswith(name) and not p.name.startswith(".")
    ]


@pytest.mark.parametrize("what", ["calibrate", "hysteresis"])
def test_disk_full_keeps_the_previous_model(written, tmp_path, what, fault_row):
    name = "mat.json" if what == "calibrate" else "model.json"
    target = tmp_path / name
    target.write_bytes((written / name).read_bytes())
    before = target.read_bytes()
    args = _calibrate(written, target) if what == "calibrate" else _fit(written, target)
    if what == "calibrate":  # a calibration is replaced only when asked (issue 33)
        args = [*args, "--replace"]
    rc, _, err = run_cli(*args, preexec=_limit_file_size(2048))
    line = assert_clear_error(rc, err, name)
    assert "unchanged" in line or "kept" in line, line
    assert target.read_bytes() == before
    assert not _leftovers(tmp_path, name)
    label = "calibrate mat -o" if what == "calibrate" else "hysteresis fit -o"
    fault_row("model files", f"{label}, disk full (ulimit -f)", "data kept")


@pytest.mark.parametrize("what", ["calibrate", "hysteresis"])
def test_killed_mid_write_keeps_the_previous_model(written, tmp_path, what, fault_row):
    name = "mat.json" if what == "calibrate" else "model.json"
    target = tmp_path / name
    target.write_bytes((written / name).read_bytes())
    before = target.read_bytes()
    args = _calibrate(written, target) if what == "calibrate" else _fit(written, target)
    rc, _, err = _killable_cli(*args, limit=2048)
    assert rc != 0, err  # killed by SIGXFSZ in the middle of the write
    assert target.read_bytes() == before
    assert not _leftovers(tmp_path, name)
    label = "calibrate mat -o" if what == "calibrate" else "hysteresis fit -o"
    fault_row("model files", f"{label}, killed mid-write", "data kept")


def _bad_files(folder, good: dict) -> dict:
    """A model file broken in each way of issue 28, by name."""
    folder.mkdir(exist_ok=True)
    (folder / "folder.json").mkdir(exist_ok=True)
    (folder / "binary.json").write_bytes(b"\x89HDF\r\n\x1a\n\x00\x00\x00\x00")
    (folder / "utf16.json").write_bytes(json.dumps(good).encode("utf-16"))
    (folder / "brackets.json").write_text("[]", encoding="utf-8")
    return {
        "a folder": folder / "folder.json",
        "binary": folder / "binary.json",
        "UTF-16": folder / "utf16.json",
        "[]": folder / "brackets.json",
    }


def _content(d: dict) -> dict:
    """The content of a model file (the whole file before the envelope of issue 24)."""
    return d.get("content", d)


def _rehashed(d: dict) -> dict:
    """``d`` with the SHA-256 of its content (canonical JSON: sorted keys, no spaces), as
    docs/pipeline.md defines it: an edit that the hash check cannot see."""
    if "sha256" in d:
        canonical = json.dumps(d["content"], sort_keys=True, separators=(",", ":"))
        d["sha256"] = hashlib.sha256(canonical.encode()).hexdigest()
    return d


def _ragged_model(good: dict) -> dict:
    bad = json.loads(json.dumps(good))
    content = _content(bad)
    table = content.get("everett")
    if table is None:  # a chain: the hysteresis stage's table
        for s in content["stages"]:
            if s["stage"] == "hysteresis":
                table = s["fitted"]["model"]["everett"]
    table[3] = table[3][:-2]
    return _rehashed(bad)


@pytest.mark.parametrize("case", ["a folder", "binary", "UTF-16", "[]", "ragged"])
def test_a_broken_hysteresis_model_is_one_line(written, tmp_path, case, fault_row):
    good = json.loads((written / "model.json").read_text(encoding="utf-8"))
    files = _bad_files(tmp_path / "bad", good)
    ragged = tmp_path / "bad" / "ragged.json"
    ragged.write_text(json.dumps(_ragged_model(good)), encoding="utf-8")
    files["ragged"] = ragged
    path = files[case]
    for args in (
        ["drift", "fit", written / "material.csv", "--history", path],
        ["hysteresis", "apply", path, written / "material.csv", "-o", tmp_path / "o.csv"],
        ["hysteresis", "validate", path, written / "material.csv"],
        ["hysteresis", "plot", path, "-o", tmp_path / "o.png"],
    ):
        rc, _, err = run_cli(*args)
        line = assert_clear_error(rc, err, path.name)
        want = {"a folder": "folder", "[]": "list", "ragged": "everett", "UTF-16": "UTF-16"}
        assert want.get(case, "") in line, line
    fault_row("model files", f"hysteresis model that is {case}", "clear error")


# (a calibration that is a folder, binary or ``[]`` was one clear line already)
@pytest.mark.parametrize("case", ["UTF-16", "ragged"])
def test_a_broken_calibration_is_one_line(written, tmp_path, case, fault_row):
    good = json.loads((written / "mat.json").read_text(encoding="utf-8"))
    files = _bad_files(tmp_path / "bad", good)
    ragged = tmp_path / "bad" / "ragged.json"
    ragged.write_text(json.dumps(_ragged_model(good)), encoding="utf-8")
    files["ragged"] = ragged
    path = files[case]
    for args in (
        ["process", written / "raw.h5", "--calibration", path, "-o", tmp_path / "p.h5"],
        ["health", written / "raw.h5", "--calibration", path],
    ):
        rc, _, err = run_cli(*args)
        line = assert_clear_error(rc, err, path.name)
        if case == "UTF-16":
            assert "UTF-16" in line, line
        if case == "ragged":
            assert "everett" in line, line  # names the field
    fault_row("model files", f"calibration that is {case}", "clear error")


def test_a_hand_edited_calibration_is_refused_until_accepted(written, tmp_path, fault_row):
    """One offset changed by hand (to 1.25 pF): refused with a line that says the file was
    edited and how to accept it; accepted after the documented re-hash (an offset of 1e308
    is refused even then: tests/faults/test_stage_ranges.py)."""
    d = json.loads((written / "mat.json").read_text(encoding="utf-8"))
    (convert,) = [s for s in _content(d)["stages"] if s["stage"] == "convert"]
    convert["fitted"]["elements"]["offset_pF"][3] = 1.25
    edited = tmp_path / "edited.json"
    edited.write_text(json.dumps(d), encoding="utf-8")
    out = tmp_path / "p.h5"
    rc, _, err = run_cli("process", written / "raw.h5", "--calibration", edited, "-o", out)
    line = assert_clear_error(rc, err, "edited.json")
    assert "edited" in line and "texsense rehash" in line, line
    assert not out.exists()
    rc, stdout, err = run_cli("rehash", edited)
    assert rc == 0 and "edited.json" in stdout, err
    rc, _, err = run_cli("process", written / "raw.h5", "--calibration", edited, "-o", out)
    assert rc == 0, err
    fault_row("model files", "hand-edited chain calibration (one offset 1.25 pF)", "clear error")


def _drift_stage(content: dict) -> dict:
    (drift,) = [s for s in content["stages"] if s["stage"] == "drift"]
    return drift["fitted"]["model"]


@pytest.mark.parametrize(
    ("case", "field"),
    [
        ("a level power of 20", "exponent"),
        ("a level that is neither output nor backbone", "level"),
        ("a QLV backbone curve that is not increasing", "backbone"),
        ("a QLV drift stage without its hysteresis stage", "follow the hysteresis stage"),
    ],
)
def test_a_broken_drift_stage_is_one_line(written, tmp_path, case, field, fault_row):
    """A hysteresis + drift model file (as ``drift fit --history -o`` writes it) with its
    drift stage broken by hand (and re-hashed): one line naming the file and the field; the
    good file applies."""
    from texsense.compensation.drift import DriftModel, log_kernel
    from texsense.compensation.hysteresis import HysteresisModel
    from texsense.compensation.stages import Drift, Hysteresis, StageChain

    model = HysteresisModel.load(written / "model.json")
    drift_model = DriftModel(-0.02, log_kernel(), rest_rate=0.02)
    good = StageChain([Hysteresis.of(model), Drift.of(drift_model)]).save(tmp_path / "md.json")
    rec = protocols.run_protocol("calibration", "textile-3mm", seed=9, sample_hz=None)
    cols = {"time_s": rec.times, **{k: rec.labels[k] for k in ("compression_mm", "pressure_ncm2")}}
    write_columns_csv(tmp_path / "rec.csv", cols)
    d = json.loads(good.read_text(encoding="utf-8"))
    drift = _drift_stage(_content(d))
    curve = {"inputs": [0.0, 1.0, 2.0], "responses": [0.0, 0.5, 1.5]}
    if case.startswith("a level power"):
        drift["exponent"] = 20.0
    elif case.startswith("a level that"):
        drift["level"] = "sideways"
    elif case.startswith("a QLV backbone"):
        drift.update(level="backbone", backbone=curve | {"inputs": [0.0, 2.0, 1.0]})
    else:
        drift.update(level="backbone", backbone=curve)
        _content(d)["stages"] = [s for s in _content(d)["stages"] if s["stage"] == "drift"]
    rc, _, err = run_cli("hysteresis", "apply", good, tmp_path / "rec.csv", "-o",
                         tmp_path / "good.csv")  # fmt: skip
    assert rc == 0, err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(_rehashed(d)), encoding="utf-8")
    rc, _, err = run_cli("hysteresis", "apply", bad, tmp_path / "rec.csv", "-o",
                         tmp_path / "o.csv")  # fmt: skip
    line = assert_clear_error(rc, err, "bad.json")
    assert field in line, line
    assert not (tmp_path / "o.csv").exists()
    fault_row("model files", f"drift stage with {case}", "clear error")


#: values a stage's parameter may not hold (for every type hint one of them is wrong)
ODD_PARAMS = {"text": "x", "object": {}, "list": [1, 2], "1e308": 1e308, "NaN": float("nan"),
              "true": True, "2**64": 2**64}  # fmt: skip


def test_every_stage_parameter_of_a_wrong_kind_is_one_line(written, tmp_path, fault_row):
    """Every parameter of every stage of a calibration (re-hashed: a deliberate edit) holding
    a value its type cannot (a count of 1e308 was an OverflowError out of the compiled
    detector, an object for a pressure a TypeError): a FormatError naming the file and the
    parameter, from the one place a stage's parameters are read (``Stage.from_dict``)."""
    import typing

    from texsense.compensation.stages import STAGES, load_chain
    from texsense.exceptions import FormatError

    good = json.loads((written / "mat.json").read_text(encoding="utf-8"))
    argvs, tried = [], 0
    for k, stage in enumerate(_content(good)["stages"]):
        hints = typing.get_type_hints(STAGES[stage["stage"]].__init__)
        for key in stage["params"]:
            kind = getattr(hints[key], "__name__", str(hints[key]))
            if "Layout" in kind:
                continue  # a layout is decoded by Layout.from_dict (tests/faults/test_indices.py)
            for name, value in ODD_PARAMS.items():
                if name in ("NaN", "1e308", "2**64") and "int" not in kind:
                    continue  # a number where a number belongs: its range is the stage's
                if name == "text" and "str" in kind:
                    continue
                d = json.loads(json.dumps(good))
                _content(d)["stages"][k]["params"][key] = value
                path = tmp_path / f"{stage['stage']}-{key}-{name}.json"
                path.write_text(json.dumps(_rehashed(d)), encoding="utf-8")
                with pytest.raises(FormatError, match=f"params.{key}") as e:
                    load_chain(path)
                assert path.name in str(e.value)
                argvs.append(["health", str(written / "raw.h5"), "--calibration", str(path)])
                tried += 1
    results, _, _ = batch(argvs[::7], tmp_path)  # a sample end to end: one line each
    for argv, (rc, _out, err) in zip(argvs[::7], results, strict=True):
        one_line(rc, err, Path(argv[-1]).name)
    fault_row("model files", f"{tried} stage parameters of a wrong kind (text, object, list, "
              "1e308, NaN or 2**64 for a count, true), re-hashed", "clear error",
              cases=tried)  # fmt: skip
