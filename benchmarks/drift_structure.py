"""Four hours of cycles on every spacer law: the drift structure chosen from the user's records.

For each law (textile-6mm, bouc-wen-6mm, iwan-6mm) and three variants the structure choice was
not shaped on (the Bouc–Wen law with Norton exponents 3 and 1.5 instead of 2, the Iwan law
relaxing ten times faster: "stronger creep"), specimen 0:

- the hysteresis model is the default identification from the thesis calibration record;
- the user's records are the documented workflow for a mat in use (docs/drift.md): held loads
  (4 x 25 min at 2 N/cm², 10 min off) and the first hour of cycles 0 <-> 5 N/cm² at 10 mm/min;
- drift candidates fitted on them: the documented workflow (``--clock rest+time``, both clocks
  fitted together), and the structure chosen by held-out validation
  (:func:`texsense.compensation.drift_structure.choose_structure`, ``drift fit LOADS CYCLES
  --history MODEL`` without a clock);
- scored on hours 1-4 of the four-hour cycling record (mean relative error in 0.5-3.5 N/cm²),
  against hysteresis only.

With ``--alternate``: identification of the hysteresis model and the drift *alternately*
(issue 27 item 3): round 0 is the default; each next round identifies the Preisach model again
from the calibration record with the previous round's drift removed (the drift that the
calibration record itself carries), then chooses and fits the drift again on the new
Preisach output; scored as above, with the held-out RMSE of the chosen structure and the
range of the drift removed from the calibration record.

Run:  .venv/bin/python benchmarks/drift_structure.py [--alternate] [LAW ...]   (LAW: a name of LAWS)
"""

from __future__ import annotations

import sys
from dataclasses import replace

import numpy as np

from texsense.compensation.drift import DriftModel
from texsense.compensation.drift_structure import choose_structure
from texsense.compensation.hysteresis import HysteresisModel
from texsense.sensor.materials import PRESETS
from texsense.sim import protocols
from texsense.sim.spacer import Spacer

#: name -> material: the three spacer laws and variants with other creep
LAWS = {
    "textile-6mm": PRESETS["textile-6mm"],
    "bouc-wen-6mm": PRESETS["bouc-wen-6mm"],
    "iwan-6mm": PRESETS["iwan-6mm"],
    "bouc-wen-6mm, Norton exponent 3": replace(PRESETS["bouc-wen-6mm"], creep_exponent=3.0),
    "bouc-wen-6mm, Norton exponent 1.5": replace(PRESETS["bouc-wen-6mm"], creep_exponent=1.5),
    "iwan-6mm, stronger creep (10x faster)": replace(PRESETS["iwan-6mm"], relax_s=200.0),
}


def band_error(p: np.ndarray, pm: np.ndarray) -> float:
    sel = (p >= 0.5) & (p < 3.5)
    return float(np.mean(np.abs(pm[sel] - p[sel]) / p[sel]))


def record_of(model: HysteresisModel, rec, sel=slice(None)) -> tuple:
    """(Preisach output, backbone, pressure, times) of a simulated record, as the user's."""
    uu = rec.labels["compression_mm"][sel]
    return (model.predict(uu), model.backbone(uu), rec.labels["pressure_ncm2"][sel],
            rec.times[sel])  # fmt: skip


def run(law: str) -> list[str]:
    def spacer() -> Spacer:
        return Spacer(LAWS[law], seed=0)

    cal = protocols.run_protocol("calibration", spacer(), seed=0, sample_hz=10)
    model = HysteresisModel().fit(cal.labels["compression_mm"], cal.labels["pressure_ncm2"])
    loads = protocols.run_protocol("loads", spacer(), seed=0, sample_hz=1)
    cyc = protocols.run_protocol("cyclic", spacer(), seed=0, sample_hz=10)
    t = cyc.times
    u, p = cyc.labels["compression_mm"], cyc.labels["pressure_ncm2"]
    h = model.predict(u)
    first = t < 3600.0

    recs = [record_of(model, loads), record_of(model, cyc, first)]
    joint = DriftModel.fit_joint([(a, c, d) for a, _, c, d in recs], rest_rate=0.02)
    choice = choose_structure(recs, backbone=model.backbone_curve())
    rows = []
    candidates = {"hysteresis only": h, "documented workflow (rest+time)": joint.apply(h, t)}
    if choice.model is not None:
        chosen = f"chosen by held-out validation: {choice.chosen}"
        candidates[chosen] = choice.model.apply(h, t, inputs=u)
    for name, pm in candidates.items():
        hours = hour_errors(p, pm, t)
        rows.append(
            f"| {law} ({model.method_}) | {name} | "
            + " | ".join(f"{e:.1%}" for e in hours)
            + f" | {max(hours[1:]):.1%} |"
        )
    held = ", ".join(f"{k} {v:.3g}" for k, v in choice.held_out_rmse.items())
    rows.append(
        f"| {law} | held-out RMSE (N/cm²): hysteresis only {choice.baseline_rmse:.3g}; {held} "
        "| | | | | |"
    )
    return rows


def hour_errors(p: np.ndarray, pm: np.ndarray, t: np.ndarray) -> list[float]:
    return [band_error(p[sel], pm[sel]) for sel in ((t >= k * 3600) & (t < (k + 1) * 3600)
                                                    for k in range(4))]  # fmt: skip


def alternate(law: str, rounds: int = 4) -> list[str]:
    """Hysteresis and drift identified alternately (see the module docstring)."""

    def spacer() -> Spacer:
        return Spacer(LAWS[law], seed=0)

    cal = protocols.run_protocol("calibration", spacer(), seed=0, sample_hz=10)
    loads = protocols.run_protocol("loads", spacer(), seed=0, sample_hz=1)
    cyc = protocols.run_protocol("cyclic", spacer(), seed=0, sample_hz=10)
    uc, pc, tc = cal.labels["compression_mm"], cal.labels["pressure_ncm2"], cal.times
    t, u, p = cyc.times, cyc.labels["compression_mm"], cyc.labels["pressure_ncm2"]
    first = t < 3600.0
    target, rows = pc, []
    for k in range(rounds):
        model = HysteresisModel().fit(uc, target)

        recs = [record_of(model, loads), record_of(model, cyc, first)]
        choice = choose_structure(recs, backbone=model.backbone_curve())
        if choice.model is None:
            rows.append(f"| {law} | {k} | {model.method_} | none beats hysteresis only | | | | | |")
            break
        hours = hour_errors(p, choice.model.apply(model.predict(u), t, inputs=u), t)
        hc = model.predict(uc)
        removed = choice.model.apply(hc, tc, inputs=uc) - hc
        rows.append(
            f"| {law} | {k} | {model.method_} | {choice.chosen} | "
            + " | ".join(f"{e:.1%}" for e in hours)
            + f" | {choice.held_out_rmse[choice.chosen]:.4f} | {removed.min():+.3f} .. "
            f"{removed.max():+.3f} |"
        )
        target = pc - removed
    return rows


def main_alternate(laws: list[str]) -> None:
    head = ["law", "round", "hysteresis", "drift chosen", "hour 1", "hour 2", "hour 3", "hour 4",
            "held-out RMSE (N/cm²)", "drift removed from the calibration (N/cm²)"]  # fmt: skip
    print("| " + " | ".join(head) + " |")
    print("|---|---:|---|---|---:|---:|---:|---:|---:|---|")
    for law in laws:
        for row in alternate(law):
            print(row, flush=True)


def main() -> None:
    args = sys.argv[1:]
    alternating = "--alternate" in args
    laws = [a for a in args if a != "--alternate"] or list(LAWS)
    unknown = [law for law in laws if law not in LAWS]
    if unknown:
        sys.exit(f"drift_structure.py: unknown law {unknown[0]!r}; known: {', '.join(LAWS)}")
    if alternating:
        main_alternate(laws)
        return
    print("| law (hysteresis) | drift | hour 1 | hour 2 | hour 3 | hour 4 | max of hours 2-4 |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for law in laws:
        for row in run(law):
            print(row, flush=True)


if __name__ == "__main__":
    main()
