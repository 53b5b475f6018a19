"""The monitor's web server: a static dashboard page, a WebSocket of live snapshots and a REST
API (FastAPI; OpenAPI at ``/docs`` and ``/openapi.json``).

The routes are :mod:`texsense.monitor.routes` (one router per concern: frames and status,
events and alerts, recordings, the page's files). Security is :mod:`texsense.monitor.web`,
applied to every request before any route: the server binds 127.0.0.1 unless told otherwise;
on any other address it refuses to start without a token; Host and Origin are checked on
every HTTP and WebSocket request (DNS rebinding, pages of other sites); with a token every
request must carry it; every response has the security headers.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Iterable
from contextlib import asynccontextmanager
from typing import Any

from fastapi import APIRouter, FastAPI

from texsense.exceptions import ParameterError
from texsense.monitor.live import Monitor
from texsense.monitor.routes import ROUTERS
from texsense.monitor.routes.static import STATIC
from texsense.monitor.web import Access, Guard, finish, is_loopback, plain_errors, serve_app

__all__ = ["STATIC", "create_app", "is_loopback", "serve"]

log = logging.getLogger("texsense.monitor")


def create_app(
    monitor: Monitor,
    *,
    token: str | None = None,
    access: Access | None = None,
    run_source: bool = True,
    guarded: bool = True,
    routers: Iterable[Callable[[Monitor], APIRouter]] = ROUTERS,
) -> Any:
    """The FastAPI application around ``monitor``.

    Parameters
    ----------
    monitor : Monitor
        What the app shows.
    token : str, optional
        Required on every request (ignored when ``access`` is given).
    access : Access, optional
        The rules of Host, Origin and token (default: loopback, ``token``).
    run_source : bool
        Consume the monitor's source (and watch it fall silent) while the app runs.
    guarded : bool
        Apply ``access`` here; False for an app mounted inside one that does (the station).
    routers : iterable of callables
        ``router(monitor) -> APIRouter`` each (default :data:`routes.ROUTERS`).
    """

    @asynccontextmanager
    async def lifespan(_app: Any) -> Any:
        tasks = []
        if run_source:
            tasks = [asyncio.create_task(monitor.run()), asyncio.create_task(monitor.watch())]
            tasks[0].add_done_callback(_report_end)
        yield
        await finish(tasks)
        monitor.close()

    def _report_end(task: asyncio.Task[None]) -> None:
        if not task.cancelled() and task.exception() is not None:
            log.error("%s stopped: %s", monitor.source.name, task.exception())

    app = plain_errors(FastAPI(title="texsense monitor", version="1", lifespan=lifespan))
    for make in routers:
        app.include_router(make(monitor))
    if guarded:
        app.add_middleware(Guard, access=access or Access(token))
    return app


def serve(
    monitor: Monitor,
    *,
    host: str = "127.0.0.1",
    port: int = 8765,
    token: str | None = None,
    access: Access | None = None,
) -> int | None:
    """Run the dashboard until Ctrl-C or SIGTERM (returns the signal)."""
    if not is_loopback(host) and not (token or (access and access.token)):
        raise ParameterError(
            f"binding {host} exposes the monitor beyond this machine: pass a token (--token)"
        )
    access = access or Access(token, bind=host)
    return serve_app(create_app(monitor, access=access), host, port)
