"""Reading text exports: the PMD tree (../shared/data/pmd/experiment-i, 20,024 frames of
2,048 counts) with the readers' fast path for rows of numbers (Rust, ``_core.parse_row``) and
with numpy's parse of the split tokens alone (the path the readers take for a row the fast
path refuses), CPU seconds each, best of ``--repeat``, and whether both read the same bits.

    .venv/bin/python benchmarks/read_speed.py [--repeat 2]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

import texsense
import texsense.io.pmd as pmd

TREE = Path(__file__).resolve().parents[2] / "shared" / "data" / "pmd" / "experiment-i"


@contextmanager
def slow_path() -> Any:
    """Every row refused by the fast path: the reader parses the tokens with numpy."""
    fast = pmd.parse_row
    pmd.parse_row = lambda line, sep, expected: None
    try:
        yield
    finally:
        pmd.parse_row = fast


def best_cpu(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    best, result = float("inf"), None
    for _ in range(repeat):
        start = time.process_time()
        result = fn()
        best = min(best, time.process_time() - start)
    return best, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    folders = {"one subject (S2)": TREE / "S2", "whole tree": TREE}
    print("| read | frames | numpy path (CPU s) | fast path (CPU s) | ratio | same bits |")
    print("|---|---:|---:|---:|---:|---|")
    for name, folder in folders.items():
        with slow_path():
            slow, a = best_cpu(lambda f=folder: texsense.load(f), args.repeat)
        fast, b = best_cpu(lambda f=folder: texsense.load(f), args.repeat)
        same = np.array_equal(a.frames.view(np.uint32), b.frames.view(np.uint32)) and (
            np.array_equal(a.valid, b.valid)
        )
        print(f"| {name} | {b.n_frames} | {slow:.2f} | {fast:.2f} | {slow / fast:.1f}x | {same} |")


if __name__ == "__main__":
    main()
