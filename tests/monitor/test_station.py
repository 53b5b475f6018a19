"""The ward station against a real Mosquitto (started by the test): virtual mats, stale mats,
malformed payloads, a refused mat, a broker restart, the token rule; the ward page in a real
headless Chromium (set TEXSENSE_SCREENSHOT_WARD=docs/img/station_ward.png to refresh the
screenshot in docs/station.md)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from test_browser import open_page

from conftest import ChildServer
from texsense.station.broker import Broker, parse_broker_url
from texsense.station.ward import CHECK_S, MIN_STALE_S, mat_id_of


@pytest.fixture
def broker():
    with Broker() as b:
        yield b


class StationProcess(ChildServer):
    """``texsense station ARGS`` as a child process on a free port."""

    def __init__(self, tmp_path: Path, *args: str) -> None:
        super().__init__(tmp_path, "station", *args, "--record-dir", str(tmp_path / "rec"))

    def mats(self) -> dict:
        return {m["id"]: m for m in self.get("api/mats")}

    def stop(self) -> None:
        """SIGTERM, as a service manager stops it: a station killed with SIGKILL as root would
        leave its own broker running (Mosquitto drops its privileges, and with them the
        signal that would end it with its parent)."""
        self.proc.terminate()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            super().stop()

    def post(self, path: str, headers: dict | None = None):
        """POST ``path`` (no body), JSON back."""
        req = urllib.request.Request(self.url + path, method="POST", headers=headers or {})
        with urllib.request.urlopen(req, timeout=3) as r:
            return json.load(r)


@pytest.fixture
def station(tmp_path):
    started: list[StationProcess] = []

    def start(*args: str) -> StationProcess:
        started.append(StationProcess(tmp_path, *args))
        return started[-1]

    yield start
    for s in started:
        s.stop()


class Publisher:
    """A paho client publishing raw payloads to the test broker."""

    def __init__(self, broker: Broker) -> None:
        import paho.mqtt.client as mqtt

        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
        self.client.connect("127.0.0.1", broker.port)
        self.client.loop_start()
        # a QoS 0 message published before the broker's CONNACK is dropped: wait for it
        deadline = time.monotonic() + 15
        while not self.client.is_connected():
            assert time.monotonic() < deadline, "the test publisher did not connect"
            time.sleep(0.02)

    def frame(self, mat: str, seq: int, values, prefix: str = "texsense") -> None:
        payload = json.dumps({"seq": seq, "t": seq * 0.1, "values": values, "unit": "N/cm2"})
        self.client.publish(f"{prefix}/{mat}/frames", payload).wait_for_publish(2)

    def raw(self, mat: str, payload: bytes) -> None:
        self.client.publish(f"texsense/{mat}/frames", payload).wait_for_publish(2)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        if self.client.socket() is not None:
            self.client.socket().close()


def ward_file(tmp_path: Path, *ids: str) -> Path:
    """Pressure mats of 4 x 4 elements over MQTT."""
    text = "".join(f'[[mat]]\nid = "{i}"\nlayout = "grid:4x4"\n\n' for i in ids)
    path = tmp_path / "ward.toml"
    path.write_text(text)
    return path


def test_virtual_mats_through_the_broker(broker, station):
    # stale only after 2 s without a frame: at 8x two frame periods are 0.4 s, less than a
    # loaded machine's hiccups (the mats flickered stale at a load average of 16)
    st = station("--virtual-mats", "3", "--speed", "8", "--stale-after", "2",
                 "--broker", f"mqtt://127.0.0.1:{broker.port}")  # fmt: skip
    # the start calibrates the virtual seat and bed: 30 s at a load average of 16
    first = st.until(st.mats, lambda m: len(m) == 3 and all(v["frames"] >= 3 for v in m.values()),
                     120)  # fmt: skip
    later = st.until(st.mats, lambda m: all(m[k]["frames"] > first[k]["frames"] + 3 for k in first))
    assert set(later) == {"vmat-01", "vmat-02", "vmat-03"}
    assert all(m["state"] == "live" and m["malformed"] == 0 for m in later.values())
    seat, bed = st.get("api/mats/vmat-01"), st.get("api/mats/vmat-02")
    assert len(seat["pressure"]) == 96 and seat["shape"] == [15, 16]  # a seat
    assert len(bed["pressure"]) == 2048 and bed["shape"] == [64, 32]  # a bed mat
    assert "bed" in bed["source"] and "seat" in seat["source"]
    # the bed runs the turning schedule on its side model's sides, the seat does not
    assert seat["bed"] is None and bed["bed"]["interval_s"] == 7200.0
    assert bed["bed"]["side"] in ("supine", "prone", "left", "right", "sitting", None)
    status = st.get("mats/vmat-02/api/status")  # the single-mat dashboard of that mat
    assert status["bed"] is True
    assert status["frames"] >= 1 and status["source"]["name"].startswith("mat vmat-02")
    ward = st.get("api/ward")
    assert ward["connected"] and ward["topic"] == "texsense/+/frames"


def test_virtual_mats_log_in_to_the_stations_own_broker(station, tmp_path):
    """Without --broker: the station's Mosquitto, where each virtual mat logs in as itself."""
    st = station("--virtual-mats", "1", "--speed", "8")
    m = st.until(st.mats, lambda m: m["vmat-01"]["frames"] >= 3, timeout=120)
    assert m["vmat-01"]["malformed"] == 0
    assert "log-in required" in st.log()
    ward = st.get("api/ward")
    assert ward["connected"] and ward["broker"].startswith("mqtt://texsense-station@127.0.0.1:")


def read(m: dict) -> int:
    """The frames a mat's station has read: processed, or skimmed for their time because it
    was more than 1 s behind (on a loaded machine it can be, at start; issue 33)."""
    return int(m["frames"] + m["behind"])


def test_stale_malformed_and_refused_mats(broker, station, tmp_path):
    st = station("--config", str(ward_file(tmp_path, "bed1", "bed2")), "--broker",
                 f"mqtt://127.0.0.1:{broker.port}", "--refuse-after", "1")  # fmt: skip
    st.until(lambda: st.get("api/ward")["connected"], bool)
    pub = Publisher(broker)
    try:
        for k in range(12):  # 10 Hz on both mats
            pub.frame("bed1", k, [0.5] * 16)
            pub.frame("bed2", k, [0.2] * 16)
            time.sleep(0.1)
        st.until(st.mats, lambda m: read(m["bed1"]) == 12 and read(m["bed2"]) == 12)
        # malformed payloads: counted for that mat and skipped
        pub.raw("bed1", b"{not json")
        pub.raw("bed1", json.dumps({"seq": 99, "values": [1] * 16}).encode())  # no "t"
        # one frame that does not fit the layout is skipped like any malformed one ...
        pub.frame("bed2", 12, [0.2] * 64)
        pub.frame("bed2", 13, [0.2] * 16)
        pub.frame("bed1", 12, [0.5] * 16)
        m = st.until(st.mats, lambda m: m["bed1"]["malformed"] == 2 and read(m["bed2"]) == 13)
        # (not refused; stale soon after its last frame, which may have waited for the
        # test's own requests: pages go first)
        assert m["bed2"]["state"] in ("live", "stale") and m["bed2"]["malformed"] == 1
        # ... but a mat whose frames keep not fitting is refused; the others go on
        k = 14
        while st.mats()["bed2"]["state"] != "refused":  # refused after 1 s and 10 in a row
            assert k < 200, st.log()[-3000:]
            pub.frame("bed2", k, [0.2] * 64)
            pub.frame("bed1", k - 1, [0.5] * 16)
            time.sleep(0.1)
            k += 1
        pub.frame("bed2", k, [0.2] * 16)  # ignored: the mat is refused
        m = st.until(st.mats, lambda m: m["bed2"]["ignored"] >= 1 and read(m["bed1"]) == k - 1)
        assert "64 values" in m["bed2"]["refused"] and "16 elements" in m["bed2"]["refused"]
        assert read(m["bed2"]) == 13
        # admitted again (the API of the ward page's button): its frames count again
        st.post("api/mats/bed2/admit")
        pub.frame("bed2", k + 1, [0.2] * 16)
        st.until(st.mats, lambda m: read(m["bed2"]) == 14 and m["bed2"]["state"] == "live")
        # bed1 stops: stale after two of its frame periods (0.1 s each), at least 1 s
        m = st.until(st.mats, lambda m: m["bed1"]["state"] == "stale", timeout=5)
        period = m["bed1"]["period_s"]
        assert 0.08 < period < 0.2
        # ... and live again with its next frame
        pub.frame("bed1", k, [0.5] * 16)
        st.until(st.mats, lambda m: m["bed1"]["state"] == "live")
    finally:
        pub.close()
    import sqlite3

    db = sqlite3.connect(st.db_path)
    st.until(lambda: {r[0] for r in db.execute("SELECT kind FROM events")},
             lambda kinds: {"stale", "resumed", "refused", "admitted"} <= kinds)  # fmt: skip
    last = ("SELECT e.detail, s.source FROM events e JOIN sessions s ON e.session = s.id "
            "WHERE e.kind = 'stale' ORDER BY e.id DESC")  # fmt: skip
    # bed1's stop above (bed2 goes stale later, after its own last frame)
    detail, _ = next(r for r in db.execute(last) if "bed1" in r[1])
    silent = json.loads(detail)["silent_s"]
    # (silent_s is rounded to 10 ms; the check runs every CHECK_S)
    assert MIN_STALE_S - 0.01 <= silent < MIN_STALE_S + CHECK_S + 0.1, (silent, period)


def test_the_station_reconnects_when_the_broker_restarts(station, tmp_path):
    b = Broker().start()
    try:
        st = station("--config", str(ward_file(tmp_path, "bed1")), "--broker",
                     f"mqtt://127.0.0.1:{b.port}")  # fmt: skip
        st.until(lambda: st.get("api/ward")["connected"], bool)
        pub = Publisher(b)
        pub.frame("bed1", 0, [0.3] * 16)
        st.until(st.mats, lambda m: m["bed1"]["frames"] == 1)
        pub.close()
        b.pause()
        st.until(lambda: st.get("api/ward")["connected"], lambda c: c is False, timeout=20)
        b.start()  # the same port
        st.until(lambda: st.get("api/ward")["connected"], bool, timeout=20)
        pub = Publisher(b)
        time.sleep(0.3)  # the station subscribes again after it reconnects
        for k in range(1, 4):
            pub.frame("bed1", k, [0.3] * 16)
        st.until(st.mats, lambda m: m["bed1"]["frames"] >= 3, timeout=10)
        pub.close()
    finally:
        b.stop()


def test_every_request_needs_the_token(broker, station, tmp_path):
    st = station("--config", str(ward_file(tmp_path, "bed1")), "--token", "s3cret-token",
                 "--broker", f"mqtt://127.0.0.1:{broker.port}")  # fmt: skip
    st.until(lambda: st.get("api/ward", token="s3cret-token")["connected"], bool)
    for path in ("api/mats", "api/ward", "mats/bed1/api/status", ""):
        with pytest.raises(urllib.error.HTTPError) as e:
            st.get(path)
        e.value.close()
        assert e.value.code == 401
    assert st.get("mats/bed1/api/status", token="s3cret-token")["frames"] == 0


def test_a_bed_in_the_ward_file_needs_a_side_model(tmp_path):
    from texsense.commands.station import read_config
    from texsense.exceptions import FormatError

    path = tmp_path / "ward.toml"
    path.write_text('[[mat]]\nid = "bed1"\nlayout = "grid:4x4"\nbed = true\n')
    with pytest.raises(FormatError, match="a bed needs model"):
        read_config(path, 20.0)
    path.write_text('[[mat]]\nid = "bed1"\nlayout = "grid:4x4"\nbed = "yes"\n')
    with pytest.raises(FormatError, match="bed must be true or false"):
        read_config(path, 20.0)
    path.write_text('[[mat]]\nid = "seat1"\nlayout = "grid:4x4"\n')
    (mat,), _ = read_config(path, 20.0, 90.0)
    assert not mat.bed and mat.posture_model is None and mat.turn_every_min == 90.0


def test_topics_urls_and_errors():
    assert mat_id_of("texsense/bed12/frames") == "bed12"
    assert mat_id_of("ward3/bed12/frames") == "bed12"
    assert mat_id_of("texsense/bed12/status") is None
    url = parse_broker_url("mqtt://nurse:p%40ss@10.1.2.3:1999")
    assert (url.host, url.port, url.username, url.password) == ("10.1.2.3", 1999, "nurse", "p@ss")
    with pytest.raises(ValueError, match="expected mqtt://"):
        parse_broker_url("http://x")


@pytest.mark.slow
def test_ward_page_in_headless_chromium(broker, station, tmp_path):
    from playwright.sync_api import expect

    # one bed (vmat-02): a bed's frame costs the virtual mats' process ~40 ms of a core, a
    # seat's ~6; with two, a loaded machine's publisher fell short of the 5 min of sitting
    st = station("--virtual-mats", "5", "--virtual-beds", "1", "--speed", "60",
                 "--reposition-min", "5",
                 "--config", str(ward_file(tmp_path, "bed-9", "bed-8")), "--refuse-after", "0.5",
                 "--broker", f"mqtt://127.0.0.1:{broker.port}")  # fmt: skip
    st.until(st.mats, lambda m: all(m[f"vmat-0{k}"]["frames"] > 2 for k in range(1, 6)), 120)
    pub = Publisher(broker)
    for k in range(8):  # bed-9 sends a few frames of pressure, then falls silent
        pub.frame("bed-9", k, [0.4] * 16)
        time.sleep(0.1)
    k = 0
    while st.mats()["bed-8"]["state"] != "refused":  # bed-8 sends frames of 64 values
        assert k < 200, st.log()[-3000:]
        pub.frame("bed-8", k, [0.4] * 64)
        time.sleep(0.1)
        k += 1
    pub.close()
    st.until(st.mats, lambda m: m["bed-9"]["state"] == "stale", 10)
    with open_page(st.url, 1240, 760) as (page, errors):
        tiles = page.locator(".tile")
        expect(tiles).to_have_count(7, timeout=20_000)
        expect(page.locator('.tile[data-id="bed-9"] .state')).to_have_text("no data")
        refused = page.locator('.tile[data-id="bed-8"]')
        expect(refused.locator(".problem")).to_contain_text("64 values")
        refused.locator("button.admit").click()  # admitted again: it waits for frames
        expect(refused).to_have_attribute("data-state", "waiting", timeout=5_000)
        expect(page.locator("#broker")).to_contain_text("connected")
        # a tile says what its numbers are: "above 32 mmHg for ... min", the peak in mmHg;
        # a bed is drawn as a bed (taller than wide), with what lies beyond its edges
        seat = page.locator('.tile[data-id="vmat-01"]')
        bed = page.locator('.tile[data-id="vmat-02"]')
        expect(seat.locator(".above")).to_have_text("above 32 mmHg for")
        expect(seat.locator(".peak")).to_contain_text(re.compile(r"peak \d+ mmHg"))
        assert page.evaluate("() => { const c = document.querySelector('.tile[data-id=\"vmat-02\"] "
                             "canvas'); return c.height > c.width; }")  # fmt: skip
        expect(bed.locator(".bed-line")).to_contain_text(re.compile("turn (now|due in)"))
        assert st.get("api/mats/vmat-02")["orientation"]["top"] == "head"
        # 5 min of exposure at 60x: an alert within seconds, on top of the ward
        alert = page.locator(".tile.is-alert").first
        expect(alert).to_be_visible(timeout=60_000)
        expect(tiles.first).to_have_class("tile is-alert")
        expect(alert.locator("button.ack")).to_be_visible()
        page.wait_for_timeout(400)
        shot = tmp_path / "ward.png"
        page.screenshot(path=str(shot), full_page=True)  # every tile, none cut off
        assert shot.stat().st_size > 20_000
        if os.environ.get("TEXSENSE_SCREENSHOT_WARD"):
            shutil.copyfile(shot, os.environ["TEXSENSE_SCREENSHOT_WARD"])
        mat_id = alert.get_attribute("data-id")  # the tile itself: ".first" may be another by now
        page.locator(f'.tile[data-id="{mat_id}"] button.ack').click()
        expect(page.locator(f'.tile[data-id="{mat_id}"]')).to_have_attribute(
            "data-state", "acknowledged", timeout=5_000
        )
        one = st.get(f"api/mats/{mat_id}")
        assert one["alert"] is not None and one["alert"]["active"] is False
        # a click opens that mat's own dashboard
        page.locator(f'.tile[data-id="{mat_id}"] canvas').click()
        expect(page).to_have_url(st.url + f"mats/{mat_id}/", timeout=5_000)
        frames = page.locator("#frames")
        expect(frames).not_to_have_text("0", timeout=30_000)  # a busy machine
        expect(page.locator("#source")).to_contain_text(f"mat {mat_id}")
        assert not errors, errors


def test_two_stations_split_a_site_by_topic(broker, tmp_path):
    """ward3 and ward4 publish under their own prefixes; each station sees only its ward."""
    made = []
    try:
        for ward in ("ward3", "ward4"):
            folder = tmp_path / ward
            folder.mkdir()
            made.append(StationProcess(folder, "--config", str(ward_file(folder, "bed1", "bed2")),
                                       "--mats", f"{ward}/+/frames",
                                       "--broker", f"mqtt://127.0.0.1:{broker.port}"))  # fmt: skip
        for st in made:
            st.until(lambda st=st: st.get("api/ward")["connected"], bool)
        pub = Publisher(broker)
        for k in range(3):
            pub.frame("bed1", k, [0.1] * 16, prefix="ward3")
        pub.frame("bed2", 0, [0.2] * 16, prefix="ward4")
        pub.close()
        w3, w4 = made
        m3 = w3.until(w3.mats, lambda m: read(m["bed1"]) == 3)
        m4 = w4.until(w4.mats, lambda m: m["bed2"]["frames"] == 1)
        assert m3["bed2"]["frames"] == 0 and m4["bed1"]["frames"] == 0
    finally:
        for st in made:
            st.stop()


def test_a_mat_from_a_local_replay_source(broker, station, tmp_path):
    """A ward file can name local sources too: a replayed pressure recording here."""
    import numpy as np

    from texsense.data.layout import Layout
    from texsense.data.recording import Recording
    from texsense.io import save

    rec = Recording(np.full((50, 16), 0.6), np.arange(50) * 0.05, Layout.grid(4, 4))
    save(rec, tmp_path / "chair.h5")
    (tmp_path / "ward.toml").write_text(
        f'[[mat]]\nid = "chair1"\nlayout = "{tmp_path / "chair.h5"}"\n'
        f'source = "replay:{tmp_path / "chair.h5"}"\n'
    )
    st = station("--config", str(tmp_path / "ward.toml"), "--broker",
                 f"mqtt://127.0.0.1:{broker.port}")  # fmt: skip
    m = st.until(st.mats, lambda m: m["chair1"]["frames"] >= 10)
    assert m["chair1"]["source"].startswith("replay:") and m["chair1"]["state"] == "live"
