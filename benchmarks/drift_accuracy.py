"""Drift identification and compensation: virtual spacer steps, VHB 4910 relaxation, and
hours of cycling (hysteresis only vs hysteresis + drift).

Run:  .venv/bin/python benchmarks/drift_accuracy.py       (writes docs/img/drift_*.png)
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _realdata import vhb_relaxation
from texsense.drift import DriftModel, fit_gamma, prony_kernel, split_steps
from texsense.hysteresis import HysteresisModel
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
    fig.savefig(IMG / "drift_vhb.png", dpi=100)
    plt.close(fig)


def cycling(hours: float = 2.5) -> None:
    sp = Spacer.preset("textile-6mm", seed=0)
    cal = protocols.run_protocol("calibration", sp, seed=0, sample_hz=None)
    model = HysteresisModel().fit(cal.labels["compression_mm"], cal.labels["pressure_ncm2"])
    st = protocols.run_protocol("steps", "textile-6mm", seed=0, sample_hz=10)
    drift, _ = DriftModel.fit(
        split_steps(st.times, st.labels["pressure_ncm2"], st.labels["compression_mm"])
    )
    sp.reset()
    cycles = int(hours * 3600 / 19.2)
    rec = protocols.run_protocol("validation", sp, seed=0, sample_hz=2, cycles=cycles)
    u, p, t = rec.labels["compression_mm"], rec.labels["pressure_ncm2"], rec.times
    h = model.predict(u)
    hd = model.with_drift(drift).predict(u, times_s=t)
    print("| time | hysteresis only | hysteresis + drift (γ from steps) |")
    print("|---|---:|---:|")
    windows = np.arange(0, t[-1], 900.0)
    errs = []
    for w in windows:
        sel = (t >= w) & (t < w + 900) & (p >= 0.5) & (p < 3.5)
        e = [float(np.mean(np.abs(x[sel] - p[sel]) / p[sel])) for x in (h, hd)]
        errs.append(e)
        print(f"| {w / 60:.0f}-{w / 60 + 15:.0f} min | {e[0]:.1%} | {e[1]:.1%} |")
    errs = np.asarray(errs)
    fig, ax = plt.subplots(figsize=(7, 4.2), layout="constrained")
    ax.plot(windows / 60 + 7.5, 100 * errs[:, 0], "o-", label="hysteresis only")
    ax.plot(windows / 60 + 7.5, 100 * errs[:, 1], "s-", label="hysteresis + drift")
    ax.set_xlabel("time of continuous validation cycles [min]")
    ax.set_ylabel("mean relative error 0.5-3.5 N/cm² [%]")
    ax.set_title("virtual textile spacer under hours of cycling (cf. thesis fig. 5.8)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.savefig(IMG / "drift_cycling.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    IMG.mkdir(parents=True, exist_ok=True)
    virtual_steps()
    print()
    vhb()
    print()
    cycling()
