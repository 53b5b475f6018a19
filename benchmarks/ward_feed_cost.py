"""What the ward page's WebSocket feed costs the station, measured in-process: CPU time (this
process's, so other load on the machine does not count) of the frames and of the viewers'
feeds, and the bytes each viewer receives, for M mats of 1024 elements (32 x 32, capacitance,
the compiled pipeline) at 1 Hz and V ward viewers; beside it what the ward sent before (the
whole ward as JSON, five times a second, to every viewer).

Run:  .venv/bin/python benchmarks/ward_feed_cost.py [--seconds 10] [--loads 200,600]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from archive_scale import big_calibration
from texsense.data.layout import Layout
from texsense.station.tiles import TICK_S, WardFeed
from texsense.station.ward import MatConfig, Station


def payloads(cal, n: int = 16) -> list[str]:
    rng = np.random.default_rng(0)
    out = []
    for k in range(n):
        e = 1.0 + 0.8 * np.sin(k / 3 + np.arange(1024) / 50) + rng.normal(0, 0.01, 1024)
        cap = cal.offset_pF + cal.gain * np.interp(
            e, cal.curve_compression_mm, cal.curve_capacitance_pF
        )
        out.append(json.dumps([round(float(v), 5) for v in cap]))
    return out


def run(cal, pool: list[str], tmp: Path, mats: int, viewers: int, seconds: int) -> dict:
    st = Station(None, [MatConfig(f"m{k:03d}", Layout.grid(32, 32), cal) for k in range(mats)],
                 record_dir=tmp)  # fmt: skip
    feeds = [WardFeed(st) for _ in range(viewers)]
    ticks = round(1 / TICK_S)
    frames_cpu = feed_cpu = 0.0
    got = [0] * viewers
    tiles = [0] * viewers
    now, clock = time.time(), 0.0
    for sec in range(seconds):
        for tick in range(ticks):  # the mats' frames spread over the second
            t0 = time.process_time()
            for m in range(tick * mats // ticks, (tick + 1) * mats // ticks):
                values = pool[(sec + m) % len(pool)]
                text = f'{{"seq":{sec},"t":{now + sec:.6f},"values":{values},"unit":"pF"}}'
                st.handle(f"texsense/m{m:03d}/frames", text.encode(), now=now + clock)
            t1 = time.process_time()
            clock += TICK_S
            for k, f in enumerate(feeds):
                msg = f.message(now=clock)
                if msg is not None and sec >= 1:  # the first second holds the whole ward
                    got[k] += len(msg)
                    tiles[k] += msg.count('"map":')
            frames_cpu += t1 - t0
            feed_cpu += time.process_time() - t1
    t0 = time.process_time()
    whole = json.dumps(st.ward(), separators=(",", ":"))
    before_cpu = (time.process_time() - t0) * 5  # five times a second, once for all viewers
    n = seconds - 1
    st.stop()
    return {
        "frames_ms": 1e3 * frames_cpu / seconds,
        "feed_ms": 1e3 * feed_cpu / seconds,
        "kBps": max(got, default=0) / n / 1e3,
        "tiles": max(tiles, default=0) / n,
        "before_MBps": 5 * len(whole) / 1e6,
        "before_ms": 1e3 * before_cpu,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=int, default=10)
    ap.add_argument("--loads", default="200,600", help="mats, comma-separated")
    ap.add_argument("--viewers", default="1,10")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        cal = big_calibration(1024, tmp / "cal.json")
        pool = payloads(cal)
        print("| mats (1024 elements, 1 Hz) | ward viewers | frames: CPU ms/s | the viewers' "
              "feeds: CPU ms/s | each viewer receives | tiles/s | before: each viewer | "
              "before: CPU ms/s |")  # fmt: skip
        print("|---:|---:|---:|---:|---:|---:|---:|---:|")
        for mats in (int(v) for v in args.loads.split(",")):
            for viewers in (int(v) for v in args.viewers.split(",")):
                r = run(cal, pool, tmp / f"{mats}-{viewers}", mats, viewers, args.seconds)
                print(f"| {mats} | {viewers} | {r['frames_ms']:.0f} | {r['feed_ms']:.0f} | "
                      f"{r['kBps']:.0f} kB/s | {r['tiles']:.0f} | {r['before_MBps']:.1f} MB/s | "
                      f"{r['before_ms']:.0f} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
