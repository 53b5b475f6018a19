"""A frame's CPU cost against the number of mats a station cycles through (issue 38): M mats
of 32 x 32 elements built as `texsense station` builds them (calibration, pipeline, tracker),
then F frames of each fed through `Station.handle` in turn, as a member reads them (mat 1's
frame, mat 2's, ..., then every mat's next), in one process without a broker; CPU ms per
frame and the collector's full collections (generation 2, timed by `gc.callbacks`) meanwhile.

Run:  .venv/bin/python benchmarks/station_mats_cost.py --mats 100,500,1000 --frames 40

Each count runs in a process of its own. ``--no-freeze`` leaves what was built in the
collector's full collections (what `texsense station` freezes out of them: freeze_built).
"""

from __future__ import annotations

import argparse
import gc
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from archive_scale import big_calibration
from station_frame_cost import payloads


def one(mats: int, frames: int, freeze: bool) -> dict:
    from texsense.compensation.stages import load_chain
    from texsense.data.layout import Layout
    from texsense.station.ward import MatConfig, Station

    with tempfile.TemporaryDirectory() as d:
        cal0 = big_calibration(1024, Path(d) / "cal.json")
        cal = load_chain(str(Path(d) / "cal.json"))
        configs = [MatConfig(f"m{k:04d}", Layout.grid(32, 32), cal, "capacitance", "mqtt", 20.0)
                   for k in range(mats)]  # fmt: skip
        station = Station(None, configs, record_dir=d)
        pay = payloads(cal0, 1024, frames)
        if freeze:
            gc.collect()
            gc.freeze()
        pauses: list[float] = []
        started = [0.0]

        def timed(phase: str, info: dict) -> None:
            if info["generation"] == 2:
                if phase == "start":
                    started[0] = time.perf_counter()
                else:
                    pauses.append(1e3 * (time.perf_counter() - started[0]))

        gc.callbacks.append(timed)
        c0 = time.process_time()
        for f in range(frames):
            for k in range(mats):
                station.handle(f"texsense/m{k:04d}/frames", pay[f], 1000.0 + f)
        cpu = time.process_time() - c0
        gc.callbacks.remove(timed)
    return {"mats": mats, "ms": 1e3 * cpu / (mats * frames), "pauses": pauses}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mats", default="100,500,1000")
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--no-freeze", action="store_true")
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one is not None:
        print(json.dumps(one(args.one, args.frames, not args.no_freeze)))
        return
    print("| mats | frames each | CPU per frame (ms) | full collections | their pauses (ms) |")
    print("|---:|---:|---:|---:|---|")
    for m in (int(v) for v in args.mats.split(",")):
        cmd = [sys.executable, __file__, "--one", str(m), "--frames", str(args.frames)]
        out = subprocess.run(cmd + (["--no-freeze"] if args.no_freeze else []),
                             capture_output=True, text=True, check=True)  # fmt: skip
        r = json.loads(out.stdout.strip().splitlines()[-1])
        pauses = ", ".join(f"{p:.0f}" for p in r["pauses"]) or "–"
        print(f"| {m} | {args.frames} | {r['ms']:.3f} | {len(r['pauses'])} | {pauses} |",
              flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
