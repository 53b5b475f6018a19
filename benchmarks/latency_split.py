"""The viewers' samples of a `station_group_capacity.py --dump` row, summed up (issue 38):
how many, the first frame's latency, the largest in the first 10 s (the start, when every
mat's first frame comes at once), p99 over all samples, after the first tenth (the
benchmark's own p99) and from 10 s on, how many samples were over 100 ms (after the first
tenth, and from 10 s on), and with ``--late MS`` every sample over MS split
into its parts (publisher to the member's inbox, in the inbox and processed, to the viewer).

Run:  .venv/bin/python benchmarks/latency_split.py /tmp/dump/row1.jsonl [--late 100]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def summary(path: Path) -> dict[str, float]:
    rows = sorted((json.loads(line) for line in path.read_text().splitlines() if line),
                  key=lambda r: r["t"])  # fmt: skip
    t0 = rows[0]["t"]
    t = np.array([r["t"] - t0 for r in rows])
    lat = np.array([1e3 * (r["viewer"] - r["t"]) for r in rows])
    return {
        "samples": len(rows), "first": float(lat[0]), "max_start": float(lat[t < 10].max()),
        "p99_all": float(np.percentile(lat, 99)),
        "p99_tenth": float(np.percentile(lat[len(lat) // 10 :], 99)),
        "p99_10s": float(np.percentile(lat[t >= 10], 99)),
        "p50": float(np.percentile(lat[len(lat) // 10 :], 50)),
        "late": int(np.sum(lat[len(lat) // 10 :] > 100.0)),
        "late_10s": int(np.sum(lat[t >= 10] > 100.0)),
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dumps", nargs="+", type=Path)
    ap.add_argument("--late", type=float, help="list the samples over this many ms, split")
    args = ap.parse_args()
    print("| dump | samples | first frame | largest, first 10 s | p99, all | p99 after the "
          "first tenth | p99 from 10 s | p50 | over 100 ms after the first tenth | "
          "from 10 s |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for path in args.dumps:
        s = summary(path)
        print(f"| {path} | {s['samples']} | {s['first']:.0f} ms | {s['max_start']:.0f} ms | "
              f"{s['p99_all']:.0f} ms | {s['p99_tenth']:.0f} ms | {s['p99_10s']:.0f} ms | "
              f"{s['p50']:.0f} ms | {s['late']} | {s['late_10s']} |")  # fmt: skip
        if args.late is None:
            continue
        rows = sorted((json.loads(x) for x in path.read_text().splitlines() if x),
                      key=lambda r: r["t"])  # fmt: skip
        for r in rows:
            lat = 1e3 * (r["viewer"] - r["t"])
            if lat > args.late:
                inbox = 1e3 * (r["received_at"] - r["t"])
                print(f"  {r['t'] - rows[0]['t']:6.2f} s {r['mat']}: {lat:.0f} ms = to the inbox "
                      f"{inbox:.0f} + in it and processed {r['processed_ms']:.0f} + to the "
                      f"viewer {lat - inbox - r['processed_ms']:.0f}")  # fmt: skip


if __name__ == "__main__":
    main()
