"""Repair of failed elements on real pressure maps (PhysioNet PMD, experiment i).

Failures are laid over real maps: random elements (10/25/50 %) and clustered ones (lint
shorting neighbouring lines: segments of two adjacent rows or columns fail together, to
10/25 % of the elements). The last value of a failed element is its reading 5 frames (5 s)
earlier in the same posture file — or, in the last scenario, a frame of the same subject in
another posture (a failure that began long ago). Errors of the repaired map against the
true map, averaged over frames.

Run:  .venv/bin/python benchmarks/pipeline_repair.py     (writes docs/img/repair_pmd.png)
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import texsense
from _realdata import DATA
from texsense.compensation.repair import METHODS, Repair

IMG = Path(__file__).resolve().parents[1] / "docs" / "img"
LAG = 5  # frames between the last good reading and the evaluated frame


def random_failures(rng: np.random.Generator, n: int, share: float) -> np.ndarray:
    bad = np.zeros(n, bool)
    bad[rng.choice(n, round(share * n), replace=False)] = True
    return bad


def clustered_failures(rng: np.random.Generator, rows: int, cols: int, share: float) -> np.ndarray:
    """Segments (8-32 elements) of two neighbouring rows or columns, until ``share`` failed."""
    bad = np.zeros((rows, cols), bool)
    while bad.mean() < share:
        if rng.random() < 0.5:
            r = rng.integers(0, rows - 1)
            length = rng.integers(8, min(32, cols) + 1)
            c = rng.integers(0, cols - length + 1)
            bad[r : r + 2, c : c + length] = True
        else:
            c = rng.integers(0, cols - 1)
            length = rng.integers(8, 33)
            r = rng.integers(0, rows - length + 1)
            bad[r : r + length, c : c + 2] = True
    return bad.ravel()


def main(frames: int = 300, seed: int = 0) -> None:
    rec = texsense.load(DATA / "pmd" / "experiment-i")
    lay = rec.layout
    rows, cols = lay.shape
    rng = np.random.default_rng(seed)
    # frames with a body on the mat and a frame LAG earlier in the same file
    ff = np.asarray(rec.labels["file_frame"])
    load = rec.frames.sum(axis=1)
    ok = (ff >= LAG) & (load > np.median(load)) & np.asarray(rec.labels["reliable"], bool)
    pick = rng.choice(np.flatnonzero(ok), frames, replace=False)
    scenarios = (
        [(f"random {s:.0%}", "random", s) for s in (0.10, 0.25, 0.50)]
        + [(f"clustered {s:.0%}", "clustered", s) for s in (0.10, 0.25)]
        + [("random 25%, last value from another posture", "stale", 0.25)]
    )
    subject = np.asarray(rec.labels["subject"])
    posture = np.asarray(rec.labels["posture"])
    other = {
        int(k): int(rng.choice(np.flatnonzero((subject == subject[k]) & (posture != posture[k]))))
        for k in pick
    }
    xy = lay.xy_cm
    print(
        f"PMD experiment i, {frames} frames, {rows} x {cols} elements; errors of the repaired "
        "map against the true map (mean over frames)\n"
    )
    print(
        "| failures | method | RMSE [raw] | load error | peak error | centre of force error [cm] |"
    )
    print("|---|---|---:|---:|---:|---:|")
    example = None
    results: dict[tuple[str, str], float] = {}
    for label, kind, share in scenarios:
        masks = [
            random_failures(rng, lay.n_elements, share)
            if kind in ("random", "stale")
            else clustered_failures(rng, rows, cols, share)
            for _ in pick
        ]
        for method in METHODS:
            rep = Repair(lay, method).fit()
            rmse, le, pe, ce = [], [], [], []
            for k, bad in zip(pick, masks, strict=True):
                truth = rec.frames[k].astype(np.float64)
                rep.reset()
                before = other[int(k)] if kind == "stale" else k - LAG
                rep.step(rec.frames[before], np.ones(lay.n_elements, bool), t=0.0)
                out, _ = rep.step(np.where(bad, 0.0, truth), ~bad, t=float(LAG))
                out = np.nan_to_num(out)
                rmse.append(np.sqrt(np.mean((out - truth) ** 2)))
                le.append(abs(out.sum() - truth.sum()) / truth.sum())
                pe.append(abs(out.max() - truth.max()) / truth.max())
                c_true = (xy * truth[:, None]).sum(0) / truth.sum()
                c_out = (xy * out[:, None]).sum(0) / max(out.sum(), 1e-9)
                ce.append(float(np.hypot(*(c_out - c_true))))
                if (
                    example is None
                    and kind == "clustered"
                    and share == 0.25
                    and method == "harmonic"
                ):
                    example = (truth, bad, out)
            results[(label, method)] = float(np.mean(rmse))
            print(
                f"| {label} | {method} | {np.mean(rmse):.1f} | {np.mean(le):.1%} | "
                f"{np.mean(pe):.1%} | {np.mean(ce):.2f} |"
            )
    truth, bad, out = example
    # the same frame repaired with eq. 6.14, for the figure
    nm = Repair(lay, "neighbour-mean").fit()
    k0 = int(pick[0])
    nm.step(rec.frames[k0 - LAG], np.ones(lay.n_elements, bool), t=0.0)
    out_nm = np.nan_to_num(nm.step(np.where(bad, 0.0, truth), ~bad, t=float(LAG))[0])
    fig, axes = plt.subplots(1, 4, figsize=(11, 4.6), layout="constrained")
    vmax = float(np.percentile(truth, 99.5))
    panels = (
        ("true map", truth),
        ("25 % failed (clustered)", np.where(bad, np.nan, truth)),
        ("eq. 6.14 neighbour mean", out_nm),
        ("harmonic inpainting", out),
    )
    for ax, (title, values) in zip(axes, panels, strict=True):
        im = ax.imshow(lay.to_grid(values), vmin=0, vmax=vmax, cmap="viridis")
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(im, ax=axes, shrink=0.7, label="PMD raw value")
    fig.savefig(IMG / "repair_pmd.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    IMG.mkdir(parents=True, exist_ok=True)
    main()
