"""How many 1024-element mats one station holds, through a real Mosquitto.

Run:  .venv/bin/python benchmarks/station_load.py [--quick]

For each load (mats x rate) a fresh `texsense station` (its own process) reads M mats of
32 x 32 elements (capacitance, the seat's spacer model with per-element gain and offset, the
compiled pipeline with eq. 6.14 repair) from a Mosquitto started here. A publisher process
sends every mat's frames at the rate (the mats' phases spread over the period, as
unsynchronised mats are), each stamped with its wall-clock send time as the frame time `t`.
Viewers on the WebSockets of five mats' dashboards measure frame-to-viewer latency: the time
from publishing a frame to the viewer receiving that mat's processed snapshot. At the
end `GET /api/mats` says how many frames each mat processed, against how many were published.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from archive_scale import big_calibration
from conftest import free_port
from texsense.station.broker import Broker

PUBLISHER = r"""
import json, sys, time
import numpy as np
import paho.mqtt.client as mqtt
port, mats, hz = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
seconds, cal_offsets = float(sys.argv[4]), sys.argv[5]
offsets = np.load(cal_offsets)
rng = np.random.default_rng(0)
# 16 frames of moving capacitance per mat (cycled), as JSON text of the values
pool = []
for k in range(16):
    e = 1.0 + 0.8 * np.sin(k / 3 + np.arange(1024) / 50) + rng.normal(0, 0.01, 1024)
    cap = offsets["offset"] + offsets["gain"] * np.interp(e, offsets["curve_e"], offsets["curve_c"])
    pool.append(json.dumps([round(float(v), 5) for v in cap]))
c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
c.max_queued_messages_set(0)
c.connect("127.0.0.1", port)
c.loop_start()
period = 1.0 / hz
start = time.time()
sent = 0
k = 0
while time.time() - start < seconds:
    for m in range(mats):  # the mats are not synchronised: spread over the period
        delay = start + (k + m / mats) * period - time.time()
        if delay > 0:
            time.sleep(delay)
        now = time.time()
        payload = '{"seq":%d,"t":%.6f,"values":%s,"unit":"pF"}' % (k, now, pool[(k + m) % 16])
        c.publish(f"texsense/m{m:03d}/frames", payload)
        sent += 1
    k += 1
time.sleep(0.5)
c.loop_stop()
print(json.dumps({"sent": sent, "frames_per_mat": k}))
"""


async def viewer(url: str, latencies: list[float], stop: float) -> None:
    import websockets

    async with websockets.connect(url, max_size=None) as ws:
        while time.time() < stop:
            try:
                text = await asyncio.wait_for(ws.recv(), timeout=max(0.1, stop - time.time()))
            except TimeoutError:
                break
            snap = json.loads(text)
            latencies.append(time.time() - snap["t"])


def run_load(tmp: Path, broker: Broker, mats: int, hz: float, seconds: float) -> dict:
    ward = tmp / f"ward-{mats}-{hz}.toml"
    ward.write_text("".join(
        f'[[mat]]\nid = "m{m:03d}"\nlayout = "grid:32x32"\ncalibration = "{tmp / "cal.json"}"\n\n'
        for m in range(mats)
    ))  # fmt: skip
    port = free_port()
    log = (tmp / "station.log").open("wb")
    st = subprocess.Popen(
        [sys.executable, "-m", "texsense.cli", "station", "--config", str(ward), "--broker",
         f"mqtt://127.0.0.1:{broker.port}", "--port", str(port), "--db", str(tmp / "s.sqlite"),
         "--record-dir", str(tmp / "rec")],
        stdout=log, stderr=subprocess.STDOUT,
    )  # fmt: skip
    base = f"http://127.0.0.1:{port}/"
    try:
        for _ in range(600):
            try:
                with urllib.request.urlopen(base + "api/ward", timeout=1) as r:
                    if json.load(r)["connected"]:
                        break
            except OSError:
                pass
            time.sleep(0.1)
        pub = subprocess.Popen(
            [sys.executable, "-c", PUBLISHER, str(broker.port), str(mats), str(hz),
             str(seconds), str(tmp / "cal.npz")],
            stdout=subprocess.PIPE, text=True,
        )  # fmt: skip
        latencies: list[float] = []
        stop = time.time() + seconds
        watched = [f"m{m:03d}" for m in np.linspace(0, mats - 1, min(5, mats)).astype(int)]

        async def view_all() -> None:
            await asyncio.gather(*(
                viewer(f"ws://127.0.0.1:{port}/mats/{w}/ws", latencies, stop) for w in watched
            ))  # fmt: skip

        asyncio.run(view_all())
        out, _ = pub.communicate(timeout=120)
        sent = json.loads(out)
        time.sleep(1.0)  # the station drains what is in flight
        with urllib.request.urlopen(base + "api/mats", timeout=5) as r:
            rows = json.load(r)
        processed = sum(r["frames"] for r in rows)
        lat = np.asarray(latencies[len(latencies) // 10 :]) * 1e3  # after the start
        return {
            "mats": mats, "hz": hz, "sent": sent["sent"], "processed": processed,
            "lost": sent["sent"] - processed, "p50": float(np.percentile(lat, 50)),
            "p99": float(np.percentile(lat, 99)), "views": lat.size,
        }  # fmt: skip
    finally:
        st.kill()
        st.wait()
        log.close()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--loads", help="MATSxHZ,... (default: the table of docs/station.md)")
    args = ap.parse_args()
    loads = [(100, 1.0), (200, 1.0), (300, 1.0), (400, 1.0), (20, 10.0), (40, 10.0),
             (60, 10.0), (80, 10.0)]  # fmt: skip
    if args.quick:
        loads = [(10, 1.0), (20, 10.0)]
    if args.loads:
        loads = [(int(m), float(h)) for m, h in (x.split("x") for x in args.loads.split(","))]
    with tempfile.TemporaryDirectory() as d, Broker() as broker:
        tmp = Path(d)
        cal = big_calibration(1024, tmp / "cal.json")
        c = cal["convert"]
        np.savez(tmp / "cal.npz", offset=c.offset_pF_, gain=c.gain_,
                 curve_e=c.curve_compression_mm_, curve_c=c.curve_capacitance_pF_)  # fmt: skip
        print("| mats (1024 elements) | rate | frames published | processed | lost | "
              "frame-to-viewer p50 | p99 | holds (p99 < 100 ms, none lost) |")  # fmt: skip
        print("|---:|---:|---:|---:|---:|---:|---:|---|")
        for mats, hz in loads:
            r = run_load(tmp, broker, mats, hz, args.seconds)
            ok = r["p99"] < 100 and r["lost"] == 0
            print(f"| {mats} | {hz:g} Hz | {r['sent']} | {r['processed']} | {r['lost']} | "
                  f"{r['p50']:.0f} ms | {r['p99']:.0f} ms | {'yes' if ok else 'no'} |",
                  flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
