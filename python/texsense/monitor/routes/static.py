"""The dashboard page and its files: ``GET /``, ``GET /static/{name}`` (by name, from one
fixed folder, after checking the name resolves inside it)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fastapi import APIRouter, HTTPException
from fastapi.responses import FileResponse

from texsense.monitor.live import Monitor
from texsense.monitor.web import safe_file

__all__ = ["STATIC", "TYPES", "router"]

STATIC = Path(__file__).resolve().parents[1] / "static"
TYPES = {
    ".html": "text/html",
    ".js": "text/javascript",
    ".css": "text/css",
    ".svg": "image/svg+xml",
    ".png": "image/png",
}


def router(monitor: Monitor) -> APIRouter:
    """The routes of the dashboard's static files."""
    del monitor  # the page is the same for every monitor
    r = APIRouter(include_in_schema=False)

    @r.get("/")
    async def index() -> Any:
        return FileResponse(STATIC / "index.html", media_type="text/html")

    @r.get("/static/{name}")
    async def static(name: str) -> Any:
        path = safe_file(STATIC, name)
        if path is None or path.suffix not in TYPES:
            raise HTTPException(404, "no such file")
        return FileResponse(path, media_type=TYPES[path.suffix])

    return r
