"""The ward's web server: the overview page, REST, the ward WebSocket, and every mat's
single-mat dashboard under ``/mats/<id>/`` (the monitor's page, one per mat).

Endpoints (OpenAPI at ``/docs``):

- ``GET /api/mats``: every mat — id, source, frames received, last frame time, state
  (``waiting``, ``live``, ``alert``, ``acknowledged``, ``stale``, ``refused``) — most urgent
  first;
- ``GET /api/mats/{id}``: one mat's summary with its latest pressure map;
- ``POST /api/mats/{id}/alerts/{alert_id}/ack``: acknowledge a reposition alert;
- ``GET /api/ward``: the broker connection and the mats;
- ``WS /ws/ward``: the ward after every change (at most 5 times a second);
- ``/mats/{id}/``: the single-mat dashboard of :mod:`texsense.monitor` for that mat.

The monitor's token rule applies to every HTTP and WebSocket request, the mounted
dashboards included.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import FastAPI, HTTPException, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse, JSONResponse

from texsense.exceptions import ParameterError
from texsense.monitor.server import STATIC as MONITOR_STATIC
from texsense.monitor.server import _safe_file, create_app, is_loopback, token_ok
from texsense.station.ward import Station

__all__ = ["create_ward_app", "serve_ward"]

log = logging.getLogger("texsense.station")
STATIC = Path(__file__).with_name("static")
_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css"}


def create_ward_app(
    station: Station, *, token: str | None = None, background: list[Any] | None = None
) -> Any:
    """The FastAPI application of a station. ``background``: coroutines to run while the
    app runs (e.g. the virtual mats)."""

    @asynccontextmanager
    async def lifespan(_app: Any) -> Any:
        station.start()
        tasks = [asyncio.create_task(station.watch()), asyncio.create_task(station.publish())]
        tasks += [asyncio.create_task(c) for c in (background or [])]
        yield
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await t
        station.stop()

    app = FastAPI(title="texsense ward station", version="1", lifespan=lifespan)

    @app.middleware("http")
    async def check_token(request: Request, call_next: Any) -> Any:
        if not token_ok(request.headers, request.query_params, token):
            return JSONResponse({"detail": "missing or wrong token"}, status_code=401)
        return await call_next(request)

    @app.get("/", include_in_schema=False)
    async def index() -> Any:
        return FileResponse(STATIC / "ward.html", media_type="text/html")

    @app.get("/static/{name}", include_in_schema=False)
    async def static(name: str) -> Any:
        path = _safe_file(STATIC, name) or _safe_file(MONITOR_STATIC, name)
        if path is None or path.suffix not in _TYPES:
            raise HTTPException(404, "no such file")
        return FileResponse(path, media_type=_TYPES[path.suffix])

    @app.get("/api/ward")
    async def ward() -> dict[str, Any]:
        """Broker connection, unknown mats, and every mat (most urgent first)."""
        return station.ward()

    @app.get("/api/mats")
    async def mats() -> list[dict[str, Any]]:
        """Every mat: id, source, frames received, last frame time, state; most urgent first."""
        maps = ("pressure", "cells")
        return [{k: v for k, v in m.items() if k not in maps} for m in station.summaries()]

    def entry_of(mat_id: str) -> Any:
        entry = station.mats.get(mat_id)
        if entry is None:
            raise HTTPException(404, f"no mat {mat_id!r}")
        return entry

    @app.get("/api/mats/{mat_id}")
    async def mat(mat_id: str) -> dict[str, Any]:
        """One mat's summary with its latest pressure map (N/cm², null where unknown)."""
        return entry_of(mat_id).summary(time.time())

    @app.post("/api/mats/{mat_id}/alerts/{alert_id}/ack")
    async def acknowledge(mat_id: str, alert_id: int) -> dict[str, Any]:
        """Acknowledge a mat's reposition alert."""
        entry = entry_of(mat_id)
        try:
            event = entry.monitor.acknowledge(alert_id)
        except ParameterError as e:
            raise HTTPException(409, str(e)) from None
        station._changed()
        return event.to_dict()

    @app.websocket("/ws/ward")
    async def ws(websocket: WebSocket) -> None:
        if not token_ok(websocket.headers, websocket.query_params, token):
            await websocket.close(code=4401)
            return
        await websocket.accept()
        q = station.subscribe()
        try:
            await websocket.send_text(json.dumps(station.ward(), separators=(",", ":")))
            while True:
                await websocket.send_text(await q.get())
        except (WebSocketDisconnect, RuntimeError):
            pass
        finally:
            station.unsubscribe(q)

    for mat_id, entry in station.mats.items():
        app.mount(f"/mats/{mat_id}", create_app(entry.monitor, token=token, run_source=False))
    return app


def serve_ward(
    station: Station,
    *,
    host: str = "127.0.0.1",
    port: int = 8766,
    token: str | None = None,
    background: list[Any] | None = None,
) -> None:
    """Run the ward station's server until interrupted."""
    import uvicorn

    if not is_loopback(host) and not token:
        raise ParameterError(
            f"binding {host} exposes the ward beyond this machine: pass a token (--token)"
        )
    app = create_ward_app(station, token=token, background=background)
    uvicorn.run(app, host=host, port=port, log_level="warning")
