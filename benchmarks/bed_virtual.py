"""The bed (issue 17, docs/bed.md): at-risk regions, the side a person lies on, the turning
schedule over simulated nights, and the real check on PhysioNet PMD.

1. Regions: 8 people (none of them in the side model's training set) take every position on
   the virtual bed mat (failing elements at the thesis's rates); the regions are found from
   the true map, from the compensated pressure and from the uncompensated pressure (the
   loading curve only: no hysteresis, drift or failure handling), each given the true side.
   A prominence counts as found when a region of its name lies within 5 cm.
2. Nights: 4 people, 8 h each (positions held 20 min to 2 h 12 min, turning, sitting up,
   getting up), a frame every 10 s through the mat and the pipeline; the side model
   (``texsense.apps.posture.training.train_virtual_bed_model``, trained on other people) gives
   the side of every frame, and the turning schedule (2 h) runs once on it and once on the
   true sides: turns, time per side and turn-due alerts are compared.
3. PMD (real maps of 13 people on a 64 x 32 mat of the same size): the virtual bed's side
   model applied unchanged to the real maps (sim-to-real: supine / left / right), and the
   regions found on the real supine maps: the heel-to-sacrum distance against each
   person's height.

Run:  .venv/bin/python benchmarks/bed_virtual.py  (about 5 min)
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
from _realdata import DATA, pmd_reliable
from texsense.apps.bed import TurningSchedule, find_regions
from texsense.apps.posture.training import train_virtual_bed_model
from texsense.calibration.workflows import bed_calibration
from texsense.compensation.pipeline import Pipeline
from texsense.sim.bed import (
    POSITIONS,
    Sleeper,
    bed_layout,
    bed_mat,
    bed_session,
    every_position,
    night_plan,
)

IMG = Path(__file__).resolve().parents[1] / "docs" / "img"
LAY = bed_layout()
FOUND_CM = 5.0
PEOPLE_SEED = 77  # the side model trains on seed 41: other people


def regions_table(cal) -> dict:
    """Every position of 8 people, held 30 s: prominences found within 5 cm and the median
    distance, from the true, the compensated and the uncompensated map."""
    sources = {"true map": None, "compensated": {}, "uncompensated (loading curve only)":
               dict(hysteresis=False, drift=False, repair=None)}  # fmt: skip
    hits = {k: [] for k in sources}
    false: dict = {k: [] for k in sources}
    false_names: dict = {k: {} for k in sources}
    dist = {k: [] for k in sources}
    per_side: dict = {}
    for i in range(8):
        s = every_position(i, PEOPLE_SEED, 30.0)
        maps = {"true map": s.truth.frames}
        for name, opts in sources.items():
            if opts is not None:
                maps[name] = np.nan_to_num(Pipeline(cal, LAY, **opts).run(s.capacitance).frames)
        side = s.truth.labels["side"]
        last = {}
        for k in range(s.truth.n_frames):  # the last held frame of every position
            if s.truth.labels["hold"][k]:
                last[s.truth.labels["position"][k]] = k
        for k in last.values():
            tilted = "tilt" in s.truth.labels["position"][k]  # no prominence named there
            for name, m in maps.items():
                found = find_regions(m[k], LAY, side[k])
                truth = s.prominences[k]
                if not tilted:
                    for prom, r in found.items():
                        near = (
                            prom in truth
                            and np.hypot(r.x_cm - truth[prom][0], r.y_cm - truth[prom][1])
                            <= FOUND_CM
                        )
                        false[name].append(not near)
                        if not near:
                            false_names[name][prom] = false_names[name].get(prom, 0) + 1
                for prom, (x, y) in truth.items():
                    d = np.inf
                    if prom in found:
                        d = float(np.hypot(found[prom].x_cm - x, found[prom].y_cm - y))
                    hits[name].append(d <= FOUND_CM)
                    dist[name].append(d)
                    if name == "compensated":
                        per_side.setdefault(side[k], []).append(d <= FOUND_CM)
    print("At-risk regions: 8 people x 14 positions (the last held frame of each), "
          f"a prominence found = a region of its name within {FOUND_CM:g} cm\n")  # fmt: skip
    print("| map | prominences | found | median distance | 90th percentile | regions "
          "found where no such prominence is (not tilted) |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|")
    for name in sources:
        d = np.array(dist[name])
        ok = np.isfinite(d)
        print(f"| {name} | {d.size} | {np.mean(hits[name]):.1%} | {np.median(d[ok]):.1f} cm | "
              f"{np.percentile(d[ok], 90):.1f} cm | {sum(false[name])} of {len(false[name])} "
              f"({np.mean(false[name]):.1%}) |")  # fmt: skip
    print("\nthose on the compensated map, by name: " + ", ".join(
        f"{k} {v}" for k, v in sorted(false_names["compensated"].items())))  # fmt: skip
    print("\ncompensated, per side: " + ", ".join(
        f"{k} {np.mean(v):.1%} of {len(v)}" for k, v in sorted(per_side.items())))  # fmt: skip
    return {"hits": hits, "dist": dist}


def nights(cal, model, people: int = 4, hours: float = 8.0, frame_s: float = 10.0) -> list:
    """Simulated nights through the mat and the pipeline; the side of every frame from the
    model and from the truth."""
    out = []
    for i in range(people):
        rng = np.random.default_rng([PEOPLE_SEED, 100 + i])
        plan: list = []
        while sum(d for _, d in plan) < hours * 3600:
            plan += night_plan(rng, 4, 3600.0, sit_every=4, out_every=4, away_s=600.0,
                               spread=(0.33, 2.2))  # fmt: skip
        total, cut = 0.0, []
        for p, d in plan:  # the night ends after `hours`
            cut.append((p, min(d, hours * 3600 - total)))
            total += d
            if total >= hours * 3600:
                break
        person = Sleeper.random(10 + i, seed=PEOPLE_SEED)
        s = bed_session(person, cut, seed=50 + i, mat=bed_mat(), frame_s=frame_s)
        pressure = np.nan_to_num(Pipeline(cal, LAY).run(s.capacitance).frames)
        load = pressure.sum(axis=1) * 2.54**2
        predicted = model.predict(pressure).astype(object)
        predicted[load < 50.0] = None  # under 5 kg on the mat: nobody
        truth = s.truth.labels["side"].astype(object)
        truth[truth == "out"] = None
        out.append({"name": person.name, "t": s.truth.times, "truth": truth,
                    "predicted": predicted})  # fmt: skip
    return out


def schedule_of(t, sides, settle_s: float = 60.0) -> tuple[TurningSchedule, list]:
    sched = TurningSchedule(interval_min=120, settle_s=settle_s)
    events = [e for tt, sd in zip(t, sides, strict=True) for e in sched.step(sd, float(tt))]
    return sched, events


def nights_table(runs: list) -> None:
    print("\nNights: 4 people x 8 h, a frame every 10 s, the 2 h turning schedule on the model's "
          "sides and on the true sides (transition frames count as the side before)\n")  # fmt: skip
    print("| person | frames right (lying) | turns: true / found / matched within 3 min | "
          "time per side, largest error | turn-due alerts: true / found / matched within "
          "3 min |")  # fmt: skip
    print("|---|---:|---|---:|---|")
    for r in runs:
        truth = r["truth"].copy()
        for k in range(1, truth.size):  # a turn in progress still counts as the side before
            if truth[k] == "transition":
                truth[k] = truth[k - 1]
        lying = np.array([v is not None for v in truth])
        right = np.mean([a == b for a, b in zip(r["predicted"][lying], truth[lying],
                                                strict=True)])  # fmt: skip
        s_true, e_true = schedule_of(r["t"], truth)
        s_pred, e_pred = schedule_of(r["t"], r["predicted"])
        turns = [[e.t for e in ev if e.kind == "turn"] for ev in (e_true, e_pred)]
        extra = [
            f"{e.t / 3600:.2f} h {e.detail['from']} -> {e.detail['to']}"
            for e in e_pred
            if e.kind == "turn" and not any(abs(e.t - x) <= 180 for x in turns[0])
        ]
        missed = [
            f"{e.t / 3600:.2f} h {e.detail['from']} -> {e.detail['to']}"
            for e in e_true
            if e.kind == "turn" and not any(abs(e.t - x) <= 180 for x in turns[1])
        ]
        r["unmatched"] = (extra, missed)  # fmt: skip
        dues = [[e.t for e in ev if e.kind == "turn-due"] for ev in (e_true, e_pred)]

        def matched(a, b):
            return sum(any(abs(x - y) <= 180 for y in b) for x in a)

        sides = set(s_true.time_per_side) | set(s_pred.time_per_side)
        err = max(abs(s_true.time_per_side.get(k, 0) - s_pred.time_per_side.get(k, 0))
                  for k in sides) / 60  # fmt: skip
        r.update(turns=turns, dues=dues, truth_filled=truth)
        print(f"| {r['name']} | {right:.1%} | {len(turns[0])} / {len(turns[1])} / "
              f"{matched(turns[0], turns[1])} | {err:.1f} min | {len(dues[0])} / {len(dues[1])} / "
              f"{matched(dues[0], dues[1])} |")  # fmt: skip
    for r in runs:
        extra, missed = r["unmatched"]
        if extra or missed:
            print(f"\n{r['name']}: found but not true: {extra or 'none'}; true but not found: "
                  f"{missed or 'none'}")  # fmt: skip


def night_figure(r: dict) -> None:
    order = ["supine", "prone", "left", "right", "sitting"]
    fig, ax = plt.subplots(2, 1, figsize=(10, 4.6), sharex=True,
                           gridspec_kw={"height_ratios": [1.3, 1]})  # fmt: skip
    h = r["t"] / 3600
    for name, sides, dy in (("true", r["truth_filled"], 0.12), ("found", r["predicted"], -0.12)):
        y = np.array([order.index(v) + dy if v in order else np.nan for v in sides])
        ax[0].plot(h, y, ".", ms=2, label=name)
    ax[0].set_yticks(range(len(order)), order)
    ax[0].legend(loc="upper right", markerscale=5, fontsize=8)
    ax[0].set_title(f"{r['name']}: the side lying on, true and found by the model")
    sched = TurningSchedule(interval_min=120, settle_s=60)
    since = []
    for tt, sd in zip(r["t"], r["predicted"], strict=True):
        sched.step(sd, float(tt))
        st = sched.status(float(tt))
        since.append(np.nan if st["since_turn_s"] is None else st["since_turn_s"] / 60)
    ax[1].plot(h, since, color="#2764c5")
    ax[1].axhline(120, color="#c2410c", ls="--", lw=1)
    for t in r["dues"][1]:
        ax[1].axvline(t / 3600, color="#c2410c", lw=1.5)
    ax[1].set_ylabel("min since last turn")
    ax[1].set_xlabel("hours")
    ax[1].set_title("the turning schedule on the found sides: alert at 2 h (red lines)")
    fig.tight_layout()
    fig.savefig(IMG / "bed_night.png", dpi=110)
    plt.close(fig)


def pmd_check(model) -> dict:
    lay, frames, posture, main, subject, _ = pmd_reliable()
    pred = model.predict(frames)
    print(f"\nPMD, sim-to-real: the virtual bed's side model on all {len(main)} reliable real "
          "frames, unchanged (the maps are raw counts; the features are normalised)\n")  # fmt: skip
    print("| true class | frames | supine | left | right | prone | sitting |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for c in ("supine", "left", "right"):
        m = main == c
        cells = " | ".join(f"{np.mean(pred[m] == k):.1%}" for k in
                           ("supine", "left", "right", "prone", "sitting"))  # fmt: skip
        print(f"| {c} | {m.sum()} | {cells} |")
    lateral_true = main != "supine"
    lateral_pred = np.isin(pred, ["left", "right"])
    print(f"\nright class: {np.mean(pred == main):.1%}; supine vs on a side: "
          f"{np.mean(lateral_true == lateral_pred):.1%}")  # fmt: skip

    import csv

    with open(DATA / "pmd" / "experiment-i" / "subject-info-i.csv") as f:
        height = {f"S{row['Subject-Number']}": float(row["Height/cm"]) for row in csv.DictReader(f)}
    dist, proportion, found_all = {}, {}, []
    plain = np.isin(posture, [1])  # supine, flat bed, no variant
    for k in np.flatnonzero(plain):
        found = find_regions(frames[k], lay, "supine", threshold=0.0, unit="N/cm2")
        names = {"sacrum", "heel-l", "heel-r", "occiput"}
        found_all.append(names <= set(found))
        if names <= set(found):
            hx = np.mean([found["heel-l"].y_cm, found["heel-r"].y_cm])
            sacrum = found["sacrum"].y_cm
            dist.setdefault(subject[k], []).append(hx - sacrum)
            proportion.setdefault(subject[k], []).append(
                (hx - sacrum) / (sacrum - found["occiput"].y_cm)
            )
    subj = sorted(dist, key=lambda s: int(s[1:]))
    med = np.array([np.median(dist[s]) for s in subj])
    hts = np.array([height[s] for s in subj])
    r = float(np.corrcoef(med, hts)[0, 1])
    prop = np.array([np.median(proportion[s]) for s in subj])
    from texsense.sim.bed import prominences

    model = prominences("supine")
    model_prop = (np.mean([model["heel-l"][1], model["heel-r"][1]]) - model["sacrum"][1]) / (
        model["sacrum"][1] - model["occiput"][1])  # fmt: skip
    ratio = med / hts
    print(f"\nPMD regions on the {plain.sum()} reliable frames of posture file 1 (supine, flat): "
          f"occiput, sacrum and both heels found in {np.mean(found_all):.1%} of the frames; "
          f"heel-to-sacrum distance (median per person, 1 inch pitch assumed) against height: "
          f"r = {r:.2f} over {len(subj)} people, {ratio.mean():.3f} ± {ratio.std():.3f} of the "
          "height (the virtual body: 0.45)")  # fmt: skip
    print(f"\nWithout the pitch: (heel - sacrum) / (sacrum - occiput) along the mat, median per "
          f"person: {np.median(prop):.2f} (people from {prop.min():.2f} to {prop.max():.2f}); "
          f"the virtual body {model_prop:.2f}")  # fmt: skip
    return {"frames": frames, "posture": posture, "subject": subject, "layout": lay}


def regions_figure(pmd: dict) -> None:
    """A real PMD map and a virtual one of each side, with the regions found."""
    lay = pmd["layout"]
    pick = []
    for f, side in ((1, "supine"), (3, "left")):
        k = np.flatnonzero((pmd["subject"] == "S5") & (pmd["posture"] == f))
        pick.append((f"PMD S5, file {f} ({side}), real", pmd["frames"][k[len(k) // 2]], side,
                     "counts"))  # fmt: skip
    rng = np.random.default_rng(3)
    plan = [("supine", 40.0), ("left, foetal", 40.0), ("prone, head left", 40.0),
            ("sitting up", 40.0)]  # fmt: skip
    s = bed_session(Sleeper.random(2, seed=PEOPLE_SEED), plan, seed=int(rng.integers(99)),
                    mat=bed_mat())  # fmt: skip
    pressure = np.nan_to_num(Pipeline(bed_calibration(), LAY).run(s.capacitance).frames)
    for position, _ in plan:
        k = np.flatnonzero(s.truth.labels["position"] == position)[-1]
        pick.append((f"virtual: {position}", pressure[k] * 75.006, POSITIONS[position], "mmHg"))
    fig, axes = plt.subplots(1, len(pick), figsize=(2.3 * len(pick), 5.2))
    for ax, (title, frame, side, unit) in zip(axes, pick, strict=True):
        grid = lay.to_grid(frame, fill=0.0) if unit == "counts" else LAY.to_grid(frame, fill=0.0)
        im = ax.imshow(grid, cmap="viridis", vmin=0)
        regions = find_regions(frame if unit == "counts" else frame / 75.006,
                               lay if unit == "counts" else LAY, side,
                               threshold=0.0, unit="N/cm2")  # fmt: skip
        for r in regions.values():
            ax.add_patch(plt.Circle((r.x_cm / 2.54 - 0.5, r.y_cm / 2.54 - 0.5), 2.2,
                                    fill=False, color="#ef4444", lw=1.5))  # fmt: skip
            ax.text(r.x_cm / 2.54 + 2.2, r.y_cm / 2.54, r.name, color="white", fontsize=6)
        ax.set_title(title, fontsize=7)
        ax.set_xticks([])
        ax.set_yticks([])
        fig.colorbar(im, ax=ax, fraction=0.05, pad=0.02).ax.tick_params(labelsize=6)
        ax.set_xlabel(unit, fontsize=7)
    fig.tight_layout()
    fig.savefig(IMG / "bed_regions.png", dpi=110)
    plt.close(fig)


def main() -> None:
    t0 = time.perf_counter()
    cal = bed_calibration()
    regions_table(cal)
    print(f"\n({time.perf_counter() - t0:.0f} s)")
    model = train_virtual_bed_model()
    print(f"(side model trained: {time.perf_counter() - t0:.0f} s)")
    runs = nights(cal, model)
    nights_table(runs)
    night_figure(max(runs, key=lambda r: len(r["dues"][1])))  # one with a turn-due alert
    print(f"\n({time.perf_counter() - t0:.0f} s)")
    pmd = pmd_check(model)
    regions_figure(pmd)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
