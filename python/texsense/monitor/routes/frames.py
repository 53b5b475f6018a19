"""Frames and status: ``GET /api/status``, ``GET /api/frame/latest``, ``GET /api/history``,
``WS /ws``."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, HTTPException, WebSocket
from fastapi.responses import Response

from texsense.monitor.live import Monitor
from texsense.monitor.web import idle, stream

__all__ = ["router"]


def router(monitor: Monitor) -> APIRouter:
    """The routes of live frames and the monitor's status."""
    r = APIRouter(tags=["frames"])

    @r.get("/api/status")
    async def status() -> dict[str, Any]:
        """Source, whether frames come (``feed``), frame count, recording, open alert,
        layout."""
        lay = monitor.layout
        alert = monitor.tracker.open_alert
        return {
            "source": monitor.source.info(),
            "feed": monitor.feed_state(),
            "frames": monitor.frames,
            "skipped": monitor.clock.skipped,
            "session": monitor.session_id,
            "recording": monitor.recorder.paths if monitor.recorder else None,
            "alert": alert.to_dict() if alert else None,
            "threshold": {
                "value": monitor.tracker.threshold,
                "unit": monitor.tracker.unit,
                "ncm2": monitor.tracker.threshold_ncm2,
            },
            "reposition_min": monitor.tracker.reposition_s / 60,
            "calibrated": not monitor.raw_only,
            "raw_unit": monitor.source.unit,  # what the page shows without a calibration
            "calibration_id": None if monitor.pipeline is None else monitor.pipeline.calibration_id,
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

    @r.get("/api/frame/latest")
    async def latest() -> Response:
        """The latest snapshot (pressure in N/cm²)."""
        if monitor.latest is None:
            raise HTTPException(503, "no frame yet")
        return Response(monitor.latest_text, media_type="application/json")

    @r.get("/api/history")
    async def history() -> dict[str, Any]:
        """The statistics of the last frames the monitor holds (at most
        :data:`texsense.monitor.live.HISTORY`), oldest first, for the page's charts: a page
        opened late draws what came before it."""
        return {
            "columns": ["t", "load_N", "peak_ncm2", "contact_area_cm2", "cof_x_cm", "cof_y_cm",
                        "peak_rise", "responding", "peak_lower_ncm2", "peak_upper_ncm2"],
            "rows": list(monitor.history),
        }  # fmt: skip

    @r.websocket("/ws")
    async def ws(websocket: WebSocket) -> None:
        q = monitor.subscribe()
        try:
            first = monitor.latest_text if monitor.latest is not None else None
            if first is None:  # nothing to send before the mat's first frame
                idle(websocket)
            await stream(websocket, first, q.get)
        finally:
            monitor.unsubscribe(q)

    return r
