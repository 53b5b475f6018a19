"""Fault battery, the ward: MQTT glitches through a real Mosquitto against a running
`texsense station` (docs/station.md, "Faults"). One station with its own broker serves every
case (a mat per case, each mat publishing with its own credentials, as real mats do); the
flood of unknown topics goes through a site broker that lets anyone publish, to a second
station."""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import tomllib
import urllib.request
from pathlib import Path

import pytest

from conftest import free_port
from texsense.station.broker import Broker

#: the mats of the station: (id, grid); a mat per case
MATS = {
    "future": "4x4", "past": "4x4", "restart": "4x4", "count": "8x12", "refuse": "8x12",
    "size": "4x4", "huge": "4x4", "junk": "4x4", "victim": "4x4", "intruder": "4x4",
}  # fmt: skip


class WardStation:
    """`texsense station` in its own folder, with its own broker; helpers to publish as a mat
    and to read the station."""

    def __init__(
        self,
        folder: Path,
        mats: dict[str, str],
        *args: str,
        connected: bool = True,
        more: str = "",
        token: str | None = None,
    ) -> None:
        self.folder = folder
        self.token = token
        text = "".join(f'[[mat]]\nid = "{m}"\nlayout = "grid:{g}"\nreposition_min = 5\n\n'
                       for m, g in mats.items()) + more  # fmt: skip
        (folder / "ward.toml").write_text(text)
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}/"
        self.log_path = folder / "station.log"
        env = {**os.environ, "TMPDIR": str(folder)}
        with self.log_path.open("wb") as out:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "texsense.cli", "station", "--config", "ward.toml",
                 "--port", str(self.port), "--db", "station.sqlite",
                 *args],
                stdout=out, stderr=subprocess.STDOUT, cwd=folder, env=env,
            )  # fmt: skip
        self.seq: dict[str, int] = {}
        self.sent: dict[str, int] = {}  # messages published per mat
        self.offset: dict[str, float] = {}  # s added to a mat's frame times
        self.clients: dict[str, object] = {}
        self.client_answers: dict[str, list] = {}
        if connected:
            try:
                self.until(lambda: self.get("api/ward")["connected"], bool, 60)
            except BaseException:
                self.stop()
                raise

    def __enter__(self) -> WardStation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ----------------------------------------------------------------- reading
    def get(self, path: str):
        req = urllib.request.Request(self.url + path)
        if self.token:
            req.add_header("Authorization", f"Bearer {self.token}")
        with urllib.request.urlopen(req, timeout=5) as r:
            return json.load(r)

    def post(self, path: str):
        req = urllib.request.Request(self.url + path, method="POST")
        with urllib.request.urlopen(req, timeout=5) as r:
            return json.load(r)

    def mat(self, mat_id: str) -> dict:
        return next(m for m in self.get("api/mats") if m["id"] == mat_id)

    def until(self, what, cond, timeout: float = 20.0):
        deadline = time.monotonic() + timeout
        value = None
        while True:
            if self.proc.poll() is not None:
                pytest.fail(f"the station exited:\n{self.log()}")
            with contextlib.suppress(OSError, KeyError, StopIteration):
                value = what()
                if cond(value):
                    return value
            if time.monotonic() > deadline:
                pytest.fail(f"not reached (last: {value}):\n{self.log()[-3000:]}")
            time.sleep(0.05)

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    # ----------------------------------------------------------------- publishing
    @property
    def broker_port(self) -> int:
        return int(re.search(r"Mosquitto on mqtt://127\.0\.0\.1:(\d+)", self.log()).group(1))

    def client(self, user: str | None, password: str | None = None, wait: bool = True):
        """A paho client logged in as ``user`` (a mat: its password from the station's
        credentials file), and what the broker answered."""
        import paho.mqtt.client as mqtt

        if user is not None and password is None:
            creds = tomllib.loads((self.folder / "mat-credentials.toml").read_text())
            password = creds["mats"][user]
        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
        if user is not None:
            c.username_pw_set(user, password)
        c.reconnect_delay_set(1, 1)
        answers: list = []
        c.on_connect = lambda _c, _u, _f, rc, _p=None: answers.append(rc)
        c.on_disconnect = lambda *_a: answers.append("disconnected")
        c.connect("127.0.0.1", self.broker_port)
        c.loop_start()
        deadline = time.monotonic() + 5
        while wait and not answers and time.monotonic() < deadline:
            time.sleep(0.02)
        return c, answers

    def raw(self, mat: str, payload: bytes, as_mat: str | None = None) -> None:
        who = as_mat or mat
        if who == mat and len(payload) < 256_000:  # what the broker lets through to the mat
            self.sent[mat] = self.sent.get(mat, 0) + 1
        if who not in self.clients:
            self.clients[who], self.client_answers[who] = self.client(who)
        info = self.clients[who].publish(f"texsense/{mat}/frames", payload)
        with contextlib.suppress(RuntimeError, ValueError):
            info.wait_for_publish(5)

    def frame(self, mat: str, value: float = 0.5, n: int | None = None, step: float = 1.0):
        """The mat's next frame (its own seq; time seq x ``step`` + the mat's offset)."""
        k = self.seq.get(mat, 0)
        self.seq[mat] = k + 1
        t = k * step + self.offset.get(mat, 0.0)
        cells = n if n is not None else 96 if MATS.get(mat) == "8x12" else 16
        body = {"seq": k, "t": t, "values": [value] * cells, "unit": "N/cm2"}
        self.raw(mat, json.dumps(body).encode())

    def live_after_glitch(self, mat: str, frames: int = 1) -> dict:
        """Publish ``frames`` good frames; the mat must process every one of them (counted
        once every message sent so far has been handled: the station handles its inbox in
        slices, so some may still wait)."""
        sent = self.sent.get(mat, 0)
        before = read(self.until(lambda: self.mat(mat), lambda m: m["messages"] >= sent))
        for _ in range(frames):
            self.frame(mat)
        return self.until(lambda: self.mat(mat), lambda m: read(m) == before + frames)

    def stop(self) -> None:
        for c in self.clients.values():
            c.disconnect()
            c.loop_stop()
        self.proc.terminate()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        from faults.test_stop import broker_processes

        own = Path(f"{self.folder}/texsense-broker-")  # (not a site broker of the test's)
        for pid in broker_processes(own):  # a station that failed to stop its broker
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)


def read(m: dict) -> int:
    """The frames a mat's station has read: processed, or skimmed for their time because it
    was more than 1 s behind (on a loaded machine it is, at start; issue 33)."""
    return int(m["frames"] + m["behind"])


@contextlib.contextmanager
def enterable_folder():
    """A temporary folder that Mosquitto may enter (as root it drops to its own user, and
    pytest's folders are closed to others); removed afterwards."""
    folder = Path(tempfile.mkdtemp(prefix="texsense-test-ward-"))
    folder.chmod(0o755)
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def folder():
    with enterable_folder() as f:
        yield f


@pytest.fixture(scope="module")
def ward():
    with enterable_folder() as folder, WardStation(folder, MATS, "--refuse-after", "1") as st:
        for mat in MATS:
            for _ in range(3):
                st.frame(mat)
        st.until(lambda: st.get("api/mats"), lambda ms: all(read(m) == 3 for m in ms))
        yield st


def one_line_about(st: WardStation, mat: str, text: str) -> None:
    """The station said it once, naming the mat, and wrote no traceback."""
    log = st.log()
    lines = [line for line in log.splitlines() if f"mat {mat}" in line and text in line]
    assert len(lines) == 1, log[-3000:]
    assert "Traceback" not in log


def test_a_frame_from_the_future_clears_no_alert(ward, fault_row):
    st = ward
    for _ in range(310):  # 5 min 10 s of load: the reposition alert opens (5 min)
        st.frame("future", 1.0)
    m = st.until(lambda: st.mat("future"), lambda m: m["alert"] is not None)
    st.seq["future"] += 10**9  # a frame of an empty mat stamped 30 years ahead
    st.frame("future", 0.0)
    st.seq["future"] -= 10**9 + 1  # the mat's real clock goes on
    after = st.live_after_glitch("future")
    assert after["alert"] is not None and after["alert"]["id"] == m["alert"]["id"]
    assert after["alert"]["cleared_t"] is None and after["alert"]["active"]
    assert after["skipped"] == 1
    one_line_about(st, "future", "off the mat's clock")
    fault_row("MQTT", "one frame with t far in the future (an alert open)", "mat live",
              "the alert stays")  # fmt: skip


def test_a_frame_from_the_past_is_skipped(ward, fault_row):
    st = ward
    st.raw("past", body(seq=0, t=-1e6))
    assert st.live_after_glitch("past")["skipped"] == 1
    fault_row("MQTT", "one frame with t far in the past", "mat live")


def test_a_clock_that_restarts_is_resynchronised_with_an_event(ward, fault_row):
    st = ward
    for _ in range(5):
        st.frame("restart")
    before = st.until(lambda: st.mat("restart"), lambda m: read(m) == 8)
    st.seq["restart"] = 0  # the device restarted: its clock starts at 0 again
    st.frame("restart")  # skipped: one frame off the clock could be a glitch ...
    st.frame("restart")  # ... but two that agree are a new clock
    m = st.until(lambda: st.mat("restart"), lambda m: read(m) == read(before) + 1)
    assert m["skipped"] == 1
    (event,) = st.get("mats/restart/api/events?kind=clock")
    assert event["detail"]["source_t"] == 1.0 and event["detail"]["jump_s"] < -5
    st.live_after_glitch("restart", frames=3)
    fault_row("MQTT", "the mat's clock restarts at 0 (a real jump)", "mat live",
              "re-synchronised, event 'clock'")  # fmt: skip


def body(**fields) -> bytes:
    """A good payload of a 16-element pressure mat, with ``fields`` changed."""
    d = {"seq": 1, "t": 1, "values": [0.5] * 16, "unit": "N/cm2", **fields}
    return json.dumps({k: v for k, v in d.items() if v is not None}).encode()


VALUES = b"0.5," * 15 + b"0.5"
#: case -> (payload, what the station says about it)
JUNK = {
    "not JSON": (b"{not json", "not JSON"),
    "a JSON array": (b"[1, 2, 3]", "JSON object"),
    "an empty payload": (b"", "not JSON"),
    "binary garbage": (bytes(range(256)) * 4, "not JSON"),
    "UTF-16 JSON": (body().decode().encode("utf-16"), "not JSON"),
    "no 't'": (body(t=None), "lacks 't'"),
    "'t' NaN": (b'{"seq": 1, "t": NaN, "values": [' + VALUES + b'], "unit": "N/cm2"}', "'t'"),
    "'t' Infinity": (b'{"seq": 1, "t": Infinity, "values": [' + VALUES + b"]}", "'t'"),
    "'t' as text": (body(t="1"), "'t'"),
    "'seq' negative": (body(seq=-1), "'seq'"),
    "'seq' 2**70": (body(seq=2**70), "'seq'"),
    "a value as text": (body(values=["0.5"] * 16), "value 1"),
    "a NaN value": (b'{"seq": 1, "t": 1, "values": [NaN,' + VALUES[4:] + b"]}", "value 1"),
    "a value 1e999": (b'{"seq": 1, "t": 1, "values": [1e999,' + VALUES[4:] + b"]}", "value 1"),
    # (an integer no float holds: refused by the one JSON parser, texsense.data.files.json_loads)
    "an integer of 400 digits": (body(values=[10**400] + [1] * 15), "401 digits"),
    "'t' an integer of 400 digits": (body(t=10**400), "401 digits"),
    "'dt' an integer of 400 digits": (body(dt=10**400), "401 digits"),
    "'element_times' of 400 digits": (body(element_times=[10**400] + [1] * 15), "401 digits"),
    "a unit of length": (body(unit="mm"), "neither"),
    "capacitance on a pressure mat": (body(unit="pF"), "is not pressure"),
    "'dt' negative": (body(dt=-1), "'dt'"),
    "'dt' 1e308": (body(dt=1e308), "not a finite time"),
    "'element_times' of 3": (body(element_times=[1, 2, 3]), "'element_times'"),
}


@pytest.mark.parametrize("case", list(JUNK))
def test_a_malformed_payload_is_counted_and_skipped(ward, case, fault_row):
    st = ward
    before = st.mat("junk")
    payload, said = JUNK[case]
    st.raw("junk", payload)
    m = st.until(lambda: st.mat("junk"), lambda m: m["malformed"] == before["malformed"] + 1)
    assert said in m["last_error"], m["last_error"]
    after = st.live_after_glitch("junk")  # its next frame is processed
    assert after["refused"] is None
    assert "Traceback" not in st.log()
    fault_row("MQTT", f"a payload: {case}", "mat live")


def test_a_wrong_element_count_once_and_sustained(ward, fault_row):
    st = ward
    st.frame("count", n=95)  # 95 of 96 values, once
    m = st.live_after_glitch("count")
    assert m["malformed"] == 1 and m["refused"] is None
    one_line_about(st, "count", "got 95")
    fault_row("MQTT", "one frame with 95 of 96 values", "mat live")
    start, first = time.monotonic(), st.seq.get("refuse", 0)
    while st.mat("refuse")["state"] != "refused":  # the station refuses after 1 s (and 10)
        assert time.monotonic() < start + 20, st.log()[-3000:]
        # frame times in step with the wall clock, however slow the machine
        st.offset["refuse"] = first + time.monotonic() - start - st.seq.get("refuse", 0)
        st.frame("refuse", n=95)
        time.sleep(0.1)
    m = st.mat("refuse")
    assert m["malformed"] >= 10 and read(m) == 3
    assert "95 values" in m["refused"] and "96 elements" in m["refused"]
    st.frame("refuse")
    st.until(lambda: st.mat("refuse"), lambda m: m["ignored"] >= 1)
    assert st.post("api/mats/refuse/admit")["kind"] == "admitted"
    assert st.live_after_glitch("refuse")["refused"] is None
    kinds = [e["kind"] for e in st.get("mats/refuse/api/events")]
    assert "refused" in kinds and "admitted" in kinds
    fault_row("MQTT", "frames of 95 of 96 values for 1 s (--refuse-after 1)", "refused",
              "an event; lifted by the API and the ward page")  # fmt: skip


def test_oversized_payloads_are_never_parsed(ward, fault_row):
    st = ward
    big = b'{"seq":1,"t":1,"values":[' + b"0.5," * 50_000 + b'0.5],"unit":"N/cm2"}'  # 200 kB
    st.raw("size", big)
    st.until(lambda: st.mat("size"), lambda m: m["malformed"] == 1)
    assert "bytes" in st.mat("size")["last_error"]
    st.live_after_glitch("size")
    fault_row("MQTT", "a 200 kB payload for a 16-element mat", "mat live", "refused unparsed")
    # 46 MB (12 M values): the station's broker refuses the packet and drops the sender,
    # which comes back (paho reconnects) and goes on
    huge = b'{"seq":1,"t":1,"values":[' + b"1.5," * 12_000_000 + b"0.5]}"
    st.raw("huge", b"{}")  # (the mat's client, connected)
    answers = st.client_answers["huge"]
    st.raw("huge", huge)
    st.until(lambda: answers, lambda a: "disconnected" in a and a[-1] != "disconnected")
    st.live_after_glitch("huge")
    assert st.mat("huge")["malformed"] == 1  # the "{}"; the 46 MB never reached the station
    fault_row("MQTT", "a 46 MB payload of 12 M values", "mat live",
              "refused by the station's broker")  # fmt: skip


def test_the_stations_broker_lets_nobody_in_without_credentials(folder, fault_row):
    """(Before: `mosquitto_pub` without credentials reached any mat of a station started
    with --token.)"""
    token = "t0ken-1234"
    with WardStation(folder, {"bed1": "4x4"}, "--token", token, token=token) as st:
        c, answers = st.client(None)
        c.publish("texsense/bed1/frames", body(seq=0, t=0))
        time.sleep(0.5)
        c.disconnect()
        c.loop_stop()
        assert answers and answers[0] != 0 and answers[0].is_failure, answers
        assert st.mat("bed1")["frames"] == 0
    fault_row("MQTT", "publish to the station's own broker without credentials", "refused")


def test_nobody_publishes_without_credentials(ward, fault_row):
    st = ward
    import paho.mqtt.client as mqtt

    for user, password in [("victim", "wrong-password"), ("texsense-station", "a-guess")]:
        c, answers = st.client(user, password)
        try:
            assert answers and answers[0].is_failure, (user, answers)
            assert "authori" in str(answers[0]).lower()
            info = c.publish("texsense/victim/frames", b"{}")
            assert info.rc != mqtt.MQTT_ERR_SUCCESS or not c.is_connected()
        finally:
            c.disconnect()
            c.loop_stop()
    fault_row("MQTT", "log in to the station's broker with a wrong password", "refused")
    before = read(st.mat("victim"))
    body = {"seq": 99, "t": 99, "values": [9.0] * 16, "unit": "N/cm2"}
    st.raw("victim", json.dumps(body).encode(), as_mat="intruder")  # another mat's topic
    st.live_after_glitch("intruder")  # the intruder's own frames go through meanwhile
    time.sleep(0.3)
    assert read(st.mat("victim")) == before
    fault_row("MQTT", "a mat's credentials on another mat's topic", "refused")


def test_a_flood_of_unknown_topics_is_bounded(folder, fault_row):
    import paho.mqtt.client as mqtt
    from websockets.sync.client import connect

    with (
        Broker() as site,
        WardStation(  # a site broker that lets anyone publish
            folder, {"bed1": "4x4"}, "--broker", f"mqtt://127.0.0.1:{site.port}"
        ) as st,
    ):
        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
        c.connect("127.0.0.1", site.port)
        c.loop_start()
        for k in range(20_000):
            c.publish(f"texsense/intruder-{k}/frames", b"{}")
        c.publish("texsense/bed1/frames", body(seq=0, t=0))
        st.until(lambda: st.mat("bed1")["frames"], lambda n: n == 1, 60)
        c.disconnect()
        c.loop_stop()
        ward = st.until(lambda: st.get("api/ward"), lambda w: w["unknown_forgotten"] >= 19_900)
        assert ward["unknown_topics"] == 100 and len(json.dumps(ward)) < 20_000
        with connect(f"ws://127.0.0.1:{st.port}/ws/ward") as ws:
            assert len(ws.recv(timeout=5)) < 20_000
        assert st.log().count("unknown mat") == 1
    fault_row("MQTT", "20,000 distinct unknown topics", "mat live",
              "100 kept, the rest forgotten; /api/ward < 20 kB")  # fmt: skip


SITE_CONF = """\
# A site's Mosquitto for texsense stations (docs/station.md, "A site broker")
listener {port} 127.0.0.1
cafile {dir}/ca.pem
certfile {dir}/server.pem
keyfile {dir}/server.key
allow_anonymous false
password_file {dir}/passwd
acl_file {dir}/acl
persistence false
"""
SITE_ACL = """\
# the station of ward 3 reads its mats' frames ...
user ward3-station
topic read ward3/+/frames
# ... and every mat (user name = mat id) publishes to its own topic only
pattern write ward3/%u/frames
"""


def openssl(folder: Path, *args: str) -> None:
    subprocess.run(["openssl", *args], cwd=folder, check=True, capture_output=True)


@contextlib.contextmanager
def site_broker(folder: Path):
    """A Mosquitto as a site would run it: TLS, passwords, an ACL by pattern."""
    openssl(folder, "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2",
            "-subj", "/CN=texsense test CA", "-keyout", "ca.key", "-out", "ca.pem")  # fmt: skip
    openssl(folder, "req", "-newkey", "rsa:2048", "-nodes", "-subj", "/CN=127.0.0.1",
            "-keyout", "server.key", "-out", "server.csr")  # fmt: skip
    (folder / "san.ext").write_text("subjectAltName = IP:127.0.0.1\n")
    openssl(folder, "x509", "-req", "-in", "server.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
            "-CAcreateserial", "-days", "2", "-extfile", "san.ext",
            "-out", "server.pem")  # fmt: skip
    for user, password in [("ward3-station", "station-pass-1"), ("bed7", "bed7-pass-12")]:
        flags = ["-c"] if user == "ward3-station" else []
        subprocess.run(["mosquitto_passwd", *flags, "-b", str(folder / "passwd"), user,
                        password], check=True, capture_output=True)  # fmt: skip
    (folder / "acl").write_text(SITE_ACL)
    port = free_port()
    (folder / "site.conf").write_text(SITE_CONF.format(port=port, dir=folder))
    for f in folder.iterdir():
        f.chmod(0o644)  # Mosquitto started as root reads them as its own user
    proc = subprocess.Popen(["mosquitto", "-c", str(folder / "site.conf")],
                            stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        for _ in range(100):
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.2):
                break
            time.sleep(0.05)
        yield port
    finally:
        proc.terminate()
        proc.wait(timeout=5)


def test_a_site_broker_with_tls_and_passwords(folder, fault_row):
    import paho.mqtt.client as mqtt

    with site_broker(folder) as port:
        (folder / "station-password").write_text("station-pass-1\n")
        url = f"mqtts://ward3-station@127.0.0.1:{port}"
        site = ["--broker", url, "--mats", "ward3/+/frames", "--broker-ca",
                str(folder / "ca.pem"), "--broker-password-file",
                str(folder / "station-password")]  # fmt: skip
        with WardStation(folder, {"bed7": "4x4"}, *site) as st:  # (connected, or it fails)
            mat = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
            mat.username_pw_set("bed7", "bed7-pass-12")
            mat.tls_set(ca_certs=str(folder / "ca.pem"))
            mat.connect("127.0.0.1", port)
            mat.loop_start()
            mat.publish("ward3/bed7/frames", body(seq=0, t=0)).wait_for_publish(5)
            st.until(lambda: st.mat("bed7")["frames"], lambda n: n == 1)
            mat.disconnect()
            mat.loop_stop()
            assert "station-pass-1" not in st.log() + json.dumps(st.get("api/ward"))
        fault_row("MQTT", "a site broker with TLS, passwords and an ACL (--broker mqtts://, "
                  "--broker-ca, --broker-password-file)", "mat live")  # fmt: skip
        (folder / "station-password").write_text("a-wrong-password\n")
        with WardStation(folder, {"bed7": "4x4"}, *site, connected=False) as st:
            ward = st.until(lambda: st.get("api/ward"), lambda w: w["refusal"])
            assert "authori" in ward["refusal"].lower() and not ward["connected"]
            time.sleep(2.5)  # it tries again, and says so only once
            log = st.log()
            assert log.count("refused the station") == 1 and "Traceback" not in log, log
        fault_row("MQTT", "a site broker refuses the station's password", "said",
                  "one line; /api/ward and the ward page say it")  # fmt: skip


def test_a_mat_whose_serial_device_is_missing_is_said_and_the_ward_goes_on(folder, fault_row):
    more = '[[mat]]\nid = "chair3"\nlayout = "grid:2x3"\nsource = "serial:/dev/ttyTEXSENSE-NONE"\n'
    with WardStation(folder, {"bed1": "4x4"}, more=more) as st:
        st.frame("bed1")
        st.until(lambda: st.mat("bed1")["frames"], lambda n: n == 1)
        chair = st.until(lambda: st.mat("chair3"), lambda m: m["problem"])
        assert chair["problem"] == ("serial:/dev/ttyTEXSENSE-NONE: cannot open it (No such "
                                    "file or directory); trying again every 2 s")  # fmt: skip
        time.sleep(2.5)
        log = st.log()
        assert log.count("ttyTEXSENSE-NONE: cannot open it") == 1, log
        assert "Traceback" not in log
    fault_row("hardware", "station: a mat's serial device is missing", "said",
              "its tile says so; the other mats go on")  # fmt: skip
