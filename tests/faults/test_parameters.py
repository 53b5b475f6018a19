"""Family "a request parameter beyond what the server holds" (harden9, further attack): every
path and query parameter of every route of both servers, from their route tables, x values no
page sends (whole numbers beyond 64 bits, negative, NaN, text where a number is, 300
characters, a NUL). Each is answered with a 4xx (or what the route answers for a value it
knows), never a 500: ``GET /api/events?session=99999999999999999999999`` was an
``OverflowError`` out of SQLite. Defended in one place each: the event store refuses a number
it cannot hold (``texsense.monitor.store``), and a ``ParameterError`` or ``FormatError`` no route
answered is a 422 (``texsense.monitor.web.plain_errors``).
"""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient

from faults._families import small_recording
from faults.test_requests import _fill
from faults.test_web import BASE, loaded_monitor, loaded_station
from texsense.io import save
from texsense.monitor.server import create_app
from texsense.station.server import create_ward_app

VALUES = ["99999999999999999999999", "-99999999999999999999999", "9223372036854775808",
          "-9223372036854775809", "-1", "0", "nan", "inf", "1e3", "1.5", "x" * 300, "%00",
          "%20"]  # fmt: skip


def _parameters(app) -> list[tuple[str, str, list[str], list[str]]]:
    """(method, path, query parameters, path parameters) of every route of an app."""
    out = []

    def walk(a) -> None:
        for route in getattr(a, "routes", []):
            dep = getattr(route, "dependant", None)
            if dep is not None:
                for m in sorted(getattr(route, "methods", None) or ()):
                    if m != "HEAD":
                        out.append((m, route.path, [q.name for q in dep.query_params],
                                    [p.name for p in dep.path_params]))  # fmt: skip
            if hasattr(route, "original_router"):
                walk(route.original_router)
            elif hasattr(route, "app") and hasattr(route.app, "routes"):
                walk(route.app)

    walk(app.router)
    return out


@pytest.mark.parametrize("kind", ["monitor", "station"])
def test_no_parameter_value_is_a_500(kind, tmp_path, fault_row):
    if kind == "monitor":
        m = loaded_monitor(tmp_path)
        m.record_dir.mkdir(parents=True, exist_ok=True)
        save(small_recording(20), m.record_dir / "ok.h5")
        app, alert = create_app(m, run_source=False), m.tracker.open_alert.id
    else:
        st = loaded_station(tmp_path)
        app, alert = create_ward_app(st), st.mats["bed1"].monitor.tracker.open_alert.id
    routes = _parameters(app)
    assert any(q for _, _, q, _ in routes) and any(p for _, _, _, p in routes)
    tried, wrong = 0, []
    with TestClient(app, base_url=BASE, raise_server_exceptions=False) as client:
        for method, path, queries, params in routes:
            urls = [_fill(re.sub(r"\{" + p + r"(:\w+)?\}", v, path), alert)
                    for p in params for v in VALUES]  # fmt: skip
            urls += [_fill(path, alert) + f"?{q}={v}" for q in queries for v in VALUES]
            for url in urls:
                if "/report" in url and method == "POST":
                    continue  # (a report per value: minutes; its name is test_requests')
                r = client.request(method, url)
                tried += 1
                if r.status_code >= 500 or "Traceback" in r.text:
                    wrong.append(f"{method} {url[:120]}: {r.status_code} {r.text[:120]}")
    assert wrong == [], f"{len(wrong)} of {tried}:\n" + "\n".join(wrong)
    fault_row("requests", f"{kind}: every path and query parameter of every route x "
              f"{len(VALUES)} values no page sends", "refused", f"{tried} requests: 4xx or "
              "the route's own answer, never 500", cases=tried)  # fmt: skip
