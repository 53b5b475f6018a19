"""How long the command line takes to start, as a ratio to importing numpy in the same run.

Run:  .venv/bin/python benchmarks/cli_start.py [--repeat 15]

Each command is a fresh process, started 15 times in turn with the baseline
(``python -c "import numpy"``); the table gives the medians and the ratio (target of issue
24: ``texsense --version`` and ``--help`` at most 2 x the baseline). ``--before DIR`` adds
the same commands run from another checkout's ``python/`` folder (with its compiled core),
e.g. the commit before the change, in the same run.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

TEXSENSE = str(Path(sys.executable).with_name("texsense"))
RUNS = {
    'python -c "import numpy"': [sys.executable, "-c", "import numpy"],
    "texsense --version": [TEXSENSE, "--version"],
    "texsense --help": [TEXSENSE, "--help"],
    "texsense info --help": [TEXSENSE, "info", "--help"],
}


def wall(cmd: list[str], env: dict[str, str] | None) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env=env)
    return time.perf_counter() - t0


def main(repeat: int = 15) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--before", help="another checkout's python/ folder, run beside")
    ap.add_argument("--repeat", type=int, default=repeat, help=f"starts of each ({repeat})")
    args = ap.parse_args()
    runs = {k: (cmd, None) for k, cmd in RUNS.items()}
    if args.before:
        env = {**os.environ, "PYTHONPATH": args.before}
        for flag in ("--version", "--help"):
            cmd = [sys.executable, "-m", "texsense.cli", flag]
            runs[f"texsense {flag} (before)"] = (cmd, env)
    times: dict[str, list[float]] = {k: [] for k in runs}
    for _ in range(args.repeat):  # interleaved, so a busy moment hits every command alike
        for label, (cmd, env) in runs.items():
            times[label].append(wall(cmd, env))
    base = statistics.median(times['python -c "import numpy"'])
    print("| command | median wall time | ratio to importing numpy |")
    print("|---|---:|---:|")
    for label, ts in times.items():
        m = statistics.median(ts)
        print(f"| `{label}` | {m * 1e3:.0f} ms | {m / base:.2f} |")


if __name__ == "__main__":
    main()
