"""How long the ward page takes to show its mats when the station is busy (issue 33: under
20 virtual mats at 10x the page said "connecting…" for about 16 s).

A real ``texsense station --virtual-mats 20 --speed 10`` (its own broker; the mats simulated
in the same process, as on a test ward) is started and given time to get going; then the ward
page is opened in Debian's headless Chromium (Playwright) ``--opens`` times, and the time from
the request to the first tile drawn and to all 20 is taken. The baseline of the same run is a
quiet station (one virtual seat at 1x): what the machine and Chromium take anyway. With
``--before DIR`` the busy station of another checkout is measured too (its ``python`` folder
first on PYTHONPATH), e.g. the commit before the station drained its messages in slices.

    .venv/bin/python benchmarks/ward_open.py --before /tmp/before
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

CHROMIUM = os.environ.get("TEXSENSE_CHROMIUM", "/usr/bin/chromium")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def mats(url: str) -> list[dict]:
    with urllib.request.urlopen(url + "api/mats", timeout=30) as r:
        return list(json.load(r))


def measure(
    python_dir: str | None,
    n_mats: int,
    speed: float,
    opens: int,
    warm_s: float,
    screenshot: Path | None = None,
) -> dict:
    """Start a station, let it run ``warm_s`` after every mat has sent, open the page."""
    from playwright.sync_api import sync_playwright

    port = free_port()
    env = dict(os.environ)
    if python_dir:
        env["PYTHONPATH"] = python_dir
    work = tempfile.mkdtemp(prefix="ward-open-")
    cmd = [sys.executable, "-m", "texsense.cli", "station", "--virtual-mats", str(n_mats),
           "--speed", str(speed), "--port", str(port), "--record-dir", work,
           "--db", f"{work}/events.sqlite"]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=work, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)  # fmt: skip
    url = f"http://127.0.0.1:{port}/"
    try:
        deadline = time.monotonic() + 600
        while True:
            try:
                if all(m["frames"] > 2 for m in mats(url)):
                    break
            except OSError:
                pass
            assert proc.poll() is None and time.monotonic() < deadline, "the station did not start"
            time.sleep(1.0)
        time.sleep(warm_s)
        first, every = [], []
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
            for _ in range(opens):
                page = browser.new_page(viewport={"width": 1400, "height": 900})
                t0 = time.monotonic()
                page.goto(url, wait_until="commit", timeout=120_000)
                page.locator(".tile").first.wait_for(timeout=120_000)
                first.append(time.monotonic() - t0)
                page.wait_for_function(f"document.querySelectorAll('.tile').length >= {n_mats}",
                                       timeout=120_000)  # fmt: skip
                every.append(time.monotonic() - t0)
                if screenshot is not None:
                    page.wait_for_timeout(1500)
                    page.screenshot(path=str(screenshot))
                page.close()
                time.sleep(2.0)
            browser.close()
        return {"first": first, "every": every}
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, help="another checkout (its python folder is used)")
    ap.add_argument("--mats", type=int, default=20)
    ap.add_argument("--speed", type=float, default=10.0)
    ap.add_argument("--opens", type=int, default=5)
    ap.add_argument("--warm-s", type=float, default=20.0)
    ap.add_argument("--screenshot", type=Path, help="save the busy ward page here (PNG)")
    args = ap.parse_args()
    runs = [
        ("quiet: 1 mat at 1x (baseline)", None, 1, 1.0),
        (f"busy: {args.mats} mats at {args.speed:g}x", None, args.mats, args.speed),
    ]
    if args.before:
        runs.append((f"busy, before ({args.before})", str(args.before / "python"), args.mats,
                     args.speed))  # fmt: skip
    load = os.getloadavg()[0]
    print(f"the ward page opened {args.opens} times per station; load average {load:.1f} on "
          f"{os.cpu_count()} cores\n")  # fmt: skip
    print(
        "| station | first tile: median | max | all tiles: median | max | first tile / baseline |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    base = None
    for k, (name, path, n, speed) in enumerate(runs):
        shot = args.screenshot if k == 1 else None
        r = measure(path, n, speed, args.opens, args.warm_s, shot)
        first = statistics.median(r["first"])
        base = base or first
        print(f"| {name} | {first:.2f} s | {max(r['first']):.2f} s | "
              f"{statistics.median(r['every']):.2f} s | {max(r['every']):.2f} s | "
              f"{first / base:.1f} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
