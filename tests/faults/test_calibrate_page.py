"""Fault battery, the monitor page's calibration panel (docs/monitor.md, "Calibrate from the
page"): bad loads, unknown materials, a refused calibration, steps out of order or at the same
time, pages of other origins; the monitor in-process, its frames fed by the test."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from texsense import Layout, Recording
from texsense.calibration.session import CalibrationSession
from texsense.data.protocol import Frame
from texsense.monitor import Monitor, ReplaySource
from texsense.monitor.calibrate import _unused_stem
from texsense.monitor.server import create_app

HOST = "127.0.0.1:8765"
BASE = f"http://{HOST}"
LAYOUT = Layout.grid(3, 4)
N = LAYOUT.n_elements
#: what an element of the preset gains under 1 N/cm² (the fit expects about this)
CHANGE_PF = CalibrationSession("textile-3mm").expected_change_pF(1.0)


class Rig:
    """A raw-only monitor of a 3 x 4 capacitance mat and its app; ``feed(k, pF)`` gives it
    ``k`` frames of ``pF`` on every element (the mat's spread: +-2 %)."""

    def __init__(self, tmp_path: Path) -> None:
        rec = Recording(np.full((2, N), 10.0), [0.0, 1.0], LAYOUT, "capacitance", "pF")
        self.monitor = Monitor(ReplaySource(rec, speed=0), record_dir=tmp_path / "rec")
        self.client = TestClient(create_app(self.monitor, run_source=False), base_url=BASE)
        self.t = 0.0
        self.spread = np.random.default_rng(1).uniform(0.98, 1.02, N)

    def feed(self, k: int, change_pF: float) -> None:
        for _ in range(k):
            values = 10.0 + change_pF * self.spread
            self.monitor.process(Frame(int(self.t * 10), self.t + 0.01 * np.arange(N), values))
            self.t += 1.0

    def post(self, path: str, body: dict | None = None, **headers: str):
        return self.client.post(f"/api/calibration/{path}", json=body, headers=headers)

    def state(self) -> dict:
        return self.client.get("/api/calibration").json()

    def step(self, step: str, change_pF: float, pressure: str | None = None, frames: int = 8):
        r = self.post(f"record/{step}", {"frames": frames, "pressure": pressure})
        assert r.status_code == 200, r.text
        self.feed(frames, change_pF)


@pytest.fixture
def rig(tmp_path):
    return Rig(tmp_path)


def test_a_bad_load_is_refused_with_what_was_wrong(rig, fault_row):
    rig.step("zero", 0.0)
    bad = [("one newton", "a number with a unit"), ("1 parsec", "unknown pressure unit"),
           ("-1 kPa", "must be > 0"), ("3 s", "not a pressure unit"),
           ("", "needs its load")]  # fmt: skip
    for text, said in bad:
        r = rig.post("record/uniform", {"frames": 8, "pressure": text})
        assert r.status_code == 422 and said in r.json()["detail"], (text, r.text)
    r = rig.post("record/uniform", {"frames": 0, "pressure": "1 N/cm2"})
    assert r.status_code == 422 and "frames must lie in" in r.json()["detail"]
    r = rig.post("record/banana", {"frames": 8})
    assert r.status_code == 422 and "unknown step 'banana'" in r.json()["detail"]
    assert rig.state()["recording"] is None and rig.state()["done"] == ["zero"]
    fault_row("calibration page", "a load that is no pressure (text, unit, sign), frames 0, "
              "an unknown step", "refused")  # fmt: skip


def test_an_unknown_material_is_refused_and_no_file_is_read(rig, fault_row):
    rig.step("zero", 0.0)
    rig.step("uniform", CHANGE_PF, "10 kPa")
    for material in ("steel-wool", "/etc/passwd", "../rec/x.csv"):
        r = rig.post("fit", {"material": material})
        assert r.status_code == 422, r.text
        assert f"unknown material {material!r}" in r.json()["detail"]
        assert "textile-3mm" in r.json()["detail"]  # the presets are named
    r = rig.post("fit", {})  # the source announced no spacer
    assert r.status_code == 422 and "announced none" in r.json()["detail"]
    assert "material" not in rig.state()["done"]
    fault_row("calibration page", "an unknown material, a path as material, none", "refused")


def test_swapped_recordings_are_refused_with_the_reason_kept_for_the_page(rig, fault_row):
    rig.step("zero", CHANGE_PF)  # the load was on while "nothing on the mat" recorded
    rig.step("uniform", 0.0, "1 N/cm2")
    r = rig.post("fit", {"material": "textile-3mm"})
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert detail.startswith("calibration refused:") and "swapped" in detail
    s = rig.state()
    assert s["refused"] == detail and "material" not in s["done"] and s["fit"] is None
    assert rig.post("save").status_code == 409
    assert rig.monitor.raw_only
    # doing step 1 again clears the refusal and the steps after it
    rig.step("zero", 0.0)
    s = rig.state()
    assert s["refused"] is None and s["done"] == ["zero"]
    fault_row("calibration page", "zero and uniform swapped: the fit is refused, the reason "
              "is kept and shown", "refused")  # fmt: skip


def test_steps_out_of_order_or_at_once_are_refused(rig, fault_row):
    early = [("record/uniform", {"pressure": "1 N/cm2"}), ("fit", {"material": "textile-3mm"}),
             ("record/check", {"pressure": "1 N/cm2"}), ("save", None)]  # fmt: skip
    for path, body in early:
        r = rig.post(path, body)
        assert r.status_code == 409 and "comes after the empty mat (step 1)" in r.json()["detail"]
    assert rig.post("record/zero", {"frames": 5}).status_code == 200
    r = rig.post("record/zero", {"frames": 5})  # while step 1 records
    assert r.status_code == 409 and "still recording" in r.json()["detail"]
    assert rig.state()["recording"] == {"step": "zero", "frames": 0, "of": 5}
    rig.feed(5, 0.0)
    r = rig.post("fit", {"material": "textile-3mm"})
    assert r.status_code == 409 and "after the uniform load (step 2)" in r.json()["detail"]
    rig.step("uniform", CHANGE_PF, "1 N/cm2")
    r = rig.post("record/check", {"pressure": "1 N/cm2"})
    assert r.status_code == 409 and "after the material and fit (step 3)" in r.json()["detail"]
    assert rig.post("save").status_code == 409
    assert rig.monitor.raw_only
    fault_row("calibration page", "a step before the one it needs, or while another records",
              "refused")  # fmt: skip


def test_a_page_of_another_origin_cannot_run_a_step(rig, fault_row):
    for headers in ({"Origin": "http://evil.example"}, {"Origin": "null"},
                    {"Sec-Fetch-Site": "cross-site"}, {"Host": "evil.example:8765"}):  # fmt: skip
        for path, body in (("record/zero", {"frames": 5}), ("reset", None), ("save", None)):
            r = rig.post(path, body, **headers)
            assert r.status_code == 403, (headers, path)
        if "Sec-Fetch-Site" not in headers:  # a GET is refused by its Origin or Host
            r = rig.client.get("/api/calibration", headers=headers)
            assert r.status_code == 403, headers
    assert rig.state()["recording"] is None  # nothing started
    r = rig.post("record/zero", {"frames": 5}, Origin=BASE, **{"Sec-Fetch-Site": "same-origin"})
    assert r.status_code == 200  # the page's own button
    fault_row("calibration page", "a page of another origin or site posts a step (CSRF)",
              "refused")  # fmt: skip


def test_the_whole_way_in_process_and_a_second_save_is_refused(rig, tmp_path):
    rig.step("zero", 0.0)
    rig.step("uniform", CHANGE_PF, "1 N/cm2")
    r = rig.post("fit", {"material": "textile-3mm"})
    assert r.status_code == 200, r.text
    assert r.json()["fit"]["stages"][:2] == ["detect", "convert"]
    rig.step("check", CHANGE_PF, "1 N/cm2")
    s = rig.state()
    assert s["done"] == ["zero", "uniform", "material", "check"] and s["busy"] is None
    assert s["check"]["working"] == N and len(s["check"]["error"]) == N
    r = rig.post("save")
    assert r.status_code == 200, r.text
    saved = r.json()["saved"]
    assert Path(saved["calibration"]).parent == tmp_path / "rec"
    assert sorted(Path(p).name for p in saved["recordings"].values()) == sorted(
        Path(saved["calibration"]).stem + f"-{s}.h5" for s in ("zero", "uniform", "check")
    )
    assert not rig.monitor.raw_only and rig.monitor.latest["calibrated"] is False
    rig.feed(1, CHANGE_PF)
    assert rig.monitor.latest["calibrated"] is True
    r = rig.post("save")
    assert r.status_code == 409 and "saved already" in r.json()["detail"]


def test_a_saved_calibration_never_takes_an_existing_name(tmp_path):
    (tmp_path / "calibration-x.json").write_text("{}")
    assert _unused_stem(tmp_path, "calibration-x", {}) == "calibration-x-2"
    (tmp_path / "calibration-x-2-zero.h5").write_text("")
    assert _unused_stem(tmp_path, "calibration-x", {"zero": None}) == "calibration-x-3"


def test_a_folder_that_cannot_be_written_leaves_the_monitor_as_it_was(tmp_path, fault_row):
    rig = Rig(tmp_path)
    rig.monitor.record_dir = tmp_path / "not-a-folder"
    rig.monitor.record_dir.write_text("a file where the folder should be")
    rig.step("zero", 0.0)
    rig.step("uniform", CHANGE_PF, "1 N/cm2")
    assert rig.post("fit", {"material": "textile-3mm"}).status_code == 200
    r = rig.post("save")
    assert r.status_code == 507 and r.json()["detail"].startswith("cannot write the calibration")
    assert rig.monitor.raw_only and rig.state()["saved"] is None and rig.state()["busy"] is None
    assert rig.monitor.record_dir.read_text() == "a file where the folder should be"
    fault_row("calibration page", "save and use into a folder that cannot be written",
              "data kept")  # fmt: skip
