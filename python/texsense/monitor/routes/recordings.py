"""Recordings: ``POST /api/record/start``, ``POST /api/record/stop``,
``GET /api/recordings/{name}``."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, HTTPException
from fastapi.responses import FileResponse

from texsense.exceptions import ParameterError, WriteError
from texsense.monitor.live import Monitor
from texsense.monitor.web import safe_file

__all__ = ["router"]


def router(monitor: Monitor) -> APIRouter:
    """The routes of the crash-safe recorder."""
    r = APIRouter(tags=["recordings"])

    @r.post("/api/record/start")
    async def record_start(name: str | None = None) -> dict[str, Any]:
        """Start recording (HDF5, crash-safe). A name that an earlier recording has is
        refused (409); without a name the files are named after the session and the time."""
        try:
            return {"files": monitor.start_recording(name)}
        except ParameterError as e:
            raise HTTPException(409, str(e)) from None
        except (OSError, WriteError) as e:
            raise HTTPException(507, f"cannot record: {e}") from None

    @r.post("/api/record/stop")
    async def record_stop() -> dict[str, Any]:
        """Stop recording."""
        try:
            return {"frames": monitor.stop_recording()}
        except ParameterError as e:
            raise HTTPException(409, str(e)) from None

    @r.get("/api/recordings/{name}")
    async def recording(name: str) -> Any:
        """Download a recording by file name."""
        path = safe_file(monitor.record_dir, name)
        if path is None or path.suffix != ".h5":
            raise HTTPException(404, "no such recording")
        return FileResponse(path, media_type="application/x-hdf5", filename=path.name)

    return r
