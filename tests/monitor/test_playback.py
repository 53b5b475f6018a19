"""The dashboard's views (issue 26) without a browser: the modes' words and events, places
named in alerts, the mat's name on event log lines, the playback API on HDF5 and vendor
files, regions saved beside a recording, the report download, and the page's colour maps
against matplotlib's."""

import json
import logging
import re
import shutil

import numpy as np
import pytest
from fastapi.testclient import TestClient

from texsense import Layout, Recording, load
from texsense.apps.roi import rois_path
from texsense.data.protocol import Frame
from texsense.io import save
from texsense.monitor import ExposureTracker, Monitor, ReplaySource
from texsense.monitor.server import STATIC, create_app

MMHG = 75.00615


def feed(m, values_ncm2, seconds, start=0.0, step=1.0):
    n = m.layout.n_elements
    for k in range(int(seconds / step)):
        t = start + k * step
        m.process(Frame(k, np.full(n, t), np.asarray(values_ncm2, float), "N/cm2"))


def monitor_of(lay, tmp_path, mode=None, **tracker):
    rec = Recording(np.zeros((2, lay.n_elements)), [0.0, 1.0], lay)
    return Monitor(ReplaySource(rec, speed=0), record_dir=tmp_path / "rec", mode=mode,
                   tracker=ExposureTracker(lay, reposition_min=5, **tracker))  # fmt: skip


def test_foot_mode_has_no_seat_events_and_no_alerts(tmp_path):
    """An insole replay: loaded and unloaded at every step, for 10 minutes above 32 mmHg."""
    lay = Layout.grid(4, 2)
    m = monitor_of(lay, tmp_path, mode="foot")
    for step in range(300):  # 1 s on, 1 s off: a gait
        feed(m, np.full(8, 1.0 if step % 2 == 0 else 0.0), 1.0, start=float(step))
    assert m.store.events() == []
    seat = monitor_of(lay, tmp_path, mode="seat")
    for step in range(40):
        feed(seat, np.full(8, 1.0 if step % 2 == 0 else 0.0), 1.0, start=float(step))
    assert len(seat.store.events()) == 40  # the old storm, in seat mode: 20 seated, 20 left
    generic = monitor_of(lay, tmp_path, mode="generic")
    for step in range(40):
        feed(generic, np.full(8, 1.0 if step % 2 == 0 else 0.0), 1.0, start=float(step))
    assert [e["kind"] for e in generic.store.events()] == []  # no change held 5 s


def test_alerts_name_the_place_in_words(tmp_path, caplog):
    """A seat names its zones, any other grid rows and columns (from 1), never indices; the
    log line names the source."""
    from texsense.sim.mat import VirtualMat

    seat = VirtualMat.seat().layout
    m = monitor_of(seat, tmp_path, mode="seat")
    p = np.zeros(seat.n_elements)
    left_it = int(np.argmin(np.hypot(*(seat.xy_cm - [10, 22]).T)))  # back half, sitter's left
    p[left_it] = 1.0
    with caplog.at_level(logging.INFO, logger="texsense.monitor"):
        feed(m, p, 301)
    alert = m.tracker.open_alert
    assert alert.where == ["ischium-l"]
    assert m.store.events(kind="reposition")[0]["detail"]["where"] == ["ischium-l"]
    assert any(r.getMessage().startswith("replay: reposition 5 min into the session")
               for r in caplog.records)  # fmt: skip
    grid = Layout.grid(6, 6)
    g = monitor_of(grid, tmp_path, mode="generic")
    p = np.zeros(36)
    p[[grid.element_at(2, 3), grid.element_at(3, 3)]] = 1.0
    feed(g, p, 301)
    # no anatomy on a generic mat: the alert names no region, its details line the cells
    assert g.tracker.open_alert.where == []
    assert g.tracker.open_alert.details == ["rows 3-4, column 4"]
    # the same seat with no orientation declared (a mat on a serial line that says none):
    # its front cannot be told from its back, so no zone and no left or right is named
    bare = monitor_of(seat.with_orientation(None), tmp_path, mode="seat")
    feed(bare, np.where(np.arange(seat.n_elements) == left_it, 1.0, 0.0), 301)
    assert bare.tracker.open_alert.where == []
    assert bare.tracker.open_alert.details[0].startswith("row")


@pytest.fixture()
def folder(tmp_path, shared_data):
    """A recordings folder: a 3 x 4 pressure recording, a Tekscan export, a PMD subject
    folder, a file texsense cannot read."""
    rec_dir = tmp_path / "rec"
    rec_dir.mkdir()
    lay = Layout.grid(3, 4, pitch_cm=2.0).with_orientation("seat")
    frames = np.zeros((5, 12))
    frames[:, 5] = 40 / MMHG  # the same 40 mmHg in every frame
    frames[np.arange(5), 0] = np.array([50, 100, 150, 200, 250]) / MMHG
    valid = np.ones((5, 12), bool)
    valid[3, 7] = False  # a repaired element: its value (0) counts, as live
    meta = {"mode": "seat", "orientation": lay.orientation}
    rec = Recording(frames, np.arange(5) * 60.0, lay, valid=valid, meta=meta)
    save(rec, rec_dir / "tiny.h5")
    shutil.copyfile(shared_data / "vendor-formats" / "fscan_testL.asf", rec_dir / "walk.asf")
    (rec_dir / "notes.txt").write_text("not a recording\n")
    (rec_dir / "calibration-1.json").write_text('{"format": "texsense.chain"}\n')
    (tmp_path / "secret.h5").write_bytes((rec_dir / "tiny.h5").read_bytes())
    return rec_dir


@pytest.fixture()
def client(folder):
    lay = Layout.grid(3, 4, pitch_cm=2.0)
    m = Monitor(ReplaySource(Recording(np.zeros((2, 12)), [0.0, 1.0], lay), speed=0),
                record_dir=folder)  # fmt: skip
    return TestClient(create_app(m, run_source=False), base_url="http://127.0.0.1:8765")


def test_recordings_are_listed_and_played(client):
    names = [r["name"] for r in client.get("/api/playback").json()]
    # only recordings are listed: not a note, not a calibration file (issue 33)
    assert sorted(names) == ["tiny.h5", "walk.asf"]
    info = client.get("/api/playback/tiny.h5").json()
    assert info["frames"] == 5 and info["mode"]["name"] == "seat" and info["unit"] == "N/cm2"
    assert info["orientation"]["top"] == "front" and info["times"] == [0, 60, 120, 180, 240]
    assert info["scale"] == pytest.approx([0, 100 / MMHG]) and info["threshold"] == pytest.approx(
        32 / MMHG
    )
    assert info["series"]["peak"] == pytest.approx(
        [v / MMHG for v in (50, 100, 150, 200, 250)], abs=1e-3
    )
    f3 = client.get("/api/playback/tiny.h5/frames/3").json()
    assert f3["t"] == 180 and f3["values"][0] == pytest.approx(200 / MMHG, abs=1e-4)
    assert f3["repaired"] == [7] and f3["values"][7] == 0.0
    walk = client.get("/api/playback/walk.asf").json()
    assert walk["mode"]["name"] == "foot" and walk["frames"] == 205 and walk["started_at"]
    assert len(client.get("/api/playback/walk.asf/frames/204").json()["values"]) == 955  # sensels
    assert client.get("/api/playback/walk.asf/frames/205").status_code == 404
    bad = client.get("/api/playback/notes.txt")
    assert bad.status_code == 422 and "notes.txt" in bad.json()["detail"]


def test_regions_are_saved_beside_the_recording(client, folder):
    rois = [{"name": "front", "kind": "box", "points": [[0, 0], [8, 2]]},
            {"name": "tri", "kind": "lasso", "points": [[0, 0], [8, 0], [0, 6]]}]  # fmt: skip
    r = client.put("/api/playback/tiny.h5/rois", content=json.dumps(rois))
    assert r.status_code == 200
    stats = {s["name"]: s for s in r.json()["stats"]}
    assert stats["front"]["elements"] == [0, 1, 2, 3]
    assert stats["front"]["peak"] == pytest.approx(
        [v / MMHG for v in (50, 100, 150, 200, 250)], abs=1e-3
    )
    saved = json.loads(rois_path(folder / "tiny.h5").read_text())
    assert saved["format"] == "texsense.rois" and [x["name"] for x in saved["regions"]] == [
        "front",
        "tri",
    ]
    assert [x["name"] for x in client.get("/api/playback/tiny.h5/rois").json()] == ["front", "tri"]
    assert client.get("/api/playback/tiny.h5").json()["rois"][1]["kind"] == "lasso"
    # the sidecar is not a recording of its own
    assert "tiny.h5.rois.json" not in [x["name"] for x in client.get("/api/playback").json()]


def test_report_download(client, folder):
    # a GET writes nothing: before a POST made it, there is no report
    assert client.get("/api/playback/tiny.h5/report?format=pdf").status_code == 404
    assert not (folder / "reports").exists()
    r = client.post("/api/playback/tiny.h5/report?format=pdf")
    assert r.status_code == 200 and r.content.startswith(b"%PDF")
    assert (folder / "reports" / "tiny.h5-report.pdf").is_file()
    again = client.get("/api/playback/tiny.h5/report?format=pdf")
    assert again.status_code == 200 and again.content == r.content
    html = client.post("/api/playback/walk.asf/report?format=html")
    assert html.status_code == 200 and "Pressure report: walk.asf" in html.text


def test_view_tells_the_live_mode_and_scale(tmp_path):
    lay = Layout.grid(64, 32, pitch_cm=2.54).with_orientation("bed")
    m = monitor_of(lay, tmp_path, mode="bed")
    app = create_app(m, run_source=False)
    v = TestClient(app, base_url="http://127.0.0.1:8765").get("/api/view").json()
    assert v["mode"]["name"] == "bed" and v["mode"]["unit"] == "mmHg"
    assert v["scale_ncm2"] == pytest.approx([0, 100 / MMHG]) and v["orientation"]["top"] == "head"
    assert v["threshold_ncm2"] == pytest.approx(32 / MMHG)


def test_page_colour_maps_are_matplotlibs():
    import matplotlib

    js = (STATIC / "colormaps.js").read_text()
    for name in ("viridis", "cividis"):
        body = js.split(f"{name}: [")[1].split("],\n  ]")[0]
        stops = np.array([[int(v) for v in t] for t in re.findall(r"\[(\d+), (\d+), (\d+)", body)])
        want = np.array([matplotlib.colormaps[name](i / 31)[:3] for i in range(32)]) * 255
        assert stops.shape == (32, 3) and np.abs(stops - want).max() <= 0.5001


def test_pages_have_no_inline_scripts_or_styles():
    """A strict Content-Security-Policy (script-src 'self', style-src 'self') must not break
    the pages: no inline script or style, no event-handler attributes, nothing from a CDN."""
    for page in STATIC.glob("*.html"):
        text = page.read_text()
        assert not re.search(r"<script(?![^>]*\bsrc=)", text), page
        assert "<style" not in text and " style=" not in text, page
        assert not re.search(r"\son[a-z]+=", text), page
        assert "http://" not in text and "https://" not in text, page
    for js in STATIC.glob("*.js"):
        assert "http://" not in js.read_text() and "https://" not in js.read_text(), js


def test_a_replay_of_an_insole_is_not_a_seat(shared_data, tmp_path):
    from texsense.commands.monitor import _mode

    class Args:
        mode, source = "auto", "replay:x"

    src = ReplaySource(load(shared_data / "vendor-formats" / "fscan_testL.asf"), speed=0)
    assert _mode(Args(), src, None) == "foot"
