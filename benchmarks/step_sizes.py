"""The compiled step's latency against the mat's size, and the host's speed in the same
minute: is a step bound by its elements or by a fixed part, and which of the host's speeds
was it measured at?

Run:  .venv/bin/python benchmarks/step_sizes.py [--rounds N] [--frames N] [--rows 4 8 ...] [--json]
      [--pipeline]

Each round steps a mat of 128, 256, ..., 4096 elements (32 columns, the benchmark's
calibration and stream, every frame different) through ``Chain.step`` into arrays held, one
size after the other in one process, and times a fixed pure-Python loop (200,000 integer
multiply-adds) right after: the loop runs no texsense code, so when its time moves with the
step's, the host's speed moved, not the code. Medians per size over the frames after the
first 100 (the first half of a run shorter than 200 frames: ``--frames 20`` is a smoke
test), wall clock. ``--rows`` picks the mats (rows of 32 columns); ``--json`` prints each
round as one line of JSON instead of the table (``step_builds.py`` reads it);
``--pipeline`` times the public ``Pipeline.step`` (the frame with its time, the Python around
the chain included: issue 34's target) instead of ``Chain.step``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pipeline_speed import mat_case
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.pipeline import Pipeline

ROWS = [4, 8, 16, 32, 64, 128]


def step_median(chain, cap: np.ndarray, dt: float) -> float:
    """Median seconds of ``chain.step`` over ``cap``'s frames after the first 100."""
    n = cap.shape[1]
    held = np.empty(n), np.empty(n, np.uint8), np.empty(n, bool)
    chain.reset()
    lat = np.empty(len(cap))
    for k in range(len(cap)):
        s = time.perf_counter()
        chain.step(dt, cap[k], None, *held)
        lat[k] = time.perf_counter() - s
    return float(np.median(lat[min(100, len(lat) // 2) :]))


def pipeline_median(pipe: Pipeline, cap: np.ndarray, times: list[float]) -> float:
    """Median seconds of ``pipe.step`` over ``cap``'s frames at ``times`` after the first 100."""
    pipe.reset()
    lat = np.empty(len(cap))
    for k in range(len(cap)):
        s = time.perf_counter()
        pipe.step(cap[k], None, times[k])
        lat[k] = time.perf_counter() - s
    return float(np.median(lat[min(100, len(lat) // 2) :]))


def python_loop() -> float:
    """Seconds of a fixed pure-Python loop (the host's speed, no texsense code)."""
    s = time.perf_counter()
    x = 0
    for i in range(200_000):
        x += i * i
    return time.perf_counter() - s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--frames", type=int, default=1500)
    ap.add_argument("--rows", type=int, nargs="+", default=ROWS, help="mats of ROWS x 32")
    ap.add_argument("--json", action="store_true", help="one JSON line per round")
    ap.add_argument("--pipeline", action="store_true", help="time Pipeline.step, not Chain.step")
    args = ap.parse_args()
    cal = seat_calibration(mat_seed=5)
    cases = {}
    for rows in args.rows:
        c, lay, rec = mat_case(cal, rows, 32, args.frames, seed=3)
        pipe = Pipeline(c, lay, repair="neighbour-mean")
        cap = np.ascontiguousarray(rec.frames, dtype=np.float64)
        if args.pipeline:
            cases[rows * 32] = (pipeline_median, pipe, cap, rec.times.tolist())
        else:
            cases[rows * 32] = (
                step_median,
                pipe.compiled(),
                cap,
                float(rec.times[1] - rec.times[0]),
            )
    sizes = list(cases)
    if not args.json:
        head = " | ".join(f"{n} el.: µs (ns/el.)" for n in sizes)
        print(f"| round | {head} | Python loop, ms |")
        print("|---:|" + "---:|" * (len(sizes) + 1))
    for r in range(args.rounds):
        steps = {n: cases[n][0](*cases[n][1:]) for n in sizes}
        loop = python_loop()
        if args.json:
            print(json.dumps({"step_s": steps, "loop_s": loop}), flush=True)
            continue
        cells = [f"{t * 1e6:.1f} ({t / n * 1e9:.1f})" for n, t in steps.items()]
        print(f"| {r + 1} | " + " | ".join(cells) + f" | {loop * 1e3:.1f} |", flush=True)


if __name__ == "__main__":
    main()
