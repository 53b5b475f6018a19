"""A small archive in `texsense process`'s own process against a local Dask cluster.

Run:  .venv/bin/python benchmarks/archive_small.py [--rounds 2]

The real PMD files of subject S1 (``../shared/data/pmd/experiment-i/S1``: 17 files, 6.7 MB of
text) under a linear calibration, processed by the command as a user runs it, once with
``--workers 1`` (file after file in the command's process, what an archive under 32 MB gets by
default) and once with ``--workers 2`` (a local cluster of two worker processes), alternating,
each in a fresh output folder. Reported: wall time and the CPU of the command and its children
(the cluster's scheduler and workers included), median over the rounds.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
S1 = ROOT.parent / "shared" / "data" / "pmd" / "experiment-i" / "S1"
TEXSENSE = [sys.executable, "-m", "texsense"]


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_once(calibration: Path, out: Path, workers: int) -> tuple[float, float]:
    """(wall s, CPU s) of one `texsense process` of S1 with ``workers``."""
    cmd = [*TEXSENSE, "process", str(S1), "--calibration", str(calibration), "-o", str(out),
           "--repair", "neighbour-mean", "--workers", str(workers)]  # fmt: skip
    cpu, wall = _children_cpu(), time.monotonic()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.monotonic() - wall, _children_cpu() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2, help="alternating rounds (2)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        cal = folder / "pmd.json"
        subprocess.run([*TEXSENSE, "calibrate", "linear", "--like", str(S1 / "1.txt"),
                        "--full-scale", "4095", "-o", str(cal)], check=True,
                       capture_output=True)  # fmt: skip
        got: dict[int, list[tuple[float, float]]] = {1: [], 2: []}
        for r in range(args.rounds):
            for workers in (1, 2) if r % 2 == 0 else (2, 1):
                got[workers].append(run_once(cal, folder / f"out-{r}-{workers}", workers))
    files = len(list(S1.glob("*.txt")))
    print(f"{files} PMD files of S1, {args.rounds} alternating rounds, medians\n")
    print("| texsense process | wall | CPU (command and its children) |")
    print("|---|---:|---:|")
    names = {1: "`--workers 1`: in the command's process", 2: "`--workers 2`: local cluster"}
    for workers, rows in got.items():
        wall = statistics.median(w for w, _ in rows)
        cpu = statistics.median(c for _, c in rows)
        print(f"| {names[workers]} | {wall:.1f} s | {cpu:.1f} s |")


if __name__ == "__main__":
    main()
