"""The ward's web server: the overview page, REST, the ward WebSocket, and every mat's
single-mat dashboard under ``/mats/<id>/`` (the monitor's page, one per mat).

Endpoints (OpenAPI at ``/docs``):

- ``GET /api/mats``: every mat — id, source, frames received, last frame time, state
  (``waiting``, ``live``, ``alert``, ``acknowledged``, ``stale``, ``refused``) — most urgent
  first;
- ``GET /api/mats/{id}``: one mat's summary with its latest pressure map;
- ``POST /api/mats/{id}/alerts/{alert_id}/ack``: acknowledge a reposition alert;
- ``POST /api/mats/{id}/admit``: lift a mat's refusal;
- ``GET /api/ward``: the broker connection, the unknown mats and every mat;
- ``WS /ws/ward``: the ward's tiles as they change (:mod:`texsense.station.tiles`);
- ``/mats/{id}/``: the single-mat dashboard of :mod:`texsense.monitor` for that mat.

The ward page (``GET /``) carries the ward's tiles as they are when it is asked for (the first
message of the feed, in a JSON data block the page draws at once), so a page shows its mats
without waiting for its WebSocket: on a busy station that wait was 7-550 ms after the
page's scripts had run (issue 33). The WebSocket then starts with a reset.

The monitor's access rules (:mod:`texsense.monitor.web`: Host, Origin, token, security
headers) apply to every HTTP and WebSocket request, the mounted dashboards included.
"""

from __future__ import annotations

import asyncio
import json
import time
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import APIRouter, FastAPI, HTTPException, Request, WebSocket
from fastapi.encoders import jsonable_encoder
from fastapi.responses import Response

from texsense.exceptions import ParameterError
from texsense.monitor.routes.static import STATIC as MONITOR_STATIC
from texsense.monitor.routes.static import file_response
from texsense.monitor.server import create_app
from texsense.monitor.web import (
    SERVED,
    Access,
    Guard,
    finish,
    is_loopback,
    plain_errors,
    serve_app,
    stream,
)
from texsense.station.tiles import WardFeed
from texsense.station.ward import MatEntry, Station

__all__ = ["create_ward_app", "serve_ward"]

STATIC = Path(__file__).with_name("static")
#: Where the ward page takes the tiles it is served with.
FIRST_MARK = "<!-- first ward -->"
#: ``GET /api/mats`` is built this many mats at a time, the loop's other work (the inbox's
#: slices) between (:func:`mat_list`).
LIST_CHUNK = 100
#: The pause between two of its chunks, s: the inbox's next slice runs in it.
LIST_PAUSE_S = 0.001


def ward_page(station: Station, html: str) -> str:
    """The ward page ``html`` with the feed's first message (a new viewer's: the header and
    the most urgent tiles within a viewer's byte budget) in a JSON data block in place of
    :data:`FIRST_MARK`; every ``<`` escaped, so nothing in it (a mat id, an error text) can
    end the block. A data block is not run: the page's Content-Security-Policy, scripts from
    the station only, holds."""
    first = (WardFeed(station).message() or "null").replace("<", "\\u003c")
    block = f'<script type="application/json" id="first-ward">{first}</script>'
    return html.replace(FIRST_MARK, block, 1)


async def mat_list(station: Station) -> str:
    """Every mat's status (most urgent first) as the JSON of ``GET /api/mats``, built
    :data:`LIST_CHUNK` mats at a time with a pause between (:data:`LIST_PAUSE_S`): the
    inbox reads a slice in each. At 1,000 mats the answer held the event loop 51-60 ms
    in one piece (27 µs a mat's status, 12 ms to encode it; on a loaded 2-core machine
    its wall time is 2-3 times that), a stall of every frame waiting meanwhile (issue 38)."""
    entries = list(station.mats.values())
    rows: list[dict[str, Any]] = []
    for k in range(0, len(entries), LIST_CHUNK):
        if k:
            await asyncio.sleep(LIST_PAUSE_S)
        rows += [e.status() for e in entries[k : k + LIST_CHUNK]]
    rows.sort(key=lambda r: (-r["urgency"], -r["minutes_since_reposition"], r["id"]))
    parts = []
    for k in range(0, len(rows), LIST_CHUNK):
        if k:
            await asyncio.sleep(LIST_PAUSE_S)
        parts.append(json.dumps(rows[k : k + LIST_CHUNK], ensure_ascii=False, allow_nan=False,
                                separators=(",", ":"), default=jsonable_encoder)[1:-1])  # fmt: skip
    return "[" + ",".join(parts) + "]"


def _pages(station: Station) -> APIRouter:
    """``GET /``: the ward page with its tiles (:func:`ward_page`); ``GET /static/{name}``: its
    files and the monitor's."""
    r = APIRouter(include_in_schema=False)
    html = (STATIC / "ward.html").read_text(encoding="utf-8")

    @r.get("/")
    async def page() -> Any:
        return Response(ward_page(station, html), media_type="text/html")

    @r.get("/static/{name}")
    async def static(name: str) -> Any:
        return file_response(name, STATIC, MONITOR_STATIC)

    return r


def _api(station: Station) -> APIRouter:
    r = APIRouter(tags=["ward"])

    def entry_of(mat_id: str) -> MatEntry:
        entry = station.mats.get(mat_id)
        if entry is None:
            raise HTTPException(404, f"no mat {mat_id!r}")
        return entry

    @r.get("/api/ward")
    async def ward() -> dict[str, Any]:
        """Broker connection, unknown mats, and every mat (most urgent first)."""
        return station.ward()

    @r.get("/api/mats", response_model=list[dict[str, Any]])
    async def mats(request: Request) -> Response:
        """Every mat: id, source, frames received, last frame time, state; most urgent first."""
        served = request.scope.get(SERVED)
        if callable(served):  # built in chunks, the inbox read between: not waited for
            served()
        return Response(await mat_list(station), media_type="application/json")

    @r.get("/api/mats/{mat_id}")
    async def mat(mat_id: str) -> dict[str, Any]:
        """One mat's summary with its latest pressure map (N/cm², null where unknown)."""
        return entry_of(mat_id).summary(time.time())

    @r.post("/api/mats/{mat_id}/alerts/{alert_id}/ack")
    async def acknowledge(mat_id: str, alert_id: int) -> dict[str, Any]:
        """Acknowledge a mat's reposition alert (in a group, where the mat is held)."""
        entry_of(mat_id)
        try:
            return await station.acknowledge(mat_id, alert_id)
        except ParameterError as e:
            raise HTTPException(409, str(e)) from None

    @r.post("/api/mats/{mat_id}/admit")
    async def admit(mat_id: str) -> dict[str, Any]:
        """Lift a mat's refusal: its frames are read again (event ``admitted``)."""
        entry_of(mat_id)
        try:
            return await station.admit(mat_id)
        except ParameterError as e:
            raise HTTPException(409, str(e)) from None

    @r.websocket("/ws/ward")
    async def ws(websocket: WebSocket) -> None:
        await stream(websocket, None, WardFeed(station).next)

    return r


class Serving:
    """ASGI middleware: counts the HTTP requests being served and the WebSocket viewers until
    their first message (``Station.serving``): the station's inbox waits for them
    (:mod:`texsense.station.inbox`), so a page opens as fast on a busy station as on a quiet
    one. A viewer that has nothing to be sent yet (a mat's dashboard before its first frame:
    :func:`texsense.monitor.web.idle`) is not waited for: the frames it waits for are in that
    inbox (issue 38). The inbox waits a while after a page, its files or a viewer's first
    message (:data:`~texsense.station.ward.PAGE_GRACE_S`: the page's next requests follow),
    not after an API call's answer. ``GET /api/mats`` is not waited for at all: it says so
    (through ``texsense.served``) and is built in chunks with the inbox read between
    (:func:`mat_list`)."""

    def __init__(self, app: Any, station: Station) -> None:
        self.app, self.station = app, station

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        station, counted = self.station, [True]
        station.serving += 1
        # a page, its files or its WebSocket: a burst follows (the grace); an API call's
        # answer does not make one (a script polling GET /api/mats of 1,000 mats held the
        # inbox 0.3 s after each answer, issue 38)
        grace = scope["type"] == "websocket" or "/api/" not in scope.get("path", "")

        def release() -> None:
            if counted[0]:
                counted[0] = False
                station.serving -= 1
                if grace:
                    station.served_at = time.monotonic()

        async def sending(message: dict[str, Any]) -> None:
            if message["type"] == "websocket.send":
                release()  # a viewer's first message is out: it waits like the others now
            await send(message)

        scope[SERVED] = release  # a viewer with nothing to send yet says so (monitor.web.idle)
        try:
            await self.app(scope, receive, sending if scope["type"] == "websocket" else send)
        finally:
            release()


def create_ward_app(
    station: Station,
    *,
    token: str | None = None,
    access: Access | None = None,
    background: list[Any] | None = None,
) -> Any:
    """The FastAPI application of a station. ``background``: coroutines to run while the
    app runs (e.g. the virtual mats); ``access``: the rules of Host, Origin and token
    (default: loopback, ``token``)."""

    @asynccontextmanager
    async def lifespan(_app: Any) -> Any:
        station.start()
        tasks = [asyncio.create_task(station.watch())]
        tasks += [asyncio.create_task(c) for c in (background or [])]
        yield
        await finish(tasks)
        station.stop()

    app = plain_errors(FastAPI(title="texsense ward station", version="1", lifespan=lifespan))
    app.include_router(_pages(station))
    app.include_router(_api(station))
    for mat_id, entry in station.mats.items():
        app.mount(f"/mats/{mat_id}", create_app(entry.monitor, run_source=False, guarded=False))
    for layer, options in station.layers():  # a group's: the dashboards of mats held elsewhere
        app.add_middleware(layer, **options)
    app.add_middleware(Guard, access=access or Access(token))
    app.add_middleware(Serving, station=station)  # outermost: counted from the first byte
    return app


def serve_ward(
    station: Station,
    *,
    host: str = "127.0.0.1",
    port: int = 8766,
    token: str | None = None,
    access: Access | None = None,
    background: list[Any] | None = None,
) -> int | None:
    """Run the ward station's server until Ctrl-C or SIGTERM (returns the signal)."""
    if not is_loopback(host) and not (token or (access and access.token)):
        raise ParameterError(
            f"binding {host} exposes the ward beyond this machine: pass a token (--token)"
        )
    access = access or Access(token, bind=host)
    return serve_app(create_ward_app(station, access=access, background=background), host, port)
