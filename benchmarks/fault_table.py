"""The fault battery's table for docs/reliability.md: runs ``tests/faults`` and prints one
row per case (area, case, outcome), then the totals.

    .venv/bin/python benchmarks/fault_table.py
"""

from __future__ import annotations

import collections
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        table = Path(tmp) / "rows.json"
        env = dict(os.environ, TEXSENSE_FAULT_TABLE=str(table), TEXSENSE_NO_PROGRESS="1")
        proc = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/faults"],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
        )
        summary = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else ""
        rows = json.loads(table.read_text()) if table.exists() else []
    by_area: dict[str, list[dict[str, str]]] = collections.defaultdict(list)
    for row in rows:
        by_area[row["area"]].append(row)
    print("| area | case | outcome |")
    print("|---|---|---|")
    for area in sorted(by_area):
        for row in by_area[area]:
            detail = f" ({row['detail']})" if row["detail"] else ""
            print(f"| {area} | {row['case']} | {row['outcome']}{detail} |")
    print()
    counts = collections.Counter(row["outcome"] for row in rows)
    print(f"{len(rows)} cases: " + ", ".join(f"{n} {k}" for k, n in counts.most_common()))
    print(f"pytest: {summary}")
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main())
