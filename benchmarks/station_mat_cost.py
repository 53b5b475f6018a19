"""CPU per frame of the station for a virtual bed and a virtual seat, as ``texsense station
--virtual-mats`` runs them: the simulated mats' MQTT payloads (made first, not timed) fed to
``MatEntry.handle`` with the station's calibrations and side model, the CPU time per frame
taken (``time.process_time``, best of ``--repeat`` passes over the same frames, each on a new
mat) and, with ``--profile``, the functions that took it.

With ``--before DIR`` the same frames go through the station of another checkout too (its
``python`` folder first on PYTHONPATH, in a child process), and the ratio after / before is
printed: both in the same run on the same machine.

    .venv/bin/python benchmarks/station_mat_cost.py [--frames 300] [--before DIR]
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import json
import os
import pickle
import pstats
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

SPEED = 10.0  # the ward benchmark's simulated time per wall second


def make_payloads(kind: str, frames: int, seed: int) -> list[tuple[bytes, float]]:
    """``frames`` payloads of a virtual ``kind`` ("seat"/"bed") mat and their arrival times
    at SPEED."""
    from texsense.monitor.virtual import VirtualBedSource, VirtualSeatSource
    from texsense.station.virtual import frame_payload

    src = (
        VirtualSeatSource(speed=0, seed=seed)
        if kind == "seat"
        else VirtualBedSource(speed=0, seed=seed, hold_s=360.0)
    )

    async def take() -> list[tuple[bytes, float]]:
        out = []
        async for f in src.frames():
            out.append((frame_payload(f), float(f.element_times[0]) / SPEED))
            if len(out) == frames:
                return out
        return out

    return asyncio.run(take())


def entry(kind: str, tmp: Path) -> Any:
    """A station's entry of a virtual mat of ``kind``, configured as ``texsense station``."""
    from texsense.calibration.workflows import bed_calibration, seat_calibration
    from texsense.commands.monitor import virtual_bed_model
    from texsense.monitor.store import EventStore
    from texsense.station.virtual import VirtualMats
    from texsense.station.ward import MatEntry

    vm = VirtualMats(2, None, speed=SPEED)
    beds = bed_calibration()
    configs = vm.configs(seat_calibration(), beds, 20.0, virtual_bed_model(beds.id), 120.0)
    config = configs[0 if kind == "seat" else 1]
    return MatEntry(config, EventStore(":memory:"), tmp, 0.5)


def measure(data: dict[str, list[tuple[bytes, float]]], repeat: int, profile: bool) -> dict:
    """CPU ms per frame per kind (best of ``repeat`` passes; with ``profile`` one more pass
    under cProfile, printed and not counted)."""
    out: dict[str, dict] = {}
    for kind, payloads in data.items():
        best, done = float("inf"), 0
        for r in range(repeat + int(profile)):
            with tempfile.TemporaryDirectory() as tmp:
                e = entry(kind, Path(tmp))
                prof = cProfile.Profile() if r == repeat else None
                t0 = time.process_time()
                if prof is not None:
                    prof.enable()
                done = sum(e.handle(p, now) for p, now in payloads)
                t = time.process_time() - t0
                if prof is None:
                    best = min(best, t)
                    continue
                prof.disable()
                print(f"--- {kind}: {1e3 * t / len(payloads):.2f} ms/frame with the profiler")
                pstats.Stats(prof).sort_stats("cumulative").print_stats(35)
        out[kind] = {"ms": 1e3 * best / len(payloads), "frames": len(payloads), "done": done}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--before", type=Path, help="another checkout, measured in the same run")
    parser.add_argument("--child", type=Path, help=argparse.SUPPRESS)  # payloads in, result out
    args = parser.parse_args()
    if args.child:
        data = pickle.loads(args.child.read_bytes())
        args.child.with_suffix(".out").write_text(json.dumps(measure(data, args.repeat, False)))
        return
    data = {k: make_payloads(k, args.frames, args.seed) for k in ("seat", "bed")}
    before = None
    if args.before:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "payloads.pkl"
            path.write_bytes(pickle.dumps(data))
            env = {**os.environ, "PYTHONPATH": str(args.before.resolve() / "python")}
            cmd = [sys.executable, __file__, "--child", str(path), "--repeat", str(args.repeat)]
            subprocess.run(cmd, env=env, check=True, cwd=args.before)
            before = json.loads(path.with_suffix(".out").read_text())
    after = measure(data, args.repeat, args.profile)
    print(f"load average {os.getloadavg()[0]:.1f} (2 cores, shared)")
    head = "| mat | frames | CPU per frame |"
    if before:
        head += " before | after / before |"
    print(head)
    print("|---|---:|---:|" + ("---:|---:|" if before else ""))
    for kind in data:
        row = f"| {kind} | {after[kind]['frames']} | {after[kind]['ms']:.2f} ms |"
        if before:
            b = before[kind]["ms"]
            row += f" {b:.2f} ms | {after[kind]['ms'] / b:.2f} |"
        print(row)


if __name__ == "__main__":
    main()
