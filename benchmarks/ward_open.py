"""How long the ward page takes to show its mats when the station is busy (issue 33: under
20 virtual mats at 10x the page said "connecting…" for about 16 s, and later showed 17 of 20
tiles "no data").

A real ``texsense station --virtual-mats 20 --speed 10`` (its own broker; the mats simulated
in a process of their own, as on a test ward) is started and given time to get going; then the
ward page is opened in Debian's headless Chromium (Playwright) ``--opens`` times, and the time
from the request to the first tile drawn, to all 20, and to every tile showing data (live,
alert or acknowledged: none "waiting" or "no data") is taken. The baseline of the same run is
a quiet station (one virtual seat at 1x): what the machine and Chromium take anyway. Beside
it, what the stations did meanwhile (``GET /api/ward``): messages received and frames
processed per second, frames skipped to keep up, how far behind they read, and the age of the
tiles' data. With ``--before DIR`` the busy station of another checkout is measured too (its
``python`` folder first on PYTHONPATH).

    .venv/bin/python benchmarks/ward_open.py --screenshot /tmp/ward.png
"""

from __future__ import annotations

import argparse
import json
import math
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


def ward(url: str) -> dict:
    with urllib.request.urlopen(url + "api/ward", timeout=30) as r:
        return dict(json.load(r))


#: How long to wait for every tile to show data, s.
DATA_WAIT_S = 60.0
#: Every tile on the page shows data: none waiting for its first frame or without data.
ALL_SHOW_DATA = (
    "n => { const t = [...document.querySelectorAll('.tile')]; return t.length >= n && "
    "t.every(e => ['live', 'alert', 'acknowledged'].includes(e.dataset.state)); }"
)


#: The tiles not showing data (name: state).
NOT_SHOWING = (
    "() => [...document.querySelectorAll('.tile')].filter(e => !['live', 'alert', "
    "'acknowledged'].includes(e.dataset.state)).map(e => (e.dataset.id || e.id) + ': ' + "
    "e.dataset.state)"
)


def measure(
    python_dir: str | None,
    n_mats: int,
    speed: float,
    opens: int,
    warm_s: float,
    screenshot: Path | None = None,
    extra: tuple[str, ...] = (),
) -> dict:
    """Start a station, let it run ``warm_s`` after every mat has sent, open the page."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout
    from playwright.sync_api import sync_playwright

    port = free_port()
    env = dict(os.environ)
    if python_dir:
        env["PYTHONPATH"] = python_dir
    work = tempfile.mkdtemp(prefix="ward-open-")
    cmd = [sys.executable, "-m", "texsense.cli", "station", "--virtual-mats", str(n_mats),
           "--speed", str(speed), "--port", str(port), "--record-dir", work,
           "--db", f"{work}/events.sqlite", *extra]  # fmt: skip
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
        w0, t_w0 = ward(url), time.monotonic()
        first, every, data, ages, behind, shown = [], [], [], [], [], []
        late: list[list[str]] = []  # per open: the tiles not showing data when all were there
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
                late.append(page.evaluate(NOT_SHOWING))
                try:  # (the station before issue 33's fix never got there)
                    page.wait_for_function(ALL_SHOW_DATA, arg=n_mats, timeout=DATA_WAIT_S * 1e3)
                    data.append(time.monotonic() - t0)
                except PlaywrightTimeout:
                    data.append(math.inf)
                w = ward(url)
                behind.append(w.get("behind_s", math.nan))  # (not said before issue 33)
                ages += [w["wall"] - m["last_frame_wall"] for m in w["mats"] if m["frames"]]
                if screenshot is not None:
                    page.wait_for_timeout(1500)
                    page.screenshot(path=str(screenshot), full_page=True)
                    states = page.eval_on_selector_all(".tile", "t => t.map(e => e.dataset.state)")
                    shown.append(sum(s in ("live", "alert", "acknowledged") for s in states))
                page.close()
                time.sleep(2.0)
            browser.close()
        w1, span = ward(url), time.monotonic() - t_w0
        count = {k: sum(m.get(k, 0) for m in w1["mats"]) - sum(m.get(k, 0) for m in w0["mats"])
                 for k in ("messages", "frames", "behind")}  # fmt: skip
        return {"first": first, "every": every, "data": data, "ages": ages, "behind": behind,
                "shown": shown, "late": late,
                "rates": {k: v / span for k, v in count.items()}}  # fmt: skip
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def seconds(s: float) -> str:
    return f"{s:.2f} s" if math.isfinite(s) else f"never ({DATA_WAIT_S:g} s)"


def lag(s: float) -> str:
    return "–" if math.isnan(s) else f"{s:.2f} s"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, help="another checkout (its python folder is used)")
    ap.add_argument("--mats", type=int, default=20)
    ap.add_argument("--speed", type=float, default=10.0)
    ap.add_argument("--opens", type=int, default=5)
    ap.add_argument("--warm-s", type=float, default=20.0)
    ap.add_argument("--screenshot", type=Path, help="save the busy ward page here (PNG)")
    ap.add_argument("--turn-every", type=float, help="the busy station's --turn-every (min)")
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
    print("| station | first tile: median | max | all tiles: median | max | every tile showing "
          "data: median | max | first tile / baseline |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    base, load = None, []
    for k, (name, path, n, speed) in enumerate(runs):
        shot = args.screenshot if k == 1 else None
        extra = ("--turn-every", f"{args.turn_every:g}") if args.turn_every and k else ()
        r = measure(path, n, speed, args.opens, args.warm_s, shot, extra)
        first = statistics.median(r["first"])
        base = base or first
        print(f"| {name} | {first:.2f} s | {max(r['first']):.2f} s | "
              f"{statistics.median(r['every']):.2f} s | {max(r['every']):.2f} s | "
              f"{seconds(statistics.median(r['data']))} | {seconds(max(r['data']))} | "
              f"{first / base:.1f} |", flush=True)  # fmt: skip
        load.append((name, r))
    print("\n| station | messages received/s | frames processed/s | skipped to keep up/s | "
          "read behind: median | max | tiles' data age: median | max |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, r in load:
        q, a = r["rates"], r["ages"]
        print(f"| {name} | {q['messages']:.1f} | {q['frames']:.1f} | {q['behind']:.1f} | "
              f"{lag(statistics.median(r['behind']))} | {lag(max(r['behind']))} | "
              f"{statistics.median(a):.1f} s | {max(a):.1f} s |")  # fmt: skip
    for name, r in load:
        for k, (t, late) in enumerate(zip(r["data"], r["late"], strict=True)):
            if late:
                print(f"{name}, open {k + 1}: every tile showing data after {seconds(t)}; "
                      f"when all tiles were there, not yet: {', '.join(late)}")  # fmt: skip
    if args.screenshot:
        shown = load[1][1]["shown"]
        print(f"\n{args.screenshot}: tiles showing data 1.5 s after they all did, per open: "
              f"{shown} of {args.mats}")  # fmt: skip
    print(f"\nload average after the run: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
