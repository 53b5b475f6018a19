"""``texsense info FILE [--json]``: what a recording holds, at a glance."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from texsense.apps import stats
from texsense.commands import HELP
from texsense.commands._options import add_accept_truncated
from texsense.compensation.stages import Drift, load_chain
from texsense.data.recording import Recording
from texsense.io import load, sniff_format


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``info`` command."""
    p = sub.add_parser(
        "info",
        help=HELP["info"],
        description="Summarise any readable recording: file or folder (PMD tree).",
    )
    p.add_argument("file", type=Path, help="recording file or folder")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    add_accept_truncated(p)
    p.set_defaults(run=run)


def _summary(values: np.ndarray) -> dict[str, float] | None:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return None
    return {
        "mean": float(finite.mean()),
        "max": float(finite.max()),
        "min": float(finite.min()),
    }


def describe(rec: Recording, path: Path, fmt: str) -> dict[str, Any]:
    """A JSON-able summary of ``rec``."""
    lay = rec.layout
    labels: dict[str, Any] = {}
    for name, values in rec.labels.items():
        distinct = np.unique(values)
        labels[name] = {"distinct": int(distinct.size)}
        if distinct.size <= 20:
            labels[name]["values"] = distinct.tolist()
    period = rec.frame_period_s
    # a processed file flags its repaired readings invalid but keeps their estimates: its load
    # and peak count them, as the report, the dashboard and the alerts do
    repaired = any(str(s).startswith("repair") for s in rec.meta.get("stages") or [])
    counted = rec
    if repaired and rec.quantity == "pressure" and not rec.valid.all():
        counted = Recording(rec.frames, rec.times, rec.layout, rec.quantity, rec.unit,
                            valid=np.isfinite(rec.frames))  # fmt: skip
    info: dict[str, Any] = {
        "path": str(path),
        "format": fmt,
        "frames": rec.n_frames,
        "elements": rec.n_elements,
        "layout": lay.kind,
        "rows": None if lay.shape is None else lay.shape[0],
        "cols": None if lay.shape is None else lay.shape[1],
        "pitch_cm": None if lay.pitch_cm is None else list(lay.pitch_cm),
        "frame_period_s": None if not np.isfinite(period) else round(period, 9),
        "duration_s": rec.duration_s,
        "quantity": rec.quantity,
        "unit": rec.unit,
        "source_unit": rec.meta.get("source_unit"),
        "invalid_readings": int((~rec.valid).sum()),
        "regions": sorted(lay.regions),
        "labels": labels,
        "peak": _summary(stats.peak_pressure(counted)),
        "load_N": _summary(stats.total_load(counted)) if rec.quantity == "pressure" else None,
        "repairs_counted": counted is not rec,
    }
    if "subject" in rec.labels:
        info["subjects"] = labels["subject"]["distinct"]
    if "posture" in rec.labels:
        info["postures"] = labels["posture"]["distinct"]
    return info


def _text(info: dict[str, Any]) -> str:
    grid = (
        f"{info['rows']} x {info['cols']} grid" if info["layout"] == "grid" else "discrete points"
    )
    period = info["frame_period_s"]
    lines = [
        f"{info['path']}  ({info['format']})",
        f"  frames      {info['frames']}"
        + (f"  ({period:g} s per frame, {info['duration_s']:.6g} s)" if period else ""),
        f"  elements    {info['elements']} on a {grid}",
        f"  values      {info['quantity']} in {info['unit']}"
        + (f" (file: {info['source_unit']})" if info["source_unit"] else ""),
    ]
    if info["invalid_readings"]:
        lines.append(f"  invalid     {info['invalid_readings']} readings flagged")
    if info["regions"]:
        lines.append(f"  regions     {', '.join(info['regions'])}")
    for name, lab in info["labels"].items():
        shown = f": {', '.join(map(str, lab['values']))}" if "values" in lab else ""
        lines.append(f"  label       {name} ({lab['distinct']} distinct){shown}")
    if info["load_N"]:
        ld = info["load_N"]
        note = " (repaired readings counted)" if info.get("repairs_counted") else ""
        lines.append(f"  load        mean {ld['mean']:.4g} N, max {ld['max']:.4g} N{note}")
    if info["peak"]:
        pk = info["peak"]
        lines.append(f"  peak        mean {pk['mean']:.4g}, max {pk['max']:.4g} {info['unit']}")
    return "\n".join(lines)


def describe_model(path: Path) -> dict[str, Any]:
    """A calibration or model file: its stages, what it reads and gives, elements, id."""
    chain = load_chain(path)
    drift = chain.find(Drift)
    return {
        "file": str(path),
        "format": "texsense calibration (stage chain)",
        "stages": list(chain.names),
        "reads": "{} [{}]".format(*chain.reads),
        "gives": "{} [{}]".format(*chain.gives),
        "elements": chain.n_elements,
        "id": chain.id,
        **({} if drift is None else {"drift": drift.model_.describe()}),
    }


def run(args: argparse.Namespace) -> int:
    """Run ``texsense info``: a recording, or a calibration/model file (JSON)."""
    if args.file.suffix.lower() == ".json" and args.file.is_file():
        info = describe_model(args.file)
        if args.json:
            print(json.dumps(info, indent=2))
        else:
            print(f"{info['file']}: {info['format']}")
            for key in ("stages", "reads", "gives", "elements", "drift", "id"):
                if key not in info:
                    continue
                value = info[key]
                shown = ", ".join(value) if isinstance(value, list) else value
                print(f"  {key:<11} {shown}")
        return 0
    fmt = sniff_format(args.file)
    rec = load(args.file, format=fmt, accept_truncated=args.accept_truncated)
    info = describe(rec, args.file, fmt)
    print(json.dumps(info, indent=2) if args.json else _text(info))
    return 0
