"""Families "a request that changes state without asking" and "a request body or option that is
huge or odd" (issue 32, items 2 and 4), generated from the route tables of both servers:
every route that changes state is refused from another site (``Sec-Fetch-Site``, a foreign
``Origin``), refuses a body over the limit before reading it and answers odd bodies (NaN, not
JSON, the wrong shape) with a 4xx, never a 500; no GET route writes anything. Then a real
monitor takes a 300 MB body (announced and chunked) without its memory growing, and the
token options refuse ``/dev/zero``, a FIFO and a huge file in one line.
"""

from __future__ import annotations

import http.client
import os
import re
import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from conftest import ChildServer
from faults._families import batch, one_line, small_recording
from faults.test_web import BASE, loaded_monitor, loaded_station
from texsense.io import save
from texsense.monitor.server import create_app
from texsense.monitor.web import MAX_BODY
from texsense.station.server import create_ward_app

UNSAFE = {"POST", "PUT", "PATCH", "DELETE"}
ODD_BODIES = [b'{"frames": NaN}', b'{"frames": 1e999}', b"[", b'"x"', b"[1, 2]", b"\xff\xfe",
              b'{"regions": {"a": NaN}}', b"null",
              b"[" * 5000 + b"]" * 5000, b'{"a":' * 5000 + b"1" + b"}" * 5000]  # fmt: skip


def _fill(path: str, alert: int) -> str:
    """A route's path with plausible parameters."""
    values = {"name": "ok.h5", "i": "0", "step": "zero", "alert_id": str(alert), "mat_id": "bed1",
              "path": "app.js", "filename": "app.js"}  # fmt: skip
    return re.sub(r"\{(\w+)(:\w+)?\}", lambda m: values.get(m.group(1), "x"), path)


def _routes(app, prefix: str = "") -> list[tuple[str, str]]:
    """(method, path) of every route of an app: its routers and mounted apps included."""
    out = []
    for route in getattr(app, "routes", None) or app.router.routes:
        if hasattr(route, "original_router"):  # an included router
            out += _routes(route.original_router, prefix)
        elif getattr(route, "app", None) is not None and hasattr(route, "routes"):  # a mount
            out += _routes(route.app, prefix + route.path)
        for method in sorted(getattr(route, "methods", None) or ()):
            if method not in ("HEAD", "OPTIONS"):
                out.append((method, prefix + route.path))
    return out


@pytest.fixture(params=["monitor", "station"])
def app(request, tmp_path):
    """(kind, app, an alert id, the folder its routes may write in)."""
    if request.param == "monitor":
        m = loaded_monitor(tmp_path)
        m.record_dir.mkdir(parents=True, exist_ok=True)
        save(small_recording(), m.record_dir / "ok.h5")
        return "monitor", create_app(m, run_source=False), m.tracker.open_alert.id, tmp_path
    st = loaded_station(tmp_path)
    alert = st.mats["bed1"].monitor.tracker.open_alert.id
    return "station", create_ward_app(st), alert, tmp_path


def _snapshot(folder: Path) -> dict[str, tuple[int, float]]:
    return {str(p): (p.stat().st_size, p.stat().st_mtime) for p in folder.rglob("*")
            if p.is_file() and not p.name.endswith((".sqlite", ".sqlite-journal"))}  # fmt: skip


def test_every_route_that_changes_state_asks_first(app, fault_row):
    kind, application, alert, _ = app
    routes = _routes(application)
    unsafe = [(m, p) for m, p in routes if m in UNSAFE]
    assert unsafe, routes
    tried = 0
    with TestClient(application, base_url=BASE) as client:
        for method, path in unsafe:
            url = _fill(path, alert)
            for headers in ({"Sec-Fetch-Site": "cross-site"}, {"Sec-Fetch-Site": "same-site"},
                            {"Origin": "http://evil.example"}):  # fmt: skip
                r = client.request(method, url, headers=headers, content=b"{}")
                assert r.status_code == 403, (method, url, headers, r.status_code)
                tried += 1
            r = client.request(method, url, content=b"x" * (MAX_BODY + 1))
            assert r.status_code == 413, (method, url, r.status_code)
            r = client.request(method, url, headers={"Content-Length": str(300 << 20)},
                               content=b"x" * 10)  # fmt: skip
            assert r.status_code == 413, (method, url, r.status_code)
            tried += 2
            if url.endswith("/report"):  # it takes no body: not a report per odd body
                url = url.replace("ok.h5", "missing.h5")
            for body in ODD_BODIES:
                r = client.request(method, url, content=body,
                                   headers={"Content-Type": "application/json"})  # fmt: skip
                assert r.status_code < 500, (method, url, body, r.status_code, r.text[:200])
                assert "Traceback" not in r.text
                tried += 1
    fault_row("requests", f"{kind}: {len(unsafe)} state-changing routes x another site, "
              "bodies over the limit, odd bodies", "refused", f"{tried} requests: 403, 413, "
              "4xx (never 500)", cases=tried)  # fmt: skip


def test_no_get_route_writes(app, fault_row):
    kind, application, alert, folder = app
    gets = [(m, p) for m, p in _routes(application) if m == "GET"]
    before = _snapshot(folder)
    with TestClient(application, base_url=BASE) as client:
        for _method, path in gets:
            for query in ("", "?format=pdf", "?format=html"):
                r = client.get(_fill(path, alert) + query)
                assert r.status_code < 500, (path, query, r.status_code, r.text[:200])
    assert _snapshot(folder) == before
    fault_row(
        "requests",
        f"{kind}: {len(gets)} GET routes (reports included)",
        "nothing written",
        cases=3 * len(gets),
    )


#: names in a route's path that the file system refuses or that reach for another place
ODD_NAMES = ["a" * 300, "\u00e9" * 200, "b" * 247 + ".h5", "%2e%2e%2fok.h5", "ok.h5%00",
             "..%2f..%2fetc%2fpasswd", "%2fetc%2fpasswd", "..%5cok.h5", "%ff%fe"]  # fmt: skip


def test_names_in_the_path_that_no_file_can_have(app, fault_row):
    """Every route with a name in its path, given names too long for the file system (in bytes
    too), traversal and NUL: a 4xx, never a 500 (a 300-character name was an OSError out of
    ``safe_file``: a 500 on ``/static/`` and ``/api/recordings/``); a recording whose name
    leaves no room for its report's is refused in one line."""
    kind, application, alert, folder = app
    if kind == "monitor":  # a recording whose name is as long as a file's may be
        save(small_recording(), folder / "rec" / ("b" * 247 + ".h5"))
    named = [(m, p) for m, p in _routes(application) if re.search(r"\{(name|path|filename)", p)]
    assert named, _routes(application)
    tried = 0
    with TestClient(application, base_url=BASE) as client:
        for method, path in named:
            for name in ODD_NAMES:
                url = _fill(re.sub(r"\{(name|path|filename)(:\w+)?\}", name, path), alert)
                r = client.request(method, url, content=b"[]")
                assert r.status_code < 500, (method, url[:80], r.status_code, r.text[:200])
                tried += 1
    fault_row("requests", f"{kind}: {len(named)} routes with a name in the path x names too "
              "long, traversal, NUL", "refused", "4xx (never 500)", cases=tried)  # fmt: skip


def _rss_kib(pid: int) -> int:
    text = Path(f"/proc/{pid}/status").read_text()
    return int(re.search(r"VmRSS:\s+(\d+)", text).group(1))


def _send(port: int, headers: dict[str, str], chunks) -> tuple[int, float]:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    conn.putrequest("PUT", "/api/playback/ok.h5/rois")
    for k, v in headers.items():
        conn.putheader(k, v)
    conn.endheaders()
    start = time.monotonic()
    try:
        for chunk in chunks:
            conn.send(chunk)
    except (BrokenPipeError, ConnectionResetError):
        pass  # the server answered and closed: what is wanted
    status = conn.getresponse().status
    conn.close()
    return status, time.monotonic() - start


@pytest.mark.slow
def test_a_300_mb_body_is_refused_before_it_is_read(tmp_path, fault_row):
    rec = tmp_path / "rec"
    rec.mkdir()
    save(small_recording(), rec / "ok.h5")
    m = ChildServer(tmp_path, "monitor", "--source", "virtual", "--no-posture",
                    "--record-dir", str(rec))  # fmt: skip
    try:
        m.until(lambda: m.get("api/status")["frames"], lambda n: n > 0, 60)
        before = _rss_kib(m.proc.pid)
        block = b"x" * (1 << 20)
        announced = _send(m.port, {"Content-Length": str(300 << 20),
                                   "Content-Type": "application/json"}, [block] * 300)  # fmt: skip

        def chunked():
            for _ in range(300):
                yield b"%x\r\n" % len(block) + block + b"\r\n"
            yield b"0\r\n\r\n"

        streamed = _send(m.port, {"Transfer-Encoding": "chunked"}, chunked())
        grown = _rss_kib(m.proc.pid) - before
        assert announced[0] == 413 and streamed[0] == 413, (announced, streamed)
        assert grown < 32 * 1024, f"the monitor grew by {grown} KiB"
        assert m.get("api/status")["frames"] > 0  # still serving
    finally:
        m.stop()
    fault_row("requests", "PUT of 300 MB (announced, and chunked) to a real monitor", "refused",
              f"413; the monitor grew by {max(grown, 0) // 1024} MiB", cases=2)  # fmt: skip


def test_token_files_that_are_no_small_files(tmp_path, fault_row):
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "huge").write_bytes(b"t" * (10 << 20))
    (tmp_path / "binary").write_bytes(b"\xff\xfe\x00" * 10)
    cases = {"/dev/zero": "character device", str(tmp_path / "fifo"): "FIFO",
             str(tmp_path / "huge"): "larger than", str(tmp_path / "binary"): "UTF-8",
             str(tmp_path / "missing"): "no such file"}  # fmt: skip
    argvs = [
        [cmd, "--token-file", f, "--port", "1"] for f in cases for cmd in ("monitor", "station")
    ]
    argvs += [["station", "--broker", "mqtt://u@127.0.0.1:1", "--broker-password-file", f,
               "--virtual-mats", "1"] for f in cases]  # fmt: skip
    results, base_kib, peak_kib = batch(argvs, tmp_path, timeout=120)
    said = [cases[a[2]] if a[1] == "--token-file" else cases[a[4]] for a in argvs]
    for words, (rc, _out, err) in zip(said, results, strict=True):
        one_line(rc, err, words)
    assert peak_kib - base_kib < 64 * 1024
    fault_row("requests", f"{len(argvs)} token and password files: /dev/zero, a FIFO, 10 MB, "
              "binary, missing", "clear error", cases=len(argvs))  # fmt: skip
