"""The cost of the door every live frame goes through (``texsense.data.times.off_scale``, from
``FrameClock.place_frame``): its element times checked for a time no clock has, now one
compiled pass (``_core.first_off_scale``), against the numpy code it replaced (``~(|t| <=
1e12)`` under ``np.errstate``, kept here as the baseline), in the same run.

Run:  .venv/bin/python benchmarks/frame_door.py [--repeat N] [--sizes 96 1024 4096]

Each cell is the best of ``--repeat`` timings of 2000 calls (µs per call, wall clock) on a
frame of times all on the scale (the usual frame: the whole array is read).
"""

from __future__ import annotations

import argparse
import timeit

import numpy as np
import numpy.typing as npt

from texsense.data.times import MAX_TIME_S, off_scale


def numpy_off_scale(t: npt.ArrayLike) -> str | None:
    """The numpy version (issue 34's fifteenth round), the baseline."""
    t = np.asarray(t, dtype=np.float64).ravel()
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(t) <= MAX_TIME_S)
    if not bad.any():
        return None
    ti = t[int(np.argmax(bad))]
    if not np.isfinite(ti):
        return f"the time {ti} is not a number"
    return f"the time {ti:.9g} s is beyond any clock (|t| over 1e12 s)"


def per_call(fn, t: np.ndarray, repeat: int) -> float:
    """Best µs per call of ``fn(t)`` over ``repeat`` timings of 2000 calls."""
    return min(timeit.repeat(lambda: fn(t), number=2000, repeat=repeat)) / 2000 * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--sizes", type=int, nargs="+", default=[96, 1024, 4096])
    args = ap.parse_args()
    print("| elements | numpy (before), µs | compiled (now), µs | now / before |")
    print("|---:|---:|---:|---:|")
    for n in args.sizes:
        t = 1.7e9 + np.arange(n) * 1e-5  # Unix times of one frame's elements
        bad = t.copy()
        bad[n // 2] = np.nan
        assert off_scale(t) is None and off_scale(bad) == numpy_off_scale(bad)
        before, now = per_call(numpy_off_scale, t, args.repeat), per_call(off_scale, t, args.repeat)
        print(f"| {n} | {before:.2f} | {now:.2f} | {now / before:.3f} |")


if __name__ == "__main__":
    main()
