"""``texsense report`` (docs/report.md) on a real PMD subject, a real Tekscan export and a
processed virtual bed night: a PDF of several pages whose tables are text (read back with
Debian's ``pdftotext``), the HTML, the regions saved with a recording, and the numbers in
the tables checked against the recording itself."""

import os
import re
import shutil
import subprocess

import numpy as np
import pytest

from report_layout import check_layout
from texsense import Layout, Recording, load
from texsense.apps.report import write_report
from texsense.apps.review import open_review
from texsense.apps.roi import save_rois
from texsense.cli import main
from texsense.io import save


def pdf_text(path) -> str:
    exe = shutil.which("pdftotext")
    if exe is None:
        pytest.fail("pdftotext is missing: install Debian's poppler-utils (scripts/test.sh does)")
    return subprocess.run([exe, "-layout", str(path), "-"], capture_output=True, text=True,
                          check=True).stdout  # fmt: skip


def pages(path) -> int:
    return pdf_text(path).count("\f")


@pytest.fixture(scope="module")
def night(tmp_path_factory):
    """4 h of a simulated person on the virtual bed, a frame a minute, through the mat and
    the pipeline (positions held 20 min to 2 h: turns), as a monitor would record it."""
    from texsense.calibration.workflows import processed_bed_night

    path = tmp_path_factory.mktemp("night") / "night.h5"
    save(processed_bed_night(hours=4.0, frame_s=60.0, seed=0), path)
    return path


def test_report_of_a_pmd_subject(shared_data, tmp_path):
    subject = shared_data / "pmd" / "experiment-i" / "S2"
    out = tmp_path / "s2.pdf"
    assert main(["report", str(subject), "-o", str(out)]) == 0
    text = pdf_text(out)
    assert check_layout(out, tmp_path) == pages(out) == 3  # as docs/report.md says
    for words in ("Pressure report: S2", "Vista Medical FSA SoftFlex 2048", "raw in count",
                  "head (assumed)", "Time per side", "posture_class", "Sensor health"):  # fmt: skip
        assert words in text, words
    rec = load(subject)
    assert f"{rec.n_frames} frames" in text
    assert f"{int((~rec.labels['reliable']).sum())} frames the reader labels unreliable" in text
    # the turns in the table are the changes of the file's side (17 files back to back)
    review = open_review(rec)
    cls = rec.labels["posture_class"]
    changes = int(np.sum(cls[1:] != cls[:-1]))
    assert 0 < review.sides["turns"] <= changes
    assert re.search(rf"^\s*turns\s+{review.sides['turns']}\s*$", text, re.MULTILINE)


def test_report_of_a_tekscan_export(shared_data, tmp_path):
    src = shared_data / "vendor-formats" / "fscan_testL.asf"
    out = tmp_path / "fscan.html"
    write_report(src, out)
    html = out.read_text()
    assert '<td class="l">foot</td>' in html and "kPa" in html
    assert "2017-02-16 11:26:22" in html  # the export's own start time
    assert html.count("data:image/png;base64,") == 3
    pdf = tmp_path / "fscan.pdf"
    write_report(src, pdf)
    text = pdf_text(pdf)
    assert "0-600 kPa (fixed)" in text and "tekscan-ascii" in text


def test_report_of_a_virtual_night_with_regions(night, tmp_path):
    save_rois(night, [{"name": "my heel box", "kind": "box", "points": [[30, 140], [50, 162]]}])
    out = tmp_path / "night.pdf"
    assert main(["report", str(night), "-o", str(out)]) == 0
    text = pdf_text(out)
    assert check_layout(out, tmp_path) == pages(out)
    review = open_review(night)
    assert "my heel box" in text and "region(s) of interest drawn by the user" in text
    assert "calibration id" in text and load(night).meta["calibration_id"] in text
    assert "0-100 mmHg (fixed)" in text and "32 mmHg held 20 min" in text
    # the events table lists what the review recomputed, with their places
    for e in review.events:
        assert e["text"].split(":")[0] in text
    alerts = [e for e in review.events if e["kind"] == "reposition"]
    assert alerts and all(e["detail"]["where"] for e in alerts)
    # regions in the alert's words, the grid positions on a details line under it (issue 33)
    assert not any(re.search(r"\b(row|column)s? \d", e["text"]) for e in alerts)
    placed = [e["places"] for e in alerts if e["places"]]
    assert placed and all(p.startswith("also row") for p in placed)
    assert placed[0][: placed[0].index(",")] in text
    assert review.sides["turns"] >= 1 and f"{review.sides['turns']} turn(s)" in text
    # per side, the at-risk regions found on that side's mean map
    sides = [s for s in review.sides["time_per_side_s"] if s != "transition"]
    assert any(f"({s})" in text for s in sides)


def test_region_numbers_match_the_recording(tmp_path):
    """A 2 x 2 mat: the region table's mean, peak and time above the threshold by hand."""
    lay = Layout.grid(2, 2, pitch_cm=2.0)
    mmhg = np.array([[10, 50, 0, 0], [20, 60, 0, 0], [30, 20, 0, 0]], float)
    rec = Recording(mmhg / 75.00615, [0.0, 60.0, 120.0], lay, meta={"mode": "seat"})
    path = tmp_path / "tiny.h5"
    save(rec, path)
    rois = [{"name": "top row", "kind": "box", "points": [[0, 0], [4, 2]]}]
    out = tmp_path / "tiny.html"
    write_report(path, out, rois=rois)
    html = out.read_text()
    row = html.split("top row</td>")[1].split("</tr>")[0]
    cells = [c.split(">")[1].split("<")[0] for c in row.split("<td")[1:]]
    # elements, area, mean of the loaded frames' means (30, 40, 25), highest, time > 32 mmHg
    assert cells == ["2", "8", "32", "60", "2 min"]


def test_report_refuses_to_replace_its_input(night, tmp_path, capsys):
    copy = tmp_path / "n.h5"
    shutil.copyfile(night, copy)
    before = copy.read_bytes()
    assert main(["report", str(copy), "-o", str(tmp_path / "n.h5")]) == 1
    assert "a report is .pdf or .html" in capsys.readouterr().err
    assert copy.read_bytes() == before


def live_seat_recording(folder):
    """20 min of the virtual seat's person through the monitor (reposition after 5 min), the
    recording started once an alert had been raised: what a nurse records."""
    import asyncio

    from texsense.apps.alerts import ExposureTracker
    from texsense.calibration.workflows import seat_calibration
    from texsense.compensation.pipeline import Pipeline
    from texsense.monitor import Monitor
    from texsense.monitor.virtual import VirtualSeatSource

    source = VirtualSeatSource(speed=0, hold_s=300.0)
    tracker = ExposureTracker(source.layout, reposition_min=5)
    pipeline = Pipeline(seat_calibration(), source.layout)
    m = Monitor(source, pipeline=pipeline, tracker=tracker, record_dir=folder)
    wall = 1_767_250_800.0  # 2026-01-01 07:00 (UTC): the wall clock of a real mat

    async def run() -> list[str]:
        paths: list[str] = []
        async for frame in source.frames():
            m.process(frame, wall=wall + frame.t)
            if not paths and m.tracker.open_alert is not None:
                paths = m.start_recording("seat")
            if frame.t > 20 * 60:
                m.stop_recording()
                return paths
        return paths

    return asyncio.run(run())[-1]


@pytest.mark.skipif(os.environ.get("TEXSENSE_REPORT_PAGES") is None, reason="docs images only")
def test_render_report_pages_for_the_docs(night, shared_data, tmp_path):
    """TEXSENSE_REPORT_PAGES=docs/img renders the first pages of three reports as PNG."""
    target = os.environ["TEXSENSE_REPORT_PAGES"]
    seat = live_seat_recording(tmp_path)
    for name, src in (("night", night), ("pmd", shared_data / "pmd/experiment-i/S2"),
                      ("seat", seat)):  # fmt: skip
        out = f"/tmp/report-{name}.pdf"
        write_report(src, out)
        subprocess.run(["pdftoppm", "-r", "70", "-png", "-f", "1", "-l", "3", out,
                        f"{target}/report_{name}"], check=True)  # fmt: skip


def test_tables_run_on_with_their_title_and_head_and_never_onto_an_empty_page():
    from texsense.apps.report._pdf import _LINE, _paginate

    rows = [("row", f"r{i}") for i in range(30)]
    lines = [("title", "A"), ("head", "h"), *rows, ("row", ""), ("title", "B"), ("head", "hb"),
             ("row", "x"), ("row", "")]  # fmt: skip
    pages = _paginate(lines, 10.5 * _LINE, 25 * _LINE)
    assert [p[:2] for p in pages] == [
        [("title", "A"), ("head", "h")],
        *[[("title", "A (continued)"), ("head", "h")]] * 2,
    ]
    assert sum(p.count(("title", "B")) for p in pages) == 1
    assert sum(p.count(r) for p in pages for r in rows) == 30  # every row once
    assert pages[-1][-1] == ("row", "x")  # no blank line ends the report, no page of it
    # a title with too little room under it for its head and a row starts the next page
    pages = _paginate(lines[33:], 3.5 * _LINE, 25 * _LINE)
    assert pages[0] == [] and pages[1][0] == ("title", "B")


def test_health_finds_a_dead_element_inside_the_load_not_the_edges():
    from texsense.apps.review_events import element_health

    lay = Layout.grid(8, 8)
    m = np.zeros((20, 8, 8))
    m[:, 2:6, 2:6] = np.linspace(0.5, 1.0, 20)[:, None, None]  # a loaded square, edges empty
    m[:, 3, 4] = 0.0  # a dead element inside it
    valid = np.ones((20, 64), bool)
    valid[5:10, lay.element_at(0, 0)] = False  # a reading flagged invalid for 5 frames
    h = element_health(Recording(lay.from_grid(m), np.arange(20.0), lay, valid=valid))
    assert np.flatnonzero(h["silent"]).tolist() == [lay.element_at(3, 4)]
    assert h["invalid_share"][lay.element_at(0, 0)] == 0.25 and h["invalid_share"].sum() == 0.25


def test_out_of_bed_says_how_long_the_bed_was_empty_when_it_came_not_for_how_long() -> None:
    # a night's report read "out of bed (for 1 min)" for a person out of bed 9 min: after_s
    # is the offload time the event waits for
    from texsense.apps.review_events import event_text

    text = event_text("out-of-bed", {"after_s": 60.0})
    assert text == "out of bed (empty for 1 min by then)" and "(for " not in text


def test_the_summary_names_the_exposure_alert_in_the_modes_words() -> None:
    # a bed's report counted "1 reposition" where the dashboard and docs/report.md's mode table
    # say a bed's exposure alert asks for a turn: the pressure alert
    from types import SimpleNamespace

    from texsense.apps.report._content import _alert_count
    from texsense.apps.views import MODES

    events = [{"kind": "reposition", "source": "recomputed"}]
    counts = {m: _alert_count(SimpleNamespace(events=events, mode=MODES[m])) for m in MODES}
    assert counts["seat"] == "1 reposition, 0 turn due"
    assert counts["bed"] == "1 pressure alert, 0 turn due"
    assert counts["generic"] == "1 offload alert, 0 turn due"


def test_the_colour_bar_labels_the_threshold_as_a_tick_of_its_own_in_bold() -> None:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from texsense.apps.report._figures import colour_bar

    fig = Figure()
    ax, cax = fig.add_axes((0.1, 0.1, 0.6, 0.8)), fig.add_axes((0.75, 0.1, 0.05, 0.8))
    img = ax.imshow(np.linspace(0, 100, 20).reshape(4, 5), vmin=0, vmax=100)
    colour_bar(fig, img, cax, "pressure [mmHg]", 32.0)
    labels = {t.get_text(): t.get_fontweight() for t in cax.get_yticklabels()}
    assert labels.get("32") == "bold", labels
    assert "40" not in labels  # too close to the threshold: gives way
    assert {"0", "20", "60", "80", "100"} <= set(labels)


def test_a_processed_night_with_bounds_shows_the_bounds_of_its_peak(tmp_path):
    """``process --interval`` keeps the bounds of every value; the report's peak over time
    gets its own: each frame's peak lies between them, and the band has a width."""
    night, cal, out = tmp_path / "night.h5", tmp_path / "mat.json", tmp_path / "out.h5"
    truth = tmp_path / "truth.h5"
    assert main(["simulate", "night", "--hours", "0.15", "--seed", "3", "-o", str(night),
                 "--truth", str(truth), "--calibration", str(cal)]) == 0  # fmt: skip
    assert main(["process", str(night), "--calibration", str(cal), "-o", str(out),
                 "--interval", "0.95"]) == 0  # fmt: skip
    s = open_review(out).series
    assert "load_N_lower" not in s  # (the sums of the bounds: every error aligned)
    for key in ("peak",):
        lo, v, hi = s[f"{key}_lower"], s[key], s[f"{key}_upper"]
        seen = np.isfinite(v)
        assert seen.sum() > 10
        assert np.all(lo[seen] <= v[seen] * (1 + 1e-5) + 1e-6), key
        assert np.all(v[seen] <= hi[seen] * (1 + 1e-5) + 1e-6), key
        assert np.nanmax(hi - lo) > 0, key
    write_report(out, tmp_path / "out.pdf")
    assert open_review(night).series.get("peak_lower") is None  # no bounds: no band


def test_the_bounds_of_the_peak_count_the_readings_the_statistics_count():
    """The bounds of the peak (``review._bounds_series``) over the readings the statistics
    count (``stats._values``: valid and finite): a recording with invalid, NaN and infinite
    readings, a frame with none counted and one not used gives the numbers of the mask made
    on its own (finite and valid), to the bit."""
    from types import SimpleNamespace

    from texsense.apps.review import _bounds_series

    rng = np.random.default_rng(5)
    frames = rng.uniform(0, 2, (12, 20)).astype(np.float32)
    frames[1, :4] = [np.nan, np.inf, -np.inf, np.nan]
    frames[3] = np.nan
    valid = rng.random((12, 20)) > 0.2
    valid[5] = False
    valid[7, :] = np.isnan(frames[7])  # only NaN readings flagged valid: none counted
    frames[7, :3] = np.nan
    valid[7, :3] = True
    valid[1, :4] = True  # flagged valid, not finite: not counted
    lo = frames - rng.uniform(0, 0.3, frames.shape).astype(np.float32)
    hi = frames + rng.uniform(0, 0.3, frames.shape).astype(np.float32)
    lo[1, 1] = lo[2, 6] = hi[1, 1] = hi[2, 6] = 9.0  # above every other, on readings not counted
    valid[2, 6] = False
    rec = Recording(frames, np.arange(12.0), Layout.grid(4, 5), valid=valid)
    use = np.ones(12, bool)
    use[9] = False
    review = SimpleNamespace(rec=rec, bounds=(lo, hi), use=use, factor=75.006)
    got = _bounds_series(review)  # type: ignore[arg-type]

    counted = np.isfinite(rec.frames) & rec.valid  # the mask as it was made before
    any_read = counted.any(axis=1) & use
    for name, maps in (("lower", lo), ("upper", hi)):
        want = np.full(12, np.nan)
        m = np.where(counted[any_read], maps[any_read].astype(np.float64), -np.inf)
        want[any_read] = m.max(axis=1) * 75.006
        assert got[f"peak_{name}"].view(np.uint64).tolist() == want.view(np.uint64).tolist()
    assert np.isnan(got["peak_lower"][[3, 5, 7, 9]]).all()
    assert np.isfinite(got["peak_lower"][[0, 1, 2, 4]]).all()
