"""Family "an origin that is almost this server's" (harden9 item 5): both servers judge the
``Origin`` header with one strict parser (:func:`texsense.monitor.web.parse_origin`), so a page
is this server's only when its origin is exactly ``http://HOST:PORT`` of the Host it reached
(or an ``--allow-origin``, parsed the same way). Generated: every combination of a scheme, a
host, a port, something before and something after (``https://127.0.0.1:PORT``, a trailing
space, a slash, a user, upper case, a port with a leading zero ...), judged by
:class:`~texsense.monitor.web.Access` and, for a sample, sent through both servers' ``Guard``.
"""

from __future__ import annotations

import itertools
import random

import pytest
from fastapi.testclient import TestClient

from faults.test_web import BASE, loaded_monitor, loaded_station
from texsense.exceptions import ParameterError
from texsense.monitor.web import Access, parse_origin

PORT = 8765
HOST = f"127.0.0.1:{PORT}"
SCHEMES = ["http", "https", "HTTP", "ws", "wss", "ftp", "", "http:"]
HOSTS = ["127.0.0.1", "localhost", "LOCALHOST", "127.0.0.1.", "[::1]", "evil.example",
         "127.0.0.1.evil.example", "127.1", "user@127.0.0.1", "127.0.0.1 "]  # fmt: skip
PORTS = [f":{PORT}", "", ":80", f":0{PORT}", f":{PORT + 1}", ":99999", f":+{PORT}", f": {PORT}",
         f":{PORT}:{PORT}"]  # fmt: skip
BEFORE = ["", " ", "\t", "x"]
AFTER = ["", " ", "\t", "/", "/x", "?", "#", ".", "\r", "\x00"]


def _origins() -> list[str]:
    return [f"{b}{s}://{h}{p}{a}" for s, h, p, b, a
            in itertools.product(SCHEMES, HOSTS, PORTS, BEFORE, AFTER)]  # fmt: skip


def test_only_the_exact_origin_passes(fault_row):
    access = Access(None)
    origins = _origins()
    own = f"http://{HOST}"
    wrong = [o for o in origins if access.origin_ok(o, HOST) != (o == own)]
    assert wrong == [], f"{len(wrong)} of {len(origins)}: {[o for o in wrong[:20]]}"
    # the same on a server reached at port 80 (the default port left out or given)
    assert access.origin_ok("http://127.0.0.1", "127.0.0.1")
    assert access.origin_ok("http://127.0.0.1:80", "127.0.0.1")
    assert access.origin_ok("http://[::1]:8765", "[::1]:8765")
    assert not access.origin_ok("https://127.0.0.1:443", "127.0.0.1:443")
    fault_row("origins", f"{len(origins)} origins almost this server's (scheme, host, port, what "
              "comes before and after)", "refused", "all but the exact origin",
              cases=len(origins))  # fmt: skip


def test_allowed_origins_are_parsed_the_same_way():
    access = Access(None, origins=["https://portal.example/", "http://ward.example:8080"])
    assert access.origin_ok("https://portal.example", HOST)
    assert access.origin_ok("https://portal.example:443", HOST)
    assert access.origin_ok("http://ward.example:8080", HOST)
    for near in ("https://portal.example ", "https://portal.example/", "http://portal.example",
                 "https://PORTAL.example", "https://portal.example:8443", " https://portal.example",
                 "https://user@portal.example", "http://ward.example:08080"):  # fmt: skip
        assert not access.origin_ok(near, HOST), near
    for bad in ("portal.example", "https://portal.example/path", "null", "https://", "*"):
        with pytest.raises(ParameterError, match="--allow-origin"):
            Access(None, origins=[bad])
    assert parse_origin("http://127.0.0.1:65536") is None
    assert parse_origin("http://[::g]:1") is None


@pytest.mark.parametrize("kind", ["monitor", "station"])
def test_both_servers_refuse_them(kind, tmp_path, fault_row):
    from texsense.monitor.server import create_app
    from texsense.station.server import create_ward_app

    if kind == "monitor":
        app = create_app(loaded_monitor(tmp_path), run_source=False)
    else:
        app = create_ward_app(loaded_station(tmp_path))
    sample = random.Random(9).sample(_origins(), 150)
    sample += [f"https://{HOST}", f"http://{HOST} ", f"http://{HOST}/", f"HTTP://{HOST}"]
    base = BASE.rstrip("/")
    host = base.split("://", 1)[1]
    wrong = []
    with TestClient(app, base_url=base) as client:
        own = client.get("/", headers={"Origin": f"http://{host}"})
        assert own.status_code == 200, own.text
        for origin in sample:
            origin = origin.replace(HOST, host)
            if any(c in origin for c in "\r\x00"):
                continue  # no HTTP client sends them
            r = client.get("/", headers={"Origin": origin})
            if (r.status_code == 200) != (origin == f"http://{host}"):
                wrong.append(f"{origin!r}: {r.status_code}")
    assert wrong == [], "\n".join(wrong)
    fault_row("origins", f"{kind}: origins almost its own, sent", "refused",
              f"{len(sample)} requests: 403 but for the exact origin",
              cases=len(sample))  # fmt: skip
