"""Accuracy of the Preisach compensation: virtual spacers (thesis §4.5) and real records.

Run:  .venv/bin/python benchmarks/hysteresis_accuracy.py       (writes docs/img/hyst_*.png)
      .venv/bin/python benchmarks/hysteresis_accuracy.py --float32
      (every prediction through the experimental float32 bank of issue 34, benchmarks/_float32.py;
      no figures written)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _float32 import FLOAT32, predict
from _realdata import elastomer_sawtooth, vhb_cycle
from texsense.compensation.hysteresis import HysteresisModel
from texsense.compensation.hysteresis._identify import identify_thesis
from texsense.compensation.hysteresis.plots import validation_figure
from texsense.sim import protocols
from texsense.sim.spacer import Spacer

IMG = Path(__file__).resolve().parents[1] / "docs" / "img"
BANDS = ((0.5, 3.5), (3.5, 10.0))


def mean_of_branches(u: np.ndarray, p: np.ndarray, bins: int = 200):
    """The single-valued baseline: the mean of the rising and the falling branch, binned
    over the input from a record's rising and falling samples."""
    du = np.gradient(u)
    edges = np.linspace(u.min(), u.max(), bins + 1)
    centres = 0.5 * (edges[1:] + edges[:-1])
    means = []
    for mask in (du > 0, du < 0):
        idx = np.clip(np.digitize(u[mask], edges) - 1, 0, bins - 1)
        sums = np.bincount(idx, p[mask], bins)
        counts = np.bincount(idx, minlength=bins)
        ok = counts > 0
        means.append(np.interp(centres, centres[ok], sums[ok] / counts[ok]))
    curve = 0.5 * (means[0] + means[1])
    return lambda x: np.interp(x, centres, curve)


def from_ident(ident, sign=1.0) -> HysteresisModel:
    m = HysteresisModel()
    m.everett_, m.u_min_, m.u_max_ = ident.everett, ident.u_min, ident.u_max
    m.offset_, m.sign_, m.method_, m.details_, m.provenance_ = (
        ident.offset,
        sign,
        ident.method,
        {},
        {},
    )
    return m


def band_errors(p: np.ndarray, pm: np.ndarray) -> list[str]:
    out = []
    for lo, hi in BANDS:
        s = (p >= lo) & (p < hi)
        rel = np.abs(pm[s] - p[s]) / p[s]
        out += [f"{rel.mean():.1%}", f"{rel.max():.1%}"]
    return out


def virtual(name: str = "textile-6mm", seeds=(0, 1, 2, 3), figure: bool = True) -> None:
    print(
        f"| {name} specimen | method | identified from | mean 0.5-3.5 | max 0.5-3.5 "
        "| mean 3.5-10 | max 3.5-10 |"
    )
    print("|---|---|---|---:|---:|---:|---:|")
    for seed in seeds:
        sp = Spacer.preset(name, seed=seed)
        cal = protocols.run_protocol("calibration", sp, seed=seed, sample_hz=None)
        sp.reset()
        cal4 = protocols.run_protocol(
            "calibration", sp, seed=seed, sample_hz=None, falling_from=(1.0, 0.6, 0.3, 0.13)
        )
        sp.reset()
        saw = protocols.run_protocol("sawtooth", sp, seed=seed + 100, sample_hz=None)
        sp.reset()
        val = protocols.run_protocol("validation", sp, seed=seed, sample_hz=None)
        uc, pc = cal.labels["compression_mm"], cal.labels["pressure_ncm2"]
        us, ps = saw.labels["compression_mm"], saw.labels["pressure_ncm2"]
        u, p = val.labels["compression_mm"], val.labels["pressure_ncm2"]
        thesis = identify_thesis(uc, pc)
        rows = [
            ("mean of branches (no model)", "calibration", mean_of_branches(uc, pc)(u)),
            (
                "Preisach, thesis method",
                "calibration (3 falling curves)",
                predict(from_ident(thesis), u),
            ),
            (
                "Preisach, thesis method, 200 x 200",
                "4 falling curves (100/60/30/13 %)",
                predict(
                    from_ident(
                        identify_thesis(
                            cal4.labels["compression_mm"], cal4.labels["pressure_ncm2"], grid=200
                        )
                    ),
                    u,
                ),
            ),
        ]
        for source, (ui, pi) in (
            ("calibration (3 falling curves)", (uc, pc)),
            ("65 s random sawtooth", (us, ps)),
        ):
            m = HysteresisModel().fit(ui, pi)
            rows.append((f"Preisach, default ({m.method_})", source, predict(m, u)))
        for label, source, pm in rows:
            print(f"| {seed} | {label} | {source} | " + " | ".join(band_errors(p, pm)) + " |")
        if figure and seed == 0 and not FLOAT32:
            pm = from_ident(thesis).predict(u)
            n = u.size // 50  # one validation cycle
            validation_figure(
                u[:n],
                p[:n],
                pm[:n],
                IMG / f"hyst_{name}_validation.png",
                title=f"{name}, seed 0: first validation cycle, thesis method "
                "(cf. thesis fig. 4.8/4.9)",
            )


def nrmse(y: np.ndarray, m: np.ndarray) -> float:
    return float(np.sqrt(np.mean((m - y) ** 2)) / np.ptp(y))


def rel_err(y: np.ndarray, m: np.ndarray, floor: float = 0.1) -> tuple[float, float]:
    s = np.abs(y) >= floor * np.abs(y).max()
    r = np.abs(m[s] - y[s]) / np.abs(y[s])
    return float(r.mean()), float(np.percentile(r, 95))


def real() -> None:
    print("| record | method | NRMSE | mean rel. error | 95th pct rel. error |")
    print("|---|---|---:|---:|---:|")
    t, d, f = elastomer_sawtooth()
    cut = int(0.6 * t.size)
    fit_u, fit_y, test_u, test_y = d[:cut], f[:cut], d, f
    base = mean_of_branches(fit_u, fit_y)
    m = HysteresisModel(input_name="displacement_mm", output_name="force_n", output_unit="N").fit(
        fit_u, fit_y
    )
    full = predict(m, test_u)
    for label, pred in (("mean of branches", base(test_u)), ("Preisach, default", full)):
        y, pm = test_y[cut:], pred[cut:]
        mean, p95 = rel_err(y, pm)
        print(
            f"| elastomer sawtooth, last 40 % (fit on first 60 %) | {label} | "
            f"{nrmse(y, pm):.3f} | {mean:.1%} | {p95:.1%} |"
        )
    if not FLOAT32:
        validation_figure(
            test_u,
            test_y,
            full,
            IMG / "hyst_elastomer.png",
            input_label="displacement [mm]",
            output_label="force [N]",
            title="elastomer random sawtooth: default identification on the first 60 %, "
            "predicted over the whole record",
        )
    # VHB 4910 at 0.01 /s: identify on stretches 1.5, 2.5, 3.0, predict 2.0
    parts = [vhb_cycle(n) for n in ("0d01_3d0", "0d01_2d5", "0d01_1d5")]
    uu = np.concatenate([p[1] for p in parts])
    yy = np.concatenate([p[2] for p in parts])
    _, ut, yt = vhb_cycle("0d01_2d0")
    base = mean_of_branches(uu, yy)
    thesis = HysteresisModel(
        method="thesis", input_name="displacement_mm", output_name="force_n", output_unit="N"
    ).fit(uu, yy)
    lsq = HysteresisModel(input_name="displacement_mm", output_name="force_n", output_unit="N").fit(
        uu, yy
    )
    for label, pm in (
        ("mean of branches", base(ut)),
        ("Preisach, thesis method", predict(thesis, ut)),
        (f"Preisach, default ({lsq.method_})", predict(lsq, ut)),
    ):
        mean, p95 = rel_err(yt, pm)
        print(
            f"| VHB 4910, stretch 2.0 (fit on 1.5/2.5/3.0, 0.01 /s) | {label} | "
            f"{nrmse(yt, pm):.3f} | {mean:.1%} | {p95:.1%} |"
        )
    if FLOAT32:
        return
    validation_figure(
        ut,
        yt,
        thesis.predict(ut),
        IMG / "hyst_vhb.png",
        input_label="displacement [mm]",
        output_label="force [N]",
        title="VHB 4910 stretch 2.0 predicted from the cycles to 1.5, 2.5 and 3.0",
    )


if __name__ == "__main__":
    IMG.mkdir(parents=True, exist_ok=True)
    virtual("textile-6mm")
    print()
    for foam in ("foam-7mm", "foam-13mm", "foam-9mm"):
        virtual(foam, seeds=(0,), figure=False)
        print()
    real()
