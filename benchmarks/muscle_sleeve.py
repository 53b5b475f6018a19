"""Contractions found by a textile sleeve on a virtual forearm, with and without compensation.

Run:  .venv/bin/python benchmarks/muscle_sleeve.py [--plot docs/img/muscle_sleeve.png]
      [--sessions 5] [--minutes 10]

Five 10-minute sessions (texsense.sim.muscle: random contractions of 0.4-2 s and intensity
0.2-1, a minute of rest every three, the sleeve's preload of 0.15 N/cm² all the time), read at
the high-rate mode (4 elements in 48 ms), each sleeve calibrated as a user would. A true
contraction counts as found when a detected onset lies within 0.4 s of its start; a detected
onset that matches none is false. Intensity: the detected relative intensity against the true
one (both relative to the session's strongest).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from texsense.apps.muscle import activation, detect
from texsense.calibration.workflows import sleeve_calibration
from texsense.compensation.pipeline import Pipeline
from texsense.sim.muscle import session

VARIANTS = {
    "compensated (Preisach + drift)": {},
    "uncompensated (first-loading curve)": {"hysteresis": False, "drift": False},
}


def score(s, found_onsets, intensity):
    matched, errs = 0, []
    used = set()
    for t0, k in zip(s.onsets_s, s.intensity / s.intensity.max(), strict=True):
        near = [j for j, o in enumerate(found_onsets) if abs(o - t0) < 0.4 and j not in used]
        if near:
            matched += 1
            used.add(near[0])
            errs.append(abs(intensity[near[0]] - k))
    false = [o for j, o in enumerate(found_onsets) if j not in used]
    rest_s = sum(b - a for a, b in s.rest)
    false_rest = sum(any(a <= o < b for a, b in s.rest) for o in false)
    minutes = (s.times[-1] - s.times[0]) / 60
    return matched, len(false) / minutes, false_rest / (rest_s / 60), float(np.mean(errs))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--plot", type=Path)
    ap.add_argument("--first-seed", type=int, default=0, help="sessions first-seed .. first-seed+4")
    ap.add_argument("--sessions", type=int, default=5, help="how many sessions (5)")
    ap.add_argument("--minutes", type=float, default=10.0, help="of each session (10)")
    args = ap.parse_args()
    totals = {n: [0, 0, [], [], []] for n in VARIANTS}
    shown = None
    head = " | ".join(f"{n}: found / false per min (at rest) / intensity error" for n in VARIANTS)
    print(f"| session | contractions | {head} |")
    print("|---:|---:|" + "---|" * len(VARIANTS))
    for seed in range(args.first_seed, args.first_seed + args.sessions):
        s = session(args.minutes, seed=seed)
        cal = sleeve_calibration(seed=seed)
        rec = s.scan.capacitance
        cells = []
        for name, kw in VARIANTS.items():
            p = Pipeline(cal, rec.layout, repair=None, **kw).run(rec)
            act = activation(p)
            c = detect(p.times, act)
            m, fpm, frest, ierr = score(s, c.onsets_s, c.intensity)
            t = totals[name]
            t[0] += m
            t[1] += len(s.onsets_s)
            t[2].append(fpm)
            t[3].append(frest)
            t[4].append(ierr)
            cells.append(f"{m}/{len(s.onsets_s)} / {fpm:.2f} ({frest:.2f}) / {ierr:.2f}")
            if seed == args.first_seed:
                shown = shown or {"s": s}
                shown[name] = (p, act, c)
        print(f"| {seed} | {len(s.onsets_s)} | " + " | ".join(cells) + " |")
    cells = []
    for name in VARIANTS:
        t = totals[name]
        cells.append(f"**{100 * t[0] / t[1]:.1f} %** / {np.mean(t[2]):.2f} ({np.mean(t[3]):.2f}) "
                     f"/ {np.mean(t[4]):.2f}")  # fmt: skip
    print(f"| all | {totals[next(iter(VARIANTS))][1]} | " + " | ".join(cells) + " |")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        s = shown["s"]
        win = (s.times >= 100) & (s.times < 160)
        fig, axes = plt.subplots(2, 1, figsize=(10.5, 5), sharex=True)
        ax = axes[0]
        ax.plot(s.times[win], s.pressure[win, 0], "k", lw=2, label="true pressure, element 1")
        for (name, (p, _, _)), c in zip(
            ((n, shown[n]) for n in VARIANTS), ("tab:blue", "tab:red"), strict=True
        ):
            ax.plot(p.times[win], p.frames[win, 0], color=c, lw=1, label=name)
        ax.set_ylabel("N/cm²")
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        ax.set_title("a minute of the sleeve (session 0): pressure over the muscle belly")
        ax = axes[1]
        name = next(iter(VARIANTS))
        p, act, c = shown[name]
        ax.plot(p.times[win], act[win], color="tab:blue", lw=1, label="activation (compensated)")
        for o in s.onsets_s[(s.onsets_s >= 100) & (s.onsets_s < 160)]:
            ax.axvline(o, color="0.6", lw=3, alpha=0.5)
        for o in [v for v in c.onsets_s if 100 <= v < 160]:
            ax.axvline(o, color="tab:green", lw=1, ls="--")
        ax.axhline(0.06, color="tab:orange", lw=1, ls=":", label="onset threshold")
        ax.plot([], [], color="0.6", lw=3, alpha=0.5, label="true onsets")
        ax.plot([], [], color="tab:green", lw=1, ls="--", label="detected onsets")
        ax.set_xlabel("time, s")
        ax.set_ylabel("N/cm²")
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        print(f"\nwrote {args.plot}")


if __name__ == "__main__":
    main()
