"""What a station behind pays for a frame it skims (issue 38): CPU per frame of a mat's MQTT
payloads fed to ``MatEntry.handle`` directly (no broker) when each is processed in full,
followed (``skim=True``: the pipeline, the exposure and its alerts, no snapshot:
:meth:`texsense.monitor.live.Monitor.follow`) or only peeked at for its time (``peek=True``,
what a station more than ``FOLLOW_S`` behind does). A virtual seat (96 elements, the
station's pipeline with in-use drift and bounds) and a 32 x 32 mat; the three ways
alternate, best of ``--rounds``, in one process on the same machine.

Run:  .venv/bin/python benchmarks/station_follow_cost.py [--frames N] [--rounds R]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from archive_scale import big_calibration
from station_frame_cost import payloads as grid_payloads
from texsense.calibration.workflows import seat_calibration
from texsense.data.layout import Layout
from texsense.monitor.store import EventStore
from texsense.monitor.virtual import VirtualSeatSource
from texsense.station.virtual import VirtualMats, frame_payload
from texsense.station.ward import MatConfig, MatEntry

WAYS = {"processed": {}, "followed": {"skim": True}, "peeked": {"skim": True, "peek": True}}


def seat(frames: int) -> tuple[MatConfig, list[bytes]]:
    config = VirtualMats(1, None).configs(seat_calibration(), None)[0]
    src = VirtualSeatSource(speed=0, seed=3)

    async def take() -> list[bytes]:
        out: list[bytes] = []
        async for f in src.frames():
            out.append(frame_payload(f))
            if len(out) == frames:
                break
        return out

    return config, asyncio.run(take())


def grid(frames: int, folder: Path) -> tuple[MatConfig, list[bytes]]:
    cal = big_calibration(1024, folder / "cal.json")
    return MatConfig("g", Layout.grid(32, 32), cal), grid_payloads(cal, 1024, frames)


def cost(config: MatConfig, data: list[bytes], way: dict, folder: Path) -> float:
    """CPU ms per frame over ``data`` (the first frame processed in full, not counted)."""
    entry = MatEntry(config, EventStore(":memory:"), folder, 1.0)
    entry.handle(data[0], 1000.0)
    t0 = time.process_time()
    for k, p in enumerate(data[1:], 1):
        entry.handle(p, 1000.0 + k, **way)
    return 1e3 * (time.process_time() - t0) / (len(data) - 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        mats = {"virtual seat (96)": seat(args.frames), "32 x 32 mat": grid(args.frames, folder)}
        print("| mat | " + " | ".join(f"{w} (ms)" for w in WAYS) + " | followed / processed |")
        print("|---|" + "---:|" * (len(WAYS) + 1))
        for name, (config, data) in mats.items():
            best = {w: min(cost(config, data, WAYS[w], folder) for _ in range(args.rounds))
                    for w in WAYS}  # fmt: skip
            row = " | ".join(f"{best[w]:.3f}" for w in WAYS)
            print(f"| {name} | {row} | {best['followed'] / best['processed']:.2f} |")


if __name__ == "__main__":
    main()
