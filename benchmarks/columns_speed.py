"""Column tables (``time_s,compression_mm,...``): the reader and writer of texsense against a
plain line-by-line reading and writing of the same table (each line through
``parse_csv_row``; each row's values joined by their ``repr``), CPU seconds, best of
``--repeat``, and whether both read the same bits and write the same bytes.

    .venv/bin/python benchmarks/columns_speed.py [--repeat 3]

The table is the virtual spacer's step protocol of docs/drift.md (``texsense simulate steps
--seed 2 --csv``: 144,185 rows of 4 columns).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from _timing import best_of
from texsense.io._text import TextLines, parse_csv_row
from texsense.io.columns_csv import read_columns_csv, write_columns_csv


def read_by_line(path: Path) -> dict[str, np.ndarray]:
    """The baseline: every data line parsed on its own."""
    with TextLines(path) as lines:
        while (line := lines.peek()) is not None and line.text.startswith("#"):
            next(lines)
        head = lines.next_nonblank()
        assert head is not None
        names = head.text.split(",")
        rows = [parse_csv_row(path, ln, len(names), "the row") for ln in lines.data_lines()]
    data = np.array(rows, dtype=np.float64)
    return {n: data[:, i].copy() for i, n in enumerate(names)}


def write_by_line(path: Path, columns: dict[str, np.ndarray]) -> None:
    """The baseline: each row's values joined by their repr, a line at a time."""
    arrays = list(columns.values())
    with open(path, "w", encoding="utf-8") as out:
        out.write(f"# rows: {arrays[0].size}\n" + ",".join(columns) + "\n")
        for row in zip(*(a.tolist() for a in arrays), strict=True):
            out.write(",".join(repr(v) for v in row) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="repetitions (best of)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        table = folder / "steps.csv"
        subprocess.run([sys.executable, "-m", "texsense", "simulate", "steps", "--seed", "2",
                        "--csv", str(table)], check=True, capture_output=True)  # fmt: skip
        base = read_by_line(table)
        mine = read_columns_csv(table)
        same_read = all(np.array_equal(base[n], mine[n], equal_nan=True) for n in base)
        write_by_line(folder / "a.csv", base)
        write_columns_csv(folder / "b.csv", base)
        same_bytes = (folder / "a.csv").read_bytes() == (folder / "b.csv").read_bytes()
        rows, cols = base["time_s"].size, len(base)

        def cpu(fn: Callable[[], object]) -> float:
            return best_of(fn, repeat=args.repeat, clock=time.process_time)[0]

        t = {
            "read, line by line": cpu(lambda: read_by_line(table)),
            "read, texsense (blocks of lines)": cpu(lambda: read_columns_csv(table)),
            "write, line by line": cpu(lambda: write_by_line(folder / "a.csv", base)),
            "write, texsense (pieces of rows)": cpu(
                lambda: write_columns_csv(folder / "b.csv", base)
            ),
        }
    print(f"{rows} rows x {cols} columns; best of {args.repeat}, CPU s\n")
    print("| path | CPU s |")
    print("|---|---:|")
    for name, seconds in t.items():
        print(f"| {name} | {seconds:.2f} |")
    print(f"\nsame values read: {same_read}; same bytes written: {same_bytes}")


if __name__ == "__main__":
    main()
