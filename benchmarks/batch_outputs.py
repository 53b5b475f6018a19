"""Where a batch's output lives, and what that costs (issue 34, twentieth round): the Preisach
kernel on the benchmark's 4000 x 4096 walk writing into an array held, into a new numpy array,
into the output the batch makes itself (``out=None``, as ``HysteresisModel.predict`` does),
``predict`` itself, and the pipeline's ``run`` (float32) and ``process`` (float64) at 4096
elements, which make their outputs too; beside them the copy of the walk on one core and on
all cores (``pipeline_speed.py``'s yardstick).

Run:  .venv/bin/python benchmarks/batch_outputs.py [--repeat N] [--clock wall|cpu]
      [--no-huge-pages] [--frames T]

``--no-huge-pages`` switches off numpy's request for huge pages for large arrays
(``numpy._core.multiarray._set_madvise_hugepage(False)``), to see what the batches' outputs
owe to them. To compare builds, run it with another build's package on ``PYTHONPATH``, in
turns. Each row is the best of three runs of the batch, per repetition; the table gives the
median and the range over the repetitions.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable

import numpy as np

import pipeline_speed as ps
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.pipeline import Pipeline


def rows(frames: int) -> tuple[list[tuple[str, Callable[[], object]]], int, int]:
    """(label, run) of every row, and the element-samples of the walk and of the
    pipeline's recording."""
    cal = seat_calibration(mat_seed=5)
    model = cal["hysteresis"].model_
    walk = ps.random_walk(model, frames, 4096)
    bank = model.bank(walk.shape[1])
    ok = np.ones(walk.shape, bool)
    held = np.empty_like(walk)
    c, lay, rec = ps.mat_case(cal, 64, 64, max(200, min(frames, 4_000_000 // 4096)))
    pipe = Pipeline(c, lay, repair="neighbour-mean")

    def kernel(schedule: str, out: Callable[[], np.ndarray | None]) -> Callable[[], object]:
        return lambda: (bank.reset(), bank.run(walk, ok, schedule=schedule, out=out()))

    return (
        [
            (
                "Preisach kernel into an array held, frame after frame",
                kernel("frames", lambda: held),
            ),
            (
                "Preisach kernel into an array held, blocks in parallel",
                kernel("parallel", lambda: held),
            ),
            (
                "Preisach kernel into a new numpy array (`np.empty`), blocks in parallel",
                kernel("parallel", lambda: np.empty_like(walk)),
            ),
            (
                "Preisach kernel into its own output (`out=None`), blocks in parallel",
                kernel("parallel", lambda: None),
            ),
            ("`HysteresisModel.predict`", lambda: model.predict(walk)),
            ("pipeline `run` (float32), 4096 elements", lambda: pipe.reset().run(rec)),
            (
                "pipeline `process` (float64), 4096 elements",
                lambda: pipe.reset().process(rec.frames, rec.times, rec.valid),
            ),
        ],
        walk.size,
        rec.frames.size,
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3, help="repetitions of the whole set")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall")
    ap.add_argument("--frames", type=int, default=4000, help="frames of the walk")
    ap.add_argument(
        "--no-huge-pages", action="store_true", help="numpy's huge pages for large arrays off"
    )
    args = ap.parse_args()
    if args.repeat < 1 or args.frames < 10:
        ap.error("--repeat must be >= 1 and --frames >= 10")
    if args.no_huge_pages:
        np._core.multiarray._set_madvise_hugepage(False)
    ps.CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    threads = int(os.environ.get("RAYON_NUM_THREADS") or len(os.sched_getaffinity(0)))
    cases, walk_size, rec_size = rows(args.frames)
    shape = (args.frames, 4096)
    rates: dict[str, list[float]] = {"copy, one core": [], f"copy, {threads} cores": []}
    rates.update({label: [] for label, _ in cases})
    for _ in range(args.repeat):
        rates["copy, one core"].append(ps.copy_rate(shape))
        rates[f"copy, {threads} cores"].append(ps.copy_rate(shape, threads))
        for label, run in cases:
            size = rec_size if label.startswith("pipeline") else walk_size
            rates[label].append(size / ps.timed(run))
    print(
        f"{args.clock} clock, {args.repeat} repetitions, numpy's huge pages "
        f"{'off' if args.no_huge_pages else 'on'}; M element-samples/s"
    )
    print()
    print("| row | median | range |")
    print("|---|---:|---:|")
    for label, r in rates.items():
        print(f"| {label} | {np.median(r) / 1e6:.1f} | {min(r) / 1e6:.1f}-{max(r) / 1e6:.1f} |")


if __name__ == "__main__":
    main()
