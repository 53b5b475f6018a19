"""The virtual sensor against the thesis: target table, speed, and the figures in
docs/virtual-sensor.md.

Run:  .venv/bin/python benchmarks/virtual_sensor.py          (writes docs/img/sim_*.png)
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from texsense import Layout
from texsense.apps.plotting import draw_map
from texsense.sensor.materials import PRESETS, SpacerMaterial
from texsense.sim.failures import FailureModel
from texsense.sim.machine import TestMachine
from texsense.sim.mat import VirtualMat
from texsense.sim.spacer import Spacer
from texsense.sim.targets import (
    cyclic_peaks,
    hysteresis_metrics,
    speed_metrics,
    step_metrics,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import best_of

IMG = Path(__file__).resolve().parents[1] / "docs" / "img"


def table() -> None:
    seeds = (0, 1, 2, 3)
    hyst = [hysteresis_metrics(Spacer.preset("textile-6mm", seed=s)) for s in seeds]
    steps = [step_metrics(Spacer.preset("textile-6mm", seed=s)) for s in seeds]
    speed = speed_metrics(Spacer.preset("textile-6mm", seed=0))
    foams = {
        n: hysteresis_metrics(Spacer.preset(n, seed=0))["max_branch_difference"]
        for n in PRESETS
        if n.startswith("foam")
    }
    shifts = {
        p3: np.ptp(cyclic_peaks(Spacer.preset("textile-6mm", seed=0), p3)[1])
        for p3 in (2.5, 5.0, 7.5)
    }
    m = TestMachine(Spacer.preset("foam-9mm"))
    m.ramp_to_pressure(10, 50).ramp_to_pressure(0, 50)
    after = 9.0 - m.spacer.creep_set_mm()[0]
    m.hold_pressure(3 * 3600, sample_s=10)
    later = 9.0 - m.spacer.creep_set_mm()[0]

    def rng(values, fmt):
        return f"{fmt.format(min(values))} - {fmt.format(max(values))}"

    rows = [
        (
            "§4.1 fig. 4.1: max difference rising/falling, 6 mm textile",
            "> 50 %",
            rng([h["max_branch_difference"] * 100 for h in hyst], "{:.1f}") + " %",
        ),
        (
            "§4.1: error of the mean of both branches",
            "20-30 %",
            rng([h["max_mean_branch_error"] * 100 for h in hyst], "{:.1f}") + " %",
        ),
        (
            "§4.1 fig. 4.2: branch difference of foams",
            "20-60 %",
            ", ".join(f"{k} {v:.1%}" for k, v in foams.items()),
        ),
        (
            "§4.1 fig. 4.3: speed dependence 0-4 mm, 0.1-50 mm/min",
            "< 2 %",
            f"{max(speed.values()):.2%}",
        ),
        (
            "§5.1.2 eq. 5.1: proportionality of steps 2.5-10 N/cm²",
            "< 4 %",
            rng([s.proportionality_spread * 100 for s in steps], "{:.2f}") + " %",
        ),
        (
            "§5.2 eq. 5.3, §6.4.5: γ (common fit over the 4 steps)",
            "-0.025",
            rng([s.gamma_common for s in steps], "{:.4f}"),
        ),
        (
            "§5.2 fig. 5.6: one-step fit error of γ ln(t + 1)",
            "< 1 %",
            rng([s.max_error_single * 100 for s in steps], "{:.2f}") + " %",
        ),
        (
            "§5.2 fig. 5.7: common-γ fit error",
            "< 4 %",
            rng([s.max_error_common * 100 for s in steps], "{:.2f}") + " %",
        ),
        (
            "fig. 5.4/5.5: loop shift under 4 h of 0 <-> p3",
            "towards higher compression",
            ", ".join(f"+{v * 1000:.0f} µm (p3 = {k:g})" for k, v in shifts.items()),
        ),
        ("§2.3.3: 9 mm foam thickness after a compression", "8.2-8.4 mm", f"{after:.2f} mm"),
        ("§2.3.3: 9 mm foam after hours", "> 8.9 mm", f"{later:.2f} mm after 3 h"),
        (
            "§2.3.3: compression at 10 N/cm², 6 mm textile",
            "about 70 %",
            f"{hyst[0]['compression_at_max_mm'] / 6 * 100:.0f} %",
        ),
    ]
    print("| thesis | thesis value | simulator (4 specimens where ranged) |")
    print("|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} |")


def speed() -> None:
    sp = Spacer.preset("textile-6mm")
    t = np.arange(0, 4 * 3600, 0.1)
    p = 2.5 + 2.5 * np.sin(2 * np.pi * t / 60.0)  # 4 h of one-minute cycles at 10 Hz
    t_press, _ = best_of(lambda: sp.reset().drive_pressure(t, p), repeat=1)
    comp = sp.reset().drive_pressure(t, p).compression_mm[:, 0]
    t_disp, _ = best_of(lambda: sp.reset().drive_displacement(t, comp))
    mat = VirtualMat(Layout.grid(15, 16, pitch_cm=2.07), "textile-3mm", seed=0)
    frame = np.random.default_rng(0).random((1, 240)) * 3
    clock = [0.0]

    def one_frame():
        clock[0] += 10.0
        mat.scan([clock[0]], frame)

    t_frame, _ = best_of(one_frame, repeat=20)
    print("| what | time |")
    print("|---|---|")
    print(f"| 4 h at 10 Hz, one element, pressure controlled (144,000 samples) | {t_press:.2f} s |")
    print(f"| 4 h at 10 Hz, one element, displacement controlled | {t_disp:.3f} s |")
    print(
        f"| one multiplexed scan frame of 240 elements (mechanics + readout) | "
        f"{t_frame * 1000:.2f} ms |"
    )


def fig_loops() -> None:
    # the presets of the first spacer law; the second law (bouc-wen-6mm) has its own figure
    names = [n for n, m in PRESETS.items() if isinstance(m, SpacerMaterial)]
    fig, axes = plt.subplots(1, len(names), figsize=(17, 3.6), layout="constrained")
    for ax, name in zip(axes, names, strict=True):
        m = TestMachine(Spacer.preset(name, seed=0))
        m.ramp_to_pressure(10, 10).ramp_to_pressure(0, 10)
        for share in (0.7, 0.3):
            m.ramp_to_pressure(10 * share, 10).ramp_to_pressure(0, 10)
        tr = m.trace()
        ax.plot(tr.compression_mm, tr.pressure_ncm2, lw=1)
        ax.set_title(f"{name}\n0→10→0, 0→7→0, 0→3→0 N/cm², 10 mm/min", fontsize=9)
        ax.set_xlabel("compression [mm]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("pressure [N/cm²]")
    fig.savefig(IMG / "sim_loops.png", dpi=100)
    plt.close(fig)


def fig_steps() -> None:
    fig, axes = plt.subplots(1, 2, figsize=(12, 4), layout="constrained")
    s = step_metrics(Spacer.preset("textile-6mm", seed=0))
    for level, t, y in zip(s.levels_ncm2, s.times_s, s.normalised, strict=True):
        axes[0].plot(t / 60, y, label=f"0 → {level:g} N/cm²")
    t = np.linspace(0, 3600, 400)
    axes[0].plot(
        t / 60,
        s.gamma_common * np.log(t + 1),
        "k--",
        label=f"γ ln(t + 1), γ = {s.gamma_common:.4f}",
    )
    axes[0].set_title("rising steps, compression held (cf. thesis fig. 5.2/5.7)", fontsize=10)
    for level in (0.25, 2.5, 5.0, 7.2):
        m = TestMachine(Spacer.preset("textile-6mm", seed=0))
        m.ramp_to_pressure(10.0, 50).hold_compression(3600).ramp_to_pressure(level, 50)
        t0, p0 = m.time_s, m.pressure_ncm2
        m.hold_compression(3600)
        tr = m.trace()
        after = tr.times_s > t0
        axes[1].plot(
            (tr.times_s[after] - t0) / 60,
            (tr.pressure_ncm2[after] - p0) / (10.0 - level),
            label=f"10 → {level:g}",
        )
    axes[1].set_title("falling steps after 1 h at 10 N/cm² (cf. fig. 5.3)", fontsize=10)
    for ax in axes:
        ax.set_xlabel("time after the step [min]")
        ax.set_ylabel("pressure change / step size")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.savefig(IMG / "sim_steps.png", dpi=100)
    plt.close(fig)


def fig_scan() -> None:
    mat = VirtualMat.seat(seed=4, failures=FailureModel())
    lay = mat.layout
    x, y = lay.xy_cm[:, 0], lay.xy_cm[:, 1]
    # two ischial tuberosities and the thighs of a seated person (a quick stand-in body)
    p = (
        3.0 * np.exp(-((x - 12) ** 2 + (y - 26) ** 2) / 18)
        + 3.0 * np.exp(-((x - 21) ** 2 + (y - 26) ** 2) / 18)
        + 0.8 * np.exp(-((x - 11) ** 2) / 14) * (y < 22)
        + 0.8 * np.exp(-((x - 22) ** 2) / 14) * (y < 22)
    )
    frames = np.repeat(p[None, :], 30, axis=0)
    scan = mat.scan(np.arange(30) * 1.6, frames)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6), layout="constrained")
    for ax, rec, title in (
        (axes[0], scan.pressure, "true pressure [N/cm²]"),
        (axes[1], scan.capacitance, "measured capacitance [pF], frame 29"),
    ):
        img = draw_map(ax, rec, 29)
        fig.colorbar(img, ax=ax, shrink=0.8)
        ax.set_title(title, fontsize=10)
    et = scan.capacitance.element_times[29] - scan.capacitance.times[29]
    axes[2].scatter(np.arange(96), et * 1000, s=6)
    axes[2].set_xlabel("element")
    axes[2].set_ylabel("read at [ms] after the frame start")
    axes[2].set_title(
        f"multiplexing: {mat.cdc.element_time_s * 1000:.1f} ms per element, "
        f"{mat.cdc.frame_time_s(96):.2f} s per frame",
        fontsize=10,
    )
    axes[2].grid(alpha=0.3)
    fig.suptitle(
        "virtual seat: 96 of 240 electrodes (checkerboard), 3 mm textile spacer, "
        "AD7745 at 83.8 Hz; failed elements read 0 pF",
        fontsize=10,
    )
    fig.savefig(IMG / "sim_scan.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    table()
    print()
    speed()
    IMG.mkdir(parents=True, exist_ok=True)
    fig_loops()
    fig_steps()
    fig_scan()
    print("\nwrote docs/img/sim_loops.png, sim_steps.png, sim_scan.png")
