"""Sessions, events and alerts: ``GET /api/sessions``, ``GET /api/events``,
``POST /api/alerts/{id}/ack``."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, HTTPException

from texsense.exceptions import ParameterError
from texsense.monitor.live import Monitor

__all__ = ["router"]


def router(monitor: Monitor) -> APIRouter:
    """The routes of the event store and the alerts."""
    r = APIRouter(tags=["events"])

    @r.get("/api/sessions")
    async def sessions() -> list[dict[str, Any]]:
        """Every monitor session, newest first."""
        return monitor.store.sessions()

    @r.get("/api/events")
    async def events(
        session: int | None = None, kind: str | None = None, limit: int = 200
    ) -> list[dict[str, Any]]:
        """Events (seated, left, reposition, acknowledged, cleared, clock), newest first."""
        if not 1 <= limit <= 10000:
            raise HTTPException(422, "limit must lie in 1..10000")
        return monitor.store.events(session, kind, limit)

    @r.post("/api/alerts/{alert_id}/ack")
    async def acknowledge(alert_id: int) -> dict[str, Any]:
        """Acknowledge an alert."""
        try:
            return monitor.acknowledge(alert_id).to_dict()
        except ParameterError as e:
            raise HTTPException(404, str(e)) from None

    return r
