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
from _realdata import pmd_reliable
from texsense import Layout
from texsense.apps.posture import FeatureSet, loso, make_classifier, mirror_frames
from texsense.apps.posture.features import reduce_maps
from texsense.apps.posture.study import (
    ErrorStudy,
    plot_study,
    sensor_hysteresis_model,
    study_tables,
)
from texsense.io.pmd import MIRROR_CLASS, MIRROR_POSTURE, POSTURE_CLASS

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
    """All reliable frames and the every-EVERY-th subsample mask."""
    layout, frames, posture, main, subject, file_frame = pmd_reliable()
    return layout, frames, posture, main, subject, file_frame % EVERY == 0


def mirrored(frames, posture, subject, layout):
    """Left-right mirrored copies of every frame with both labels swapped (every PMD posture
    has a mirror image, MIRROR_POSTURE), as (frames, posture, main class, subject)."""
    posture_m = np.array([MIRROR_POSTURE[int(p)] for p in posture])
    main_m = np.array([MIRROR_CLASS[POSTURE_CLASS[int(p)]] for p in posture])
    return mirror_frames(frames, layout), posture_m, main_m, subject


def classification(layout: Layout, frames, posture, main, subject) -> dict:
    runs = [
        ("naive Bayes (thesis)", THESIS, "naive-bayes", False),
        ("naive Bayes", ROTATED, "naive-bayes", False),
        ("LDA (shrinkage)", ROTATED, "lda", False),
        ("logistic regression", MAPS, "logistic", False),
        ("logistic regression", ROTATED, "logistic", False),
        ("linear SVM", MAPS, "linear-svm", False),
        ("linear SVM", ROTATED, "linear-svm", False),
        ("logistic regression", MAPS, "logistic", True),
        ("logistic regression", ROTATED, "logistic", True),
        ("linear SVM", MAPS, "linear-svm", True),
        ("linear SVM", ROTATED, "linear-svm", True),
    ]
    flipped, posture_m, main_m, subject_m = mirrored(frames, posture, subject, layout)
    print(
        f"PMD experiment I: {frames.shape[0]} frames (every {EVERY}th reliable frame), "
        f"{np.unique(subject).size} subjects, leave-one-subject-out\n"
    )
    print(
        "| classifier | features | mirrored training copies | 3 classes: mean | worst subject "
        "| 17 posture files: mean | worst subject | time |"
    )
    print("|---|---|---|---:|---:|---:|---:|---:|")
    cache: dict = {}
    out = {}
    for label, fs, clf, mirror in runs:
        key = id(fs)
        if key not in cache:
            cache[key] = fs.transform(frames, layout), fs.transform(flipped, layout)
        X, X_m = cache[key]
        t0 = time.perf_counter()
        if mirror:
            r3 = loso(X, main, subject, clf, extra=(X_m, main_m, subject_m))
            r17 = loso(X, posture, subject, clf, extra=(X_m, posture_m, subject_m))
        else:
            r3 = loso(X, main, subject, clf)
            r17 = loso(X, posture, subject, clf)
        dt = time.perf_counter() - t0
        fdesc = DESCRIPTION[id(fs)]
        print(
            f"| {label} | {fdesc} | {'yes' if mirror else 'no'} | {r3.accuracy:.1%} | "
            f"{r3.minimum[1]:.1%} ({r3.minimum[0]}) | {r17.accuracy:.1%} | "
            f"{r17.minimum[1]:.1%} ({r17.minimum[0]}) | {dt:.0f} s |"
        )
        out[f"{label}, {fdesc}{', mirrored' if mirror else ''}"] = {"3": r3, "17": r17}
    return out


def mirror_check(layout: Layout, frames, posture, subject) -> None:
    """Is MIRROR_POSTURE right? A classifier trained on the original maps of the other
    subjects labels the mirrored maps of each posture file; the declared mirror image should
    be what it says most often."""
    X = MAPS.transform(frames, layout)
    flipped, *_ = mirrored(frames, posture, subject, layout)
    X_f = MAPS.transform(flipped, layout)
    pred = np.empty_like(posture)
    for s in np.unique(subject):
        test = subject == s
        model = make_classifier("logistic").fit(X[~test], posture[~test])
        pred[test] = model.predict(X_f[test])
    print("\nmirror check (logistic regression on centred, log, pooled maps, leave one subject "
          "out; mirrored frames of each file):\n")  # fmt: skip
    print("| file | declared mirror image | labelled as it | most frequent labels |")
    print("|---:|---:|---:|---|")
    for p in np.unique(posture):
        got = pred[posture == p]
        values, counts = np.unique(got, return_counts=True)
        top = np.argsort(-counts)[:3]
        tops = ", ".join(f"{values[i]} ({counts[i] / got.size:.0%})" for i in top)
        share = np.mean(got == MIRROR_POSTURE[int(p)])
        print(f"| {p} | {MIRROR_POSTURE[int(p)]} | {share:.0%} | {tops} |")


C_GRID = (0.001, 0.01, 0.1, 1.0)


def nested(layout: Layout, frames, posture, main, subject, sub) -> dict:
    """The chosen set-up on all reliable frames, its regularisation C chosen inside every
    fold: for each held-out subject, C is picked by a 4-fold split by subject of the other 12
    subjects' every-5th frames (mirrored copies included), then the model is trained on all
    their frames and tested on the held-out subject's frames. No number seen here chose
    anything."""
    flipped, posture_m, main_m, _subject_m = mirrored(frames, posture, subject, layout)
    X, X_m = MAPS.transform(frames, layout), MAPS.transform(flipped, layout)
    runs = [
        ("3 classes", "logistic", "logisticregression__C", main, main_m),
        ("17 posture files", "linear-svm", "svc__C", posture, posture_m),
    ]
    print(
        f"\nall {frames.shape[0]} reliable frames, centred, log, 2x2 pooled maps with mirrored "
        "training copies, C chosen inside each fold (nested leave-one-subject-out):\n"
    )
    print("| target | classifier | mean | worst subject | C chosen (per held-out subject) | time |")
    print("|---|---|---:|---:|---|---:|")
    out = {}
    for target, clf, param, y, y_m in runs:
        t0 = time.perf_counter()
        per_subject, chosen = {}, []
        for s in np.unique(subject):
            train, train_sub = subject != s, (subject != s) & sub
            fold_of = {v: f"fold{i % 4}" for i, v in enumerate(np.unique(subject[train]))}
            fold = np.array([fold_of.get(v, "held out") for v in subject])  # 3 subjects each
            scores = []
            for c in C_GRID:
                est = make_classifier(clf).set_params(**{param: c})
                extra = (X_m[train_sub], y_m[train_sub], fold[train_sub])
                scores.append(loso(X[train_sub], y[train_sub], fold[train_sub], est,
                                   extra=extra).accuracy)  # fmt: skip
            c = C_GRID[int(np.argmax(scores))]
            chosen.append(c)
            est = make_classifier(clf).set_params(**{param: c})
            est.fit(np.vstack([X[train], X_m[train]]), np.concatenate([y[train], y_m[train]]))
            per_subject[str(s)] = float(np.mean(est.predict(X[~train]) == y[~train]))
        mean = float(np.mean(list(per_subject.values())))
        worst = min(per_subject, key=per_subject.__getitem__)
        counts = ", ".join(f"{c:g} x{chosen.count(c)}" for c in C_GRID if c in chosen)
        print(
            f"| {target} | {clf} | {mean:.1%} | {per_subject[worst]:.1%} ({worst}) | {counts} | "
            f"{time.perf_counter() - t0:.0f} s |"
        )
        out[target] = {"accuracy": mean, "per_subject": per_subject, "C": chosen}
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
    ax.set_title(
        f"PMD, 17 posture files, linear SVM with mirrored copies, LOSO {report.accuracy:.1%}",
        fontsize=10,
    )
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
    layout, frames, posture, main, subject, sub = load()
    t0 = time.perf_counter()
    reports = classification(layout, frames[sub], posture[sub], main[sub], subject[sub])
    mirror_check(layout, frames[sub], posture[sub], subject[sub])
    final = nested(layout, frames, posture, main, subject, sub)
    confusion_figure(reports[f"linear SVM, {DESCRIPTION[id(MAPS)]}, mirrored"]["17"])
    t1 = time.perf_counter()
    numbers = study(layout, frames[sub], posture[sub])
    print(f"classification {t1 - t0:.0f} s, study {time.perf_counter() - t1:.0f} s")
    Path("/tmp/posture_pmd.json").write_text(json.dumps({"study": numbers, "final": final}))
