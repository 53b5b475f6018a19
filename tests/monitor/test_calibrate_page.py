"""The monitor page's calibration steps through the API (docs/monitor.md, "Calibrate from the
page"): `texsense monitor --source serial:LINK` on a virtual device with no calibration;
the test puts the loads on the mat by writing them to the device's standard input, as
`texsense simulate device` reads them, and runs the steps as the page's buttons do."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from test_browser import open_page

from conftest import MonitorProcess
from texsense import load
from texsense.compensation.stages.chain import load_chain

#: The device's speed: a frame every 1.6 s / 20 = 0.08 s.
SPEED = "20"


class Device:
    """``texsense simulate device`` as a child process whose load the test changes."""

    def __init__(self, tmp_path: Path, link: str = "ttyTEX0") -> None:
        self.link = tmp_path / link
        cmd = [sys.executable, "-m", "texsense.cli", "simulate", "device", "--mat", "seat",
               "--link", link, "--speed", SPEED, "--load", "empty"]  # fmt: skip
        pipes = {"stdin": subprocess.PIPE, "stdout": subprocess.PIPE, "stderr": subprocess.STDOUT}
        self.proc = subprocess.Popen(cmd, cwd=tmp_path, text=True, **pipes)
        deadline = time.monotonic() + 30
        while not self.link.is_symlink():
            assert self.proc.poll() is None, self.proc.stdout.read()
            assert time.monotonic() < deadline, "the device did not come up"
            time.sleep(0.05)

    def load(self, text: str) -> int:
        """Change the load; the device's sequence number of the first frame under it."""
        self.proc.stdin.write(text + "\n")
        self.proc.stdin.flush()
        said = f"load {text} from frame "
        while True:  # the device says when it changed the load ("load X from frame N")
            line = self.proc.stdout.readline()
            assert line, f"the device exited ({self.proc.poll()})"
            if said in line:
                return int(line.split(said)[1].split()[0])

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        self.proc.communicate(timeout=10)


class Page:
    """The calls the panel makes."""

    def __init__(self, mon: MonitorProcess, device: Device) -> None:
        self.mon, self.device = mon, device

    def post(self, path: str, body: dict | None = None, headers: dict | None = None):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.mon.url + path, data=data, method="POST")
        req.add_header("Content-Type", "application/json")
        for k, v in (headers or {}).items():
            req.add_header(k, v)
        try:
            with urllib.request.urlopen(req, timeout=60) as r:
                return r.status, json.load(r)
        except urllib.error.HTTPError as e:
            return e.code, json.load(e)

    def state(self) -> dict:
        return self.mon.get("api/calibration")

    def put(self, load: str, settle: int = 6) -> None:
        """Change the load and wait until the monitor has processed ``settle`` frames under
        it (by the device's sequence numbers: a monitor behind its serial line on a busy
        machine is waited for)."""
        first = self.device.load(load)
        self.mon.until(
            lambda: self.mon.get("api/frame/latest")["seq"], lambda s: s >= first + settle, 60
        )

    def step(self, step: str, pressure: str | None = None, frames: int = 10) -> dict:
        status, body = self.post(f"api/calibration/record/{step}",
                                 {"frames": frames, "pressure": pressure})  # fmt: skip
        assert status == 200, body
        return self.mon.until(self.state, lambda s: step in s["done"] and s["busy"] is None, 60)


@pytest.fixture
def page(tmp_path, monitor_process):
    device = Device(tmp_path)
    mon = monitor_process("--source", f"serial:{device.link}", "--record-dir",
                          str(tmp_path / "rec"))  # fmt: skip
    mon.wait_for_frames(3, timeout=60)
    yield Page(mon, device)
    mon.stop()
    device.stop()


def test_the_steps_calibrate_the_running_monitor(page, tmp_path):
    s = page.state()
    assert s["available"] and not s["calibrated"] and s["done"] == []
    assert s["default_material"] == "textile-3mm"  # what the device announced
    assert "foam-7mm" in s["presets"]
    # the device announces how the mat lies on its serial line: the maps name its edges
    assert page.mon.get("api/view")["orientation"]["top"] == "front"
    assert s["orientation"]["top"] == "front"
    # a person says the seat lies the other way round: the live map follows at once
    status, s = page.post("api/calibration/orientation", {"kind": "seat", "edge": "bottom"})
    assert status == 200 and s["orientation"]["top"] == "back", s
    assert page.mon.get("api/view")["orientation"]["left"] == "right"
    status, body = page.post("api/calibration/orientation", {"kind": "seat", "edge": "press"})
    assert status == 409 and "empty mat (step 1)" in body["detail"]

    s = page.step("zero")
    assert s["recordings"]["zero"]["frames"] == 10 and s["recording"] is None
    page.put("uniform:1.0")
    s = page.step("uniform", "1 N/cm2")
    rec = s["recordings"]
    assert rec["uniform"]["pressure_ncm2"] == 1.0
    assert rec["uniform"]["median_pF"] > rec["zero"]["median_pF"] + 0.05

    status, s = page.post("api/calibration/fit", {"material": s["default_material"]})
    assert status == 200, s
    assert s["done"] == ["zero", "uniform", "material"] and s["refused"] is None
    assert s["fit"]["material"] == "textile-3mm"
    assert {"convert", "hysteresis"} <= set(s["fit"]["stages"])
    assert 0.5 < s["fit"]["gain"][0] <= s["fit"]["gain"][1] < 2.0
    assert all(f["level"] == "warn" for f in s["findings"])

    page.put("uniform:1.5")
    status, s = page.post("api/calibration/record/check?wait=true",
                          {"frames": 10, "pressure": "15 kPa"})  # fmt: skip
    assert status == 200 and s["done"][-1] == "check" and s["busy"] is None, s
    check = s["check"]
    assert check["pressure_ncm2"] == pytest.approx(1.5)
    assert check["working"] == 96 and len(check["error"]) == 96
    assert abs(check["mat_median_ncm2"] / 1.5 - 1) < 0.15, check["lines"]
    off = {o["element"] for o in check["off"]}  # the errors are rounded to 4 decimals
    assert all(abs(e) >= 0.0999 for k, e in enumerate(check["error"]) if k in off)
    assert all(abs(e) <= 0.1001 for k, e in enumerate(check["error"]) if k not in off)
    print("\n".join(check["lines"]))

    status, s = page.post("api/calibration/save")
    assert status == 200, s
    saved = s["saved"]
    cal = Path(saved["calibration"])
    assert cal.parent == tmp_path / "rec" and cal.name.startswith("calibration-")
    assert load_chain(cal).id == saved["calibration_id"] and saved["checked"]
    assert load_chain(cal).orientation["top"] == "back"  # how the mat lies, kept with it
    for step in ("zero", "uniform", "check"):
        r = load(saved["recordings"][step])
        assert r.n_frames == 10 and r.unit == "pF" and r.meta["spacer"] == "textile-3mm"
        assert r.meta["calibration_step"] == step and np.all(np.diff(r.times) > 0)
    assert s["calibrated"] and page.mon.status()["calibration_id"] == saved["calibration_id"]

    # the running monitor now shows pressure (its spacer model starts at rest: the check
    # load, the highest so far, is on the curve of first loading)
    page.mon.wait_for_frames(page.mon.status()["frames"] + 3)
    snap = page.mon.get("api/frame/latest")
    assert snap["calibrated"] is True
    p = np.array([v for v in snap["pressure"] if v is not None])
    assert p.size >= 90 and abs(np.median(p) / 1.5 - 1) < 0.15, np.median(p)
    events = page.mon.get("api/events?kind=calibrated")
    assert len(events) == 1 and events[0]["detail"]["file"] == str(cal)
    assert "now showing pressure" in page.mon.log()
    # the check load still lies on the mat: nobody sat down (issue 33); the mat emptied,
    # then a person: that is a sitter
    assert page.mon.get("api/events?kind=seated") == []
    page.put("empty")
    page.put("uniform:1.0")
    page.mon.until(lambda: page.mon.get("api/events?kind=seated"), lambda e: len(e) == 1, 30)


def test_a_second_calibration_takes_a_new_name(page, tmp_path):
    names = []
    for _ in range(2):
        page.put("empty")
        page.step("zero", frames=6)
        page.put("uniform:1.0")
        page.step("uniform", "10 kPa", frames=6)
        status, s = page.post("api/calibration/fit", {"material": "textile-3mm"})
        assert status == 200, s
        status, s = page.post("api/calibration/save")
        assert status == 200, s
        assert not s["saved"]["checked"]
        names.append(Path(s["saved"]["calibration"]).name)
    assert names[0] != names[1] and all((tmp_path / "rec" / n).is_file() for n in names)
    assert len(list((tmp_path / "rec").glob("calibration-*.h5"))) == 4


@pytest.mark.slow
def test_the_panel_in_headless_chromium(page, tmp_path):
    """The panel as a user meets it: shown by itself (no calibration), step 1 recorded with
    the load still on, so the fit is refused and the reason shown; step 1 again, then the
    load, the fit, the check map and "save and use": the map shows pressure. A screenshot of
    the panel is saved (TEXSENSE_SCREENSHOT_CALIBRATION=docs/img/monitor_calibration.png
    refreshes the one in docs/monitor.md)."""
    from playwright.sync_api import expect

    page.put("uniform:1.0")
    with open_page(page.mon.url, 1400, 900) as (web, errors):
        panel = web.locator("#calibration")
        expect(panel).to_be_visible(timeout=20_000)  # no calibration: the panel comes up
        expect(web.locator("#uncalibrated")).to_be_visible()
        expect(web.locator("#cal-material")).to_have_value("textile-3mm")
        expect(web.locator("#cal-uniform")).to_be_disabled()
        web.fill("#cal-frames", "8")
        # how the mat lies: announced by the device, shown, and set on the panel
        expect(web.locator("#cal-orient-status")).to_contain_text("top front")
        web.select_option("#cal-edge", "bottom")
        web.click("#cal-orient")
        expect(web.locator("#cal-orient-status")).to_contain_text("top back", timeout=10_000)
        web.select_option("#cal-edge", "top")
        web.click("#cal-orient")
        expect(web.locator("#cal-orient-status")).to_contain_text("top front", timeout=10_000)

        web.click("#cal-zero")  # the load is still on: a wrong "empty" mat
        expect(web.locator("#cal-zero-status")).to_contain_text("8 frames", timeout=30_000)
        page.put("empty")
        web.click("#cal-uniform")
        expect(web.locator("#cal-uniform-status")).to_contain_text("8 frames", timeout=30_000)
        web.click("#cal-fit")
        message = web.locator("#cal-message")
        expect(message).to_be_visible(timeout=30_000)
        expect(message).to_contain_text("calibration refused")
        expect(message).to_contain_text("swapped")
        expect(web.locator("#cal-findings")).to_contain_text("refused: the reasons above")
        expect(web.locator("#cal-check")).to_be_disabled()

        web.click("#cal-zero")  # again, empty this time
        expect(message).to_be_hidden()
        expect(web.locator("#cal-step-uniform")).not_to_have_class("cal-step done")
        expect(web.locator("#cal-zero-status")).to_contain_text("8 frames", timeout=30_000)
        page.put("uniform:1.0")
        web.fill("#cal-pressure", "10 kPa")
        web.click("#cal-uniform")
        expect(web.locator("#cal-uniform-status")).to_contain_text("at 1.000 N/cm²", timeout=30_000)
        web.click("#cal-fit")
        expect(web.locator("#cal-findings")).to_contain_text("fitted textile-3mm", timeout=30_000)
        page.put("uniform:1.5")
        web.fill("#cal-check-pressure", "15 kPa")
        web.click("#cal-check")
        report = web.locator("#cal-report")
        expect(report).to_contain_text("for 1.500 (median", timeout=30_000)
        expect(report).to_contain_text("Worst: e")
        expect(web.locator("#cal-map")).to_be_visible()
        expect(web.locator("#cal-step-check")).to_have_class("cal-step done")
        expect(web.locator("#map-title")).to_have_text("raw readings")
        web.wait_for_timeout(300)
        panel.screenshot(path=str(tmp_path / "panel.png"))
        assert (tmp_path / "panel.png").stat().st_size > 10_000
        shot = tmp_path / "calibration.png"  # the page: header, notice, panel, raw map
        web.screenshot(path=str(shot))
        if os.environ.get("TEXSENSE_SCREENSHOT_CALIBRATION"):
            shutil.copyfile(shot, os.environ["TEXSENSE_SCREENSHOT_CALIBRATION"])

        web.click("#cal-save")
        expect(web.locator("#cal-saved")).to_contain_text("in use: ", timeout=30_000)
        expect(web.locator("#map-title")).to_have_text("pressure (compensated)", timeout=20_000)
        expect(web.locator("#uncalibrated")).to_be_hidden()
        expect(web.locator("#show-pressure")).to_be_enabled()
        expect(web.locator("#cal-save")).to_be_disabled()
        expect(web.locator("#events")).to_contain_text("calibration in use", timeout=10_000)
        web.click("#cal-close")
        expect(panel).to_be_hidden()
        web.click("#calibrate")  # reachable again from the header
        expect(panel).to_be_visible()
        assert errors == [], errors
    saved = page.state()["saved"]
    assert Path(saved["calibration"]).is_file()


#: what a page with no calibration must not show anywhere in its scale, cards and legend
PRESSURE_UNITS = ("mmHg", "N/cm", "kPa")


@pytest.mark.slow
def test_a_page_without_calibration_shows_no_pressure(page, tmp_path):
    """A new mat, not yet calibrated, with a person on it: the page shows the raw readings in
    pF (the scale "pF above ..."), scale presets for raw readings only, the cards the raw
    rise and the elements responding (load and PPI "–" with a link to calibrate), no unit
    selector, exposure or threshold, and no pressure unit in the scale, the cards or the
    legend. A screenshot is saved (TEXSENSE_SCREENSHOT_RAW=docs/img/monitor_raw.png
    refreshes the one in docs/monitor.md). Then a calibration made and used through the
    panel's API: the same page switches to pressure with its units, presets and cards."""
    from playwright.sync_api import expect

    page.put("person")  # somebody sits on the mat: the readings rise above the empty ones
    with open_page(page.mon.url, 1280, 1000) as (web, errors):
        expect(web.locator("#map-title")).to_have_text("raw readings", timeout=20_000)
        web.click("#cal-close")  # the panel comes up by itself; look at the dashboard
        expect(web.locator("#calibration")).to_be_hidden()
        expect(web.locator("#scale-text")).to_have_text(re.compile(r"^\d+\.\d+ pF above \d+\.\d+$"))
        expect(web.locator("#peak-label")).to_have_text("peak rise")
        expect(web.locator("#peak")).to_have_text(re.compile(r"^\d+\.\d+ pF$"))
        expect(web.locator("#area-label")).to_have_text("elements responding")
        expect(web.locator("#area")).to_have_text(re.compile(r"^\d+ of 96$"))
        expect(web.locator("#load")).to_have_text("–")
        expect(web.locator("#ppi")).to_have_text("–")
        expect(web.locator("#raw-cards-note")).to_contain_text("calibrate to see pressure")
        expect(web.locator("#unit")).to_be_hidden()  # no pressure unit to choose
        # no "compensated" toggle that does nothing; the map knows how the mat lies (its
        # device announces it on the serial line) and names its edges
        expect(web.locator("#data-toggle")).to_be_hidden()
        edges = web.evaluate("() => [map.orientation.top, map.orientation.left]")
        assert edges == ["front", "left"], edges
        expect(web.locator("#exposure-panel")).to_be_hidden()
        expect(web.locator("#threshold-note")).to_have_text("")
        options = "os => os.map(o => o.textContent)"
        presets = web.eval_on_selector_all("#scale-preset option", options)
        assert presets == ["fixed at the highest so far", "my range"], presets
        peak = float(web.inner_text("#peak").split()[0])
        responding = int(web.inner_text("#area").split()[0])
        assert peak > 0.1 and responding > 10, (peak, responding)  # the person is seen
        snap = page.mon.get("api/frame/latest")
        assert snap["raw_stats"]["unit"] == "pF" and snap["stats"]["load_N"] is None
        # the colour scale goes to the highest rise so far: the range boxes say the same
        # (both read in one go: the highest so far rises with every live frame)
        box, text = web.evaluate(
            "() => [document.querySelector('#scale-max').value,"
            " document.querySelector('#scale-text').innerText]"
        )
        assert float(box) == pytest.approx(float(text.split()[0]), abs=0.011)
        parts = ("section.map .legend", ".scale-controls", ".cards", "#raw-cards-note", ".marks")
        shown = {sel: web.inner_text(sel) for sel in parts}
        for sel, text in shown.items():
            assert not any(u in text for u in PRESSURE_UNITS), (sel, text)
        web.wait_for_timeout(300)
        shot = tmp_path / "raw.png"
        web.screenshot(path=str(shot))
        if os.environ.get("TEXSENSE_SCREENSHOT_RAW"):
            shutil.copyfile(shot, os.environ["TEXSENSE_SCREENSHOT_RAW"])
        web.click("#calibrate-hint")  # the hint opens the calibration panel
        expect(web.locator("#calibration")).to_be_visible()

        # a calibration made, saved and used through the API the panel calls
        page.put("empty")
        page.step("zero", frames=6)
        page.put("uniform:1.0")
        page.step("uniform", "1 N/cm2", frames=6)
        status, s = page.post("api/calibration/fit", {"material": "textile-3mm"})
        assert status == 200, s
        status, s = page.post("api/calibration/save")
        assert status == 200 and s["calibrated"], s
        expect(web.locator("#map-title")).to_have_text("pressure (compensated)", timeout=20_000)
        expect(web.locator("#unit")).to_be_visible()
        web.select_option("#unit", "mmHg")
        expect(web.locator("#scale-text")).to_have_text(re.compile(r"^\d+ mmHg$"))
        expect(web.locator("#peak-label")).to_have_text("peak")
        expect(web.locator("#peak")).to_have_text(re.compile(r"^\d+ mmHg$"))
        expect(web.locator("#ppi")).to_have_text(re.compile(r"^\d+ mmHg$"))
        expect(web.locator("#load")).to_have_text(re.compile(r"^\d+ N$"))
        expect(web.locator("#area-label")).to_have_text("contact area")
        expect(web.locator("#area")).to_have_text(re.compile(r"^\d+ cm²$"))
        expect(web.locator("#raw-cards-note")).to_be_hidden()
        expect(web.locator("#exposure-panel")).to_be_visible()
        expect(web.locator("#threshold")).to_contain_text("mmHg")
        expect(web.locator("#scale-preset")).to_contain_text("seat: 0–100 mmHg")
        web.select_option("#unit", "kPa")
        expect(web.locator("#peak")).to_have_text(re.compile(r"^\d+ kPa$"))
        # the raw view of a calibrated mat: the raw presets, the unit choice still there
        web.click("#show-raw")
        expect(web.locator("#scale-text")).to_contain_text("pF above")
        expect(web.locator("#scale-preset")).not_to_contain_text("mmHg")
        web.click("#show-pressure")
        expect(web.locator("#scale-text")).to_have_text(re.compile(r"^\d+ kPa$"))
        assert errors == [], errors
