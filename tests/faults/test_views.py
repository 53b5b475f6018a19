"""Fault cases of the views (issue 26): the report's recording argument, the playback API's
file names and frame indices, the regions a page posts. Each gives one clear line or a 4xx,
never a traceback; names resolve only inside the monitor's recordings folder."""

import json
import shutil

import numpy as np
import pytest
from fastapi.testclient import TestClient
from tests.faults.conftest import assert_clear_error, run_cli

from texsense import Layout, Recording
from texsense.apps.roi import MAX_ROIS, rois_path
from texsense.io import save
from texsense.monitor import Monitor, ReplaySource
from texsense.monitor.server import create_app


@pytest.fixture()
def folder(tmp_path):
    rec_dir = tmp_path / "rec"
    rec_dir.mkdir()
    lay = Layout.grid(2, 3)
    save(Recording(np.ones((4, 6)), np.arange(4.0), lay), rec_dir / "ok.h5")
    (rec_dir / "broken.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + b"\x00" * 64)
    (tmp_path / "outside.h5").write_bytes((rec_dir / "ok.h5").read_bytes())
    return rec_dir


@pytest.fixture()
def client(folder):
    m = Monitor(ReplaySource(Recording(np.zeros((2, 6)), [0.0, 1.0], Layout.grid(2, 3)), speed=0),
                record_dir=folder)  # fmt: skip
    return TestClient(create_app(m, run_source=False), base_url="http://127.0.0.1:8765")


@pytest.mark.parametrize(
    ("case", "args", "names"),
    [
        ("recording missing", ["missing.h5"], ["missing.h5", "no such file"]),
        ("recording not readable", ["notes.txt"], ["notes.txt", "unknown format"]),
        ("recording truncated HDF5", ["cut.h5"], ["cut.h5"]),
        ("output neither .pdf nor .html", ["ok.h5", "-o", "r.docx"], ["r.docx", ".pdf or .html"]),
        ("output is the input", ["ok.h5", "-o", "ok.h5"], ["ok.h5"]),
        ("output folder missing", ["ok.h5", "-o", "nowhere/r.pdf"], ["nowhere"]),
        ("colour scale malformed", ["ok.h5", "--scale", "9,1"], ["--scale"]),
        ("unit not a pressure", ["ok.h5", "--unit", "pF"], ["pF"]),
        ("regions file malformed", ["ok.h5", "--rois", "bad.json"], ["bad.json"]),
    ],
)
def test_report_cli_faults(tmp_path, fault_row, case, args, names):
    lay = Layout.grid(2, 3)
    save(Recording(np.ones((4, 6)), np.arange(4.0), lay), tmp_path / "ok.h5")
    (tmp_path / "notes.txt").write_text("hello\n")
    (tmp_path / "cut.h5").write_bytes((tmp_path / "ok.h5").read_bytes()[:700])
    (tmp_path / "bad.json").write_text('{"regions": [{"name": "x", "kind": "circle"}]}')
    if "-o" not in args:
        args = [*args, "-o", "r.pdf"]
    rc, _, err = run_cli("report", *args, cwd=tmp_path)
    assert_clear_error(rc, err, *names)
    assert not (tmp_path / "r.pdf").exists()
    fault_row("report", case, "clear error")


@pytest.mark.parametrize(
    "name",
    [
        "..%2Foutside.h5",
        "%2E%2E%2Foutside.h5",
        "..%5Coutside.h5",
        ".hidden",
        "ok.h5%00.pdf",
        "missing.h5",
        "ok.h5.rois.json",
    ],
)
def test_playback_names_resolve_only_inside_the_folder(client, fault_row, name):
    for path in (f"/api/playback/{name}", f"/api/playback/{name}/frames/0",
                 f"/api/playback/{name}/report", f"/api/playback/{name}/rois"):  # fmt: skip
        r = client.get(path)
        assert r.status_code == 404, (path, r.status_code)
    fault_row("playback API", f"file name {name!r}", "refused")


def test_playback_unreadable_file_is_a_422(client, fault_row):
    r = client.get("/api/playback/broken.h5")
    assert r.status_code == 422 and "broken.h5" in r.json()["detail"]
    assert "Traceback" not in r.text
    fault_row("playback API", "a file in the folder texsense cannot read", "refused")


@pytest.mark.parametrize(("index", "status"), [("-1", 404), ("4", 404), ("99999999999", 404),
                                                ("1.5", 422), ("abc", 422)])  # fmt: skip
def test_playback_frame_indices(client, fault_row, index, status):
    r = client.get(f"/api/playback/ok.h5/frames/{index}")
    assert r.status_code == status, r.text
    fault_row("playback API", f"frame index {index}", "refused")


def _box(name="a", points=((0, 0), (1, 1)), kind="box", **extra):
    return {"name": name, "kind": kind, "points": [list(p) for p in points], **extra}


def _json(*regions):
    return json.dumps(list(regions)).encode()


@pytest.mark.parametrize(
    ("case", "body", "status", "words"),
    [
        ("not JSON", b"{regions", 400, "not JSON"),
        ("not a list", b'{"name": "a"}', 422, "a list"),
        ("unknown kind", _json(_box(kind="circle")), 422, "'circle'"),
        ("box with one corner", _json(_box(points=[(0, 0)])), 422, "2 corners"),
        ("lasso of two points", _json(_box(kind="lasso")), 422, "3-500"),
        ("coordinates not numbers", _json(_box(points=[("x", 0), (1, 1)])), 422, "numbers"),
        (
            "coordinates not finite",
            b'[{"name": "a", "kind": "box", "points": [[1e400, 0], [1, 1]]}]',
            422,
            "finite",
        ),
        ("name empty", _json(_box(name=" ")), 422, "name"),
        ("two regions of one name", _json(_box(), _box()), 422, "two regions"),
        ("unknown field", _json(_box(x=1)), 422, "unknown"),
        ("too many regions", _json(*[_box(f"r{k}") for k in range(MAX_ROIS + 1)]), 422, "at most"),
        ("body too large", b"[" + b" " * (300 * 1024) + b"]", 413, "KiB"),
    ],
)
def test_regions_posted_by_the_page(client, folder, fault_row, case, body, status, words):
    before = rois_path(folder / "ok.h5").exists()
    r = client.put("/api/playback/ok.h5/rois", content=body)
    assert r.status_code == status, r.text
    assert words in r.json()["detail"] and "Traceback" not in r.text
    assert rois_path(folder / "ok.h5").exists() == before  # nothing written
    fault_row("playback regions", case, "refused")


def test_a_broken_sidecar_is_said_not_hidden(client, folder, fault_row):
    rois_path(folder / "ok.h5").write_text("{not json")
    r = client.get("/api/playback/ok.h5/rois")
    assert r.status_code == 422 and "ok.h5.rois.json" in r.json()["detail"]
    rc_dir = folder.parent / "cli"
    rc_dir.mkdir()
    shutil.copyfile(folder / "ok.h5", rc_dir / "ok.h5")
    rois_path(rc_dir / "ok.h5").write_text('{"format": "texsense.rois", "regions": [1]}')
    rc, _, err = run_cli("report", "ok.h5", "-o", "r.pdf", cwd=rc_dir)
    assert_clear_error(rc, err, "ok.h5.rois.json", "region 1")
    fault_row("report", "a broken regions sidecar beside the recording", "clear error")
