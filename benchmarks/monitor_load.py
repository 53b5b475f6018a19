"""Load on the live monitor: many WebSocket viewers of a 1024-element mat at 10 frames/s.

A real `texsense monitor` process replays a capacitance recording of a 32 x 32 virtual mat
(real PhysioNet PMD lying pressure maps, pooled from 64 x 32, through the virtual sensor
with the thesis's failure rates) at real time (10 frames/s) and compensates it with the
full pipeline (calibration from zeroing + equilibration, Preisach + drift, repair). Viewers
on the same machine measure frame-to-viewer latency: receipt time minus the wall-clock time
the frame reached the monitor (``received_at`` in every snapshot). Python viewers read the
stamp from the text; the Chromium viewer is the real dashboard page (Playwright, Debian
chromium) with a listener on its WebSocket. CPU: the monitor process's user+system time
over the measuring window (/proc, Linux). The 1-viewer row is the baseline of the run.

Run:  .venv/bin/python benchmarks/monitor_load.py            (about 3 minutes)
      .venv/bin/python benchmarks/monitor_load.py --seconds 10 --viewers 1,20
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _realdata import DATA
from texsense import Layout, load
from texsense.calibration.workflows import calibrate_virtual_mat
from texsense.io import write_hdf5
from texsense.sim.failures import FailureModel
from texsense.sim.mat import VirtualMat

ROWS, COLS, FPS = 32, 32, 10.0
WARMUP_S = 3.0
STAMP = '"received_at":'


def make_recording(folder: Path, frames: int = 600, seed: int = 3) -> tuple[Path, Path]:
    """The 1024-element capacitance recording and its calibration file."""
    maps = []
    for k in range(1, 18):
        rec = load(DATA / "pmd" / "experiment-i" / "S1" / f"{k}.txt")
        maps.append(rec.frames.reshape(-1, 64, 32))
    counts = np.concatenate(maps)[:frames].astype(np.float64)
    pooled = counts.reshape(-1, ROWS, 2, COLS).mean(axis=2).reshape(-1, ROWS * COLS)
    pressure = 1.5 * pooled / np.percentile(pooled, 99.9)  # counts -> N/cm², peak ~1.5
    layout = Layout.grid(ROWS, COLS, pitch_cm=2.07, element_size_cm=2.0)

    def mat(failures: FailureModel | None = None) -> VirtualMat:
        return VirtualMat(layout, converters=128, failures=failures, seed=seed)

    times = np.arange(pressure.shape[0]) / FPS
    cap = mat(FailureModel()).scan(times, pressure).capacitance  # with per-element times
    rec_path = write_hdf5(cap, folder / "mat1024-capacitance.h5")
    cal_path = folder / "mat1024-calibration.json"
    calibrate_virtual_mat(mat()).save(cal_path)  # the same elements, before any failed
    return Path(rec_path), cal_path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Monitor:
    """`texsense monitor` replaying the recording, in its own process."""

    def __init__(self, rec: Path, cal: Path, folder: Path) -> None:
        self.port = free_port()
        cmd = [sys.executable, "-m", "texsense.cli", "monitor", f"--source=replay:{rec}"]
        cmd += ["--calibration", str(cal), "--speed", "1", "--port", str(self.port)]
        cmd += ["--db", str(folder / "load.sqlite"), "--record-dir", str(folder / "rec")]
        self.log = (folder / "monitor.log").open("wb")
        self.proc = subprocess.Popen(cmd, stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 60
        while True:
            try:
                url = f"http://127.0.0.1:{self.port}/api/status"
                with urllib.request.urlopen(url, timeout=2) as r:
                    if json.load(r)["frames"] > 0:
                        return
            except OSError:
                pass
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise SystemExit(f"the monitor did not start: see {folder / 'monitor.log'}")
            time.sleep(0.2)

    def stop(self) -> None:
        self.proc.kill()
        self.proc.wait()
        self.log.close()


async def python_viewer(port: int, until: float, out: list[tuple[float, float]]) -> None:
    """One WebSocket viewer: (receipt wall time, latency s) of every frame."""
    import websockets

    async with websockets.connect(f"ws://127.0.0.1:{port}/ws", max_size=None) as ws:
        while time.time() < until:
            try:
                text = await asyncio.wait_for(ws.recv(), timeout=max(until - time.time(), 0.01))
            except TimeoutError:
                break
            now = time.time()
            i = text.rfind(STAMP) + len(STAMP)
            j = text.find(",", i)
            out.append((now, now - float(text[i:j])))


BROWSER_HOOK = """
window.__latency = [];
const NativeWebSocket = window.WebSocket;
window.WebSocket = function (url, protocols) {
  const ws = new NativeWebSocket(url, protocols);
  ws.addEventListener("message", (m) => {
    const now = Date.now() / 1000, i = m.data.lastIndexOf('"received_at":') + 14;
    window.__latency.push([now, now - parseFloat(m.data.slice(i, m.data.indexOf(",", i)))]);
  });
  return ws;
};
"""


def browser_viewer(port: int, seconds: float) -> list[tuple[float, float]]:
    """The dashboard page in headless Chromium; latencies recorded in the page."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(
            executable_path=os.environ.get("TEXSENSE_CHROMIUM", "/usr/bin/chromium"),
            args=["--no-sandbox", "--disable-gpu", "--disable-background-networking"],
        )
        page = browser.new_page(viewport={"width": 1100, "height": 760})
        page.add_init_script(BROWSER_HOOK)
        page.goto(f"http://127.0.0.1:{port}/")
        page.wait_for_timeout(seconds * 1000)
        got = page.evaluate("window.__latency")
        browser.close()
    return [(float(a), float(b)) for a, b in got]


def measure(mon: Monitor, viewers: int, browsers: int, seconds: float) -> dict[str, float]:
    """Run ``viewers`` viewers (``browsers`` of them Chromium pages) for ``seconds``."""
    import threading

    start = time.time() + 0.5
    until = start + WARMUP_S + seconds
    py_out: list[list[tuple[float, float]]] = [[] for _ in range(viewers - browsers)]
    br_out: list[list[tuple[float, float]]] = [[] for _ in range(browsers)]

    def run_browser(k: int) -> None:
        br_out[k] = browser_viewer(mon.port, until - time.time() + 0.5)

    threads = [threading.Thread(target=run_browser, args=(k,)) for k in range(browsers)]
    for th in threads:
        th.start()

    async def all_python() -> None:
        await asyncio.gather(*(python_viewer(mon.port, until, o) for o in py_out))

    client_cpu = time.process_time()
    cpu = {"t": 0.0, "server": 0.0}

    def window() -> None:  # CPU over the measuring window only
        time.sleep(max(start + WARMUP_S - time.time(), 0))
        cpu["t"], cpu["server"] = time.time(), cpu_seconds(mon.proc.pid)

    timer = threading.Thread(target=window)
    timer.start()
    asyncio.run(all_python())
    timer.join()
    server_cpu = (cpu_seconds(mon.proc.pid) - cpu["server"]) / (time.time() - cpu["t"])
    client_cpu = (time.process_time() - client_cpu) / (time.time() - start)
    for th in threads:
        th.join()

    def kept(o: list[tuple[float, float]]) -> np.ndarray:
        return np.array([lat for t, lat in o if start + WARMUP_S <= t <= until], dtype=float)

    lat_py = [kept(o) for o in py_out]
    lat_br = [kept(o) for o in br_out]
    every = np.concatenate([*lat_py, *lat_br]) * 1e3
    per_viewer = [v.size / seconds for v in (*lat_py, *lat_br)]
    row = {
        "viewers": viewers,
        "browsers": browsers,
        "fps_min": min(per_viewer),
        "p50": float(np.percentile(every, 50)),
        "p99": float(np.percentile(every, 99)),
        "max": float(every.max()),
        "server_cpu": 100 * server_cpu,
        "client_cpu": 100 * client_cpu,
    }
    if browsers:
        b = np.concatenate(lat_br) * 1e3
        row["browser_p50"], row["browser_p99"] = np.percentile(b, [50, 99])
    return row


def processing_ms(port: int, n: int = 50) -> tuple[float, float]:
    """Median and 99th percentile of the monitor's own processing time per frame."""
    got = []
    for _ in range(n):
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/frame/latest") as r:
            got.append(json.load(r)["processed_ms"])
        time.sleep(1 / FPS)
    return float(np.median(got)), float(np.percentile(got, 99))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=30.0, help="measuring window per row")
    ap.add_argument(
        "--viewers",
        default="1,5,20,20b,40",
        help="rows: viewer counts; 'b' = one of them is the Chromium dashboard",
    )
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="texsense-load-") as tmp:
        folder = Path(tmp)
        rec, cal = make_recording(folder)
        print(
            f"replaying {ROWS * COLS} elements at {FPS:.0f} frames/s; {args.seconds:.0f} s per row"
        )
        print(
            "\n| viewers | of which Chromium | frames/s per viewer (min) | latency p50 | "
            "latency p99 | max | Chromium p50 / p99 | monitor CPU (% of a core) | "
            "viewers' CPU | p99 vs 1 viewer |"
        )
        print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        base = None
        mon = Monitor(rec, cal, folder)
        try:
            proc = processing_ms(mon.port)
            for spec in args.viewers.split(","):
                browsers = 1 if spec.endswith("b") else 0
                row = measure(mon, int(spec.rstrip("b")), browsers, args.seconds)
                base = base or row["p99"]
                chromium = (
                    f"{row['browser_p50']:.1f} / {row['browser_p99']:.1f} ms" if browsers else "–"
                )
                print(
                    f"| {row['viewers']} | {browsers} | {row['fps_min']:.1f} | "
                    f"{row['p50']:.1f} ms | {row['p99']:.1f} ms | {row['max']:.0f} ms | "
                    f"{chromium} | {row['server_cpu']:.0f} % | {row['client_cpu']:.0f} % | "
                    f"{row['p99'] / base:.2f} |",
                    flush=True,
                )
        finally:
            mon.stop()
        print(
            f"\nmonitor processing per frame (pipeline, repair, stats, alerts; without JSON): "
            f"median {proc[0]:.1f} ms, p99 {proc[1]:.1f} ms"
        )


if __name__ == "__main__":
    main()
