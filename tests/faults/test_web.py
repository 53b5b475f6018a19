"""Fault battery, web: foreign pages, foreign Host names (DNS rebinding), cross-site
requests, tokens and security headers, against the monitor's and the station's servers
(docs/monitor.md, "Security"). Most cases use the apps in-process; the last one is a real
headless Chromium on a page of another origin against running servers."""

from __future__ import annotations

import contextlib
import http.server
import sys
import threading
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from conftest import ROOT, ChildServer
from faults.conftest import assert_clear_error, run_cli
from texsense import Layout, Recording
from texsense.data.protocol import Frame
from texsense.io import save
from texsense.monitor import ExposureTracker, Monitor, ReplaySource
from texsense.monitor.server import create_app
from texsense.station.server import create_ward_app
from texsense.station.ward import MatConfig, Station

# Debian's Chromium as the dashboard's tests drive it (open_page: for test_stop.py too)
sys.path.insert(0, str(ROOT / "tests" / "monitor"))
from test_browser import CHROMIUM_ARGS, chromium, open_page  # noqa: F401

HOST = "127.0.0.1:8765"
BASE = f"http://{HOST}"
EVIL = "http://evil.example"


def loaded_monitor(tmp_path: Path) -> Monitor:
    """A monitor of a 2 x 3 pressure mat with an open reposition alert."""
    lay = Layout.grid(2, 3)
    rec = Recording(np.ones((2, 6)), [0.0, 1.0], lay, "pressure", "N/cm2")
    m = Monitor(ReplaySource(rec, speed=0), record_dir=tmp_path / "rec",
                tracker=ExposureTracker(lay, reposition_min=5))  # fmt: skip
    for k in range(320):
        m.process(Frame(k, np.full(6, float(k)), np.ones(6), "N/cm2"))
    assert m.tracker.open_alert is not None
    return m


def loaded_station(tmp_path: Path) -> Station:
    st = Station(None, [MatConfig("bed1", Layout.grid(2, 3), quantity="pressure",
                                  reposition_min=5)], record_dir=tmp_path)  # fmt: skip
    for k in range(320):
        st.mats["bed1"].feed(Frame(k, np.full(6, float(k)), np.ones(6), "N/cm2"), float(k))
    return st


@pytest.fixture(params=["monitor", "station"])
def server(request, tmp_path):
    """(client, URL of a state-changing route, a GET route, the WebSocket, what to check
    that the state did not change)."""
    if request.param == "monitor":
        m = loaded_monitor(tmp_path)
        app = create_app(m, run_source=False)
        ack = f"/api/alerts/{m.tracker.open_alert.id}/ack"
        return request.param, TestClient(app, base_url=BASE), ack, "/api/status", "/ws", m
    st = loaded_station(tmp_path)
    m = st.mats["bed1"].monitor
    app = create_ward_app(st)
    ack = f"/api/mats/bed1/alerts/{m.tracker.open_alert.id}/ack"
    return request.param, TestClient(app, base_url=BASE), ack, "/api/mats", "/ws/ward", m


def ws_refused(client: TestClient, path: str, headers: dict[str, str], host: str = HOST) -> bool:
    try:
        with client.websocket_connect(f"ws://{host}{path}", headers=headers) as ws:
            ws.receive_text()
    except WebSocketDisconnect as e:
        return e.code in (4401, 4403)
    return False


def test_another_host_name_is_refused_dns_rebinding(server, fault_row):
    kind, client, _ack, get, ws, _m = server
    for path in ("/", get, "/static/app.js", "/docs"):
        r = client.get(path, headers={"Host": "evil.example:8765"})
        assert r.status_code == 403 and "unknown Host" in r.json()["detail"], path
    assert ws_refused(client, ws, {}, host="evil.example:8765")
    if kind == "station":  # a mat's dashboard mounted in the station too
        r = client.get("/mats/bed1/api/status", headers={"Host": "evil.example"})
        assert r.status_code == 403
    assert client.get(get).status_code == 200  # 127.0.0.1 itself
    assert client.get(get, headers={"Host": "localhost:8765"}).status_code == 200
    assert client.get(get, headers={"Host": "[::1]:8765"}).status_code == 200
    for odd in ODD_HOSTS:  # a loopback name with something after it is no loopback name
        assert client.get(get, headers={"Host": odd}).status_code == 403, odd
    fault_row("web", f"{kind}: a request naming another host (DNS rebinding), loopback, no "
              "token", "refused", cases=4 + len(ODD_HOSTS))  # fmt: skip


#: Host headers that start like a loopback name and are none (the part after ':' was dropped
#: whatever it held, so these passed as 127.0.0.1)
ODD_HOSTS = ["127.0.0.1:8765.evil.example", "localhost:8765@evil.example", "localhost:abc", "[::1",
             "[::1]evil.example", "[::1]:80.evil.example", "127.0.0.1:+80"]  # fmt: skip


def test_a_page_of_another_origin_reads_nothing(server, fault_row):
    kind, client, _ack, get, ws, _m = server
    for origin in (EVIL, "http://127.0.0.1:9999", "http://localhost:8765", "null"):
        r = client.get(get, headers={"Origin": origin})
        assert r.status_code == 403 and "cross-origin" in r.json()["detail"], origin
        assert ws_refused(client, ws, {"Origin": origin}), origin
    assert client.get(get, headers={"Origin": BASE}).status_code == 200  # its own page
    with client.websocket_connect(f"ws://{HOST}{ws}", headers={"Origin": BASE}) as sock:
        assert sock.receive_text()
    fault_row("web", f"{kind}: a page of another origin reads the API and the WebSocket",
              "refused")  # fmt: skip


def test_a_cross_site_post_changes_nothing(server, fault_row):
    kind, client, ack, _get, _ws, m = server
    alert = m.tracker.open_alert
    for headers in ({"Origin": EVIL}, {"Origin": "null"}, {"Sec-Fetch-Site": "cross-site"},
                    {"Origin": BASE, "Sec-Fetch-Site": "same-site"}):  # fmt: skip
        r = client.post(ack, headers=headers)
        assert r.status_code == 403, headers
        assert alert.active, headers
    r = client.post(ack, headers={"Origin": BASE, "Sec-Fetch-Site": "same-origin"})
    assert r.status_code == 200 and not alert.active  # the dashboard's own button
    fault_row("web", f"{kind}: a cross-site POST acknowledging a live alert (CSRF)", "refused")


def test_the_token_is_needed_everywhere_and_comes_from_a_file_or_the_environment(
    tmp_path, fault_row
):
    from texsense.monitor.web import Access, resolve_token

    m = loaded_monitor(tmp_path)
    client = TestClient(create_app(m, access=Access("s3cret-token")), base_url=BASE)
    for path in ("/", "/api/status", "/api/events", "/static/app.js", "/openapi.json"):
        assert client.get(path).status_code == 401, path
        assert client.get(path, headers={"Authorization": "Bearer wrong-token"}).status_code == 401
        assert client.get(path, headers={"X-Texsense-Token": "s3cret-token"}).status_code == 200
    assert ws_refused(client, "/ws?token=wrong-token", {})
    fault_row("web", "no or a wrong token, on every route and the WebSocket", "refused")
    (tmp_path / "token").write_text("from-a-file-123\n")
    assert resolve_token(None, tmp_path / "token", {}) == "from-a-file-123"
    assert resolve_token(None, None, {"TEXSENSE_TOKEN": "from-the-env-1"}) == "from-the-env-1"
    assert resolve_token(None, None, {}) is None
    rc, _out, err = run_cli("monitor", "--host", "0.0.0.0", "--no-posture", cwd=tmp_path)
    assert "--token-file" in assert_clear_error(rc, err, "0.0.0.0")
    fault_row("web", "monitor bound beyond loopback without a token", "clear error")
    rc, _out, err = run_cli("monitor", "--token-file", tmp_path / "none", cwd=tmp_path)
    assert_clear_error(rc, err, "--token-file", "none")
    (tmp_path / "short").write_text("abc")
    rc, _out, err = run_cli("station", "--virtual-mats", "1", "--token-file", tmp_path / "short",
                            cwd=tmp_path)  # fmt: skip
    assert_clear_error(rc, err, "8 characters")
    fault_row("web", "a token file that is missing or too short", "clear error")


def test_every_response_has_the_security_headers(server, fault_row):
    kind, client, _ack, get, _ws, _m = server
    for r in (client.get("/"), client.get(get), client.get("/static/none.js"),
              client.get(get, headers={"Origin": EVIL}), client.get("/docs")):  # fmt: skip
        csp = r.headers["content-security-policy"]
        assert "frame-ancestors 'none'" in csp and "default-src 'none'" in csp
        assert r.headers["x-frame-options"] == "DENY"
        assert r.headers["referrer-policy"] == "no-referrer"
        assert r.headers["x-content-type-options"] == "nosniff"
    page = client.get("/").headers["content-security-policy"]
    assert "script-src 'self';" in page and "unsafe-inline" not in page
    fault_row("web", f"{kind}: framing, sniffing and referrer leaks (security headers)",
              "headers set", "CSP, X-Frame-Options, Referrer-Policy, nosniff")  # fmt: skip


def test_names_and_origins_can_be_allowed(tmp_path, fault_row):
    from texsense.monitor.web import Access

    m = loaded_monitor(tmp_path)
    access = Access(None, hosts=["ward3.example"], origins=["https://portal.example"])
    client = TestClient(create_app(m, access=access), base_url=BASE)
    assert client.get("/api/status", headers={"Host": "ward3.example"}).status_code == 200
    assert (
        client.get("/api/status", headers={"Origin": "https://portal.example"}).status_code == 200
    )
    assert client.get("/api/status", headers={"Host": "ward4.example"}).status_code == 403
    public = Access("s3cret-token", bind="0.0.0.0")
    assert public.host_ok("192.168.1.20:8765") and not public.host_ok("evil.example")
    fault_row("web", "a name or origin that is not allowed (--allow-host, --allow-origin)",
              "refused")  # fmt: skip


# ----------------------------------------------------------------------------- in Chromium
ATTACK = """<!doctype html><meta charset="utf-8"><title>a page of another site</title>
<script>
window.results = {ws: [], posts: []};
function tryWs(url) {
  const ws = new WebSocket(url);
  ws.onopen = () => window.results.ws.push("open " + url);
  ws.onmessage = (m) => window.results.ws.push("read " + url + " " + m.data.slice(0, 40));
}
async function tryPost(url) {
  try {
    await fetch(url, {method: "POST", mode: "no-cors"});
    window.results.posts.push("sent " + url);
  } catch (e) { window.results.posts.push("failed " + url); }
}
</script>"""


class _Page(http.server.BaseHTTPRequestHandler):
    def do_GET(self):
        body = ATTACK.encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):
        pass


@contextlib.contextmanager
def attacker_site():
    """A web server of another origin (localhost on another port) serving :data:`ATTACK`."""
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Page)
    thread = threading.Thread(target=srv.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://localhost:{srv.server_address[1]}/"
    finally:
        srv.shutdown()
        srv.server_close()


def status(url: str) -> dict:
    import json

    with urllib.request.urlopen(url + "api/status", timeout=3) as r:
        return json.load(r)


@pytest.mark.slow
def test_a_foreign_page_in_chromium_reads_no_map_and_acknowledges_no_alert(tmp_path, fault_row):
    from playwright.sync_api import sync_playwright

    rec = Recording(np.ones((400, 6)), np.arange(400.0), Layout.grid(2, 3), "pressure", "N/cm2")
    save(rec, tmp_path / "chair.h5")
    m = ChildServer(tmp_path, "monitor", "--source", f"replay:{tmp_path / 'chair.h5'}",
                    "--speed", "100", "--reposition-min", "5")  # fmt: skip
    try:
        alert = m.until(lambda: status(m.url)["alert"], lambda a: a and a["active"], 60)
        with attacker_site() as evil, sync_playwright() as pw:
            rules = "--host-resolver-rules=MAP rebound.test 127.0.0.1"
            browser = pw.chromium.launch(executable_path=chromium(), args=[*CHROMIUM_ARGS, rules])
            try:
                page = browser.new_page()
                page.goto(evil)
                ws, post = f"ws://127.0.0.1:{m.port}/ws", f"{m.url}api/alerts/{alert['id']}/ack"
                page.evaluate(f"tryWs({ws!r}); tryPost({post!r})")
                page.wait_for_timeout(2500)  # the monitor sends a snapshot per frame
                results = page.evaluate("window.results")
                # DNS rebinding: a name of the attacker's that now points at 127.0.0.1
                rebound = page.goto(f"http://rebound.test:{m.port}/")
                rebound_status, rebound_text = rebound.status, rebound.text()
            finally:
                browser.close()
        assert len(results["posts"]) == 1 and results["ws"] == [], results  # never opened
        assert status(m.url)["alert"]["active"], "a foreign page acknowledged the alert"
        assert rebound_status == 403 and "texsense monitor" not in rebound_text
        log = m.log()  # the requests did reach the monitor, and were refused
        assert f"refused POST /api/alerts/{alert['id']}/ack" in log, log
        assert "refused WebSocket /ws" in log and "Traceback" not in log
    finally:
        m.stop()
    fault_row("web", "a foreign page in Chromium reads the WebSocket and POSTs an "
              "acknowledgement; a rebound DNS name", "refused")  # fmt: skip
