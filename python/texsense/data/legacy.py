"""The one reader of the model files of earlier versions: it converts them to the content of
the present formats (:mod:`texsense.data.modelfile`), which the present readers then check and
load. Nothing here is ever written.

=============================  ==================================================
earlier file                   read as
=============================  ==================================================
``texsense.calibration`` v1,   a chain: convert, hysteresis and (with a drift
kind ``mat`` (first round)     stage attached to its model) drift; its ``id``
                               is checked against its content
``texsense.calibration`` v1,   a chain of one linear stage (offset, gain)
kind ``linear``
``texsense.chain`` v1          a chain (the stages converted one by one)
``texsense.stage`` v1                      a stage (the detector's ``thresholds`` become its
                               parameters)
``texsense.hysteresis`` v1                a hysteresis model; with a drift stage attached
                               (``drift``), a chain of hysteresis and drift
=============================  ==================================================

Every file of these kinds in ``tests/fixtures/models`` is read in tests/test_legacy.py and
gives the numbers the code of its time gave.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from texsense.exceptions import FormatError

__all__ = ["upgrade"]

#: Fields of a first-round calibration file around its body.
_ENVELOPE_V1 = ("format", "version", "id", "software", "provenance")


def upgrade(d: dict[str, Any], source: str | Path) -> tuple[str, dict[str, Any]] | None:
    """``(format, content)`` in the present formats for a file of an earlier version, or
    None when ``d`` is none of them."""
    fmt, version = d.get("format"), d.get("version")
    try:
        if fmt == "texsense.calibration" and version == 1:
            return _calibration_v1(d, source)
        if fmt == "texsense.chain" and version == 1:
            stages = d.get("stages")
            if not isinstance(stages, list):
                raise FormatError(source, "missing field 'stages' (a list)")
            return "texsense.chain", {"stages": [_stage_v1(s, source) for s in stages]}
        if fmt == "texsense.stage" and version == 1:
            return "texsense.stage", _stage_v1(d, source)
        if fmt == "texsense.hysteresis" and version == 1:
            return _hysteresis_v1(d, source)
    except (KeyError, TypeError, AttributeError) as e:
        raise FormatError(source, f"{fmt} version 1: missing or garbled field {e}") from None
    return None


def _hysteresis_content(d: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in d.items() if k not in ("format", "version", "drift")}


def _hysteresis_stage(model: dict[str, Any], params: dict[str, Any] | None = None) -> dict:
    method = model["method"]
    params = params or {"method": "thesis" if method == "thesis" else "auto"}
    params = {**params, "grid": int(model["grid"])}
    if params.get("method") not in ("auto", "lsq", "thesis"):
        params["method"] = "auto"  # the first round stored the fitted method
    return {"stage": "hysteresis", "params": params, "fitted": {"model": model}}


def _drift_stage(drift: dict[str, Any]) -> dict[str, Any]:
    params = {"kind": drift.get("kind", "log"), "rest_rate": drift.get("rest_rate", 0.0)}
    return {"stage": "drift", "params": params, "fitted": {"model": drift}}


def _hysteresis_v1(d: dict[str, Any], source: str | Path) -> tuple[str, dict[str, Any]]:
    model = _hysteresis_content(d)
    if d.get("drift") is None:
        return "texsense.hysteresis", model
    # a drift stage attached to the model: the chain of both
    return "texsense.chain", {"stages": [_hysteresis_stage(model), _drift_stage(d["drift"])]}


def _stage_v1(s: Any, source: str | Path) -> dict[str, Any]:
    if not isinstance(s, dict) or s.get("format") != "texsense.stage":
        raise FormatError(
            source, "a stage of the chain is not a texsense.compensation.stage object"
        )
    name, params, fitted = s.get("stage"), dict(s.get("params") or {}), s.get("fitted")
    if name == "detect":
        params = {"layout": params["layout"], **params.get("thresholds", {})}
    elif name == "hysteresis" and fitted is not None:
        model = _hysteresis_content(fitted["model"])
        return _hysteresis_stage(model, params)
    return {"stage": name, "params": params, "fitted": fitted}


def _check_id(d: dict[str, Any], source: str | Path) -> None:
    """The first round's id: the first 16 hex digits of the SHA-256 of the body."""
    if "id" not in d:
        return
    body = {k: v for k, v in d.items() if k not in _ENVELOPE_V1}
    found = hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:16]
    if d["id"] != found:
        raise FormatError(
            source,
            f"was edited after texsense wrote it (its id {d['id']} does not match its content, "
            f"{found}); if the edit is deliberate, remove the file's 'id' field",
        )


def _calibration_v1(d: dict[str, Any], source: str | Path) -> tuple[str, dict[str, Any]]:
    kind = d.get("kind", "mat")
    if kind not in ("mat", "linear"):
        raise FormatError(source, f"unknown calibration kind {kind!r} (known: mat, linear)")
    _check_id(d, source)
    if kind == "linear":
        params = {
            "input_quantity": d["input"]["quantity"],
            "input_unit": d["input"]["unit"],
            "output_quantity": d["output"]["quantity"],
            "output_unit": d["output"]["unit"],
            "full_scale": d.get("full_scale"),
        }
        fitted = {"offset": d["elements"]["offset"], "gain": d["elements"]["gain"]}
        return "texsense.chain", {"stages": [{"stage": "linear", "params": params,
                                              "fitted": fitted}]}  # fmt: skip
    convert = {
        "stage": "convert",
        "params": {
            "thickness_mm": d["thickness_mm"],
            "uniform_pressure_ncm2": d.get("uniform_pressure_ncm2") or 1.0,
        },
        "fitted": {"curve": d["curve"], "elements": d["elements"]},
    }
    stages = [convert]
    model = d.get("model")
    if model is not None:
        if model.get("format") != "texsense.hysteresis" or model.get("version") != 1:
            raise FormatError(source, "field 'model': not a texsense.compensation.hysteresis model")
        stages.append(_hysteresis_stage(_hysteresis_content(model)))
        if model.get("drift") is not None:
            stages.append(_drift_stage(model["drift"]))
    return "texsense.chain", {"stages": stages}
