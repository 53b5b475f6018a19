"""The fault battery's tables for docs/reliability.md: runs ``tests/faults`` and prints the
families of issue 32 (each with the cases its tests generate and their outcomes), then one row
per case (area, case, outcome), then the totals.

    .venv/bin/python benchmarks/fault_table.py [TEST FILES] [PYTEST OPTIONS]

Test files (default: all of ``tests/faults``) and options after the script go to pytest
(``--durations=15``); pytest's own report is then printed to stderr, the tables to stdout.
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
#: The families of issue 32 and after, in the order of docs/reliability.md (the areas their
#: tests record).
FAMILIES = ["reach outside", "identity", "declares more", "not a file", "round trip", "values",
            "settings", "requests", "nesting", "output place", "option file", "stop mid-write",
            "paths in files", "no effect", "hostile value", "origins", "duplicate keys",
            "not Unicode", "layout fields", "stored state", "stage ranges", "clock"]  # fmt: skip


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        table = Path(tmp) / "rows.json"
        env = dict(os.environ, TEXSENSE_FAULT_TABLE=str(table), TEXSENSE_NO_PROGRESS="1")
        proc = subprocess.run(
            [
                sys.executable,
                "-m",
                "pytest",
                "-q",
                "-p",
                "no:cacheprovider",
                *([] if any(Path(a).exists() for a in sys.argv[1:]) else ["tests/faults"]),
                *sys.argv[1:],
            ],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
        )
        summary = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else ""
        if len(sys.argv) > 1 or proc.returncode:
            print(proc.stdout, proc.stderr, sep="\n", file=sys.stderr)
        rows = json.loads(table.read_text()) if table.exists() else []
    by_area: dict[str, list[dict[str, str]]] = collections.defaultdict(list)
    for row in rows:
        by_area[row["area"]].append(row)
    print("| family | rows | cases generated | outcomes |")
    print("|---|---:|---:|---|")
    for family in FAMILIES:
        got = by_area.get(family, [])
        cases = sum(int(r.get("cases", 1)) for r in got)
        outcomes = collections.Counter(r["outcome"] for r in got)
        said = ", ".join(f"{n} {k}" for k, n in outcomes.most_common())
        print(f"| {family} | {len(got)} | {cases} | {said} |")
    print()
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
