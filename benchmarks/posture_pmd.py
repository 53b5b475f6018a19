"""Posture classification and the error-modelling study on real pressure maps: PhysioNet PMD
experiment I (13 subjects, 17 posture files, 64 x 32 raw counts), leave-one-subject-out.

Run:  .venv/bin/python benchmarks/posture_pmd.py
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _realdata import DATA
from texsense import Layout
from texsense.io.pmd import POSTURE_CLASS, read_pmd
from texsense.posture import FeatureSet, loso
from texsense.posture.features import reduce_maps
from texsense.posture.study import (
    ErrorStudy,
    plot_study,
    sensor_hysteresis_model,
    study_tables,
)

IMG = Path(__file__).resolve().parents[1] / "docs" / "img"
EVERY = 5  # every 5th reliable frame (1 Hz frames of a held posture are nearly identical)

THESIS = FeatureSet(("elements", "centre", "areas4", "areas16"))  # §6.3.2
MAPS = FeatureSet(("elements",), align=True, log=True, pool=2)  # beyond the thesis
ROTATED = FeatureSet(("elements",), align=True, rotate=True, log=True, pool=2)
DESCRIPTION = {
    id(THESIS): "elements, CoF, 4+16 areas",
    id(MAPS): "centred, log, 2x2 pooled map",
    id(ROTATED): "centred + rotated, log, 2x2 pooled",
}


def load() -> tuple:
    rec = read_pmd(DATA / "pmd" / "experiment-i")
    keep = rec.labels["reliable"] & (rec.labels["file_frame"] % EVERY == 0)
    frames = rec.frames[keep].astype(np.float64)
    posture = rec.labels["posture"][keep]
    subject = rec.labels["subject"][keep]
    main = np.array([POSTURE_CLASS[int(p)] for p in posture])
    return rec.layout, frames, posture, main, subject


def classification(layout: Layout, frames, posture, main, subject) -> dict:
    runs = [
        ("naive Bayes (thesis)", THESIS, "naive-bayes"),
        ("naive Bayes", ROTATED, "naive-bayes"),
        ("LDA (shrinkage)", ROTATED, "lda"),
        ("logistic regression", MAPS, "logistic"),
        ("logistic regression", ROTATED, "logistic"),
        ("linear SVM", MAPS, "linear-svm"),
        ("linear SVM", ROTATED, "linear-svm"),
    ]
    print(
        f"PMD experiment I: {frames.shape[0]} frames (every {EVERY}th reliable frame), "
        f"{np.unique(subject).size} subjects, leave-one-subject-out\n"
    )
    print(
        "| classifier | features | 3 classes: mean | worst subject | 17 posture files: mean | "
        "worst subject | time |"
    )
    print("|---|---|---:|---:|---:|---:|---:|")
    cache: dict = {}
    out = {}
    for label, fs, clf in runs:
        key = id(fs)
        if key not in cache:
            cache[key] = fs.transform(frames, layout)
        X = cache[key]
        t0 = time.perf_counter()
        r3 = loso(X, main, subject, clf)
        r17 = loso(X, posture, subject, clf)
        dt = time.perf_counter() - t0
        fdesc = DESCRIPTION[id(fs)]
        print(
            f"| {label} | {fdesc} | {r3.accuracy:.1%} | {r3.minimum[1]:.1%} ({r3.minimum[0]}) | "
            f"{r17.accuracy:.1%} | {r17.minimum[1]:.1%} ({r17.minimum[0]}) | {dt:.0f} s |"
        )
        out[f"{label}, {fdesc}"] = {"3": r3, "17": r17}
    return out


def confusion_figure(report) -> None:
    c = report.confusion / report.confusion.sum(axis=1, keepdims=True)
    fig, ax = plt.subplots(figsize=(6.2, 5.4), layout="constrained")
    im = ax.imshow(100 * c, cmap="Blues", vmin=0, vmax=100)
    n = len(report.labels)
    ax.set_xticks(range(n), [str(v) for v in report.labels], fontsize=7)
    ax.set_yticks(range(n), [str(v) for v in report.labels], fontsize=7)
    for i in range(n):
        for j in range(n):
            if c[i, j] >= 0.05:
                ax.text(j, i, f"{100 * c[i, j]:.0f}", ha="center", va="center", fontsize=6,
                        color="w" if c[i, j] > 0.5 else "k")  # fmt: skip
    ax.set_xlabel("predicted posture file")
    ax.set_ylabel("true posture file")
    ax.set_title(f"PMD, 17 posture files, linear SVM, LOSO {report.accuracy:.1%}", fontsize=10)
    fig.colorbar(im, ax=ax, label="% of the true posture's frames")
    fig.savefig(IMG / "posture_pmd_confusion.png", dpi=100)
    plt.close(fig)


def study(layout: Layout, frames, posture) -> dict:
    """§6.4 on PMD: reference pattern per posture file = mean of its aligned maps over all
    subjects, pooled 2 x 2 (as the thesis averaged its Tekscan mat 2 x 2), counts scaled so
    the largest reference value is 5 N/cm² (the thesis's seat range; PMD gives no
    calibration)."""
    pooled, small = reduce_maps(frames, layout, align=True, rotate=True, pool=2)
    labels = np.unique(posture)
    refs = np.vstack([pooled[posture == p].mean(axis=0) for p in labels])
    refs *= 5.0 / refs.max()
    s = ErrorStudy(refs, small, labels, hysteresis_model=sensor_hysteresis_model(), seed=0)
    results = s.run()
    print("\nerror-modelling study on PMD (17 reference patterns, 512 elements, naive Bayes):\n")
    print(study_tables(results))
    fig = plot_study(
        results, "PhysioNet PMD, 17 postures: modelled errors (cf. thesis fig. 6.9-6.12)"
    )
    fig.savefig(IMG / "posture_pmd_study.png", dpi=100)
    plt.close(fig)
    return ErrorStudy.to_dict(results)


if __name__ == "__main__":
    IMG.mkdir(parents=True, exist_ok=True)
    data = load()
    t0 = time.perf_counter()
    reports = classification(*data)
    confusion_figure(reports[f"linear SVM, {DESCRIPTION[id(ROTATED)]}"]["17"])
    layout, frames, posture, _, _ = data
    t1 = time.perf_counter()
    numbers = study(layout, frames, posture)
    print(f"classification {t1 - t0:.0f} s, study {time.perf_counter() - t1:.0f} s")
    Path("/tmp/posture_pmd.json").write_text(json.dumps(numbers))
