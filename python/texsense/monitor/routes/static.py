"""The dashboard page and its files: ``GET /``, ``GET /static/{name}`` (by name, from one
fixed folder, after checking the name resolves inside it)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fastapi import APIRouter, HTTPException
from fastapi.responses import Response

from texsense.monitor.live import Monitor
from texsense.monitor.web import safe_file

__all__ = ["STATIC", "TYPES", "file_response", "pages", "router"]

STATIC = Path(__file__).resolve().parents[1] / "static"
TYPES = {
    ".html": "text/html",
    ".js": "text/javascript",
    ".css": "text/css",
    ".svg": "image/svg+xml",
    ".png": "image/png",
}


def file_response(name: str, *folders: Path) -> Response:
    """The file ``name`` of the first of ``folders`` that has it (by name only, of a served
    type), else 404. The page's files are small (tens of kB): read at once in the event
    loop, not through a worker thread, which on a busy station (every core taken by frames)
    waited seconds for its turn at each step (issue 33: the ward page's files took 4-6 s each
    under 20 virtual mats, a JSON route 1 s)."""
    for folder in folders:
        path = safe_file(folder, name)
        if path is not None and path.suffix in TYPES:
            return Response(path.read_bytes(), media_type=TYPES[path.suffix])
    raise HTTPException(404, "no such file")


def pages(index: Path, *folders: Path) -> APIRouter:
    """``GET /``: the page ``index``; ``GET /static/{name}``: the files of ``folders``."""
    r = APIRouter(include_in_schema=False)

    @r.get("/")
    async def page() -> Any:
        return Response(index.read_bytes(), media_type="text/html")

    @r.get("/static/{name}")
    async def static(name: str) -> Any:
        return file_response(name, *folders)

    return r


def router(monitor: Monitor) -> APIRouter:
    """The routes of the dashboard's static files."""
    del monitor  # the page is the same for every monitor
    return pages(STATIC / "index.html", STATIC)
