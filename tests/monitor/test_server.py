import numpy as np
import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from texsense import Layout, Recording, load
from texsense.data.protocol import Frame
from texsense.exceptions import ParameterError
from texsense.monitor import ExposureTracker, Monitor, ReplaySource
from texsense.monitor.server import create_app, is_loopback, serve


def local_client(app, **kwargs):
    """A test client that reaches the app as a browser on this machine would (Host
    127.0.0.1:8765; the default Host ``testserver`` is refused)."""
    return TestClient(app, base_url="http://127.0.0.1:8765", **kwargs)


@pytest.fixture()
def monitor(tmp_path):
    lay = Layout.grid(2, 3)
    rec = Recording(np.ones((2, 6)), [0.0, 1.0], lay, "pressure", "N/cm2")
    m = Monitor(
        ReplaySource(rec, speed=0),
        record_dir=tmp_path / "rec",
        tracker=ExposureTracker(lay, reposition_min=5),
    )
    return m


def feed(m, seconds, p=1.0, start=0.0):
    for k in range(int(seconds)):
        m.process(Frame(k, np.full(6, start + k), np.full(6, p), "N/cm2"))


def test_rest_api_status_frames_events_alert_and_recording(monitor):
    client = local_client(create_app(monitor, run_source=False))
    assert client.get("/api/frame/latest").status_code == 503
    feed(monitor, 320)
    st = client.get("/api/status").json()
    assert st["frames"] == 320 and st["layout"]["shape"] == [2, 3]
    assert st["alert"]["active"] and st["threshold"]["unit"] == "mmHg"
    latest = client.get("/api/frame/latest").json()
    assert latest["stats"]["peak_ncm2"] == 1.0 and len(latest["pressure"]) == 6
    kinds = [e["kind"] for e in client.get("/api/events").json()]
    assert kinds == ["reposition", "seated"]
    alert_id = st["alert"]["id"]
    assert client.post(f"/api/alerts/{alert_id}/ack").json()["kind"] == "acknowledged"
    assert client.post("/api/alerts/77/ack").status_code == 404
    files = client.post("/api/record/start").json()["files"]
    assert client.post("/api/record/start").status_code == 409
    feed(monitor, 5, start=320.0)
    assert client.post("/api/record/stop").json() == {"frames": 5}
    assert load(files[0]).n_frames == 5
    name = files[0].rsplit("/", 1)[1]
    assert client.get(f"/api/recordings/{name}").status_code == 200
    assert client.get("/api/sessions").json()[0]["recordings"] == files
    assert "/api/status" in client.get("/openapi.json").json()["paths"]
    page = client.get("/")
    assert page.status_code == 200 and "texsense monitor" in page.text
    assert client.get("/static/app.js").status_code == 200


def test_websocket_sends_snapshots(monitor):
    client = local_client(create_app(monitor, run_source=False))
    feed(monitor, 1)
    with client.websocket_connect("ws://127.0.0.1:8765/ws") as ws:
        assert ws.receive_json()["frames"] == 1
        feed(monitor, 1, start=1.0)
        assert ws.receive_json()["frames"] == 2


def test_no_path_traversal(monitor, tmp_path):
    (tmp_path / "secret.h5").write_text("x")
    client = local_client(create_app(monitor, run_source=False))
    for url in [
        "/static/..%2F..%2Fexceptions.py",
        "/static/../live.py",
        "/static/%2e%2e",
        "/static/.hidden.js",
        "/api/recordings/..%2Fsecret.h5",
        "/api/recordings/%2E%2E%2Fsecret.h5",
        "/static/index.html%00.js",
    ]:
        r = client.get(url)
        assert r.status_code == 404, url
        assert r.text != "x"


def test_token_is_required_on_every_request_when_set(monitor):
    client = local_client(create_app(monitor, token="s3cret", run_source=False))
    feed(monitor, 1)
    for url in ["/", "/api/status", "/api/frame/latest", "/openapi.json", "/static/app.js"]:
        assert client.get(url).status_code == 401, url
        assert client.get(url, headers={"Authorization": "Bearer s3cret"}).status_code == 200
    assert client.post("/api/record/start?token=wrong").status_code == 401
    assert client.get("/api/status", headers={"X-Texsense-Token": "s3cret"}).status_code == 200
    assert client.get("/api/status?token=s3cret").status_code == 200
    with (
        pytest.raises(WebSocketDisconnect),
        client.websocket_connect("ws://127.0.0.1:8765/ws") as ws,
    ):
        ws.receive_json()
    with client.websocket_connect("ws://127.0.0.1:8765/ws?token=s3cret") as ws:
        assert ws.receive_json()["frames"] == 1


def test_binding_beyond_loopback_needs_a_token(monitor):
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")
    with pytest.raises(ParameterError, match="token"):
        serve(monitor, host="0.0.0.0")


def test_cli_names_a_port_in_use_before_starting(capsys):
    import socket

    from texsense.cli import main

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert main(["monitor", "--no-posture", "--port", str(port)]) == 1
    err = capsys.readouterr().err
    assert f"cannot listen on 127.0.0.1:{port}" in err and "--port" in err


def test_cli_refuses_a_public_address_without_a_token(capsys):
    from texsense.cli import main

    assert main(["monitor", "--host", "0.0.0.0", "--no-posture"]) == 1
    assert "--token" in capsys.readouterr().err


def test_a_recording_name_is_never_reused(monitor):
    """POST /api/record/start?name=x twice used to truncate the first recording."""
    client = local_client(create_app(monitor, run_source=False))
    feed(monitor, 3)
    (first,) = client.post("/api/record/start?name=x").json()["files"]
    feed(monitor, 4, start=3.0)
    assert client.post("/api/record/stop").json() == {"frames": 4}
    again = client.post("/api/record/start?name=x")
    assert again.status_code == 409 and "exists already" in again.json()["detail"]
    assert load(first).n_frames == 4  # the first recording is whole
    # unnamed recordings started within the same second get names of their own
    names = []
    for k in range(2):
        names += client.post("/api/record/start").json()["files"]
        feed(monitor, 1, start=7.0 + k)
        client.post("/api/record/stop")
    assert len(set(names)) == 2 and all(load(f).n_frames == 1 for f in names)
