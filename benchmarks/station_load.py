"""How many 1024-element mats one station holds, through a real Mosquitto, and what its
ward page costs.

Run:  .venv/bin/python benchmarks/station_load.py [--quick]
      .venv/bin/python benchmarks/station_load.py --loads 600x1 --ward-viewers 0,10

For each load (mats x rate) a fresh `texsense station` (its own process) reads M mats of
32 x 32 elements (capacitance, the seat's spacer model with per-element gain and offset, the
compiled pipeline with eq. 6.14 repair) from a Mosquitto started here. A publisher process
(MQTT 3.1.1 PUBLISH packets written to a plain socket, QoS 0, the frames' real JSON payload:
paho's client cost it three times the CPU, on the same two cores) sends every mat's frames at
the rate (the mats' phases spread over the period, as
unsynchronised mats are), each stamped with its wall-clock send time as the frame time `t`.
Viewers on the WebSockets of five mats' dashboards measure frame-to-viewer latency: the time
from publishing a frame to the viewer receiving that mat's processed snapshot. At the
end `GET /api/mats` says how many frames each mat processed, against how many were published.

With ``--ward-viewers``, each load is also run with that many viewers of the ward page's
WebSocket (``/ws/ward``): each counts the bytes and messages it receives after the first
5 s (the first message holds the whole ward). The row with 0 ward viewers is the baseline of
the dashboards' latency. For comparison, the column "before" is what each ward viewer
received before the ward feed sent only changed, downsampled tiles: the whole ward
(``GET /api/ward``, measured at the end of the row) five times a second.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
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
import json, socket, struct, sys, time
import numpy as np
port, mats, hz = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
seconds, cal_offsets = float(sys.argv[4]), sys.argv[5]
offsets = np.load(cal_offsets)
rng = np.random.default_rng(0)
# 16 frames of moving capacitance per mat (cycled), as JSON text of the values
pool = []
for k in range(16):
    e = 1.0 + 0.8 * np.sin(k / 3 + np.arange(1024) / 50) + rng.normal(0, 0.01, 1024)
    cap = offsets["offset"] + offsets["gain"] * np.interp(e, offsets["curve_e"], offsets["curve_c"])
    pool.append(json.dumps([round(float(v), 5) for v in cap]).encode())

def length(n):  # MQTT's remaining length (7 bits a byte)
    out = bytearray()
    while True:
        n, b = n >> 7, n & 127
        out.append(b | (128 if n else 0))
        if not n:
            return bytes(out)

# MQTT 3.1.1 over a plain socket, QoS 0 (what a mat sends): CONNECT (no keep-alive), CONNACK,
# then one PUBLISH packet per frame; nothing else runs in this process
sock = socket.create_connection(("127.0.0.1", port))
cid = b"texsense-bench-publisher"
head = b"\x00\x04MQTT\x04\x02\x00\x00" + struct.pack(">H", len(cid)) + cid
sock.sendall(b"\x10" + length(len(head)) + head)
ack = sock.recv(4)
if ack[:1] != b"\x20" or ack[3:4] != b"\x00":
    raise SystemExit(f"the broker refused the publisher: {ack!r}")
topics = [b"texsense/m%03d/frames" % m for m in range(mats)]
topics = [struct.pack(">H", len(t)) + t for t in topics]
period = 1.0 / hz
start = time.time()
cpu0 = time.process_time()
sent = 0
k = 0
while time.time() - start < seconds:
    for m in range(mats):  # the mats are not synchronised: spread over the period
        delay = start + (k + m / mats) * period - time.time()
        if delay > 0:
            time.sleep(delay)
        now = time.time()
        payload = b'{"seq":%d,"t":%.6f,"values":%s,"unit":"pF"}' % (k, now, pool[(k + m) % 16])
        body = topics[m] + payload
        sock.sendall(b"\x30" + length(len(body)) + body)
        sent += 1
    k += 1
cpu = time.process_time() - cpu0
time.sleep(0.5)
sock.sendall(b"\xe0\x00")  # DISCONNECT
sock.close()
print(json.dumps({"sent": sent, "frames_per_mat": k, "cpu_us_per_frame": 1e6 * cpu / max(sent, 1)}))
"""


async def receive(url: str, stop: float, each) -> None:
    """Call ``each(text)`` for every message of a WebSocket until ``stop`` (wall time)."""
    import websockets

    # a busy station (600 mats) may take longer than the default 10 s to answer a handshake
    async with websockets.connect(url, max_size=None, open_timeout=60) as ws:
        while time.time() < stop:
            try:
                text = await asyncio.wait_for(ws.recv(), timeout=max(0.1, stop - time.time()))
            except TimeoutError:
                break
            each(text)


async def viewer(url: str, latencies: list[float], stop: float) -> None:
    """A dashboard's viewer: the latency of each snapshot."""
    await receive(url, stop, lambda text: latencies.append(time.time() - json.loads(text)["t"]))


def count(got: dict, settle: float):
    """What a ward viewer counts of each message after ``settle`` (wall time)."""

    def each(text: str) -> None:
        if time.time() >= settle:
            got["bytes"] += len(text)
            got["messages"] += 1
            got["tiles"] += text.count('"map":')

    return each


async def ward_viewers(url: str, n: int, stop: float, settle: float) -> list[dict]:
    got = [{"bytes": 0, "messages": 0, "tiles": 0} for _ in range(n)]
    await asyncio.gather(*(receive(url, stop, count(g, settle)) for g in got))
    return got


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run_load(
    tmp: Path, broker: Broker, mats: int, hz: float, seconds: float, ward_viewers: int = 0
) -> dict:
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
        start = time.time()
        stop = start + seconds
        watched = [f"m{m:03d}" for m in np.linspace(0, mats - 1, min(5, mats)).astype(int)]
        wards_proc = None
        if ward_viewers:
            # in a process of their own: receiving megabytes a second must not slow the
            # dashboards' viewers, whose latency is measured
            wards_proc = subprocess.Popen(
                [sys.executable, __file__, "--ward-viewers-of", f"ws://127.0.0.1:{port}/ws/ward",
                 str(ward_viewers), str(stop), str(start + 5.0)],
                stdout=subprocess.PIPE, text=True,
            )  # fmt: skip

        async def station_cpu() -> None:  # the station's CPU over the measuring window
            await asyncio.sleep(5.0)
            t0, c0 = time.time(), cpu_seconds(st.pid)
            await asyncio.sleep(max(stop - time.time(), 0.0))
            cpu.append((cpu_seconds(st.pid) - c0) / (time.time() - t0))

        cpu: list[float] = []

        async def view_all() -> None:
            await asyncio.gather(*(
                viewer(f"ws://127.0.0.1:{port}/mats/{w}/ws", latencies, stop) for w in watched
            ), station_cpu())  # fmt: skip

        asyncio.run(view_all())
        out, _ = pub.communicate(timeout=120)
        sent = json.loads(out)
        wards = json.loads(wards_proc.communicate(timeout=60)[0]) if wards_proc else []
        time.sleep(1.0)  # the station drains what is in flight
        with urllib.request.urlopen(base + "api/mats", timeout=30) as r:
            rows = json.load(r)
        with urllib.request.urlopen(base + "api/ward", timeout=30) as r:
            whole_ward = len(r.read())
        processed = sum(r["frames"] for r in rows)
        window = seconds - 5.0
        ward = {
            "ward_kBps": max((w["bytes"] / window / 1e3 for w in wards), default=0.0),
            "ward_msgs": max((w["messages"] / window for w in wards), default=0.0),
            "ward_tiles": max((w["tiles"] / window for w in wards), default=0.0),
            "before_MBps": 5 * whole_ward / 1e6,
        }
        lat = np.asarray(latencies[len(latencies) // 10 :]) * 1e3  # after the start
        return {
            "mats": mats, "hz": hz, "sent": sent["sent"], "processed": processed,
            "lost": sent["sent"] - processed, "p50": float(np.percentile(lat, 50)),
            "p99": float(np.percentile(lat, 99)), "views": lat.size, **ward,
            "cpu": 100 * cpu[0] if cpu else float("nan"),
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
    ap.add_argument("--ward-viewers", default="0",
                    help="ward-page viewers, a row for each: e.g. 0,10")  # fmt: skip
    ap.add_argument("--ward-viewers-of", nargs=4, help=argparse.SUPPRESS)  # (the subprocess)
    args = ap.parse_args()
    if args.ward_viewers_of:
        url, n, stop, settle = args.ward_viewers_of
        print(json.dumps(asyncio.run(ward_viewers(url, int(n), float(stop), float(settle)))))
        return
    viewers = [int(v) for v in args.ward_viewers.split(",")]
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
        if viewers == [0]:
            print("| mats (1024 elements) | rate | frames published | processed | lost | "
                  "frame-to-viewer p50 | p99 | holds (p99 < 100 ms, none lost) |")  # fmt: skip
            print("|---:|---:|---:|---:|---:|---:|---:|---|")
        else:
            print("| mats (1024 elements) | rate | ward viewers | frames published | processed "
                  "| lost | frame-to-viewer p50 | p99 | station CPU | each ward viewer | "
                  "messages/s | tiles/s | before (whole ward 5/s) |")  # fmt: skip
            print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for mats, hz in loads:
            for n in viewers:
                r = run_load(tmp, broker, mats, hz, args.seconds, n)
                ok = r["p99"] < 100 and r["lost"] == 0
                head = f"| {mats} | {hz:g} Hz |"
                tail = (f" {r['sent']} | {r['processed']} | {r['lost']} | {r['p50']:.0f} ms | "
                        f"{r['p99']:.0f} ms |")  # fmt: skip
                if viewers == [0]:
                    print(f"{head}{tail} {'yes' if ok else 'no'} |", flush=True)
                    continue
                ward = (f" {r['ward_kBps']:.0f} kB/s | {r['ward_msgs']:.1f} | "
                        f"{r['ward_tiles']:.0f} | {r['before_MBps']:.1f} MB/s |" if n else
                        f" – | – | – | {r['before_MBps']:.1f} MB/s |")  # fmt: skip
                print(f"{head} {n} |{tail} {r['cpu']:.0f} % |{ward}", flush=True)


if __name__ == "__main__":
    main()
