"""Playback, the fixed colour scale, the region tool and the report button in a real headless
Chromium (Debian's, driven by Playwright) on a real ``texsense monitor`` process (issue 26).

A small recording makes the checks exact: element A reads 40 mmHg in every frame while the
frame's peak (element P) grows from 50 to 245 mmHg, and element B reads k mmHg in frame k,
so the colour of B tells which frame the map shows.

TEXSENSE_SCREENSHOT_PLAYBACK=docs/img/monitor_playback.png refreshes the screenshot of
docs/monitor.md (a virtual bed night played back, a region drawn round the sacrum).
"""

import os
import shutil
import subprocess

import numpy as np
import pytest
from test_browser import open_page

from texsense import Layout, Recording
from texsense.apps.roi import rois_path
from texsense.io import save

MMHG = 75.00615
ROWS, COLS = 8, 6
A, B, P = (1, 1), (6, 4), (4, 2)  # (row, col)


def tiny_recording(path):
    lay = Layout.grid(ROWS, COLS, pitch_cm=2.0).with_orientation("seat")
    idx = {k: lay.element_at(*rc) for k, rc in (("A", A), ("B", B), ("P", P))}
    frames = np.zeros((40, lay.n_elements))
    frames[:, idx["A"]] = 40
    frames[:, idx["B"]] = np.arange(40)
    frames[:, idx["P"]] = 50 + 5 * np.arange(40)
    meta = {"mode": "seat", "orientation": lay.orientation}
    posture = np.where(np.arange(40) < 20, "upright", "leaning left")
    save(Recording(frames / MMHG, np.arange(40.0), lay, meta=meta, labels={"posture": posture}),
         path)  # fmt: skip
    return idx


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """One monitor replaying the tiny recording for the module's tests (the region test,
    which saves regions beside it, comes last)."""
    from conftest import MonitorProcess

    tmp_path = tmp_path_factory.mktemp("tiny")
    rec_dir = tmp_path / "rec"
    rec_dir.mkdir()
    idx = tiny_recording(rec_dir / "tiny.h5")
    # a calibration beside the recordings (not one of them), and a recording that is broken
    (rec_dir / "calibration-1.json").write_text('{"format": "texsense.chain"}\n')
    (rec_dir / "person1.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 600)
    m = MonitorProcess(tmp_path, "--source", f"replay:{rec_dir / 'tiny.h5'}", "--speed", "1",
                       "--record-dir", str(rec_dir))  # fmt: skip
    try:
        m.wait_for_frames(1, timeout=60)
        yield m, rec_dir, idx
    finally:
        m.stop()


def pixel(page, element):
    """The colour (r, g, b) the map shows at the centre of ``element``."""
    return page.evaluate(
        "(i) => { const [x, y] = map.centre(i); const d = document.getElementById('heatmap')"
        ".getContext('2d').getImageData(Math.round(x), Math.round(y), 1, 1).data;"
        " return [d[0], d[1], d[2]]; }",
        element,
    )


def expected(page, mmhg):
    """The colour of ``mmhg`` on the page's fixed 0-100 mmHg scale."""
    text = page.evaluate("(v) => colourOf('viridis', v / 100)", mmhg)
    return [int(v) for v in text[4:-1].split(",")]


def open_recording(page, name):
    from playwright.sync_api import expect

    page.click(f'button.rec-open[data-name="{name}"]')
    expect(page.locator("#playback")).to_be_visible(timeout=20_000)
    expect(page.locator("#pb-frame")).to_have_text("0", timeout=20_000)


def scrub(page, frame):
    from playwright.sync_api import expect

    page.locator("#pb-scrub").fill(str(frame))
    expect(page.locator("#pb-frame")).to_have_text(str(frame), timeout=10_000)
    expect(page.locator("#heatmap")).to_have_attribute("data-frame", str(frame))


@pytest.mark.slow
def test_scrub_to_a_frame_shows_that_frame(tiny):
    from playwright.sync_api import expect

    m, _, idx = tiny
    with open_page(m.url, 1280, 1000) as (page, errors):
        page.select_option("#unit", "mmHg")
        # a replay of pressure: no "compensated" and no raw toggle (issue 33)
        expect(page.locator("#map-title")).to_have_text("pressure")
        expect(page.locator("#data-toggle")).to_be_hidden()
        # only recordings are listed; one that does not open says why on the page, and the
        # next opens (the header is not left on "opening person1.h5…")
        expect(page.locator("button.rec-open")).to_have_count(2)
        page.click('button.rec-open[data-name="person1.h5"]')
        expect(page.locator("#pb-message")).to_contain_text("person1.h5 does not open:")
        open_recording(page, "tiny.h5")
        expect(page.locator("#pb-message")).to_be_hidden()
        expect(page.locator("#source")).to_have_text("playing back tiny.h5 · 40 frames")
        for k in (17, 3, 39):
            scrub(page, k)
            assert pixel(page, idx["B"]) == expected(page, k), f"frame {k}"
        # what the recording says of the frame: its posture label and its PPI
        expect(page.locator("#posture")).to_have_text("leaning left")
        expect(page.locator("#posture-truth")).to_have_text("from the recording's label posture")
        expect(page.locator("#ppi")).to_contain_text("mmHg")
        assert errors == [], errors


@pytest.mark.slow
def test_the_same_value_has_the_same_colour_in_two_frames(tiny):
    from playwright.sync_api import expect

    m, _, idx = tiny
    with open_page(m.url, 1280, 1000) as (page, errors):
        page.select_option("#unit", "mmHg")
        # live: the scale stays 0-100 mmHg while the frames' peaks grow
        frames = page.locator("#frames")
        expect(frames).not_to_have_text("0", timeout=20_000)
        first, colour = frames.inner_text(), pixel(page, idx["A"])
        expect(frames).not_to_have_text(first, timeout=10_000)
        assert pixel(page, idx["A"]) == colour == expected(page, 40)
        expect(page.locator("#scale-text")).to_have_text("100 mmHg")
        # playback: frame 2 peaks at 60 mmHg, frame 30 at 200 mmHg; A is 40 in both
        open_recording(page, "tiny.h5")
        scrub(page, 2)
        at_2 = pixel(page, idx["A"])
        scrub(page, 30)
        assert pixel(page, idx["A"]) == at_2 == expected(page, 40)
        assert pixel(page, idx["P"]) == expected(page, 100)  # 200 mmHg: the top of the scale
        expect(page.locator("#scale-text")).to_have_text("100 mmHg")
        assert errors == [], errors


@pytest.mark.slow
def test_region_tool_and_report_button(tiny):
    from playwright.sync_api import expect

    m, rec_dir, _ = tiny
    with open_page(m.url, 1280, 1000) as (page, errors):
        page.select_option("#unit", "mmHg")
        open_recording(page, "tiny.h5")
        scrub(page, 10)
        # a box from the top left of cell (4, 1) to the bottom right of cell (6, 4): 3 x 4 cells
        page.click("#roi-box")
        x0, y0 = page.evaluate("() => map.fromCm(2.2, 8.2)")
        x1, y1 = page.evaluate("() => map.fromCm(9.8, 13.8)")
        box = page.locator("#heatmap").bounding_box()
        page.mouse.move(box["x"] + x0, box["y"] + y0)
        page.mouse.down()
        page.mouse.move(box["x"] + x1, box["y"] + y1, steps=6)
        page.mouse.up()
        row = page.locator("#roi-rows tr").first
        expect(row).to_have_attribute("data-elements", "12")
        # the region holds P (100 mmHg in frame 10) and B (10 mmHg): its peak and mean
        expect(row).to_contain_text("100 mmHg")
        expect(row).to_contain_text(f"{(100 + 10) / 12:.0f} mmHg")
        page.click("#roi-save")
        expect(page.locator("#roi-save")).to_have_text("saved ✓", timeout=10_000)
        expect(page.locator("#roi-chart")).to_be_visible()
        assert "region 1" in rois_path(rec_dir / "tiny.h5").read_text()
        with page.expect_download(timeout=60_000) as download:
            page.click("#pb-report")
        pdf = rec_dir.parent / "report.pdf"
        download.value.save_as(pdf)
        assert pdf.read_bytes().startswith(b"%PDF")
        text = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True,
                              text=True, check=True).stdout  # fmt: skip
        assert "Pressure report: tiny.h5" in text and "region 1" in text
        assert errors == [], errors


@pytest.mark.slow
def test_a_night_played_back_jumps_to_its_alerts(monitor_process, tmp_path):
    """A processed virtual bed night in the recordings folder: open it, jump to the first
    alert, draw a lasso round the place the alert names, save a screenshot."""
    from playwright.sync_api import expect

    from texsense.apps.review import open_review
    from texsense.calibration.workflows import processed_bed_night

    rec_dir = tmp_path / "rec"
    rec_dir.mkdir()
    save(processed_bed_night(hours=4.0, frame_s=60.0, seed=0), rec_dir / "night.h5")
    events = open_review(rec_dir / "night.h5").events
    alert = next(e for e in events if e["kind"] == "reposition")
    stops = sorted({e["i"] for e in events if 0 < e["i"] <= alert["i"]})  # "next event" stops
    m = monitor_process("--source", f"replay:{rec_dir / 'night.h5'}", "--speed", "600",
                        "--record-dir", str(rec_dir))  # fmt: skip
    m.wait_for_frames(1, timeout=60)
    with open_page(m.url, 1320, 1180) as (page, errors):
        open_recording(page, "night.h5")
        for stop in stops:
            page.click("#pb-next-event")
            expect(page.locator("#pb-frame")).to_have_text(str(stop), timeout=10_000)
        expect(page.locator("#events li.current")).to_contain_text("reposition alert")
        page.click("#roi-lasso")
        box = page.locator("#heatmap").bounding_box()
        cx, cy = page.evaluate("(i) => map.centre(i)", alert["detail"]["elements"][0])
        page.mouse.move(box["x"] + cx - 30, box["y"] + cy - 30)
        page.mouse.down()
        for dx, dy in ((30, -40), (34, 0), (30, 40), (0, 46), (-34, 30), (-36, 0)):
            page.mouse.move(box["x"] + cx + dx, box["y"] + cy + dy, steps=4)
        page.mouse.up()
        expect(page.locator("#roi-rows tr")).to_have_count(1)
        page.click("#roi-save")
        expect(page.locator("#roi-save")).to_have_text("saved ✓", timeout=20_000)
        page.wait_for_timeout(300)
        # the header stays on the recording (a live render used to put the live source back)
        expect(page.locator("#source")).to_have_text("playing back night.h5 · 241 frames")
        shot = tmp_path / "playback.png"
        page.screenshot(path=str(shot), full_page=True)
        assert shot.stat().st_size > 20_000
        if os.environ.get("TEXSENSE_SCREENSHOT_PLAYBACK"):
            shutil.copyfile(shot, os.environ["TEXSENSE_SCREENSHOT_PLAYBACK"])
        assert errors == [], errors


@pytest.mark.slow
def test_a_foot_replay_shows_only_the_controls_that_apply(monitor_process, shared_data):
    """A Tekscan F-Scan export replayed live (foot mode): no "compensated" title or raw
    toggle, no threshold in the legend, no posture card, and a chart whose time axis says
    seconds (it read 0:00 - 0:00 on a few seconds)."""
    from playwright.sync_api import expect

    walk = shared_data / "vendor-formats" / "fscan_testL.asf"
    m = monitor_process("--source", f"replay:{walk}", "--speed", "1")
    m.wait_for_frames(1, timeout=60)
    with open_page(m.url, 1280, 900) as (page, errors):
        expect(page.locator("#frames")).not_to_have_text("0", timeout=20_000)
        expect(page.locator("#map-title")).to_have_text("pressure")
        expect(page.locator("#data-toggle")).to_be_hidden()
        expect(page.locator("#threshold-mark")).to_be_hidden()
        expect(page.locator("#exposure-panel")).to_be_hidden()
        expect(page.locator("#posture")).to_be_hidden()  # no model, no posture on a foot
        labels = page.evaluate("() => charts.labels")
        assert labels[0] == "0.0 s" and labels[1].endswith(" s") and labels[1] != "0.0 s", labels
        if os.environ.get("TEXSENSE_SCREENSHOT_FOOT"):  # to look at, not in the docs
            page.screenshot(path=os.environ["TEXSENSE_SCREENSHOT_FOOT"], full_page=True)
        assert errors == [], errors
