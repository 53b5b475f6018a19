"""The range of every parameter of every stage (harden14b): a value out of its declared range
(:mod:`texsense.data.ranges`, ``Stage.ranges``) is refused in one line naming the stage and
the parameter, through a model file (written by the project's writer, one field tampered,
re-hashed: a deliberate edit) and through the constructor; the values at the range's ends
are accepted. The fitted numbers a file carries (Everett table, drift kernel, offsets and
gains, ...) are refused out of their bounds, naming the field. A sample runs through the
commands that load a calibration: one line, no traceback."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from faults._families import batch, one_line
from texsense import Layout
from texsense.compensation.drift import DriftModel, log_kernel
from texsense.compensation.stages import STAGES, Drift, Linear, Repair, StageChain, load_chain
from texsense.data.modelfile import content_hash
from texsense.data.ranges import Instance, Maybe, RangeError
from texsense.exceptions import FormatError, ParameterError

#: the fitted numbers of a file, tampered with these (one entry of an array, or the number)
ODD_NUMBERS = {"NaN": math.nan, "inf": math.inf, "-inf": -math.inf, "1e300": 1e300,
               "-1e300": -1e300, "text": "1.0"}  # fmt: skip


def _content(d: dict) -> dict:
    return d["content"]


def _rehashed(d: dict) -> dict:
    d["sha256"] = content_hash(d["content"])
    return d


@pytest.fixture(scope="module")
def files(tmp_path_factory, calibration_files):
    """Good files of every stage: a mat's chain (detect, convert, hysteresis, drift), a
    linear chain, a repair stage."""
    return make_files(tmp_path_factory.mktemp("ranges"), calibration_files)


def make_files(d: Path, calibration_files: Path) -> Path:
    """The files of :func:`files` in the folder ``d``."""
    mat = load_chain(calibration_files / "mat.json")
    drift = Drift.of(DriftModel(-0.02, log_kernel(), "log", 0.5, gamma_time=-0.01))
    StageChain([*mat.stages, drift]).save(d / "mat.json")
    lay = Layout.grid(4, 4)
    linear = Linear("capacitance", "pF", "pressure", "N/cm2", full_scale=100.0)
    StageChain([linear.fit(np.zeros(16), np.ones(16))]).save(d / "linear.json")
    Repair(lay, "idw8").fit().save(d / "repair.json")
    (d / "raw.h5").write_bytes((calibration_files / "raw.h5").read_bytes())
    return d


@pytest.fixture(scope="module")
def calibration_files(tmp_path_factory):
    """A 4 x 4 mat's calibration made by ``texsense calibrate mat`` and a recording (as
    test_models.py makes them)."""
    return make_calibration(tmp_path_factory.mktemp("cal"))


def make_calibration(folder: Path) -> Path:
    """The files of :func:`calibration_files` in the folder ``folder``."""
    from faults.conftest import run_cli
    from faults.test_models import _calibrate, calibration_inputs

    d = calibration_inputs(folder)
    rc, _, err = run_cli(*_calibrate(d, d / "mat.json"))
    assert rc == 0, err
    return d


def _stages(d: dict) -> list[dict]:
    c = _content(d)
    return c.get("stages", [c])


def _cases(files: Path):
    """(file name, stage index, stage name, parameter, kind) of every declared parameter."""
    for name in ("mat.json", "linear.json", "repair.json"):
        good = json.loads((files / name).read_text(encoding="utf-8"))
        for k, stage in enumerate(_stages(good)):
            cls = STAGES[stage["stage"]]
            for key, kind in cls.ranges.items():
                if not isinstance(kind, Instance):  # a Layout checks itself (test_layout_fields)
                    yield name, good, k, cls, key, kind


def _tampered(good: dict, k: int, edit) -> dict:
    d = json.loads(json.dumps(good))
    edit(_stages(d)[k])
    return _rehashed(d)


def test_every_stage_declares_every_parameter():
    """A parameter without a declared range fails here (and in its constructor)."""
    for name, cls in STAGES.items():
        assert set(cls.ranges) == set(cls._param_names()), name


def test_every_parameter_out_of_range_is_one_line(files, tmp_path, fault_row):
    """Every stage x every declared parameter x values beyond its range (NaN, infinities,
    just past each end, huge, text, a bool, a list): refused from the file and from the
    constructor in one line naming the stage and the parameter; the ends accepted."""
    got_through, tried, argvs = [], 0, []
    for name, good, k, cls, key, kind in _cases(files):
        for n, value in enumerate(kind.beyond()):
            tried += 2
            path = tmp_path / f"{cls.name}-{key}-{n}.json"
            d = _tampered(good, k, lambda s, key=key, value=value: s["params"].update({key: value}))
            path.write_text(json.dumps(d), encoding="utf-8")
            try:
                load_chain(path)
                got_through.append(f"file {path.name}: taken")
            except FormatError as e:
                text = str(e)
                if not (f"params.{key}" in text and cls.name in text and path.name in text):
                    got_through.append(f"file {path.name}: {text}")
                elif "\n" in text:
                    got_through.append(f"file {path.name}: more than one line")
            argvs.append(["health", str(files / "raw.h5"), "--calibration", str(path)])
            params = {**_good_params(cls, files), key: value}
            try:
                cls(**params)
                got_through.append(f"constructor {cls.name}.{key}={value!r}: taken")
            except ParameterError as e:
                if not (key in str(e) and cls.name in str(e)) or "\n" in str(e):
                    got_through.append(f"constructor {cls.name}.{key}={value!r}: {e}")
            except Exception as e:  # a traceback's kind
                got_through.append(f"constructor {cls.name}.{key}={value!r}: {e!r}")
        for value in kind.edges():
            if value is None or (isinstance(kind, Maybe) and name == "linear.json"):
                continue  # None is the default; a linear unit must fit its quantity (fit)
            cls(**{**_good_params(cls, files), key: value})  # accepted
            d = _tampered(good, k, lambda s, key=key, value=value: s["params"].update({key: value}))
            path = tmp_path / "edge.json"
            path.write_text(json.dumps(d), encoding="utf-8")
            if name != "linear.json":
                load_chain(path)  # accepted
    print(f"{len(got_through)} of {tried} got through:", *got_through[:40], sep="\n")
    assert not got_through
    _end_to_end(argvs[::9], tmp_path)
    fault_row("stage ranges", f"{tried // 2} stage parameters out of range x file and "
              "constructor", "clear error", cases=tried)  # fmt: skip


def _good_params(cls: type, files: Path) -> dict[str, Any]:
    """Constructor arguments of ``cls`` that it accepts (its file's, the layout decoded)."""
    lay = Layout.grid(4, 4)
    out: dict[str, Any] = {
        "layout": lay,
        "thickness_mm": 3.0,
        "input_quantity": "capacitance",
        "input_unit": "pF",
    }
    return {k: v for k, v in out.items() if k in cls._param_names()}


def _numbers(node: Any, path: str = ""):
    """(dotted path, index or None) of every number and array of numbers under ``node``."""
    if isinstance(node, dict):
        for key, value in node.items():
            if key not in ("details", "provenance"):  # free text of the fit
                yield from _numbers(value, f"{path}.{key}" if path else key)
    elif isinstance(node, list) and node and isinstance(node[0], (int, float, list)):
        yield path, 0
    elif isinstance(node, (int, float)) and not isinstance(node, bool):
        yield path, None


def _set(stage: dict, path: str, index: int | None, value: Any) -> None:
    *parents, last = path.split(".")
    node = stage
    for p in parents:
        node = node[p]
    if index is None:
        node[last] = value
    else:
        target = node[last]
        while isinstance(target[index], list):
            target = target[index]
        target[index] = value


def test_every_fitted_number_out_of_bounds_is_one_line(files, tmp_path, fault_row):
    """Every number and array of numbers a stage's fitted state holds in a file (an entry
    made NaN, infinite, 1e300, -1e300 or text): refused in one line naming the field."""
    got_through, tried, argvs = [], 0, []
    for name in ("mat.json", "linear.json", "repair.json"):
        good = json.loads((files / name).read_text(encoding="utf-8"))
        for k, stage in enumerate(_stages(good)):
            for path_, index in _numbers({"fitted": stage["fitted"]}):
                for odd, value in ODD_NUMBERS.items():
                    tried += 1
                    path = tmp_path / f"{stage['stage']}-{path_}-{odd}.json"
                    d = _tampered(good, k, lambda s, p=path_, i=index, v=value: _set(s, p, i, v))
                    path.write_text(json.dumps(d), encoding="utf-8")
                    argvs.append(["health", str(files / "raw.h5"), "--calibration", str(path)])
                    try:
                        load_chain(path)
                        got_through.append(f"{path.name}: taken")
                    except FormatError as e:
                        last = path_.split(".")[-1]
                        if last not in str(e) or "\n" in str(e) or path.name not in str(e):
                            got_through.append(f"{path.name}: {e}")
    print(f"{len(got_through)} of {tried} got through:", *got_through[:60], sep="\n")
    assert not got_through
    _end_to_end(argvs[::11], tmp_path)
    fault_row("stage ranges", f"{tried} fitted numbers out of bounds", "clear error", cases=tried)


def test_the_cli_ranges_lie_within_the_stages():
    """An option that sets a stage's parameter never takes a value the stage refuses."""
    from texsense.commands._options import RANGES
    from texsense.compensation.stages import Convert, Hysteresis

    for option, (cls, key) in {
        "--grid": (Hysteresis, "grid"), "--cells": (Hysteresis, "cells"),
        "--smoothing": (Hysteresis, "smoothing"), "--folds": (Hysteresis, "folds"),
        "--rest-rate": (Drift, "rest_rate"), "--drift-rest-rate": (Drift, "rest_rate"),
        "--thickness-mm": (Convert, "thickness_mm"), "--full-scale": (Linear, "full_scale"),
    }.items():  # fmt: skip
        r, kind = RANGES[option], cls.ranges[key]
        for end, is_open, away in ((r.lo, r.lo_open, -1), (r.hi, r.hi_open, 1)):
            assert end is not None, f"{option} is unbounded; {cls.name}'s {key}: {kind.text()}"
            value = math.nextafter(end, -away * math.inf) if is_open else end
            if kind.holds(int(value)) or kind.holds(float(value)):
                continue
            pytest.fail(f"{option} takes {value}; {cls.name}'s {key} is {kind.text()}")


def test_the_constructors_check_their_own_parameters():
    """Examples of the issue: each one line naming the stage and the parameter."""
    from texsense.compensation.health import FailureDetector
    from texsense.compensation.stages import Convert, Hysteresis

    lay = Layout.grid(2, 2)
    for make, key in [
        (lambda: FailureDetector(lay, stuck_floor_pF=math.nan), "stuck_floor_pF"),
        (lambda: FailureDetector(lay, stuck_frames=10**9), "stuck_frames"),
        (lambda: Convert(-3.0), "thickness_mm"),
        (lambda: Hysteresis(grid=0), "grid"),
        (lambda: Hysteresis(grid=10**9), "grid"),
        (lambda: Drift(rest_rate=-1.0), "rest_rate"),
        (lambda: Repair(lay, "nearest"), "method"),
    ]:
        with pytest.raises(RangeError, match=key) as e:
            make()
        assert e.value.key == key and "\n" not in str(e.value)
    FailureDetector(lay, stuck_floor_pF=-math.inf, min_pF=-math.inf, jump_pF=math.inf)


def _end_to_end(argvs: list[list[str]], tmp_path: Path) -> None:
    """A sample through ``health``, ``process`` and ``export mcu``: one line each."""
    runs = []
    for n, argv in enumerate(argvs):
        cal = argv[-1]
        runs += [argv, ["process", argv[1], "--calibration", cal, "-o", str(tmp_path / f"o{n}.h5")],
                 ["export", "mcu", cal, "-o", str(tmp_path / f"m{n}.c")]]  # fmt: skip
    results, _, _ = batch(runs, tmp_path)
    for argv, (rc, _out, err) in zip(runs, results, strict=True):
        one_line(rc, err, Path(argv[3] if argv[0] != "export" else argv[2]).name)


#: a drift model's parameters by their field in its file
_DRIFT_FIELDS = {"rest_window": "rest_window_s"}


def test_the_models_own_files_check_the_same_ranges(files, calibration_files, tmp_path, fault_row):
    """A hysteresis model file's ``params`` and a drift model file's numbers and names (the
    models' declared ``RANGES``, the stages' being theirs) x the values beyond each range:
    one line naming the file and the field, from the model's reader and from ``load_chain``;
    a sample through ``hysteresis apply`` and ``process``."""
    from texsense.compensation.drift import RANGES as DRIFT_RANGES
    from texsense.compensation.hysteresis import HysteresisModel
    from texsense.compensation.hysteresis._model import RANGES as MODEL_RANGES

    mat = load_chain(calibration_files / "mat.json")
    mat["hysteresis"].model_.save(tmp_path / "model.json")
    DriftModel(-0.02, log_kernel(), "log", 0.5, gamma_time=-0.01).save(tmp_path / "drift.json")
    cases = [
        ("model.json", HysteresisModel, f"params.{k}", k, kind)
        for k, kind in MODEL_RANGES.items()
        if k in ("method", "grid", "cells", "smoothing", "folds")
    ]
    cases += [("drift.json", DriftModel, _DRIFT_FIELDS.get(k, k), k, kind)
              for k, kind in DRIFT_RANGES.items()]  # fmt: skip
    got_through, tried, argvs = [], 0, []
    for name, cls, field, key, kind in cases:
        good = json.loads((tmp_path / name).read_text(encoding="utf-8"))
        for n, value in enumerate(kind.beyond()):
            d = json.loads(json.dumps(good))
            node = d["content"]
            *parents, last = field.split(".")
            for p in parents:
                node = node[p]
            node[last] = value
            path = tmp_path / f"{name[:-5]}-{key}-{n}.json"
            path.write_text(json.dumps(_rehashed(d)), encoding="utf-8")
            for read in (cls.load, load_chain):
                tried += 1
                try:
                    read(path)
                    got_through.append(f"{path.name} by {read.__qualname__}: taken")
                except FormatError as e:
                    if field not in str(e) or path.name not in str(e) or "\n" in str(e):
                        got_through.append(f"{path.name} by {read.__qualname__}: {e}")
            argvs.append(path)
    print(f"{len(got_through)} of {tried} got through:", *got_through[:40], sep="\n")
    assert not got_through
    material = calibration_files / "material.csv"
    runs = []
    for n, path in enumerate(argvs[::5]):
        runs.append(
            ["hysteresis", "apply", str(path), str(material), "-o", str(tmp_path / f"a{n}.csv")]
        )
        runs.append(["process", str(files / "raw.h5"), "--calibration", str(path), "-o",
                     str(tmp_path / f"p{n}.h5")])  # fmt: skip
    results, _, _ = batch(runs, tmp_path)
    for argv, (rc, _out, err) in zip(runs, results, strict=True):
        one_line(rc, err, Path(argv[2] if argv[0] == "hysteresis" else argv[3]).name)
    fault_row("stage ranges", f"{tried} model parameters out of range (hysteresis and drift "
              "model files, their reader and load_chain)", "clear error", cases=tried)  # fmt: skip


#: values in many a range that a stage may divide by or scale with (harden15): denormals,
#: 1e-300, a gain of 1e-13; the fitted numbers also at the ends of the bounds they have
DEGENERATE = [5e-324, -5e-324, 1e-300, -1e-300, 1e-13]
DEGENERATE_FITTED = [*DEGENERATE, 1e15, -1e15, 1e12, -1e12, 1e6, 1e3]


def _degenerate_cases(files: Path):
    """(file name, good file, stage index, tampering, what) of every declared real parameter at
    the degenerate values it holds and its ends, and every fitted number at the degenerate
    values."""
    from texsense.data.ranges import Real

    for name in ("mat.json", "linear.json"):
        good = json.loads((files / name).read_text(encoding="utf-8"))
        for k, stage in enumerate(_stages(good)):
            cls = STAGES[stage["stage"]]
            for key, kind in cls.ranges.items():
                real = kind.kind if isinstance(kind, Maybe) else kind
                for value in (DEGENERATE + real.edges()) if isinstance(real, Real) else []:
                    if real.holds(value):
                        edit = lambda s, key=key, value=value: s["params"].update({key: value})  # noqa: E731
                        yield name, good, k, edit, f"{cls.name} params.{key}={value!r}"
            for path_, index in _numbers({"fitted": stage["fitted"]}):
                for value in DEGENERATE_FITTED:
                    edit = lambda s, p=path_, i=index, v=value: _set(s, p, i, v)  # noqa: E731
                    yield name, good, k, edit, f"{cls.name} {path_}[{index}]={value!r}"


def degenerate_outcomes(files: Path, tmp_path: Path) -> tuple[int, list[str]]:
    """Every case of :func:`_degenerate_cases`: refused at load in one line naming the file,
    or run on the mat's sample with every reading it marks valid finite; else what went
    wrong (taken and inf or NaN given as valid, an error or traceback while running)."""
    from texsense.io import load

    raw = load(files / "raw.h5")
    wrong, tried = [], 0
    for name, good, k, edit, what in _degenerate_cases(files):
        tried += 1
        path = tmp_path / "degenerate.json"
        path.write_text(json.dumps(_tampered(good, k, edit)), encoding="utf-8")
        try:
            chain = load_chain(path)
        except FormatError as e:
            if path.name not in str(e) or "\n" in str(e):
                wrong.append(f"{name} {what}: {e}")
            continue
        try:
            out = chain.run(raw)
        except Exception as e:
            wrong.append(f"{name} {what}: taken, then {type(e).__name__}: {e}")
            continue
        frames = np.asarray(out.frames, np.float64)
        bad = int(np.count_nonzero(~np.isfinite(frames[out.valid])))
        if bad:
            wrong.append(f"{name} {what}: taken, {bad} readings inf or NaN marked valid")
    return tried, wrong


def test_no_value_in_range_makes_a_stage_give_inf(files, tmp_path, fault_row):
    """Degenerate values inside the declared ranges (a linear gain of 1e-300 was in
    ``[-1e15, 1e15]``, its readings became inf marked valid; a Preisach input range of 5e-324
    loaded and failed when run): refused at load in one line, or the chain's valid readings
    stay finite."""
    tried, wrong = degenerate_outcomes(files, tmp_path)
    print(f"{len(wrong)} of {tried} went wrong:", *wrong[:40], sep="\n")
    assert not wrong
    fault_row("stage ranges", f"{tried} parameters and fitted numbers at degenerate values in "
              "range", "clear error or finite", cases=tried)  # fmt: skip
