"""The monitor's web routes, one :class:`fastapi.APIRouter` per concern. Each module has a
``router(monitor) -> APIRouter``; :data:`ROUTERS` lists them in the order they are included.

To add a concern: write a module with ``def router(monitor: Monitor) -> APIRouter`` and add
its ``router`` to :data:`ROUTERS` (as :func:`texsense.monitor.playback.playback_router`,
playback of recordings, is).
The access rules (Host, Origin, token) and the security headers are not the routers' business:
:class:`texsense.monitor.web.Guard` applies them to every request before any router sees it.
"""

from __future__ import annotations

from texsense.monitor.playback import playback_router
from texsense.monitor.routes import calibration, events, frames, recordings, static

__all__ = ["ROUTERS"]

#: The routers of :func:`texsense.monitor.server.create_app`.
ROUTERS = (
    frames.router,
    events.router,
    recordings.router,
    calibration.router,  # the page's calibration panel (texsense.monitor.calibrate)
    playback_router,  # playback, regions, reports (texsense.monitor.playback)
    static.router,
)
