"""Numbers that hold through a night (issue 37): drift corrected in use, and every value's bound.

1. **Nights.** For every spacer law (the bed's textile spacer ``textile-3mm``, ``bouc-wen-6mm``,
   ``iwan-6mm``) and seeds 0, 1, 2: ``texsense simulate night --spacer LAW --hours 8 --seed S``
   (a person lying still for long periods, turning, sitting up, out of bed once; the mat empty
   for the first 5 min; a frame every 10 s; elements failing at the thesis's rates), calibrated
   as the user would (zero, uniform 1 N/cm², the law's preset), processed three ways:
   hysteresis only (no drift stage), laboratory-only drift (the preset's drift stage,
   ``--in-use-drift off``) and in use (``process`` by default). Per hour: the mean relative
   error over measured elements whose true pressure is 10-150 mmHg (repaired elements are
   scored by the bounds, not here), and the total load's error (mean over occupied frames).
2. **Bounds on the nights** (``--interval 0.95``): coverage of the true value over every
   element and frame, over the elements at 10-150 mmHg, and the median half-width there.
3. **Bounds on records** of specimens the model was not fitted on (and, 3b, on the last quarter
   of a real elastomer record, ../shared/data/elastomer-stretch): the hysteresis model fitted on
   the preset specimen's calibration record with its first hour of cycles held out
   (``hysteresis fit --held-out``), applied with ``--interval 0.95`` to four hours of cycles of
   specimens 0-3 of each law: coverage, median half-width and RMSE.
4. **Cost** of the in-use estimator per frame at 4096 elements (64 x 64), against the
   pipeline's own time per frame (``Pipeline.step`` on the same stream, in the same run).
5. **Bounds by the families the scores came from** (``--skip`` without ``families``; in use,
   95 %): each night's bounds with the shipped score tables (seed-100 nights of the textile
   law and Iwan), with tables from its own family's seed-100 night only, and from the other
   two families' only (its family never used for its scores). The families: the textile law
   (``textile-3mm`` and the foams), Iwan, Bouc–Wen.

``--calibrate`` makes the conformal scores of :data:`texsense.compensation.intervals.SCORES`
(pooled) and ``BAND_SCORES`` (the mat's, per band of the value) instead, on data the tables
above do not judge: nights of seed 100 of the ``--laws`` given (``textile-3mm iwan-6mm``; no
``bouc-wen-6mm`` night of seed 100 was simulated) and records of specimens 12 and 13; it prints
the dictionaries to paste into ``intervals.py``.

Nights are simulated once into ``--cache`` (default ``~/.cache/texsense/nights``): an 8-h night
takes 1-4 min on the shared 2-core machine (textile 52 s, Bouc–Wen 71 s, Iwan 161 s wall at a
load average of 3-8), and processing it three ways about 20 s.

Run:  .venv/bin/python benchmarks/night_drift.py [--seeds 0 1 2] [--laws ...] [--cache DIR]
      .venv/bin/python benchmarks/night_drift.py --calibrate --laws textile-3mm iwan-6mm
      .venv/bin/python benchmarks/night_drift.py --skip nights records real cost --laws ...
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from texsense import Layout
from texsense.calibration.night import night_calibration
from texsense.calibration.workflows import PRESET_SPECIMEN, material_record
from texsense.compensation import intervals
from texsense.compensation.hysteresis import HysteresisModel
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import StageChain, load_chain
from texsense.io import load, save
from texsense.sim import protocols
from texsense.sim.night import virtual_night

LAWS = ("textile-3mm", "bouc-wen-6mm", "iwan-6mm")
#: spacers no night of which was run while the in-use estimator or its bounds were developed
#: (the textile law with a foam's parameters): ``--laws foam-9mm foam-13mm``
UNSEEN = ("foam-9mm", "foam-13mm", "foam-7mm")
RECORD_LAWS = ("textile-6mm", "bouc-wen-6mm", "iwan-6mm")
MMHG = 75.006
BAND = (10 / MMHG, 150 / MMHG)
#: A band of the value needs this many calibration scores for its own multiplier.
MIN_BAND = 200
METHODS = {
    "hysteresis only": dict(drift=False),
    "laboratory drift": dict(in_use=False),
    "in use": dict(in_use=True),
}


def night_files(
    law: str, seed: int, hours: float, cache: Path
) -> tuple[object, object, StageChain]:
    """The raw night, its truth and the mat's calibration (simulated once into ``cache``)."""
    cache.mkdir(parents=True, exist_ok=True)
    raw_p = cache / f"n-{law}-{hours:g}-{seed}-raw.h5"
    truth_p = cache / f"n-{law}-{hours:g}-{seed}-truth.h5"
    cal_p = cache / f"cal-{law}.json"
    if not cal_p.exists():
        night_calibration(law).save(cal_p)
    if not (raw_p.exists() and truth_p.exists()):
        n = virtual_night(law, hours, seed)
        save(n.raw, raw_p)
        save(n.truth, truth_p)
    return load(raw_p), load(truth_p), load_chain(cal_p)


def process(chain: StageChain, raw: object, level: float | None, **opts: object) -> tuple:
    """The pipeline's output (values, measured mask, bounds) and the in-use status."""
    pipe = Pipeline(chain, raw.layout, interval=level if opts.get("drift", True) else None, **opts)
    values, ok, _ = pipe.process(raw.frames, raw.times, raw.valid)
    return values, ok, pipe.bounds_, pipe.in_use_status()


def scores(
    chain: StageChain, raw: object, truth: np.ndarray, **opts: object
) -> tuple[np.ndarray, np.ndarray]:
    """|y - v| / σ of every element-frame (the multiplier set to 1 gives σ), and the band of
    its value ``v`` (:func:`texsense.compensation.intervals.band_of`)."""
    pipe = Pipeline(chain, raw.layout, interval=0.95, **opts)
    pipe.interval_multiplier = 1.0
    values, _, _ = pipe.process(raw.frames, raw.times, raw.valid)
    _, hi = pipe.bounds_
    sigma = np.maximum(hi - values, 1e-12)
    return (np.abs(truth - values) / sigma).ravel(), intervals.band_of(values).ravel()


def hourly(
    values: np.ndarray,
    ok: np.ndarray,
    truth: np.ndarray,
    times: np.ndarray,
    area: np.ndarray,
    hours: int,
) -> tuple[list[float], list[float]]:
    """Per hour: mean relative error of measured elements at 10-150 mmHg, and the total load's
    mean relative error over occupied frames."""
    hour = ((times - times[0]) // 3600).astype(int)
    band = (truth >= BAND[0]) & (truth <= BAND[1]) & ok
    rel = np.abs(values - truth) / np.where(truth > 0, truth, 1.0)
    load_v, load_t = np.nan_to_num(values) @ area, truth @ area
    occupied = load_t > 0.5 * np.median(load_t[load_t > 0])
    err, lerr = [], []
    for h in range(hours):
        m = (hour == h)[:, None] & band
        err.append(float(rel[m].mean()) if m.any() else float("nan"))
        f = (hour == h) & occupied
        lerr.append(
            float(np.mean(np.abs(load_v[f] - load_t[f]) / load_t[f])) if f.any() else float("nan")
        )
    return err, lerr


def nights_table(laws: list[str], seeds: list[int], hours: float, cache: Path) -> None:
    """Tables 1 and 2."""
    n_h = round(hours)
    cols = " | ".join(f"hour {h + 1}" for h in range(n_h))
    print(f"\n## Nights ({hours:g} h): per-element mean relative error at 10-150 mmHg, by hour\n")
    print(f"| law | seed | drift | {cols} | max of hours | total load, worst hour |")
    print("|---|---:|---|" + "---:|" * (n_h + 2))
    cover_rows = []
    summary: dict[tuple[str, str], list[float]] = {}
    for law in laws:
        for seed in seeds:
            t0 = time.time()
            raw, truth_rec, chain = night_files(law, seed, hours, cache)
            truth = truth_rec.frames.astype(np.float64)
            area = np.asarray(raw.layout.area_cm2)
            for name, opts in METHODS.items():
                v, ok, bnd, status = process(chain, raw, 0.95, **opts)
                err, lerr = hourly(v, ok, truth, raw.times, area, n_h)
                summary.setdefault((law, name), []).append(max(err))
                print(
                    f"| {law} | {seed} | {name} | "
                    + " | ".join(f"{100 * e:.1f}%" for e in err)
                    + f" | {100 * max(err):.1f}% | {100 * max(lerr):.1f}% |",
                    flush=True,
                )
                if bnd is not None:
                    lo, hi = bnd
                    inside = (truth >= lo) & (truth <= hi)
                    band = (truth >= BAND[0]) & (truth <= BAND[1])
                    hw = 0.5 * (hi - lo)[band] * MMHG
                    rmse = float(np.sqrt(np.mean((v - truth)[band] ** 2))) * MMHG
                    cover_rows.append(
                        (
                            law,
                            seed,
                            name,
                            inside.mean(),
                            inside[band].mean(),
                            float(np.median(hw)),
                            rmse,
                        )
                    )
                if name == "in use":
                    print(f"|  |  | in-use state at the end: {status} |" + " |" * (n_h + 1))
            print(f"(night {law} seed {seed}: {time.time() - t0:.0f} s)", file=sys.stderr)
    print("\n## Bounds on the nights (95 %)\n")
    print(
        "| law | seed | drift | coverage, all element-frames | coverage at 10-150 mmHg | "
        "median half-width at 10-150 mmHg | RMSE at 10-150 mmHg | half-width / RMSE |"
    )
    print("|---|---:|---|---:|---:|---:|---:|---:|")
    for law, seed, name, c_all, c_band, hw, rmse in cover_rows:
        print(
            f"| {law} | {seed} | {name} | {100 * c_all:.1f}% | {100 * c_band:.1f}% | "
            f"{hw:.1f} mmHg | {rmse:.1f} mmHg | {hw / rmse:.2f} |"
        )


def held_out_model(law: str, seed: int = PRESET_SPECIMEN) -> HysteresisModel:
    """The hysteresis model of a preset specimen with its first hour of cycles held out (what
    ``hysteresis fit calib.csv --held-out cycles.csv`` makes)."""
    m = material_record(protocols.run_protocol("calibration", law, seed=seed, sample_hz=None))
    model = HysteresisModel().fit(m["compression_mm"], m["pressure_ncm2"])
    cyc = protocols.run_protocol("validation", law, seed=seed, sample_hz=10, cycles=60)
    model.hold_out(cyc.labels["compression_mm"], cyc.labels["pressure_ncm2"], "first hour")
    return model


def record_bounds(model: HysteresisModel, law: str, seed: int, multiplier: float | None) -> tuple:
    """Four hours of cycles of specimen ``seed``: (truth, value, lower, upper)."""
    from texsense.commands.hysteresis import _apply_bounds

    rec = protocols.run_protocol("validation", law, seed=seed, sample_hz=1, cycles=240)
    u, y = rec.labels["compression_mm"], rec.labels["pressure_ncm2"]
    v = model.predict(u)
    saved, saved_bands = dict(intervals.SCORES), dict(intervals.BAND_SCORES)
    if multiplier is not None:  # σ itself: a flat score table at the multiplier
        intervals.SCORES["record"] = tuple([multiplier] * 101)
        intervals.BAND_SCORES.pop("record", None)
    try:
        lo, hi = _apply_bounds(model, None, u, v, rec.times, 0.95)
    finally:
        intervals.SCORES.clear()
        intervals.SCORES.update(saved)
        intervals.BAND_SCORES.clear()
        intervals.BAND_SCORES.update(saved_bands)
    return y, v, lo, hi


def records_table(laws: tuple[str, ...]) -> None:
    """Table 3."""
    print("\n## Bounds on records of specimens the model was not fitted on (95 %)\n")
    print("| law | specimen | coverage | median half-width | RMSE | half-width / RMSE |")
    print("|---|---:|---:|---:|---:|---:|")
    for law in laws:
        model = held_out_model(law)
        for seed in range(4):
            y, v, lo, hi = record_bounds(model, law, seed, None)
            inside = (y >= lo) & (y <= hi)
            hw = float(np.median(0.5 * (hi - lo)))
            rmse = float(np.sqrt(np.mean((v - y) ** 2)))
            print(
                f"| {law} | {seed} | {100 * inside.mean():.1f}% | {hw:.3f} N/cm² | "
                f"{rmse:.3f} N/cm² | {hw / rmse:.2f} |",
                flush=True,
            )


def real_record_table() -> None:
    """Table 3b: a real record (../shared/data/elastomer-stretch, the random sawtooth of a
    conductive elastomer on a test rig: stretch -> force, N): the hysteresis model fitted on its
    first half, the third quarter held out, the bounds judged on the last quarter."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _realdata import elastomer_sawtooth
    from texsense.commands.hysteresis import _apply_bounds

    t, d, f = elastomer_sawtooth()
    u = -d  # stretch
    a, b = t.size // 2, (3 * t.size) // 4
    model = HysteresisModel().fit(u[:a], f[:a])
    model.hold_out(u[a:b], f[a:b], "third quarter")
    v = np.asarray(model.predict(u[b:]), dtype=np.float64)
    lo, hi = _apply_bounds(model, None, u[b:], v, t[b:], 0.95)
    y = f[b:]
    inside = (y >= lo) & (y <= hi)
    hw = float(np.median(0.5 * (hi - lo)))
    rmse = float(np.sqrt(np.mean((v - y) ** 2)))
    print("\n## Bounds on a real record (95 %): elastomer-stretch random sawtooth, last quarter\n")
    print("| record | samples judged | coverage | median half-width | RMSE | half-width / RMSE |")
    print("|---|---:|---:|---:|---:|---:|")
    print(
        f"| 2_7-5_4Epin_rand_sawtooth.csv | {y.size} | {100 * inside.mean():.1f}% | "
        f"{hw:.3f} N | {rmse:.3f} N | {hw / rmse:.2f} |"
    )


def cost_table() -> None:
    """Table 4: the estimator's time per frame against the pipeline's, 64 x 64 elements."""
    from texsense.calibration.workflows import seat_calibration
    from texsense.compensation.stages import Convert

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from pipeline_speed import mat_chain

    n, frames = 4096, 400
    rng = np.random.default_rng(0)
    chain = mat_chain(seat_calibration(), n, rng)
    conv = chain["convert"]
    assert isinstance(conv, Convert)
    lay = Layout.grid(64, 64)
    # a still person's map with reading noise: what the estimator works on most of the time
    base = np.interp(
        np.clip(rng.normal(0.4, 0.3, n), 0, 1.5),
        [0, 1.5],
        [float(conv.curve_capacitance_pF_[0]), float(conv.curve_capacitance_pF_[-1])],
    )
    cap = base[None, :] + rng.normal(0, 0.002, (frames, n))
    times = np.arange(frames) * 1.0
    out = {}
    for name, in_use in (("pipeline", False), ("pipeline + in-use", True)):
        best = np.inf
        for _ in range(3):
            pipe = Pipeline(chain, lay, in_use=in_use)
            t0 = time.perf_counter()
            for k in range(frames):
                pipe.step(cap[k], None, float(times[k]))
            best = min(best, (time.perf_counter() - t0) / frames)
        out[name] = best
    extra = out["pipeline + in-use"] - out["pipeline"]
    print("\n## Cost per frame, 4096 elements (Pipeline.step, best of 3, shared 2-core machine)\n")
    print("| pipeline | pipeline + in-use estimator | estimator's share |")
    print("|---:|---:|---:|")
    print(
        f"| {1e6 * out['pipeline']:.0f} µs | {1e6 * out['pipeline + in-use']:.0f} µs | "
        f"{100 * extra / out['pipeline']:.1f} % |"
    )


def mat_scores(law: str, hours: float, cache: Path) -> Path:
    """The scores of the seed-100 night of ``law`` (in use and laboratory-only), kept in
    ``cache``."""
    part = cache / f"scores-mat-{law}.npz"
    if not part.exists():
        raw, truth_rec, chain = night_files(law, 100, hours, cache)
        truth = truth_rec.frames.astype(np.float64)
        both = [scores(chain, raw, truth, in_use=flag) for flag in (False, True)]
        np.savez(
            part,
            score=np.concatenate([b[0] for b in both]).astype(np.float32),
            band=np.concatenate([b[1] for b in both]).astype(np.int8),
        )
    print(f"scores of the {law} night: done", file=sys.stderr, flush=True)
    return part


def band_tables(s: np.ndarray, b: np.ndarray) -> tuple[tuple, tuple]:
    """The pooled quantiles (0-100 %) and those per band (50-100 %; None below ``MIN_BAND``
    scores)."""
    per_band = tuple(
        intervals.conformal_quantiles(s[b == k], range(50, 101)) if np.sum(b == k) >= MIN_BAND
        else None
        for k in range(len(intervals.BAND_EDGES))
    )  # fmt: skip
    return intervals.conformal_quantiles(s, range(101)), per_band


#: The law family of every night's spacer (the foams are the textile law with other parameters).
FAMILY = {
    "textile-3mm": "textile law",
    "foam-9mm": "textile law",
    "foam-13mm": "textile law",
    "foam-7mm": "textile law",
    "iwan-6mm": "Iwan",
    "bouc-wen-6mm": "Bouc-Wen",
}
#: The calibration night (seed 100) of every family.
FAMILY_NIGHT = {"textile law": "textile-3mm", "Iwan": "iwan-6mm", "Bouc-Wen": "bouc-wen-6mm"}


def family_table(laws: list[str], seeds: list[int], hours: float, cache: Path) -> None:
    """Table 4: the bounds in use with score tables made from the seed-100 nights of chosen
    families: the shipped one (textile and Iwan), the night's own family only, and the other
    two families only (the night's family never used for its scores)."""
    parts = {f: np.load(mat_scores(law, hours, cache)) for f, law in FAMILY_NIGHT.items()}

    def tables(fams: list[str]) -> tuple[tuple, tuple]:
        return band_tables(
            np.concatenate([parts[f]["score"] for f in fams]),
            np.concatenate([parts[f]["band"] for f in fams]),
        )

    print("\n## Bounds in use (95 %) by the families the scores came from\n")
    print(
        "| law | seed | scores from | coverage, all element-frames | coverage at 10-150 mmHg | "
        "median half-width at 10-150 mmHg | half-width / RMSE |"
    )
    print("|---|---:|---|---:|---:|---:|---:|")
    saved, saved_bands = dict(intervals.SCORES), dict(intervals.BAND_SCORES)
    try:
        for law in laws:
            fam = FAMILY[law]
            others = [f for f in FAMILY_NIGHT if f != fam]
            variants = {
                "shipped (textile law, Iwan)": (saved["mat"], saved_bands["mat"]),
                f"own family ({fam})": tables([fam]),
                f"other families ({', '.join(others)})": tables(others),
            }
            for seed in seeds:
                raw, truth_rec, chain = night_files(law, seed, hours, cache)
                truth = truth_rec.frames.astype(np.float64)
                band = (truth >= BAND[0]) & (truth <= BAND[1])
                for name, (pooled, per_band) in variants.items():
                    intervals.SCORES["mat"], intervals.BAND_SCORES["mat"] = pooled, per_band
                    v, _, (lo, hi), _ = process(chain, raw, 0.95, in_use=True)
                    inside = (truth >= lo) & (truth <= hi)
                    hw = float(np.median(0.5 * (hi - lo)[band])) * MMHG
                    rmse = float(np.sqrt(np.mean((v - truth)[band] ** 2))) * MMHG
                    print(
                        f"| {law} | {seed} | {name} | {100 * inside.mean():.1f}% | "
                        f"{100 * inside[band].mean():.1f}% | {hw:.1f} mmHg | {hw / rmse:.2f} |",
                        flush=True,
                    )
    finally:
        intervals.SCORES.update(saved)
        intervals.BAND_SCORES.update(saved_bands)


def calibrate(cache: Path, hours: float, laws: list[str]) -> None:
    """The conformal score tables on data the benchmark does not judge (each part's scores
    kept in ``cache``, so that a part simulated later adds to the others): pooled, and per band
    of the value (a band with fewer than ``MIN_BAND`` scores takes the pooled table)."""
    for law in laws:
        mat_scores(law, hours, cache)
    for law in RECORD_LAWS:
        part = cache / f"scores-record-{law}.npz"
        if not part.exists():
            model = held_out_model(law)
            rec, band = [], []
            for seed in (12, 13):
                y, v, _, hi = record_bounds(model, law, seed, 1.0)
                rec.append(np.abs(y - v) / np.maximum(hi - v, 1e-12))
                band.append(intervals.band_of(v))
            np.savez(part, score=np.concatenate(rec), band=np.concatenate(band).astype(np.int8))
    pooled, per_band = {}, {}
    for name, files in (
        ("mat", [cache / f"scores-mat-{law}.npz" for law in laws]),
        ("record", [cache / f"scores-record-{law}.npz" for law in RECORD_LAWS]),
    ):
        missing = [f.name for f in files if not f.exists()]
        if missing:
            print(f"{name}: missing {', '.join(missing)}: not printed", file=sys.stderr)
            continue
        parts = [np.load(f) for f in files]
        s = np.concatenate([p["score"] for p in parts])
        b = np.concatenate([p["band"] for p in parts])
        pooled[name], bands = band_tables(s, b)
        if name != "record":  # records: pooled only (intervals.BAND_SCORES)
            per_band[name] = bands
    print("SCORES: dict[str, tuple[float, ...]] = {")
    for name, q in pooled.items():
        print(f'    "{name}": {q},')
    print("}")
    print("BAND_SCORES: dict[str, tuple[tuple[float, ...] | None, ...]] = {")
    for name, q in per_band.items():
        print(f'    "{name}": {q},')
    print("}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--laws", nargs="+", default=list(LAWS), choices=LAWS + UNSEEN)
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--hours", type=float, default=8.0)
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "texsense" / "nights")
    ap.add_argument("--calibrate", action="store_true", help="make the score tables (seed 100)")
    ap.add_argument(
        "--skip", nargs="*", default=["families"],
        choices=("nights", "records", "real", "cost", "families"),
    )  # fmt: skip
    args = ap.parse_args()
    if args.calibrate:
        calibrate(args.cache, args.hours, args.laws)
        return 0
    if "nights" not in args.skip:
        nights_table(args.laws, args.seeds, args.hours, args.cache)
    if "records" not in args.skip:
        records_table(RECORD_LAWS)
    if "real" not in args.skip:
        real_record_table()
    if "cost" not in args.skip:
        cost_table()
    if "families" not in args.skip:
        family_table(args.laws, args.seeds, args.hours, args.cache)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
