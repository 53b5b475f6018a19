"""What the Preisach kernel's rate depends on: the same bank, frame after frame (the row of
``pipeline_speed.py``'s issue-34 target), on inputs of different shapes, each as a share of
the copy rate measured in the same run (issue 34, seventeenth round).

Run:  .venv/bin/python benchmarks/preisach_inputs.py [--frames 1000] [--elements 4096]
      [--repeat 3]

The shapes, from the least work per step to the benchmark's walk:

- constant: no element moves (no turning point, nothing wiped); on the AVX-512 path a step
  of groups at rest reads their heads and writes the last outputs again (since the
  seventeenth round; before, it also looked up the Everett function);
- rising ramp: every element moves, none turns;
- alternating: every element turns every frame around the same input (a turning point pushed
  every step, nothing wiped below the first loop);
- the walk, the same for every element: every kind of step, but all elements of a frame take
  the same branches (predictable across the groups);
- the walk in one half of the mat, the other half at rest (an unloaded region: its inputs at
  the range's lower end; groups whose elements all hold still take a short step);
- the walk (``pipeline_speed.py``'s): each element its own random walk, so the kernel's
  branches (a wipe-out deeper than one loop, a stack on the heap) go one way in one group and
  the other way in the next.

The gap between the walk alike in every element and the walk is what the kernel loses to
branches that vary from group to group. On an AVX-512 processor every shape also runs with
the kernel's other lookup of the Everett cells (``texsense._core.set_simd_lookup``: a
gather per corner, or a load per lane from the table by cell), alternating with the
processor's own, and the table gives their ratio (issue 34, eighteenth round).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pipeline_speed import random_walk
from texsense import _core
from texsense.calibration.workflows import seat_calibration


def shapes(model: object, frames: int, n: int) -> dict[str, np.ndarray]:
    """The inputs (frames x n) of every row of the table."""
    lo, hi = model.u_min_, model.u_max_
    walk = random_walk(model, frames, n)
    t = np.arange(frames, dtype=float)[:, None]
    full = (frames, n)
    return {
        "constant": np.full(full, (lo + hi) / 2),
        "rising ramp (moves, never turns)": np.broadcast_to(lo + (hi - lo) * t / frames, full),
        "alternating (turns every frame)": np.broadcast_to(
            (lo + hi) / 2 + 0.001 * (-1.0) ** t, full
        ),
        "the walk, the same for every element": np.broadcast_to(walk[:, :1], full),
        "the walk in one half, the other half at rest": np.where(np.arange(n) < n // 2, walk, lo),
        "the walk, each element its own (pipeline_speed.py's)": walk,
    }


def rates(model: object, x: np.ndarray, repeat: int, lookups: list[str]) -> dict[str, float]:
    """Element-steps per second of the bank on ``x`` by each of the AVX-512 kernel's
    ``lookups`` of the Everett cells, frame after frame (best of ``repeat``, CPU clock, the
    lookups in turn and their order reversed every other time), into an output array
    allocated beforehand."""
    ok = np.ones(x.shape, bool)
    out = np.empty_like(x)
    best = dict.fromkeys(lookups, float("inf"))
    try:
        for r in range(repeat):
            for lookup in lookups if r % 2 == 0 else lookups[::-1]:
                _core.set_simd_lookup(lookup)
                bank = model.bank(x.shape[1])
                start = time.process_time()
                bank.run(x, ok, schedule="frames", out=out)
                best[lookup] = min(best[lookup], time.process_time() - start)
    finally:
        _core.set_simd_lookup("auto")
    return {k: x.size / t for k, t in best.items()}


def copy_rate(shape: tuple[int, int], repeat: int) -> float:
    """Element-samples per second of ``np.multiply(x, 1.0, out=y)`` (CPU clock)."""
    x = np.random.default_rng(0).random(shape)
    y = np.empty_like(x)
    best = float("inf")
    for _ in range(max(repeat, 5)):
        start = time.process_time()
        np.multiply(x, 1.0, out=y)
        best = min(best, time.process_time() - start)
    return x.size / best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--elements", type=int, default=4096)
    ap.add_argument("--repeat", type=int, default=3, help="best of this many runs per row")
    args = ap.parse_args()
    model = seat_calibration(mat_seed=5)["hysteresis"].model_
    inputs = {
        k: np.ascontiguousarray(v) for k, v in shapes(model, args.frames, args.elements).items()
    }
    copy = copy_rate((4000, args.elements), args.repeat)
    print(
        f"Preisach kernel, frame after frame, {args.frames} frames x {args.elements} elements; "
        f"copy rate {copy / 1e6:.0f} M element-samples/s (best of {max(args.repeat, 5)}, "
        "CPU clock)"
    )
    # on AVX-512 both lookups of the Everett cells, the processor's first (`simd_lookup`)
    path, default = _core.simd_path()[0], _core.simd_lookup()[1]
    other = "gather" if default == "loads" else "loads"
    lookups = [default, other] if path == "avx512" else [default]
    print(f"SIMD path {path}; the Everett cells by {default} (this processor's lookup)")
    print()
    head = "| input | rate | share of the copy rate | ns per element-step |"
    if len(lookups) == 2:
        head += f" by {other}: rate | {default} / {other} |"
    print(head)
    print("|---|---:|---:|---:|" + ("---:|---:|" if len(lookups) == 2 else ""))
    for name, x in inputs.items():
        got = rates(model, x, args.repeat, lookups)
        r = got[default]
        line = f"| {name} | {r / 1e6:.1f} M/s | {100 * r / copy:.2f} % | {1e9 / r:.2f} |"
        if len(lookups) == 2:
            line += f" {got[other] / 1e6:.1f} M/s | {r / got[other]:.2f} x |"
        print(line)


if __name__ == "__main__":
    main()
