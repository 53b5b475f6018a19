"""Cost of one frame on the station's event-loop thread: a 32 x 32 mat's MQTT payloads fed to
``MatEntry.handle`` directly (no broker), profiled, and split into JSON parsing, the frame
statistics, the compiled pipeline's ``step`` and the rest.

Run:  .venv/bin/python benchmarks/station_frame_cost.py [--frames N]

With ``--before DIR`` (another checkout's ``python`` folder, with its compiled core) the CPU
time of a frame and of a mat's checkpoint (taken and packed), without the profiler, best of 3
passes, is printed for that checkout and this one, alternating ``--rounds`` times, each in a
child process: the two in the same run on the same machine.
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

#: part -> (file, function) profiled (cumulative time: what it calls included)
PARTS = {
    "payload parsing (JSON, values)": ("data/protocol.py", "parse_mqtt_payload"),
    "frame statistics": ("monitor/live.py", "_stats_of"),
    "pipeline step": ("compensation/pipeline.py", "step"),
    "exposure and alerts": ("monitor/live.py", "_exposure"),
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


def plain(frames: int) -> None:
    """One line of JSON: this checkout's CPU ms per frame and per checkpoint."""
    from texsense.station import checkpoint

    with tempfile.TemporaryDirectory() as tmp:
        cal = big_calibration(1024, Path(tmp) / "cal.json")
        data = payloads(cal, 1024, frames + 20)
        best = []
        for _ in range(3):
            entry = MatEntry(
                MatConfig("m1", Layout.grid(32, 32), cal), EventStore(":memory:"), Path(tmp), 0.5
            )
            for k, p in enumerate(data[:20]):
                entry.handle(p, float(k))
            t0 = time.process_time()
            for k, p in enumerate(data[20:]):
                entry.handle(p, float(k + 20))
            best.append((time.process_time() - t0) / frames * 1e3)
        t0 = time.process_time()
        for _ in range(100):
            checkpoint.take(entry, often=True).pack()
        ck = (time.process_time() - t0) / 100 * 1e3
    print(json.dumps({"frame_ms": round(min(best), 3), "checkpoint_ms": round(ck, 3)}))


def before_after(before: str, frames: int, rounds: int) -> None:
    import os
    import subprocess

    print("| round | frame, before (ms CPU) | after | checkpoint, before | after |")
    print("|---:|---:|---:|---:|---:|")
    for k in range(rounds):
        got = []
        for path in (before, str(Path(__file__).resolve().parents[1] / "python")):
            env = {**os.environ, "PYTHONPATH": path}
            out = subprocess.run([sys.executable, __file__, "--plain", "--frames", str(frames)],
                                 env=env, capture_output=True, text=True, check=True)  # fmt: skip
            got.append(json.loads(out.stdout.strip().splitlines()[-1]))
        print(f"| {k + 1} | {got[0]['frame_ms']} | {got[1]['frame_ms']} | "
              f"{got[0]['checkpoint_ms']} | {got[1]['checkpoint_ms']} |", flush=True)  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--before", help="another checkout's python folder")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--plain", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.plain:
        plain(args.frames)
        return
    if args.before:
        before_after(args.before, args.frames, args.rounds)
        return
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
    for part, (file, name) in PARTS.items():
        ms = sum(v[3] for k, v in stats.items() if k[0].endswith(file) and k[2] == name)
        ms = ms / args.frames * 1e3
        named += ms
        print(f"| {part} | {ms:.2f} |")
    print(f"| rest (monitor bookkeeping) | {max(total - named, 0.0):.2f} |")
    print(f"| total (with profiler overhead) | {total:.2f} |")


if __name__ == "__main__":
    main()
