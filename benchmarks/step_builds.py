"""The compiled step of another build (another checkout's interpreter, its own texsense and
compiled core) against this one's, process after process: a compiled change cannot be timed
in one process beside the code it replaced, so the two alternate, each run followed by a
fixed pure-Python loop (``step_sizes.py``'s), which shows the host's speed in that minute.

Run:  .venv/bin/python benchmarks/step_builds.py OTHER/.venv/bin/python [--pairs 6] [--rows 32]
      [--pipeline]

Each pair runs ``step_sizes.py --json`` (one round, the mat of ROWS x 32 elements,
``Chain.step`` into arrays held, or ``Pipeline.step`` with ``--pipeline``, median over the
stream's frames after the first 100) with
the other interpreter, then with this one (this one first in the even pairs). Prints each
pair's medians, the ratio this / other, and each run's Python loop; then the median of the
ratios. Pairs whose two loops differ by more than 15 % ran at different host speeds and are
marked; the median of the ratios is given over all pairs and over the others.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

SCRIPT = Path(__file__).resolve().parent / "step_sizes.py"


def run(python: str, rows: int, frames: int, pipeline: bool = False) -> tuple[float, float]:
    """(step seconds, Python loop seconds) of one run of ``step_sizes.py`` by ``python``."""
    cmd = [python, str(SCRIPT), "--rounds", "1", "--rows", str(rows), "--frames", str(frames)]
    cmd += ["--pipeline"] if pipeline else []
    try:
        done = subprocess.run([*cmd, "--json"], capture_output=True, text=True, check=False)
    except OSError as e:
        sys.exit(f"step_builds: cannot run {python}: {e.strerror}")
    if done.returncode != 0:
        last = done.stderr.strip().splitlines()[-1:]
        sys.exit(f"step_builds: {python} failed (exit {done.returncode}): {' '.join(last)}")
    try:
        line = json.loads(done.stdout.strip().splitlines()[-1])
        return float(next(iter(line["step_s"].values()))), float(line["loop_s"])
    except (IndexError, ValueError, KeyError, TypeError, AttributeError, StopIteration):
        sys.exit(f"step_builds: {python} printed no step_sizes.py result: {done.stdout[:80]!r}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("other", help="the other build's Python interpreter")
    ap.add_argument("--pairs", type=int, default=6)
    ap.add_argument("--rows", type=int, default=32, help="a mat of ROWS x 32 elements")
    ap.add_argument("--frames", type=int, default=1500)
    ap.add_argument("--pipeline", action="store_true", help="time Pipeline.step (step_sizes.py)")
    args = ap.parse_args()
    this = sys.executable
    print("| pair | other: step µs (loop ms) | this: step µs (loop ms) | this / other |")
    print("|---:|---:|---:|---:|")
    ratios, same_speed = [], []
    for p in range(args.pairs):
        order = [args.other, this] if p % 2 == 0 else [this, args.other]
        got = {py: run(py, args.rows, args.frames, args.pipeline) for py in order}
        (o, lo), (t, lt) = got[args.other], got[this]
        ratio = t / o
        ratios.append(ratio)
        apart = abs(lt / lo - 1) > 0.15
        if not apart:
            same_speed.append(ratio)
        mark = " (host speed changed)" if apart else ""
        print(
            f"| {p + 1} | {o * 1e6:.1f} ({lo * 1e3:.1f}) | {t * 1e6:.1f} ({lt * 1e3:.1f}) | "
            f"{ratio:.3f}{mark} |",
            flush=True,
        )
    print(f"\nmedian ratio this / other: {np.median(ratios):.3f} over {len(ratios)} pairs", end="")
    if same_speed:
        print(f"; {np.median(same_speed):.3f} over the {len(same_speed)} at one host speed")
    else:
        print()


if __name__ == "__main__":
    main()
