"""A day's wear of compression stockings on virtual legs, read by the textile sensor strip.

Run:  .venv/bin/python benchmarks/stocking_wear.py [--plot docs/img/stocking_wear.png]

For every compression class (RAL-GZ 387) on three leg sizes, 8 h of wear (a frame every 10 s)
through the virtual strip (textile-3mm spacer, which creeps under the held load); the strip is
calibrated as a user would (zeroing, 1 N/cm² equilibration, spacer model and drift from
another specimen's test-machine records). After 8 h: the class read at B and the pressure
error at every point, with the full compensation (Preisach + drift, eq. 4.15-4.22 and 5.8),
with the Preisach model alone, and uncompensated (the first-loading curve), beside the truth.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from texsense.apps.stocking import compression_class
from texsense.calibration.workflows import strip_calibration
from texsense.compensation.pipeline import Pipeline
from texsense.data.units import convert
from texsense.sim.stocking import LEGS, POINTS, wear

VARIANTS = {
    "compensated (Preisach + drift)": {},
    "Preisach, no drift stage": {"drift": False},
    "uncompensated (first-loading curve)": {"hysteresis": False, "drift": False},
}


def last_10_min(times: np.ndarray, values: np.ndarray) -> np.ndarray:
    sel = times >= times[-1] - 600.0
    return np.nanmean(values[sel], axis=0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--plot", type=Path)
    args = ap.parse_args()
    rows, traces = [], {}
    for k, (leg_name, leg) in enumerate(LEGS.items()):
        cal = strip_calibration(seed=k)
        for cls in ("I", "II", "III", "IV"):
            times, truth, scan = wear(cls, leg, hours=8.0, seed=k)
            true_mm = np.asarray(convert(last_10_min(times, truth), "N/cm2", "mmHg"))
            out = {"truth": true_mm}
            for name, kw in VARIANTS.items():
                rec = Pipeline(cal, scan.capacitance.layout, repair=None, **kw).run(
                    scan.capacitance
                )
                mm = np.asarray(convert(rec.frames.astype(float), "N/cm2", "mmHg"))
                out[name] = last_10_min(times, mm)
                if cls == "II" and leg_name == "medium":
                    traces[name] = (times, mm[:, 0])
            if cls == "II" and leg_name == "medium":
                traces["truth"] = (times, np.asarray(convert(truth[:, 0], "N/cm2", "mmHg")))
            rows.append((cls, leg_name, out))
    print("after 8 h of wear: the class read at B, and the largest error at B, B1, C, D (mmHg)\n")
    head = " | ".join(f"{n}: class / max error" for n in VARIANTS)
    print(f"| class | leg | true pressure B, B1, C, D (mmHg) | true class | {head} |")
    print("|---|---|---|---|" + "---|" * len(VARIANTS))
    right = dict.fromkeys(VARIANTS, 0)
    for cls, leg_name, out in rows:
        truth_cls = compression_class(float(out["truth"][0]))
        cells = []
        for name in VARIANTS:
            got = compression_class(float(out[name][0]))
            right[name] += got == truth_cls
            err = float(np.max(np.abs(out[name] - out["truth"])))
            cells.append(f"{got} / {err:.1f}")
        p = ", ".join(f"{v:.1f}" for v in out["truth"])
        print(f"| {cls} | {leg_name} | {p} | {truth_cls} | {' | '.join(cells)} |")
    print("\nclass read right after 8 h: " + ", ".join(
        f"{n} {right[n]}/{len(rows)}" for n in VARIANTS))  # fmt: skip
    # at every point: the RAL-GZ 387 range (or gap) its reading falls in, against the truth's
    points_right = {
        n: sum(
            compression_class(float(out[n][j])) == compression_class(float(out["truth"][j]))
            for _, _, out in rows
            for j in range(len(POINTS))
        )
        for n in VARIANTS
    }
    total = len(rows) * len(POINTS)
    print("readings in the same class range (or gap) as the true pressure, all points: "
          + ", ".join(f"{n} {points_right[n]}/{total}" for n in VARIANTS))  # fmt: skip
    name = next(iter(VARIANTS))
    for cls, leg_name, out in rows:
        for j, point in enumerate(POINTS):
            t, m = float(out["truth"][j]), float(out[name][j])
            if compression_class(m) != compression_class(t):
                where = f"class {cls} {leg_name} leg, {point}"
                print(f"  {name}, {where}: true {t:.2f} mmHg ({compression_class(t)}), "
                      f"read {m:.2f} ({compression_class(m)})")  # fmt: skip
    errs = {n: [] for n in VARIANTS}
    for _, _, out in rows:
        for n in VARIANTS:
            errs[n].append(np.abs(out[n] - out["truth"]))
    print("mean error per point after 8 h (mmHg), " + ", ".join(POINTS) + ":")
    for n in VARIANTS:
        e = np.mean(errs[n], axis=0)
        print(f"  {n}: " + ", ".join(f"{v:.2f}" for v in e))
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7.5, 3.8))
        colours = ["tab:blue", "tab:orange", "tab:red"]
        widths = [1.4, 3.0, 1.2]  # the two without drift stage coincide: orange under red
        for k, name in enumerate(VARIANTS):
            t, v = traces[name]
            ax.plot(t / 3600, v, color=colours[k], lw=widths[k], label=name)
        t, v = traces["truth"]
        ax.plot(t / 3600, v, color="k", lw=2.0, label="true pressure")
        ax.axhspan(23, 32, color="0.9", zorder=0)
        ax.text(7.9, 31.4, "class II (RAL-GZ 387): 23-32 mmHg", ha="right", va="top", fontsize=8)
        ax.set_xlabel("hours of wear")
        ax.set_ylabel("pressure at B (ankle), mmHg")
        ax.set_ylim(18, 40)
        ax.set_title("class II stocking, medium leg: the textile strip at the ankle")
        ax.legend(fontsize=8, loc="upper left")
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        print(f"\nwrote {args.plot}")


if __name__ == "__main__":
    main()
