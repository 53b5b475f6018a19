"""Thesis chapter 6 on the virtual seat: 9 subjects x 3 rounds x 16 postures, the textile
sensor through the pipeline (raw / hysteresis compensated / failures replaced / both, with
and without the back sensor), the reference mat, the drift test (train round 1, test round 2
vs 3) and the error-modelling study on the reference patterns.

Run:  .venv/bin/python benchmarks/posture_seat.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from texsense.apps.posture import (
    FeatureSet,
    loso,
    make_classifier,
    reduce_maps,
    sequential_forward_selection,
)
from texsense.apps.posture.study import (
    ErrorStudy,
    plot_study,
    sensor_hysteresis_model,
    study_tables,
)
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.pipeline import Pipeline
from texsense.sim.seated import Subject, simulate_session

IMG = Path(__file__).resolve().parents[1] / "docs" / "img"
SUBJECTS = 9
THESIS = FeatureSet(("elements", "centre", "areas4", "areas16", "back"))
K_MAX = 16

VARIANTS = [  # thesis Table 6.1 rows
    ("raw data", dict(hysteresis=False, drift=False, repair=None)),
    ("hysteresis compensated", dict(drift=False, repair=None)),
    ("failing sensors replaced (eq. 6.14)",
     dict(hysteresis=False, drift=False, repair="neighbour-mean")),
    ("hysteresis compensated + failing replaced", dict(drift=False, repair="neighbour-mean")),
]  # fmt: skip
THESIS_TABLE = {  # Table 6.1: without / with back sensor
    "raw data": (0.43, 0.63),
    "hysteresis compensated": (0.51, 0.77),
    "failing sensors replaced (eq. 6.14)": (0.55, 0.81),
    "hysteresis compensated + failing replaced": (0.59, 0.82),
}


def sessions() -> list:
    t0 = time.perf_counter()
    out = [simulate_session(Subject.random(i, seed=1), seed=i) for i in range(SUBJECTS)]
    print(f"simulated {SUBJECTS} sessions in {time.perf_counter() - t0:.0f} s")
    return out


def failure_statistics(runs: list) -> None:
    """The virtual mat's failures against thesis §6.5.2.5 (58 of 96 elements fail at least
    once per round on average, at most 65; 67 over three rounds, at most 77)."""
    per_round, all_rounds, share = [], [], []
    for s in runs:
        posture, rnd = s.truth.labels["posture"], s.truth.labels["round"]
        seated = posture >= 0
        for r in np.unique(rnd[seated]):
            per_round.append(int(s.failed[seated & (rnd == r)].any(axis=0).sum()))
        all_rounds.append(int(s.failed[seated].any(axis=0).sum()))
        share.append(float(s.failed[posture > 0].mean()))
    n = runs[0].failed.shape[1]
    print(
        f"failures ({n} elements): at least once per round {np.mean(per_round):.1f} on average "
        f"(max {max(per_round)}; thesis 58, max 65), over three rounds {np.mean(all_rounds):.1f} "
        f"(max {max(all_rounds)}; thesis 67, max 77); {np.mean(share):.1%} of the readings in "
        "a posture failed\n"
    )


def stack(parts: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(parts, axis=0)


def reference_data(runs: list) -> tuple:
    """The reference mat's hold frames of all subjects, averaged 2 x 2 to 256 elements (as the
    thesis averaged its Tekscan, §6.4.1): frames, layout, posture, subject, back sensor."""
    maps, y, g, back = [], [], [], []
    for s in runs:
        hold = s.reference.labels["hold"]
        m, small = reduce_maps(s.reference.frames[hold], s.reference.layout, pool=2)
        maps.append(m)
        y.append(s.reference.labels["posture"][hold])
        g.append(s.reference.labels["subject"][hold])
        back.append(s.reference_back[hold])
    return stack(maps), small, stack(y), stack(g), stack(back)


def textile_data(runs: list, cal) -> dict:
    """Pressure of every variant, hold frames only, all subjects stacked."""
    data: dict = {}
    lay = runs[0].truth.layout
    for label, cfg in VARIANTS:
        frames, y, g, rnd, back = [], [], [], [], []
        for s in runs:
            out = Pipeline(cal, lay, **cfg).run(s.capacitance).frames.astype(np.float64)
            hold = s.truth.labels["hold"]
            frames.append(np.nan_to_num(out[hold]))  # a failed, unrepaired element reads 0
            y.append(s.truth.labels["posture"][hold])
            g.append(s.truth.labels["subject"][hold])
            rnd.append(s.truth.labels["round"][hold])
            back.append(s.back[hold])
        data[label] = (stack(frames), stack(y), stack(g), stack(rnd), stack(back))
    return data


def table_6_1(runs: list, cal) -> None:
    lay = runs[0].truth.layout
    data = textile_data(runs, cal)
    best_label = VARIANTS[-1][0]
    frames, y, g, rnd, back = data[best_label]
    X = THESIS.transform(frames, lay, back)
    names = THESIS.names(lay)
    t0 = time.perf_counter()
    chosen, scores = sequential_forward_selection(
        X, y, g, K_MAX, "naive-bayes", show_progress=False
    )
    k = int(np.argmax(scores)) + 1
    cols = chosen[:k]
    print(
        f"forward selection (naive Bayes, LOSO cost, on the compensated data with back sensor, "
        f"{time.perf_counter() - t0:.0f} s): best k = {k} ({scores[k - 1]:.1%}): "
        + ", ".join(names[c] for c in cols)
        + "\n"
    )
    no_back = [c for c in cols if names[c] != "back"]
    print(
        "| data | thesis: without back sensor | ours | thesis: with back sensor | ours | "
        "ours, LDA on all features, with back sensor |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    for label, _ in VARIANTS:
        frames, y, g, rnd, back = data[label]
        X = THESIS.transform(frames, lay, back)
        a0 = loso(X[:, no_back], y, g, "naive-bayes").accuracy
        a1 = loso(X[:, cols], y, g, "naive-bayes").accuracy
        lda = loso(X, y, g, "lda").accuracy
        t0, t1 = THESIS_TABLE[label]
        print(f"| {label} | {t0:.0%} | {a0:.1%} | {t1:.0%} | {a1:.1%} | {lda:.1%} |")
    # the reference mat, averaged 2 x 2 to 256 elements as the thesis did with its Tekscan
    ref_frames, small, ry, rg, rback = reference_data(runs)
    RX = THESIS.transform(ref_frames, small, rback)
    rnames = THESIS.names(small)
    every = slice(None, None, 4)  # selection on every 4th frame keeps it to a minute
    rchosen, rscores = sequential_forward_selection(
        RX[every], ry[every], rg[every], K_MAX, "naive-bayes", show_progress=False
    )
    rk = int(np.argmax(rscores)) + 1
    rcols = rchosen[:rk]
    r_no_back = [c for c in rcols if rnames[c] != "back"]
    a0 = loso(RX[:, r_no_back], ry, rg, "naive-bayes").accuracy
    a1 = loso(RX[:, rcols], ry, rg, "naive-bayes").accuracy
    lda = loso(RX, ry, rg, "lda").accuracy
    print(f"| reference mat (256 of 1024 elements, own {rk} features) | 56% | {a0:.1%} | 84% | "
          f"{a1:.1%} | {lda:.1%} |")  # fmt: skip
    # drift (§6.5.2.4): train on round 1, test on round 2 (no unloading) and round 3
    frames, y, g, rnd, back = data[best_label]
    X = THESIS.transform(frames, lay, back)[:, cols]
    r2, r3 = [], []
    for s in np.unique(g):
        train = (g != s) & (rnd == 1)
        model = make_classifier("naive-bayes").fit(X[train], y[train])
        for target, acc in ((2, r2), (3, r3)):
            test = (g == s) & (rnd == target)
            acc.append(float(np.mean(model.predict(X[test]) == y[test])))
    diff = np.abs(np.array(r2) - np.array(r3))
    print(
        f"\ndrift (§6.5.2.4; naive Bayes on rounds 1 of the other subjects, compensated data, "
        f"back sensor): round 2 {np.mean(r2):.1%}, round 3 (after 30 min unloaded) "
        f"{np.mean(r3):.1%}; difference of the means {abs(np.mean(r2) - np.mean(r3)):.1%}, "
        f"largest per subject {diff.max():.1%} (thesis: 1 % and < 12 %)\n"
    )


def study(runs: list) -> None:
    """§6.4-6.5.1 on the reference mat's patterns (256 elements, mean over all subjects)."""
    maps, small, y, _, _ = reference_data(runs)
    labels = np.arange(1, 17)
    refs = np.vstack([maps[y == p].mean(axis=0) for p in labels])
    st = ErrorStudy(refs, small, labels, hysteresis_model=sensor_hysteresis_model(), seed=0)
    results = st.run(show_progress=False)
    print(
        "error-modelling study on the virtual seat (16 reference patterns, 256 elements, "
        "naive Bayes):\n"
    )
    print(study_tables(results))
    fig = plot_study(
        results, "virtual seat, 16 postures: modelled errors (cf. thesis fig. 6.9-6.12)"
    )
    fig.savefig(IMG / "posture_seat_study.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    IMG.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    runs = sessions()
    failure_statistics(runs)
    cal = seat_calibration()
    table_6_1(runs, cal)
    study(runs)
    print(f"total {time.perf_counter() - t0:.0f} s")
