"""Reading text exports: the PMD tree (../shared/data/pmd/experiment-i, 20,024 frames of
2,048 counts) with the readers' fast path for rows of numbers (Rust, ``_core.parse_row``) and
with numpy's parse of the split tokens alone (the path the readers take for a row the fast
path refuses), CPU seconds each, best of ``--repeat``, and whether both read the same bits.

    .venv/bin/python benchmarks/read_speed.py [--repeat 2]
"""

from __future__ import annotations

import argparse
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

import texsense
import texsense.io.pmd as pmd
from _timing import best_of

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    folders = {"one subject (S2)": TREE / "S2", "whole tree": TREE}
    print("| read | frames | numpy path (CPU s) | fast path (CPU s) | ratio | same bits |")
    print("|---|---:|---:|---:|---:|---|")
    for name, folder in folders.items():
        with slow_path():
            slow, a = best_of(texsense.load, folder, repeat=args.repeat, clock=time.process_time)
        fast, b = best_of(texsense.load, folder, repeat=args.repeat, clock=time.process_time)
        same = np.array_equal(a.frames.view(np.uint32), b.frames.view(np.uint32)) and (
            np.array_equal(a.valid, b.valid)
        )
        print(f"| {name} | {b.n_frames} | {slow:.2f} | {fast:.2f} | {slow / fast:.1f}x | {same} |")


if __name__ == "__main__":
    main()
