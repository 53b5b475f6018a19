"""Cost of one frame on the station's event-loop thread: a 32 x 32 mat's MQTT payloads fed to
``MatEntry.handle`` directly (no broker), profiled, and split into JSON parsing, the frame
statistics, the compiled pipeline's ``step`` and the rest.

Run:  .venv/bin/python benchmarks/station_frame_cost.py [--frames N]
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from archive_scale import big_calibration
from texsense.data.layout import Layout
from texsense.monitor.store import EventStore
from texsense.station.ward import MatConfig, MatEntry

PARTS = {
    "JSON parsing": ("loads",),
    "frame statistics": ("frame_stats",),
    "pipeline step": ("step",),
}


def payloads(cal, n: int, frames: int) -> list[bytes]:
    rng = np.random.default_rng(0)
    out = []
    for k in range(frames):
        x = 1.0 + 0.8 * np.sin(k / 3 + np.arange(n) / 50) + rng.normal(0, 0.01, n)
        conv = cal["convert"]
        cap = conv.offset_pF_ + conv.gain_ * np.interp(
            x, conv.curve_compression_mm_, conv.curve_capacitance_pF_
        )
        values = [round(float(v), 5) for v in cap]
        out.append(json.dumps({"seq": k, "t": float(k), "values": values, "unit": "pF"}).encode())
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        cal = big_calibration(1024, Path(tmp) / "cal.json")
        entry = MatEntry(
            MatConfig("m1", Layout.grid(32, 32), cal), EventStore(":memory:"), Path(tmp), 0.5
        )
        data = payloads(cal, 1024, args.frames)
        profile = cProfile.Profile()
        t0 = time.perf_counter()
        profile.enable()
        for k, p in enumerate(data):
            entry.handle(p, float(k))
        profile.disable()
        total = (time.perf_counter() - t0) / args.frames * 1e3
    stats = pstats.Stats(profile).stats  # {(file, line, name): (cc, nc, tt, ct, callers)}
    print("| part | ms per frame |")
    print("|---|---:|")
    named = 0.0
    for part, names in PARTS.items():
        ms = sum(v[3] for k, v in stats.items() if k[2] in names) / args.frames * 1e3
        named += ms
        print(f"| {part} | {ms:.2f} |")
    print(f"| rest (monitor bookkeeping) | {max(total - named, 0.0):.2f} |")
    print(f"| total (with profiler overhead) | {total:.2f} |")


if __name__ == "__main__":
    main()
