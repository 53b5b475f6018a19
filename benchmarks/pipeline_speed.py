"""Speed of the compiled pipeline against the physical yardstick of this machine: the rate at
which it copies the same array (``np.multiply(x, 1.0, out=y)``), measured in the same run.

Run:  .venv/bin/python benchmarks/pipeline_speed.py [--threads N]

- Preisach batch: ``HysteresisModel.predict`` on a 4000 x 4096 random walk, step by step
  (one thread, frame order; one thread, element blocks; all threads);
- the whole pipeline (detect -> convert -> Preisach + drift -> eq. 6.14 repair) at 96, 1024 and
  4096 elements with 2 % failed readings;
- ``Pipeline.step`` latency on a real stream (every frame different), median and p99;
- the state kept per element.

The machine is shared and noisy: every rate is also given as a share of the copy rate of the
same run, which is what the targets of issue 19 are stated in.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import best_of
from texsense import Layout, Recording
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import Convert, StageChain


def copy_rate(shape: tuple[int, int]) -> float:
    x = np.random.default_rng(0).random(shape)
    y = np.empty_like(x)
    t, _ = best_of(lambda: np.multiply(x, 1.0, out=y), repeat=7)
    return x.size / t


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


def share(rate: float, copy: float) -> str:
    return f"{rate / 1e6:.1f} M/s | {100 * rate / copy:.2f} %"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="smaller sizes (a smoke test)")
    args = ap.parse_args()
    frames = 400 if args.quick else 4000
    cal = seat_calibration(mat_seed=5)
    model = cal["hysteresis"].model_
    walk = random_walk(model, frames, 4096)
    copy = copy_rate(walk.shape)
    print(f"copy rate of a ({frames}, 4096) float64 array: {copy / 1e6:.0f} M element-samples/s")
    print()
    print("| path | rate | share of the copy rate |")
    print("|---|---:|---:|")
    bank = model.bank(walk.shape[1])  # the Rust PreisachBank behind predict
    ok = np.ones(walk.shape, bool)
    for label, schedule in (
        ("one thread, frame after frame", "frames"),
        ("one thread, blocks of 128 elements through all frames", "blocks"),
        ("blocks in parallel (all cores)", "parallel"),
    ):
        t, _ = best_of(lambda s=schedule: (bank.reset(), bank.run(walk, ok, schedule=s)))
        print(f"| Preisach kernel, {label} | {share(walk.size / t, copy)} |")
    t, _ = best_of(lambda: model.predict(walk))
    print(f"| Preisach `HysteresisModel.predict` | {share(walk.size / t, copy)} |")
    for rows, cols in ((8, 12), (32, 32), (64, 64)):
        n = rows * cols
        nf = max(200, min(frames, 4_000_000 // n))
        c, lay, rec = mat_case(cal, rows, cols, nf)
        pipe = Pipeline(c, lay, repair="neighbour-mean")
        t, _ = best_of(lambda pipe=pipe, rec=rec: pipe.reset().run(rec))
        print(
            f"| pipeline `run`, {n} elements x {nf} frames | {share(rec.frames.size / t, copy)} |"
        )
    print()
    # step latency on a real stream: 1024 elements, every frame different
    c, lay, rec = mat_case(cal, 32, 32, 2000, seed=3)
    pipe = Pipeline(c, lay, repair="neighbour-mean")
    cap = np.ascontiguousarray(rec.frames, dtype=np.float64)
    lat = np.empty(rec.n_frames)
    for k in range(rec.n_frames):
        s = time.perf_counter()
        pipe.step(cap[k], None, float(rec.times[k]))
        lat[k] = time.perf_counter() - s
    lat = lat[100:]
    print("| `Pipeline.step`, 1024 elements, changing frames | median | p99 |")
    print("|---|---:|---:|")
    print(f"| latency | {np.median(lat) * 1e6:.0f} µs | {np.percentile(lat, 99) * 1e6:.0f} µs |")
    state = getattr(pipe, "state_bytes_per_element", None)
    if state is not None:
        print()
        print(f"state per element: {state()} bytes")


if __name__ == "__main__":
    main()
