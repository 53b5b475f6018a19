"""Drift identification and compensation: virtual spacer steps, VHB 4910 relaxation, and
hours of cycling (hysteresis only vs hysteresis + drift).

Run:  .venv/bin/python benchmarks/drift_accuracy.py       (writes docs/img/drift_*.png)
      .venv/bin/python benchmarks/drift_accuracy.py --float32
      (the cycling table's predictions through the experimental float32 banks of issue 34,
      benchmarks/_float32.py; no figures written)
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _float32 import FLOAT32, apply, predict
from _realdata import vhb_relaxation
from texsense.compensation.drift import DriftModel, fit_gamma, split_steps
from texsense.compensation.drift_kernels import prony_kernel
from texsense.compensation.hysteresis import HysteresisModel
from texsense.sim import protocols
from texsense.sim.spacer import Spacer

IMG = Path(__file__).resolve().parents[1] / "docs" / "img"


def virtual_steps() -> None:
    print("| specimen | γ common | fit error one step | fit error common | spread | proportional |")
    print("|---|---:|---:|---:|---:|---|")
    fig, ax = plt.subplots(figsize=(7, 4.2), layout="constrained")
    for seed in range(4):
        rec = protocols.run_protocol("steps", "textile-6mm", seed=seed, sample_hz=10)
        steps = split_steps(rec.times, rec.labels["pressure_ncm2"], rec.labels["compression_mm"])
        fit = fit_gamma(steps)
        print(
            f"| {seed} | {fit.gamma_common:.4f} | {fit.max_error_single:.2%} | "
            f"{fit.max_error_common:.2%} | {fit.proportionality_spread:.2%} | "
            f"{'yes' if fit.proportional else 'no'} |"
        )
        if seed == 0:
            for t, p, s in steps:
                ax.plot((t - t[0]) / 60, (p - p[0]) / s, lw=1, label=f"step {s:.1f} N/cm²")
            tt = np.linspace(0, 3600, 200)
            ax.plot(
                tt / 60,
                fit.gamma_common * np.log1p(tt),
                "k--",
                label=f"γ ln(t + 1), γ = {fit.gamma_common:.4f}",
            )
    ax.set_xlabel("time after the step [min]")
    ax.set_ylabel("pressure change / step size")
    ax.set_title("virtual 6 mm textile spacer, specimen 0 (cf. thesis fig. 5.6/5.7)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if not FLOAT32:
        fig.savefig(IMG / "drift_steps.png", dpi=100)
    plt.close(fig)


def _hold(name: str) -> tuple[np.ndarray, np.ndarray]:
    t, d, f = vhb_relaxation(name)
    settled = int(np.argmax((np.arange(t.size) > np.argmax(f)) & (np.abs(d - d[-1]) < 0.05)))
    start = int(np.searchsorted(t, t[settled] + 1.0))
    return t[start:] - t[start], (f[start:] - f[start]) / f[start]


def vhb() -> None:
    print("| VHB 4910 | kernel identified on | max error on own record | predicting the other |")
    print("|---|---|---:|---:|")
    holds = {n: _hold(n) for n in ("2d0", "4d0")}
    fig, ax = plt.subplots(figsize=(7, 4.2), layout="constrained")
    for fit_on, other in (("2d0", "4d0"), ("4d0", "2d0")):
        t, y = holds[fit_on]
        to, yo = holds[other]
        g = float(np.log1p(t) @ y / (np.log1p(t) @ np.log1p(t)))
        k = prony_kernel(t, y)
        rows = [
            (
                f"ln(1 + t), γ = {g:.4f}",
                np.max(np.abs(y - g * np.log1p(t))),
                np.max(np.abs(yo - g * np.log1p(to))),
            ),
            (f"Prony, {k.weights.size} terms", k.max_error, np.max(np.abs(yo + k(to)))),
        ]
        for label, own, cross in rows:
            print(
                f"| stretch {fit_on[0]}.0 | {label} | {own:.1%} | {cross:.1%} "
                f"(stretch {other[0]}.0) |"
            )
        if fit_on == "2d0":
            ax.semilogx(t[1:], y[1:], lw=1, label="measured, stretch 2.0")
            ax.semilogx(t[1:], g * np.log1p(t[1:]), "--", label="γ ln(t + 1)")
            ax.semilogx(t[1:], -k(t[1:]), ":", lw=2, label="Prony series")
    ax.set_xlabel("time in the hold [s]")
    ax.set_ylabel("force change / force at the start")
    ax.set_title("VHB 4910 relaxation: where the logarithm does not hold", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if not FLOAT32:
        fig.savefig(IMG / "drift_vhb.png", dpi=100)
    plt.close(fig)


def _band_error(x: np.ndarray, p: np.ndarray, sel: np.ndarray) -> float:
    """Mean relative error in 0.5-3.5 N/cm² (the thesis's band, §4.5) of the selected samples."""
    sel = sel & (p >= 0.5) & (p < 3.5)
    return float(np.mean(np.abs(x[sel] - p[sel]) / p[sel]))


def _cycling_run(seed: int, hours: float) -> tuple[np.ndarray, ...]:
    """Calibrate specimen ``seed``, unload it, cycle it for ``hours``: t, p, h, drift (γ from
    the specimen's steps) and the unit-γ drift term of its Preisach output."""
    sp = Spacer.preset("textile-6mm", seed=seed)
    cal = protocols.run_protocol("calibration", sp, seed=seed, sample_hz=None)
    model = HysteresisModel().fit(cal.labels["compression_mm"], cal.labels["pressure_ncm2"])
    st = protocols.run_protocol("steps", "textile-6mm", seed=seed, sample_hz=10)
    drift = DriftModel.fit_steps(
        split_steps(st.times, st.labels["pressure_ncm2"], st.labels["compression_mm"])
    )
    sp.reset()
    cycles = int(hours * 3600 / 14.0)  # a cycle takes 15-16 s; cut at `hours` below
    rec = protocols.run_protocol("validation", sp, seed=seed, sample_hz=10, cycles=cycles)
    keep = rec.times < hours * 3600
    u, p = rec.labels["compression_mm"][keep], rec.labels["pressure_ncm2"][keep]
    t = rec.times[keep]
    if t[-1] < hours * 3600 - 60:
        raise RuntimeError(f"specimen {seed}: the cycles ended at {t[-1]:.0f} s")
    h = predict(model, u)
    return t, p, h, apply(drift, h, t), drift.gamma


def _record_figure(run: tuple, cyc: DriftModel) -> None:
    """Fig. 5.8-like: the last cycles of specimen 0's 4 h record, measured and compensated."""
    t, p, h, hd, _ = run
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8), layout="constrained")
    for ax, (lo, hi) in zip((a1, a2), ((0, 60), (t[-1] - 60, t[-1])), strict=True):
        sel = (t >= lo) & (t <= hi)
        tm = (t[sel] - lo) if lo == 0 else (t[sel] - t[-1]) / 1.0
        ax.plot(tm, p[sel], "k", lw=2, label="measured (virtual spacer)")
        ax.plot(tm, h[sel], lw=1, label="hysteresis only")
        ax.plot(tm, hd[sel], lw=1, label="+ drift, γ from steps")
        ax.plot(tm, cyc.apply(h, t)[sel], "--", lw=1, label="+ drift, γ from cycling")
        ax.set_ylabel("pressure [N/cm²] (peaks of 10 cut off)")
        ax.set_ylim(-0.6, 4.0)
        ax.grid(alpha=0.3)
    a1.set_xlabel("time from the start [s]")
    a2.set_xlabel("time before the end of 4 h [s]")
    a1.set_title("first minute", fontsize=10)
    a2.set_title("last minute of four hours", fontsize=10)
    a2.legend(fontsize=8)
    fig.savefig(IMG / "drift_record.png", dpi=100)
    plt.close(fig)


def cycling(hours: float = 4.0, specimens: int = 4) -> None:
    """Thesis §5.3 / fig. 5.8: hours of the §4.5 validation cycle on specimens unloaded before
    the run; hysteresis only, + drift with γ from the specimen's steps, + drift with γ fitted
    on the first hour of specimen 0's cycling (out of sample for every other hour and
    specimen)."""
    runs = [_cycling_run(seed, hours) for seed in range(specimens)]
    t0, p0, h0 = runs[0][:3]
    first = t0 < 3600
    cyc = DriftModel.fit_history(h0[first], p0[first], t0[first])
    print(
        f"γ fitted on the first hour of specimen 0's cycles: {cyc.gamma:.5f}; specimen 0's "
        f"time-mean pressure {p0.mean():.2f} N/cm², for which eq. 5.8 with the step γ predicts "
        f"γ p̄ ln(3601) = {runs[0][4] * p0.mean() * np.log1p(3600):.2f} N/cm² after 1 h\n"
    )
    print("| specimen | hour | hysteresis only | + drift, γ from steps | + drift, γ from cycling |")
    print("|---|---|---:|---:|---:|")
    windows = np.arange(0, hours * 3600, 900.0)
    curves = []
    for seed, (t, p, h, hd, g) in enumerate(runs):
        hc = apply(cyc, h, t)
        for k in range(int(hours)):
            sel = (t >= 3600 * k) & (t < 3600 * (k + 1))
            e = [_band_error(x, p, sel) for x in (h, hd, hc)]
            print(f"| {seed} | {k}-{k + 1} h | {e[0]:.1%} | {e[1]:.1%} (γ {g:.4f}) | {e[2]:.1%} |")
        curves.append(
            [[_band_error(x, p, (t >= w) & (t < w + 900)) for x in (h, hd, hc)] for w in windows]
        )
    if FLOAT32:
        return
    _record_figure(runs[0], cyc)
    errs = 100 * np.asarray(curves)  # specimen, window, variant
    mid = (windows + 450) / 60
    fig, ax = plt.subplots(figsize=(7, 4.2), layout="constrained")
    for j, (label, mark) in enumerate(
        (
            ("hysteresis only", "o-"),
            ("+ drift, γ from steps", "s-"),
            ("+ drift, γ from 1 h of cycling", "^-"),
        )
    ):
        ax.plot(mid, errs[:, :, j].mean(axis=0), mark, label=f"{label} (mean of {specimens})")
        ax.fill_between(mid, errs[:, :, j].min(axis=0), errs[:, :, j].max(axis=0), alpha=0.15)
    ax.axhline(5, color="k", lw=0.8, ls=":")
    ax.set_xlabel("time of continuous validation cycles [min]")
    ax.set_ylabel("mean relative error 0.5-3.5 N/cm² [%]")
    ax.set_title("virtual textile spacer, 4 h of cycling (cf. thesis fig. 5.8)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(IMG / "drift_cycling.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    IMG.mkdir(parents=True, exist_ok=True)
    virtual_steps()
    print()
    vhb()
    print()
    cycling()
