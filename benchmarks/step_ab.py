"""`Pipeline.step` of another version of `pipeline.py` (e.g. main's) against this one's,
alternating in one process: the same pipeline object, the same compiled chain, the same
stream of changing frames (the mat of `pipeline_speed.py`), so the host's speed, which moves
by up to 2x between processes on a shared machine, falls on both alike (issue 34, thirteenth
round). Each block is `Pipeline.step` over the stream's 2000 frames (the first 100 left
out), timed on the CPU clock and then on the wall clock; prints the medians of the blocks
and the median of the pairs' ratios (this one / the other), then every pair's ratio. For the
other version's blocks the object takes the other module's class, so that its `step` calls
its own helpers (a helper this version no longer has, too).

Run:  .venv/bin/python benchmarks/step_ab.py OTHER/pipeline.py [--rows 32] [--pairs 8]
"""

from __future__ import annotations

import argparse
import importlib.util
import time
from collections.abc import Callable

import numpy as np

from pipeline_speed import mat_case
from texsense import _core
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.pipeline import Pipeline


def other_class(path: str) -> type[Pipeline]:
    """`Pipeline` of the module at ``path`` (it imports this `texsense`'s binding)."""
    spec = importlib.util.spec_from_file_location("other_pipeline", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.Pipeline


def block(pipe: Pipeline, cls: type[Pipeline], cap, times, clock) -> float:
    """The median time of ``cls.step`` over the stream (s), on ``pipe`` made of ``cls``
    for the block (the same state; the version's own helpers)."""
    pipe.__class__ = cls
    try:
        step: Callable[..., object] = cls.step
        pipe.reset()
        lat = np.empty(len(cap))
        for k in range(len(cap)):
            s = clock()
            step(pipe, cap[k], None, float(times[k]))
            lat[k] = clock() - s
    finally:
        pipe.__class__ = Pipeline
    return float(np.median(lat[100:]))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("other", help="the other version's compensation/pipeline.py")
    ap.add_argument("--rows", type=int, default=32, help="a mat of rows x rows elements")
    ap.add_argument("--pairs", type=int, default=8)
    args = ap.parse_args()
    _core.set_simd_path("avx512" if _core.simd_path()[1] == "avx512" else "avx2")
    c, lay, rec = mat_case(seat_calibration(mat_seed=5), args.rows, args.rows, 2000, seed=3)
    pipe = Pipeline(c, lay, repair="neighbour-mean")
    cap = np.ascontiguousarray(rec.frames, dtype=np.float64)
    steps = {"other": other_class(args.other), "this": Pipeline}
    clocks = {"cpu": time.process_time, "wall": time.perf_counter}
    got: dict[tuple[str, str], list[float]] = {(s, c): [] for s in steps for c in clocks}
    for i in range(args.pairs):
        for s in ("other", "this") if i % 2 == 0 else ("this", "other"):
            for c, clock in clocks.items():
                got[s, c].append(block(pipe, steps[s], cap, rec.times, clock))
    n = args.rows * args.rows
    print(f"| {n} elements, {args.pairs} pairs | other | this | median of the pairs' ratios |")
    print("|---|---:|---:|---:|")
    for c in clocks:
        a, b = np.array(got["other", c]) * 1e6, np.array(got["this", c]) * 1e6
        print(
            f"| `Pipeline.step`, median ({c} clock) | {np.median(a):.2f} µs "
            f"({a.min():.2f}-{a.max():.2f}) | {np.median(b):.2f} µs ({b.min():.2f}-{b.max():.2f})"
            f" | {np.median(b / a):.3f} x ({(b / a).min():.3f}-{(b / a).max():.3f}) |"
        )
    for c in clocks:  # every pair, in the order run
        r = np.array(got["this", c]) / np.array(got["other", c])
        print(f"pairs' ratios ({c} clock): " + " ".join(f"{x:.3f}" for x in r))


if __name__ == "__main__":
    main()
