"""Speed of the compiled pipeline against the physical yardstick of this machine: the rate at
which it copies the same array (``np.multiply(x, 1.0, out=y)``), measured in the same run,
on the scalar kernels and on their SIMD paths (issue 34; ``texsense._core.set_simd_path``).
The yardstick is the faster of the copy on one core and the copy on all cores (one thread per
core, each copying its own rows): rows that run on all cores are held to what all cores copy,
and on a machine whose copy is bound by memory both give about the same rate.

Run:  .venv/bin/python benchmarks/pipeline_speed.py [--repeat N] [--clock wall|cpu] [--quick]
      [--paths avx512]

- Preisach batch: the Rust ``PreisachBank`` behind ``HysteresisModel.predict`` on a
  4000 x 4096 random walk (one thread, frame order; one thread, element blocks; all threads),
  writing into an array allocated beforehand as the copy does, and ``predict`` itself (which
  allocates its output);
- the whole pipeline (detect -> convert -> Preisach + drift -> eq. 6.14 repair) at 96, 1024 and
  4096 elements with 2 % failed readings (``run`` on the recording: float32 in and out since
  issue 34's eleventh round), and at 4096 elements as before that round (``process``: the
  frames copied to float64, the values back to float32);
- ``Pipeline.step`` latency on a real stream (every frame different), median and p99, and
  its compiled part alone (``Chain.step`` into arrays held); and the
  step's median on the wall clock (``perf_counter``), measured in the same run;
- the state kept per element;
- the experimental float32 Preisach bank (``PreisachBank32``, eight lanes on AVX2; issue 34,
  seventh round) on the same walk, and its largest difference from the float64 bank.

Every path runs on both kernel paths, scalar and SIMD, back to back; the whole set is
repeated ``--repeat`` times (each repetition measures the copy rate anew) and the table gives
the medians over the repetitions. The machine is shared and noisy: every rate is also given as
a share of the copy rate of its repetition, which is what the targets of issues 19 and 34 are
stated in. Both paths give the same numbers bit for bit (tests/test_simd.py).
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from itertools import pairwise

import numpy as np

from texsense import Layout, Recording, _core
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import Convert, StageChain

CLOCK = time.perf_counter


def timed(fn: Callable[[], object], repeat: int = 3) -> float:
    """The shortest of ``repeat`` runs of ``fn`` on the chosen clock (s)."""
    best = float("inf")
    for _ in range(repeat):
        start = CLOCK()
        fn()
        best = min(best, CLOCK() - start)
    return best


def copy_rate(shape: tuple[int, int], threads: int = 1) -> float:
    """Element-samples per second of the copy on ``threads`` threads, each copying its own
    rows (numpy's ufuncs release the GIL, so the threads run at once)."""
    x = np.random.default_rng(0).random(shape)
    y = np.empty_like(x)
    if threads == 1:
        return x.size / timed(lambda: np.multiply(x, 1.0, out=y), repeat=7)
    bounds = np.linspace(0, shape[0], threads + 1).astype(int)
    parts = list(pairwise(bounds))
    with ThreadPoolExecutor(threads) as pool:

        def copy() -> None:
            jobs = [pool.submit(np.multiply, x[a:b], 1.0, out=y[a:b]) for a, b in parts]
            for j in jobs:
                j.result()

        return x.size / timed(copy, repeat=7)


def random_walk(model: object, frames: int, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = model.u_min_, model.u_max_
    w = np.abs(np.cumsum(rng.normal(0, 0.02, (frames, n)), axis=0)) % (2 * (hi - lo))
    return lo + np.where(w > hi - lo, 2 * (hi - lo) - w, w)


def mat_chain(cal: StageChain, n: int, rng: np.random.Generator) -> StageChain:
    """A mat of n elements with the seat's material curve and spacer stages and its own
    offsets and gains (no detect stage: the pipeline's detector is the conversion's expected
    range)."""
    seat = cal["convert"]
    convert = Convert(3.0).set_fitted(
        curve_compression_mm=seat.curve_compression_mm_,
        curve_capacitance_pF=seat.curve_capacitance_pF_,
        offset_pF=rng.normal(0, 0.05, n),
        gain=rng.normal(1, 0.03, n),
    )
    return StageChain([convert, *cal.without("detect", "convert").stages])


def mat_case(cal: StageChain, rows: int, cols: int, frames: int, seed: int = 1):
    """:func:`mat_chain` of rows x cols elements and a recording of it with 2 % of the
    readings failed."""
    rng = np.random.default_rng(seed)
    n = rows * cols
    lay = Layout.grid(rows, cols, pitch_cm=1.0)
    c = mat_chain(cal, n, rng)
    convert = c["convert"]
    t = np.arange(frames) * 0.1
    e = 1.2 + 0.8 * np.sin(t[:, None] / 3 + np.arange(n)[None, :] / 50)
    e += rng.normal(0, 0.01, e.shape)
    curve = np.interp(e, convert.curve_compression_mm_, convert.curve_capacitance_pF_)
    cap = convert.offset_pF_ + convert.gain_ * curve
    valid = rng.random((frames, n)) > 0.02
    cap = np.where(valid, cap, 0.0)  # a failed reading reads ~0 pF (short/break)
    return c, lay, Recording(cap, t, lay, "capacitance", "pF")


def median_row(values: list[float]) -> float:
    return float(np.median(values))


def step_latency(
    pipe: Pipeline, cap: np.ndarray, times: np.ndarray, clock: Callable[[], float] | None = None
) -> np.ndarray:
    """Each ``Pipeline.step``'s time on ``clock`` (default: the chosen one), the first 100
    frames left out."""
    clock = clock or CLOCK
    pipe.reset()
    lat = np.empty(len(cap))
    for k in range(len(cap)):
        s = clock()
        pipe.step(cap[k], None, float(times[k]))
        lat[k] = clock() - s
    return lat[100:]


def chain_latency(pipe: Pipeline, cap: np.ndarray, dt: float) -> np.ndarray:
    """The compiled part of a step alone: ``Chain.step`` into arrays held (what
    ``Pipeline.step`` calls, without its checks and copies)."""
    chain = pipe.compiled()
    chain.reset()
    n = cap.shape[1]
    held = np.empty(n), np.empty(n, np.uint8), np.empty(n, bool)
    lat = np.empty(len(cap))
    for k in range(len(cap)):
        s = CLOCK()
        chain.step(dt, cap[k], None, *held)
        lat[k] = CLOCK() - s
    return lat[100:]


def f32_bank(model: object, n: int) -> _core.PreisachBank32:
    """The experimental float32 bank (eight lanes on AVX2) of the model."""
    table = np.ascontiguousarray(model.everett_, dtype=np.float64)
    return _core.PreisachBank32(model.u_min_, model.u_max_, table, n, model.offset_, model.sign_)


def f32_difference(model: object, walk: np.ndarray) -> tuple[float, float]:
    """Largest |float32 bank - float64 bank| on the walk (N/cm²), and the largest relative
    difference where the float64 output exceeds 0.1 N/cm²."""
    ok = np.ones(walk.shape, bool)
    y64 = model.bank(walk.shape[1]).run(walk, ok)
    y32 = f32_bank(model, walk.shape[1]).run(walk, ok)
    d = np.abs(y32 - y64)
    big = np.abs(y64) > 0.1
    return float(d.max()), float((d[big] / np.abs(y64[big])).max())


def cases(
    cal: StageChain, frames: int, walk: np.ndarray
) -> list[tuple[str, Callable[[], object], int]]:
    """(label, run, element-samples) of every batch path."""
    model = cal["hysteresis"].model_
    bank = model.bank(walk.shape[1])  # the Rust PreisachBank behind predict
    ok = np.ones(walk.shape, bool)
    # the kernel rows write into one array allocated beforehand, as the copy does (a new
    # array of 131 MB costs its page faults on first write; `predict` allocates)
    into = np.empty_like(walk)
    out: list[tuple[str, Callable[[], object], int]] = []
    for label, schedule in (
        ("one thread, frame after frame", "frames"),
        ("one thread, blocks of 512 elements through all frames", "blocks"),
        ("blocks in parallel (all cores)", "parallel"),
    ):
        out.append(
            (
                f"Preisach kernel, {label}",
                lambda s=schedule: (bank.reset(), bank.run(walk, ok, schedule=s, out=into)),
                walk.size,
            )
        )
    bank32 = f32_bank(model, walk.shape[1])
    out.append(
        (
            "Preisach kernel in float32 (experimental `PreisachBank32`), one thread, frame "
            "after frame",
            lambda: (bank32.reset(), bank32.run(walk, ok, out=into)),
            walk.size,
        )
    )
    out.append(("Preisach `HysteresisModel.predict`", lambda: model.predict(walk), walk.size))
    for rows, cols in ((8, 12), (32, 32), (64, 64)):
        n = rows * cols
        nf = max(200, min(frames, 4_000_000 // n))
        c, lay, rec = mat_case(cal, rows, cols, nf)
        pipe = Pipeline(c, lay, repair="neighbour-mean")
        out.append(
            (
                f"pipeline `run`, {n} elements x {nf} frames",
                lambda pipe=pipe, rec=rec: pipe.reset().run(rec),
                rec.frames.size,
            )
        )
    out.append(
        (
            f"pipeline through float64 (`process`, values to float32), {n} elements x {nf} frames",
            lambda pipe=pipe, rec=rec: (
                pipe.reset().process(rec.frames, rec.times, rec.valid)[0].astype(np.float32)
            ),
            rec.frames.size,
        )
    )
    return out


# the ratios beside the scalar one: AVX-512 against AVX2, and one lookup of the AVX-512
# kernels against the other
LOOKUP_PAIRS = [("avx2", "avx512"), ("avx512-gather", "avx512-loads"), ("avx512-gather", "avx512")]


def use_path(p: str) -> None:
    """Run the kernels on path ``p`` from now on (``avx512-gather``: AVX-512 with the
    gathers of table cells; ``avx512-loads``: with loads per lane; ``avx512``: the
    processor's lookup)."""
    path, _, lookup = p.partition("-")
    _core.set_simd_path(path)
    _core.set_simd_lookup(lookup or "auto")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="smaller sizes (a smoke test)")
    ap.add_argument("--repeat", type=int, default=3, help="repetitions of the whole set")
    ap.add_argument(
        "--clock",
        choices=("wall", "cpu"),
        default="wall",
        help="cpu: this process's CPU time (on a loaded machine, where time slices of other "
        "processes fall into wall-clock timings; rows on several threads then give the rate "
        "per core)",
    )
    ap.add_argument(
        "--paths",
        default="",
        help="comma-separated kernel paths to time (scalar, avx2, avx512; default: every path "
        "this processor has), e.g. avx512 for a short run; on an AVX-512 processor also "
        "avx512-gather and avx512-loads (the AVX-512 kernels with that lookup of table "
        "cells; avx512 is the processor's own)",
    )
    args = ap.parse_args()
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    frames = 400 if args.quick else 4000
    _, best = _core.simd_path()
    paths = ["scalar", "avx2", "avx512"][: ["scalar", "avx2", "avx512"].index(best) + 1]
    if args.paths:
        lookups = ["avx512-gather", "avx512-loads"] if best == "avx512" else []
        asked = args.paths.split(",")
        unknown = [p for p in asked if p not in paths + lookups]
        if unknown:
            ap.error(
                f"--paths {','.join(unknown)}: this processor has {', '.join(paths + lookups)}"
            )
        paths = [p for p in paths + lookups if p in asked]
    cal = seat_calibration(mat_seed=5)
    walk = random_walk(cal["hysteresis"].model_, frames, 4096)
    batch = cases(cal, frames, walk)
    c, lay, rec = mat_case(cal, 32, 32, 2000, seed=3)
    step_pipe = Pipeline(c, lay, repair="neighbour-mean")
    cap = np.ascontiguousarray(rec.frames, dtype=np.float64)
    copies: list[float] = []
    # the threads the kernels' pool has (rayon's default: the processors this process may use)
    threads = int(os.environ.get("RAYON_NUM_THREADS") or len(os.sched_getaffinity(0)))
    one_core: list[float] = []
    all_cores: list[float] = []
    rates: dict[tuple[str, str], list[float]] = {
        (label, p): [] for label, _, _ in batch for p in paths
    }
    shares: dict[tuple[str, str], list[float]] = {
        (label, p): [] for label, _, _ in batch for p in paths
    }
    lat_med: dict[str, list[float]] = {p: [] for p in paths}
    lat_p99: dict[str, list[float]] = {p: [] for p in paths}
    lat_chain: dict[str, list[float]] = {p: [] for p in paths}
    lat_wall: dict[str, list[float]] = {p: [] for p in paths}
    try:
        for _ in range(args.repeat):
            # the yardstick: the faster of the copy on one core and on all cores (on a
            # machine whose copy is bound by memory, both cores copy no faster than one)
            one_core.append(copy_rate(walk.shape))
            all_cores.append(copy_rate(walk.shape, threads) if threads > 1 else one_core[-1])
            copy = max(one_core[-1], all_cores[-1])
            copies.append(copy)
            for label, run, size in batch:
                for p in paths:
                    use_path(p)
                    t = timed(run)
                    rates[label, p].append(size / t)
                    shares[label, p].append(size / t / copy)
            for p in paths:
                use_path(p)
                lat = step_latency(step_pipe, cap, rec.times)
                lat_med[p].append(float(np.median(lat)))
                lat_p99[p].append(float(np.percentile(lat, 99)))
                dt = float(rec.times[1] - rec.times[0])
                lat_chain[p].append(float(np.median(chain_latency(step_pipe, cap, dt))))
                wall = step_latency(step_pipe, cap, rec.times, time.perf_counter)
                lat_wall[p].append(float(np.median(wall)))
    finally:
        _core.set_simd(True)
        _core.set_simd_lookup("auto")
    all_vs_one = [b / a for a, b in zip(one_core, all_cores, strict=True)]
    print(
        f"copy rate of a ({frames}, 4096) float64 array: {median_row(copies) / 1e6:.0f} M "
        f"element-samples/s (median of {args.repeat}, {args.clock} clock; the faster of one "
        f"core, {median_row(one_core) / 1e6:.0f} M/s, and all {threads} cores, "
        f"{median_row(all_cores) / 1e6:.0f} M/s: {median_row(all_vs_one):.2f} x); "
        f"SIMD path of this processor: {best}"
    )
    print()
    head = " | ".join(f"{p}: rate | {p}: share of the copy rate" for p in paths)
    pairs = [("scalar", p) for p in paths[1:] if "scalar" in paths]
    pairs += [(a, b) for a, b in LOOKUP_PAIRS if a in paths and b in paths]
    ratios = "".join(f" {b} / {a} |" for a, b in pairs)
    print(f"| path | {head} |{ratios}")
    print("|---|" + "---:|---:|" * len(paths) + "---:|" * len(pairs))
    for label, _, _ in batch:
        cells = " | ".join(
            f"{median_row(rates[label, p]) / 1e6:.1f} M/s | "
            f"{100 * median_row(shares[label, p]):.2f} %"
            for p in paths
        )
        ratio = ""
        for a, b in pairs:
            r = [y / x for x, y in zip(rates[label, a], rates[label, b], strict=True)]
            ratio += f" {median_row(r):.2f} x |"
        print(f"| {label} | {cells} |{ratio}")
    print()
    print(
        f"| `Pipeline.step`, 1024 elements, changing frames | median ({args.clock} clock) "
        f"| p99 ({args.clock}) | its compiled part (`Chain.step`), median ({args.clock}) "
        "| median (wall clock, `perf_counter`, same run) |"
    )
    print("|---|---:|---:|---:|---:|")
    for p in paths:
        med, p99 = median_row(lat_med[p]) * 1e6, median_row(lat_p99[p]) * 1e6
        chain, wall = median_row(lat_chain[p]) * 1e6, median_row(lat_wall[p]) * 1e6
        print(f"| {p} | {med:.1f} µs | {p99:.0f} µs | {chain:.1f} µs | {wall:.1f} µs |")
    d_abs, d_rel = f32_difference(cal["hysteresis"].model_, walk)
    print()
    print(
        f"float32 bank against the float64 bank on the walk: max |difference| {d_abs:.1e} "
        f"N/cm², max relative {d_rel:.1e} where p > 0.1 N/cm²"
    )
    state = getattr(step_pipe, "state_bytes_per_element", None)
    if state is not None:
        print()
        print(f"state per element: {state()} bytes")


if __name__ == "__main__":
    main()
