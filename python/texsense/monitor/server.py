"""The monitor's web server: a static dashboard page, a WebSocket of live snapshots and a REST
API (FastAPI; OpenAPI at ``/docs`` and ``/openapi.json``).

Security: the server binds 127.0.0.1 unless told otherwise; on any other address it refuses to
start without a token, and with a token every HTTP and WebSocket request must carry it
(``Authorization: Bearer <token>``, header ``X-Texsense-Token`` or query ``?token=``). Files are
served only from two fixed places, by name, after checking the name resolves inside them.
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import logging
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import FastAPI, HTTPException, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse, JSONResponse, Response

from texsense.exceptions import ParameterError
from texsense.monitor.live import Monitor
from texsense.monitor.playback import playback_router

__all__ = ["create_app", "is_loopback", "serve"]

log = logging.getLogger("texsense.monitor")
STATIC = Path(__file__).with_name("static")
_STATIC_TYPES = {
    ".html": "text/html",
    ".js": "text/javascript",
    ".css": "text/css",
    ".svg": "image/svg+xml",
    ".png": "image/png",
}


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _safe_file(folder: Path, name: str) -> Path | None:
    """``folder / name`` if it is a plain file inside ``folder`` (no traversal), else None."""
    if not name or "/" in name or "\\" in name or name.startswith(".") or "\x00" in name:
        return None
    base = folder.resolve()
    path = (base / name).resolve()
    if path.parent != base or not path.is_file():
        return None
    return path


def token_ok(headers: Any, query: Any, token: str | None) -> bool:
    """The token rule of every HTTP and WebSocket request: without a token everything is
    allowed (loopback only); with one, ``?token=``, ``X-Texsense-Token`` or a bearer header
    must carry it."""
    if token is None:
        return True
    given = query.get("token") or headers.get("x-texsense-token") or ""
    auth = headers.get("authorization", "")
    if not given and auth.lower().startswith("bearer "):
        given = auth[7:]
    return hmac.compare_digest(given.encode(), token.encode())


def create_app(monitor: Monitor, *, token: str | None = None, run_source: bool = True) -> Any:
    """The FastAPI application around ``monitor``. With ``run_source`` the monitor consumes
    its source while the app runs."""

    def authorised(headers: Any, query: Any) -> bool:
        return token_ok(headers, query, token)

    @asynccontextmanager
    async def lifespan(_app: Any) -> Any:
        task = asyncio.create_task(monitor.run()) if run_source else None
        if task is not None:
            task.add_done_callback(_report_end)
        yield
        if task is not None:
            task.cancel()
        monitor.close()

    def _report_end(task: asyncio.Task[None]) -> None:
        if not task.cancelled() and task.exception() is not None:
            log.error("the source stopped: %r", task.exception())

    app = FastAPI(title="texsense monitor", version="1", lifespan=lifespan)
    app.include_router(playback_router(monitor))  # playback, regions, reports (playback.py)

    @app.middleware("http")
    async def check_token(request: Request, call_next: Any) -> Any:
        if not authorised(request.headers, request.query_params):
            return JSONResponse({"detail": "missing or wrong token"}, status_code=401)
        return await call_next(request)

    @app.get("/", include_in_schema=False)
    async def index() -> Any:
        return FileResponse(STATIC / "index.html", media_type="text/html")

    @app.get("/static/{name}", include_in_schema=False)
    async def static(name: str) -> Any:
        path = _safe_file(STATIC, name)
        if path is None or path.suffix not in _STATIC_TYPES:
            raise HTTPException(404, "no such file")
        return FileResponse(path, media_type=_STATIC_TYPES[path.suffix])

    @app.get("/api/status")
    async def status() -> dict[str, Any]:
        """Source, frame count, recording, open alert, layout."""
        lay = monitor.layout
        alert = monitor.tracker.open_alert
        return {
            "source": monitor.source.info(),
            "frames": monitor.frames,
            "session": monitor.session_id,
            "recording": monitor.recorder.paths if monitor.recorder else None,
            "alert": alert.to_dict() if alert else None,
            "threshold": {
                "value": monitor.tracker.threshold,
                "unit": monitor.tracker.unit,
                "ncm2": monitor.tracker.threshold_ncm2,
            },
            "reposition_min": monitor.tracker.reposition_s / 60,
            "posture_model": monitor.posture_model is not None,
            "bed": monitor.bed is not None,
            "layout": {
                "shape": lay.shape,
                "pitch_cm": lay.pitch_cm,
                "cells": None if lay.cells is None else lay.cells.tolist(),
                "elements": lay.n_elements,
                "xy_cm": lay.xy_cm.round(3).tolist(),
            },
        }

    @app.get("/api/frame/latest")
    async def latest() -> Response:
        """The latest snapshot (pressure in N/cm²)."""
        if monitor.latest is None:
            raise HTTPException(503, "no frame yet")
        return Response(monitor.latest_text, media_type="application/json")

    @app.get("/api/sessions")
    async def sessions() -> list[dict[str, Any]]:
        """Every monitor session, newest first."""
        return monitor.store.sessions()

    @app.get("/api/events")
    async def events(
        session: int | None = None, kind: str | None = None, limit: int = 200
    ) -> list[dict[str, Any]]:
        """Events (seated, left, reposition, acknowledged, cleared), newest first."""
        if not 1 <= limit <= 10000:
            raise HTTPException(422, "limit must lie in 1..10000")
        return monitor.store.events(session, kind, limit)

    @app.post("/api/alerts/{alert_id}/ack")
    async def acknowledge(alert_id: int) -> dict[str, Any]:
        """Acknowledge an alert."""
        try:
            return monitor.acknowledge(alert_id).to_dict()
        except ParameterError as e:
            raise HTTPException(404, str(e)) from None

    @app.post("/api/record/start")
    async def record_start(name: str | None = None) -> dict[str, Any]:
        """Start recording (HDF5, crash-safe)."""
        try:
            return {"files": monitor.start_recording(name)}
        except ParameterError as e:
            raise HTTPException(409, str(e)) from None

    @app.post("/api/record/stop")
    async def record_stop() -> dict[str, Any]:
        """Stop recording."""
        try:
            return {"frames": monitor.stop_recording()}
        except ParameterError as e:
            raise HTTPException(409, str(e)) from None

    @app.get("/api/recordings/{name}")
    async def recording(name: str) -> Any:
        """Download a recording by file name."""
        path = _safe_file(monitor.record_dir, name)
        if path is None or path.suffix != ".h5":
            raise HTTPException(404, "no such recording")
        return FileResponse(path, media_type="application/x-hdf5", filename=path.name)

    @app.websocket("/ws")
    async def ws(websocket: WebSocket) -> None:
        if not authorised(websocket.headers, websocket.query_params):
            await websocket.close(code=4401)
            return
        await websocket.accept()
        q = monitor.subscribe()
        try:
            if monitor.latest is not None:
                await websocket.send_text(monitor.latest_text)
            while True:
                await websocket.send_text(await q.get())
        except (WebSocketDisconnect, RuntimeError):
            pass
        finally:
            monitor.unsubscribe(q)

    return app


def serve(
    monitor: Monitor, *, host: str = "127.0.0.1", port: int = 8765, token: str | None = None
) -> None:
    """Run the dashboard until interrupted."""
    import uvicorn

    if not is_loopback(host) and not token:
        raise ParameterError(
            f"binding {host} exposes the monitor beyond this machine: pass a token (--token)"
        )
    app = create_app(monitor, token=token)
    uvicorn.run(app, host=host, port=port, log_level="warning")
