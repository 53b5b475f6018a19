"""Does a drift model identified on one kind of load work on another?

Four specimens of the virtual 6 mm textile spacer, each calibrated (default Preisach
identification from its calibration record) and recorded under three kinds of load:

- holds: the thesis's step-and-hold record (steps to 2.5/5/7.5/10 N/cm², held 1 h at constant
  compression, §5.1.2.1), 10 Hz;
- cycles: 4 h of the §4.5 validation cycle at 50 mm/min, 10 Hz (§5.3, fig. 5.8);
- sitting bouts: 4 x (2 N/cm² held by a load, i.e. pressure-controlled, 25 min; unloaded
  10 min), 1 Hz.

Drift candidates, each identified on one record of specimen 0 and applied to the records of
all four specimens (mean relative error in 0.5-3.5 N/cm²):

- time clock: eq. 5.8 as printed (`ln(1 + t)`); γ from holds (the thesis's workflow), from the
  first hour of cycles, from the bouts, or jointly from holds + cycles;
- onset kernel `ln(1 + t/τ0)`: γ and τ0 fitted on holds;
- a Prony kernel (non-negative exponentials) fitted on holds, time clock;
- superposition on the compression instead of the Preisach output, factor from holds;
- two clocks (`DriftModel.fit_joint`): `γ_rest D_rest + γ_time D_time`, both factors from
  held steps plus an hour of cycles (also with the bouts added, and from held loads, i.e. the
  bouts, plus cycles);
- rest clock (`DriftModel(rest_rate=...)`): the kernel's clock advances by
  `dt / (1 + |v| / r0)`, v the reading velocity averaged over 0.5 s; γ from holds or from
  cycles; r0 = 0.02 N/cm² per s.

Then the 4 h cycling per hour and specimen for the thesis workflow vs the rest clock, both with
γ from the specimen's own held steps only.

The same on the second spacer law (`bouc-wen-6mm`: Bouc–Wen friction, Norton creep that runs
on time, moving or not), whose drift the rest clock's idea does not describe.

Run:  .venv/bin/python benchmarks/drift_transfer.py [PRESET ...]
      (writes docs/img/drift_transfer*.png)
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from scipy.optimize import nnls

from texsense.compensation.drift import DriftModel, split_steps
from texsense.compensation.drift_kernels import DriftKernel, log_kernel
from texsense.compensation.hysteresis import HysteresisModel
from texsense.sim import protocols
from texsense.sim.spacer import Spacer

IMG = Path(__file__).resolve().parents[1] / "docs" / "img"
REST_RATE = 0.02  # N/cm² per s (averaged over 0.5 s)
HOURS = 4.0


def band_error(x: np.ndarray, p: np.ndarray, sel: np.ndarray | None = None) -> float:
    s = (p >= 0.5) & (p < 3.5)
    if sel is not None:
        s &= sel
    return float(np.mean(np.abs(x[s] - p[s]) / p[s]))


def specimen(seed: int, preset: str = "textile-6mm") -> dict:
    """Calibrate specimen ``seed`` and record holds, cycles and bouts; returns (h, p, t) of
    each (h: the Preisach output) and γ of its held steps."""
    sp = Spacer.preset(preset, seed=seed)
    cal = protocols.run_protocol("calibration", sp, seed=seed, sample_hz=None)
    model = HysteresisModel().fit(cal.labels["compression_mm"], cal.labels["pressure_ncm2"])
    st = protocols.run_protocol("steps", preset, seed=seed, sample_hz=10)
    steps = split_steps(st.times, st.labels["pressure_ncm2"], st.labels["compression_mm"])
    out = {
        "steps": steps,
        "holds": (model.predict(st.labels["compression_mm"]), st.labels["pressure_ncm2"], st.times),
        "u": {"holds": st.labels["compression_mm"]},
    }
    sp.reset()
    cycles = int(HOURS * 3600 / 14.0)  # a cycle of the textile law takes 15-16 s
    while True:  # a creeping spacer's cycles get shorter: run more until 4 h are covered
        rec = protocols.run_protocol("validation", sp, seed=seed, sample_hz=10, cycles=cycles)
        if rec.times[-1] >= HOURS * 3600:
            break
        cycles *= 2
        sp.reset()
    keep = rec.times < HOURS * 3600
    out["u"]["cycles"] = rec.labels["compression_mm"][keep]
    out["cycles"] = (
        model.predict(rec.labels["compression_mm"][keep]),
        rec.labels["pressure_ncm2"][keep],
        rec.times[keep],
    )
    sp.reset()
    bouts = protocols.run_protocol("loads", sp, seed=seed, sample_hz=1)
    tb, ub = bouts.times, bouts.labels["compression_mm"]
    out["bouts"] = (model.predict(ub), bouts.labels["pressure_ncm2"], tb)
    out["u"]["bouts"] = ub
    return out


def fit_gamma(parts: list[tuple], rest_rate: float, clock_scale: float = 1.0) -> float:
    """One γ by least squares over several records (eq. 5.8 is linear in γ)."""
    num = den = 0.0
    for h, p, t in parts:
        unit = DriftModel(1.0, log_kernel(), "log", rest_rate).apply(h, t / clock_scale) - h
        s = (p >= 0.5) & (p < 3.5)
        num += float(unit[s] @ (p - h)[s])
        den += float(unit[s] @ unit[s])
    return num / den


def main(preset: str = "textile-6mm") -> None:
    IMG.mkdir(parents=True, exist_ok=True)
    print(f"### {preset}\n")
    specs = [specimen(seed, preset) for seed in range(4)]
    s0 = specs[0]
    first_hour = tuple(x[s0["cycles"][2] < 3600] for x in s0["cycles"])
    # onset kernel: γ and τ0 on specimen 0's holds
    onset = []
    for tau0 in (1.0, 10.0, 100.0, 1000.0):
        g = fit_gamma([s0["holds"]], 0.0, tau0)
        h, p, t = s0["holds"]
        err = band_error(DriftModel(g, log_kernel()).apply(h, t / tau0), p)
        onset.append((err, tau0, g))
    _, tau0, g_onset = min(onset)

    def model(g: float, rest: float = 0.0) -> DriftModel:
        return DriftModel(g, log_kernel(), "log", rest)

    joint = DriftModel.fit_joint([s0["holds"], first_hour], rest_rate=REST_RATE)
    joint3 = DriftModel.fit_joint([s0["holds"], first_hour, s0["bouts"]], rest_rate=REST_RATE)
    joint_load = DriftModel.fit_joint([s0["bouts"], first_hour], rest_rate=REST_RATE)
    # a Prony kernel (non-negative exponentials, τ 0.1 s .. 10^5 s) fitted to the holds'
    # drift after the Preisach model, on the time clock
    h, p, t = s0["holds"]
    taus = np.geomspace(0.1, 1e5, 19)
    basis = np.column_stack(
        [
            DriftModel(1.0, DriftKernel(np.ones(1), np.array([tau]), 0.0, (0.0, 0.0))).apply(h, t)
            - h
            for tau in taus
        ]
    )
    sel = (p >= 0.5) & (p < 3.5)
    weights, _ = nnls(basis[sel], -(p - h)[sel])
    prony = DriftModel(-1.0, DriftKernel(weights, taus, 0.0, (0.0, 1e5)), "prony")
    # superposing on compression: p = h + γ_u Σ Δu ln(1 + t - t_i), γ_u from the holds
    u_unit = DriftModel(1.0, log_kernel())
    d_u = u_unit.apply(s0["u"]["holds"], t) - s0["u"]["holds"]
    g_u = float(d_u[sel] @ (p - h)[sel] / (d_u[sel] @ d_u[sel]))

    def on_compression(sp: dict, load: str) -> np.ndarray:
        h, _, t = sp[load]
        u = sp["u"][load]
        return h + g_u * (u_unit.apply(u, t) - u)

    def via(dm: DriftModel, scale: float = 1.0):
        return lambda sp, load: dm.apply(sp[load][0], sp[load][2] / scale)

    def gamma_text(dm: DriftModel) -> str:
        if dm.gamma_time:
            return f"rest {dm.gamma:+.4f}, time {dm.gamma_time:+.4f}"
        return f"{dm.gamma:+.4f}"

    def candidate(label: str, dm: DriftModel, scale: float = 1.0) -> tuple:
        return (label, via(dm, scale), gamma_text(dm))

    candidates = [
        ("hysteresis only", lambda sp, load: sp[load][0], "—"),
        candidate("time clock, γ from holds (thesis)", model(fit_gamma([s0["holds"]], 0.0))),
        candidate("time clock, γ from 1 h of cycles", model(fit_gamma([first_hour], 0.0))),
        candidate("time clock, γ from bouts", model(fit_gamma([s0["bouts"]], 0.0))),
        candidate(
            "time clock, γ jointly from holds + 1 h of cycles",
            model(fit_gamma([s0["holds"], first_hour], 0.0)),
        ),
        candidate(f"onset kernel ln(1 + t/{tau0:g} s), γ and τ0 from holds", model(g_onset), tau0),
        ("Prony kernel (19 terms) fitted on holds", via(prony), f"{weights.sum():.3f} (Σc)"),
        ("superposed on compression, γ_u from holds", on_compression, f"{g_u:+.4f} N/cm²/mm"),
        candidate(
            "rest clock, γ from holds", model(fit_gamma([s0["holds"]], REST_RATE), REST_RATE)
        ),
        candidate(
            "rest clock, γ from 1 h of cycles", model(fit_gamma([first_hour], REST_RATE), REST_RATE)
        ),
        candidate("two clocks, jointly from holds + 1 h of cycles", joint),
        candidate("two clocks, jointly from holds + 1 h of cycles + bouts", joint3),
        candidate("two clocks, jointly from held loads (bouts) + 1 h of cycles", joint_load),
    ]
    print(
        f"identified on specimen 0, applied to specimens 0-3 (mean of 4; worst in brackets); "
        f"rest rate r0 = {REST_RATE} N/cm² per s\n"
    )
    print("| drift model | γ | holds | 4 h of cycles | sitting bouts |")
    print("|---|---:|---:|---:|---:|")
    matrix = []
    for label, apply, gtxt in candidates:
        row = []
        for load in ("holds", "cycles", "bouts"):
            errs = [band_error(apply(sp, load), sp[load][1]) for sp in specs]
            row.append((float(np.mean(errs)), float(np.max(errs))))
        matrix.append(row)
        print(f"| {label} | {gtxt} | " + " | ".join(f"{m:.1%} ({w:.1%})" for m, w in row) + " |")
    print()
    # reading noise: the rest clock reads the velocity averaged over 0.5 s, so noise on a hold
    # must not stop it (specimen 0, γ from its clean holds, noise added to the output h)
    rng = np.random.default_rng(0)
    g_holds = fit_gamma([s0["holds"]], 0.0)
    print(
        "| reading noise σ (N/cm²) | holds: time clock | holds: rest clock | cycles: rest clock |"
    )
    print("|---:|---:|---:|---:|")
    for sigma in (0.0, 0.002, 0.005, 0.02):
        cells = []
        for load, rest in (("holds", 0.0), ("holds", REST_RATE), ("cycles", REST_RATE)):
            h, p, t = s0[load]
            noisy = h + rng.normal(0.0, sigma, h.size) if sigma else h
            cells.append(band_error(model(g_holds, rest).apply(noisy, t), p))
        print(f"| {sigma:g} | " + " | ".join(f"{e:.1%}" for e in cells) + " |")
    print()
    # 4 h per hour, γ from each specimen's own held steps only
    print(
        "| specimen | hour | hysteresis only | time clock (thesis workflow) | rest clock "
        "| two clocks (holds + 1 h of cycles of specimen 0) |"
    )
    print("|---|---|---:|---:|---:|---:|")
    curves = []
    for seed, sp in enumerate(specs):
        g = fit_gamma([sp["holds"]], 0.0)
        one = DriftModel.fit_steps(sp["steps"]).step_fit_
        h, p, t = sp["cycles"]
        variants = (
            h,
            DriftModel(g, log_kernel()).apply(h, t),
            DriftModel(g, log_kernel(), "log", REST_RATE).apply(h, t),
            joint.apply(h, t),
        )
        for k in range(int(HOURS)):
            sel = (t >= 3600 * k) & (t < 3600 * (k + 1))
            e = [band_error(x, p, sel) for x in variants]
            print(f"| {seed} | {k}-{k + 1} h | {e[0]:.1%} | {e[1]:.1%} | {e[2]:.1%} | {e[3]:.1%} |")
        windows = np.arange(0, HOURS * 3600, 900.0)
        curves.append(
            [[band_error(x, p, (t >= w) & (t < w + 900)) for x in variants] for w in windows]
        )
        print(
            f"|  | one-step fit error of the held steps | γ {g:+.4f} | {one.max_error_single:.2%} "
            "| same γ | |"
        )
    errs = 100 * np.asarray(curves)
    mid = (np.arange(0, HOURS * 3600, 900.0) + 450) / 60
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.3), layout="constrained")
    for j, (label, mark) in enumerate(
        (
            ("hysteresis only", "o-"),
            ("time clock (thesis)", "s-"),
            ("rest clock", "^-"),
            ("two clocks (holds + 1 h of cycles)", "d--"),
        )
    ):
        ax.plot(mid, errs[:, :, j].mean(axis=0), mark, label=label)
        ax.fill_between(mid, errs[:, :, j].min(axis=0), errs[:, :, j].max(axis=0), alpha=0.15)
    ax.axhline(5, color="k", lw=0.8, ls=":")
    ax.set_xlabel("time of continuous validation cycles [min]")
    ax.set_ylabel("mean relative error 0.5-3.5 N/cm² [%]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2)
    m = 100 * np.asarray([[c[0] for c in row] for row in matrix])
    im = ax2.imshow(np.minimum(m, 25), cmap="RdYlGn_r", aspect="auto", vmin=0, vmax=25)
    ax2.set_xticks(range(3), ["holds", "4 h of cycles", "sitting bouts"])
    ax2.set_yticks(range(len(candidates)), [c[0] for c in candidates], fontsize=8)
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            ax2.text(j, i, f"{m[i, j]:.1f}", ha="center", va="center", fontsize=8)
    ax2.set_title("applied to: mean rel. error [%] (colour capped at 25)", fontsize=10)
    fig.colorbar(im, ax=ax2, shrink=0.8)
    ax.set_title(
        f"{preset}: cycling, 4 specimens (band: min-max)\nγ from held steps; two clocks: "
        "holds + 1 h of cycles",
        fontsize=9,
    )
    suffix = "" if preset == "textile-6mm" else f"_{preset}"
    fig.savefig(IMG / f"drift_transfer{suffix}.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    for name in sys.argv[1:] or ["textile-6mm", "bouc-wen-6mm"]:
        main(name)
        print()
