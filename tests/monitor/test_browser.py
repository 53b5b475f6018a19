"""The dashboard in a real headless Chromium (Debian ``chromium``, driven by Playwright):
`texsense monitor` on the virtual seat, the frame counter grows, raw/compensated toggles,
an alert band that is not rendered without an alert, comes up with its text and button, and
shows the acknowledged text without the button after acknowledge; a screenshot is saved.

Set TEXSENSE_SCREENSHOT=docs/img/monitor_dashboard.png to refresh the one in docs/monitor.md.
"""

import atexit
import os
import queue
import re
import shutil
import subprocess
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from texsense import load

CHROMIUM = os.environ.get("TEXSENSE_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--disable-background-networking",
    "--no-first-run",
]


def chromium() -> str:
    """The Chromium binary, or a failure that says how to get it (never a silent skip)."""
    if not (Path(CHROMIUM).is_file() and os.access(CHROMIUM, os.X_OK)):
        found = shutil.which("chromium")
        if found is None:
            pytest.fail(
                f"no Chromium at {CHROMIUM}: install Debian's `chromium` (scripts/test.sh does "
                "when it may use apt-get) or point TEXSENSE_CHROMIUM at one"
            )
        return found
    return CHROMIUM


_SHARED: dict[str, Any] = {}


def shared_chromium() -> str:
    """The DevTools address of the one headless Chromium every page of this test process
    opens in (started on first use, stopped when the process exits): a Chromium per test
    cost a launch each. The Playwright driver itself is not kept between tests, as its
    event loop would stay current and break the tests that run their own (asyncio.run)."""
    proc = _SHARED.get("proc")
    if proc is not None and proc.poll() is None:
        return str(_SHARED["ws"])
    profile = tempfile.mkdtemp(prefix="texsense-chromium-")
    proc = subprocess.Popen(
        [chromium(), "--headless", "--remote-debugging-port=0", f"--user-data-dir={profile}",
         *CHROMIUM_ARGS, "about:blank"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    lines: queue.Queue[str] = queue.Queue()
    reader = threading.Thread(target=lambda: [lines.put(x) for x in proc.stderr], daemon=True)
    reader.start()
    seen: list[str] = []
    while True:
        try:
            line = lines.get(timeout=60)
        except queue.Empty:
            proc.kill()
            pytest.fail(f"Chromium gave no DevTools address in 60 s: {''.join(seen[-5:])}")
        seen.append(line)
        found = re.search(r"DevTools listening on (ws://\S+)", line)
        if found:
            break
    _SHARED.update(proc=proc, ws=found.group(1))
    atexit.register(_stop_chromium, proc, reader, profile)
    return found.group(1)


def _stop_chromium(proc: subprocess.Popen, reader: threading.Thread, profile: str) -> None:
    """Stop it, let the reader of its error output see the end, close that pipe (left open,
    it was the `ResourceWarning: unclosed file` at each test worker's exit)."""
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    reader.join(timeout=10)
    if proc.stderr is not None and not reader.is_alive():
        proc.stderr.close()
    shutil.rmtree(profile, ignore_errors=True)


@contextmanager
def open_page(url: str, width: int, height: int):
    """A page at ``url`` in a fresh context (its own cookies and storage) of the shared headless
    Chromium (:func:`shared_chromium`), and the list its script errors go to."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.connect_over_cdp(shared_chromium())
        context = browser.new_context(viewport={"width": width, "height": height})
        try:
            page = context.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(url)
            yield page, errors
        finally:
            context.close()
            browser.close()  # disconnects: the shared Chromium runs on


@pytest.fixture()
def monitor_url(tmp_path, monitor_process):
    rec_dir = str(tmp_path / "rec")
    m = monitor_process("--speed", "60", "--reposition-min", "5", "--record-dir", rec_dir)
    m.wait_for_frames(1, timeout=180)  # the first run trains the virtual seat's model
    return m.url


@pytest.mark.slow
def test_dashboard_in_headless_chromium(monitor_url, tmp_path):
    from playwright.sync_api import expect

    with open_page(monitor_url, 1180, 830) as (page, errors):
        frames = page.locator("#frames")
        expect(frames).not_to_have_text("0", timeout=20_000)
        first = int(frames.inner_text())
        # the charts open with the history the monitor holds, not "the last 1 frames"
        shown = int(page.locator("#chart-note").inner_text().split()[2])
        assert shown > 1 and shown >= min(first, 1200) // 2, (shown, first)
        # no alert yet (5 min of exposure at 60x takes longer than the page load): the
        # band must not be rendered at all, not merely be empty (issue 18)
        status = page.request.get(monitor_url + "api/status").json()
        assert status["alert"] is None, f"alert before the no-alert check: {status['alert']}"
        alert = page.locator("#alert")
        expect(alert).to_be_hidden()
        assert alert.bounding_box() is None
        page.wait_for_timeout(1500)
        assert int(frames.inner_text()) > first, "the frame counter does not grow"
        # the peak chart's bounds band (the monitor runs with bounds by default): pixels of
        # the band's fill over the chart's background, in the peak's row (the second of four)
        band = page.evaluate(
            """() => {
              const c = document.getElementById("charts"), d = c.getContext("2d")
                .getImageData(0, 0, c.width, c.height).data, rowH = c.height / 4;
              let n = 0;
              for (let y = Math.floor(rowH); y < 2 * rowH; y++) for (let x = 0; x < c.width; x++) {
                const i = 4 * (y * c.width + x);
                const near = (k, v) => Math.abs(d[i + k] - v) < 6;
                if (near(0, 210) && near(1, 223) && near(2, 242)) n++;
              }
              return n;
            }"""
        )
        assert band > 200, f"{band} pixels of the peak's bounds band"

        title = page.locator("#map-title")
        expect(title).to_have_text("pressure (compensated)")
        page.click("#show-raw")
        expect(title).to_have_text("raw readings")
        expect(page.locator("#show-raw")).to_have_class("on")
        expect(page.locator("#scale-text")).to_contain_text("pF")
        page.click("#show-pressure")
        expect(title).to_have_text("pressure (compensated)")
        page.select_option("#unit", "mmHg")
        expect(page.locator("#scale-text")).to_contain_text("mmHg")

        expect(page.locator("#posture")).to_contain_text("%", timeout=20_000)
        expect(alert).to_be_visible(timeout=60_000)  # 5 min of exposure at 60x: ~5 s
        expect(page.locator("#alert-text")).to_contain_text("Reposition")
        expect(page.locator("#ack")).to_be_visible()
        expect(page.locator("#events")).to_contain_text("reposition alert", timeout=5_000)
        page.wait_for_timeout(300)
        shot = tmp_path / "monitor.png"
        page.screenshot(path=str(shot))
        assert shot.stat().st_size > 20_000
        if os.environ.get("TEXSENSE_SCREENSHOT"):
            shutil.copyfile(shot, os.environ["TEXSENSE_SCREENSHOT"])

        page.click("#ack")
        expect(alert).to_have_class("alert acked", timeout=5_000)
        expect(alert).to_be_visible()
        expect(page.locator("#alert-text")).to_contain_text("acknowledged")
        expect(page.locator("#ack")).to_be_hidden()
        expect(page.locator("#events")).to_contain_text("alert acknowledged", timeout=5_000)

        record = page.locator("#record")
        record.click()
        expect(record).to_have_text("■ stop recording", timeout=5_000)
        page.wait_for_timeout(500)
        record.click()
        expect(record).to_have_text("● record", timeout=5_000)
        files = page.request.get(monitor_url + "api/sessions").json()[0]["recordings"]
        assert len(files) == 2 and all(Path(f).is_file() for f in files)
        assert load(files[1]).n_frames > 0
        assert errors == [], errors
    # the recording began after the alert: its report lists the alert, open at the start,
    # at the time it fired, and its acknowledgement as the monitor raised them (issue 33)
    from texsense.apps.report import write_report

    html = write_report(files[1], tmp_path / "recording.html").read_text()
    assert "reposition alert (open when the recording started)" in html
    assert "1 reposition (1 open when the recording started)" in html


@pytest.mark.slow
def test_bed_dashboard_in_headless_chromium(monitor_process, tmp_path):
    """`texsense monitor --source virtual-bed`: the turning schedule panel, the at-risk
    regions, time per side and "Turn now" (a 15 min schedule, positions held 18 min or more;
    a pressure alert after 5 min above 32 mmHg comes first: waiting for the schedule took over
    90 s on a busy machine). TEXSENSE_SCREENSHOT_BED=docs/img/monitor_bed.png refreshes the
    one in docs/bed.md."""
    from playwright.sync_api import expect

    m = monitor_process("--source", "virtual-bed", "--speed", "600", "--turn-every", "15",
                        "--reposition-min", "5",
                        "--record-dir", str(tmp_path / "rec"))  # fmt: skip
    m.wait_for_frames(1, timeout=300)  # the first run trains the virtual bed's side model
    assert m.status()["bed"] is True
    with open_page(m.url, 1180, 1000) as (page, errors):
        expect(page.locator("#bed")).to_be_visible(timeout=20_000)
        expect(page.locator("#regions li").first).to_be_visible(timeout=20_000)
        expect(page.locator("#sides .side-row").first).to_be_visible()
        expect(page.locator("#since-turn")).not_to_have_text("–")
        # one vocabulary (issue 33): the schedule's band or the pressure alert says "Turn
        # now", the card then says "turn now" with why, never "next turn due in 1 h 18 min"
        turn_now = page.locator("#turn-alert-text:visible, #alert-text:visible")
        expect(turn_now.first).to_contain_text("Turn now", timeout=90_000)
        expect(page.locator("#due-label")).to_have_text("turn")
        expect(page.locator("#due-in")).to_have_text("now")
        expect(page.locator("#due-why")).to_contain_text(re.compile("schedule: due|pressure alert"))
        expect(page.locator("#events")).to_contain_text(
            re.compile("turn due|reposition alert"), timeout=5_000
        )
        if page.locator("#alert").is_visible():  # a pressure alert names regions, no cells
            assert not re.search(r"\b(row|column)s? \d", page.locator("#alert-text").inner_text())
        # no card is cut ("41 min 41…"): every value fits its card
        fits = "(e) => e.scrollWidth <= e.clientWidth + 1"
        assert page.evaluate(f"[...document.querySelectorAll('.card .v')].every({fits})")
        page.select_option("#unit", "mmHg")
        expect(page.locator("#regions")).to_contain_text("mmHg")
        # the in-use drift correction with the age of its last check (issue 37): the state
        # the monitor serves, and one made up to read the words of a check 1.5 h old
        expect(page.locator("#in-use")).to_contain_text("drift corrected in use")
        shown = page.locator("#in-use").inner_text()
        assert "load" not in shown or "checked against" in shown, shown  # when correcting
        state = (
            "{state: 'correcting', load_correction: -0.05, since_t: 600, still_s: 3000, "
            "zeroed: 1, weight_n: 700, weighed: 2, checked_t: 4000, checked_age_s: 5400}"
        )
        words = page.evaluate(f"inUseText({state})")
        assert words.endswith("; last checked against the weight 1 h 30 min ago"), words
        page.wait_for_timeout(300)
        shot = tmp_path / "bed.png"
        page.screenshot(path=str(shot))
        assert shot.stat().st_size > 20_000
        if os.environ.get("TEXSENSE_SCREENSHOT_BED"):
            shutil.copyfile(shot, os.environ["TEXSENSE_SCREENSHOT_BED"])
        assert errors == [], errors
