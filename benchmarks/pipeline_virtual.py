"""The capacitance-to-pressure pipeline end to end on the virtual 96-element seat (thesis
failure rates), stage by stage, and its speed for 96, 1024 and 4096 elements.

Run:  .venv/bin/python benchmarks/pipeline_virtual.py
"""

from __future__ import annotations

import copy
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import best_of
from pipeline_speed import mat_case
from texsense import Recording
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.drift import DriftModel
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.repair import Repair
from texsense.compensation.stages import Drift, StageChain
from texsense.sim import protocols
from texsense.sim.failures import FailureModel
from texsense.sim.mat import VirtualMat


def calibrate(seed: int = 5) -> StageChain:
    """Zeroing + equilibration (1 N/cm²) of the seat, spacer model from a test-machine record
    of another specimen, drift γ from its steps."""
    return seat_calibration(mat_seed=seed)


def cycling_drift(cal: StageChain, seed: int = 11) -> StageChain:
    """The same calibration with γ fitted on one hour of the §4.5 validation cycles of the
    calibration specimen (DriftModel.fit_history): γ identified on cyclic load instead of
    held steps (docs/drift.md)."""
    rec = protocols.run_protocol("validation", "textile-3mm", seed=seed, sample_hz=10, cycles=240)
    keep = rec.times < 3600
    t = rec.times[keep]
    h = cal["hysteresis"].model_.predict(rec.labels["compression_mm"][keep])
    cyc = DriftModel.fit_history(h, rec.labels["pressure_ncm2"][keep], t)
    return StageChain([*copy.deepcopy(cal).without("drift").stages, Drift.of(cyc)])


def sitting_session(mat: VirtualMat, minutes: float, seed: int = 0) -> np.ndarray:
    """True pressure maps: sitting bouts of 2-6 min (two ischial peaks and the thighs,
    shifting a little), 30-90 s standing between."""
    rng = np.random.default_rng(seed)
    xy = mat.layout.xy_cm
    ft = mat.cdc.frame_time_s(mat.layout.n_elements)
    times = np.arange(0.0, minutes * 60, ft)
    p = np.zeros((times.size, xy.shape[0]))
    cx, cy = xy[:, 0].mean(), xy[:, 1].mean()
    t = 0.0
    while t < times[-1]:
        sit = rng.uniform(120, 360)
        weight = rng.uniform(0.8, 1.2)
        centre = np.array([cx, cy]) + rng.normal(0, 1.5, 2)
        sel = (times >= t) & (times < t + sit)
        for k in np.flatnonzero(sel):
            c = centre + rng.normal(0, 0.3, 2)
            d = lambda o, s, c=c: np.exp(-np.sum((xy - c - o) ** 2, axis=1) / (2 * s * s))  # noqa: E731
            p[k] = weight * (2.6 * d((-5.5, 3), 3.5) + 2.6 * d((5.5, 3), 3.5) + 0.9 * d((0, -7), 7))
        t += sit + rng.uniform(30, 90)
    return times, p


def accuracy(minutes: float = 30.0) -> None:
    cal = calibrate()
    cal_cyc = cycling_drift(cal)
    mat = VirtualMat.seat(seed=5, failures=FailureModel())
    times, truth_in = sitting_session(mat, minutes)
    scan = mat.scan(times, truth_in)
    truth = scan.pressure.frames.astype(np.float64)
    lay = mat.layout
    loaded = truth >= 0.5
    healthy = loaded & ~scan.failed
    print(
        f"virtual seat, 96 elements, {minutes:.0f} min of sitting bouts, frame {times[1]:.2f} s; "
        f"{scan.failed.all(axis=0).sum()} elements dead, {scan.failed.any(axis=0).sum()} failed at "
        f"least once, {scan.failed.mean():.1%} of readings failed\n"
    )
    print(
        "| stages | mean rel. error, loaded elements (≥ 0.5 N/cm²) | healthy ones only | "
        "failed ones |"
    )
    print("|---|---:|---:|---:|")
    configs = [
        ("capacitance -> pressure (first-loading curve)",
         dict(hysteresis=False, drift=False, repair=None)),
        ("+ hysteresis (Preisach)", dict(drift=False, repair=None)),
        ("+ drift (eq. 5.8, γ from steps)", dict(repair=None)),
        (f"+ drift (eq. 5.8, γ {cal_cyc['drift'].model_.gamma:.4f} from 1 h of cycling)",
         dict(repair=None, calibration=cal_cyc)),
        ("+ hysteresis + repair, eq. 6.14 neighbour mean",
         dict(drift=False, repair="neighbour-mean")),
        ("+ hysteresis + repair, harmonic", dict(drift=False, repair="harmonic")),
        ("+ hysteresis + repair, harmonic-temporal", dict(drift=False, repair="harmonic-temporal")),
        ("+ hysteresis + drift (cycling γ) + repair, harmonic-temporal",
         dict(repair="harmonic-temporal", calibration=cal_cyc)),
    ]  # fmt: skip
    codes = None
    bands = ((0.5, 1.0), (1.0, 2.0), (2.0, 4.0))
    by_band = {}
    for label, cfg in configs:
        cfg = dict(cfg)
        pipe = Pipeline(cfg.pop("calibration", cal), lay, **cfg)
        out = pipe.run(scan.capacitance).frames.astype(np.float64)
        out = np.nan_to_num(out)  # an unrepaired failed element shows nothing
        rel = np.abs(out - truth) / np.maximum(truth, 1e-9)
        bad = loaded & scan.failed
        print(
            f"| {label} | {rel[loaded].mean():.1%} | {rel[healthy].mean():.1%} | "
            f"{rel[bad].mean():.1%} |"
        )
        codes = pipe.codes_
        signed = (out - truth) / np.maximum(truth, 1e-9)
        by_band[label] = [signed[healthy & (truth >= lo) & (truth < hi)].mean() for lo, hi in bands]
    print("\nsigned mean relative error of the healthy elements by true pressure:\n")
    print("| stages | " + " | ".join(f"{lo:g}-{hi:g} N/cm²" for lo, hi in bands) + " |")
    print("|---|" + "---:|" * len(bands))
    for label, _ in configs[:4]:
        print(f"| {label} | " + " | ".join(f"{v:+.0%}" for v in by_band[label]) + " |")
    det = codes > 0
    print(
        f"\ndetection: {np.mean(det[scan.failed]):.1%} of failed readings found, "
        f"{np.mean(det[~scan.failed]):.2%} of healthy readings flagged\n"
    )


def speed() -> None:
    cal = calibrate()
    print(
        "| elements | frames | pipeline batch: element-samples/s | per-frame latency (step) | "
        "repair alone, Rust eq. 6.14: element-samples/s | harmonic repair, ms/frame: "
        "same / new failure pattern |"
    )
    print("|---:|---:|---:|---:|---:|---:|")
    for rows, cols in ((8, 12), (32, 32), (64, 64)):
        n = rows * cols
        frames = 200 if n > 1000 else 1000
        c, lay, rec = mat_case(cal, rows, cols, frames)  # the cases of pipeline_speed.py
        t = rec.times
        valid = rec.frames > 0
        conv = c["convert"]
        e = np.interp(
            (rec.frames - conv.offset_pF_) / conv.gain_,
            conv.curve_capacitance_pF_,
            conv.curve_compression_mm_,
        )
        cap = rec.frames
        pipe = Pipeline(c, lay, repair="neighbour-mean")
        batch = best_of(lambda: pipe.reset().run(rec))[0]  # noqa: B023
        pipe.reset()
        step = best_of(lambda: pipe.step(cap[5], None, 0.5), repeat=20)[0]  # noqa: B023
        rep = Repair(lay, "neighbour-mean").fit()
        pres = Recording(np.where(valid, e, np.nan), t, lay, "pressure", "N/cm2", valid=valid)
        rep_t = best_of(lambda: rep.reset().run(pres))[0]  # noqa: B023
        harm = Repair(lay, "harmonic").fit()
        k = int(np.argmax((~valid).sum(axis=1) >= 2))  # a frame with failures to fill
        hk = best_of(lambda: harm.step(np.where(valid[k], e[k], 0), valid[k], 0.0), repeat=5)[0]  # noqa: B023

        def fresh(harm: Repair = harm) -> None:
            harm._harmonic._cache.clear()  # a new failure pattern: factorise again
            harm.step(np.where(valid[k], e[k], 0), valid[k], 0.0)  # noqa: B023

        hf = best_of(fresh, repeat=3)[0]
        print(
            f"| {n} | {frames} | {frames * n / batch / 1e6:.2f} M | {step * 1e3:.2f} ms | "
            f"{frames * n / rep_t / 1e6:.0f} M | {hk * 1e3:.2f} / {hf * 1e3:.1f} |"
        )


if __name__ == "__main__":
    accuracy()
    speed()
