"""Calibrating the mat from the page (:mod:`texsense.monitor.calibrate`):
``GET /api/calibration`` (the steps' state), ``POST /api/calibration/record/{step}`` (``zero``,
``uniform``, ``check``: keep the next frames; ``?wait=true``: answer when they are kept),
``POST /api/calibration/fit`` (the material), ``POST /api/calibration/save`` (write and use),
``POST /api/calibration/orientation`` (how the mat lies), ``POST /api/calibration/cancel`` and
``POST /api/calibration/reset``.

Like every state-changing route they pass :class:`texsense.monitor.web.Guard` first: a page of
another origin or site cannot run them. Errors: 409 for a step out of order or while another
runs, 422 for a bad input or a refused calibration (the reasons verbatim), 507 when the files
cannot be written.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

from fastapi import APIRouter, HTTPException
from pydantic import BaseModel

from texsense.exceptions import ParameterError, WriteError
from texsense.monitor.calibrate import DEFAULT_FRAMES, PageCalibration, StepError
from texsense.monitor.live import Monitor

__all__ = ["WAIT_S", "router"]

#: Longest a ``?wait=true`` recording keeps its request open, s, besides 5 s a frame.
WAIT_S = 30.0


class RecordBody(BaseModel):
    """A recorded step: how many frames, and (uniform, check) the load, e.g. ``1 N/cm2``."""

    frames: int = DEFAULT_FRAMES
    pressure: str | None = None


class FitBody(BaseModel):
    """The material step: a spacer preset (default: the one the device announced)."""

    material: str | None = None


class OrientationBody(BaseModel):
    """How the mat lies: ``bed``, ``seat``, ``foot`` or ``none``, and the edge of its head,
    front or toes (``top``, ``bottom``, ``left``, ``right``, or ``press``)."""

    kind: str
    edge: str = "top"


def _http(e: ParameterError) -> HTTPException:
    return HTTPException(409 if isinstance(e, StepError) else 422, str(e))


def router(monitor: Monitor) -> APIRouter:
    """The routes of the page's calibration panel."""
    cal = PageCalibration(monitor)
    r = APIRouter(tags=["calibration"])

    @r.get("/api/calibration")
    async def state() -> dict[str, Any]:
        """The steps done, the one recording (frames so far), findings, check report, file."""
        return cal.state()

    @r.post("/api/calibration/record/{step}")
    async def record(
        step: str, body: RecordBody | None = None, wait: bool = False
    ) -> dict[str, Any]:
        """Keep the next ``frames`` frames of the live stream for ``step``; poll
        ``GET /api/calibration`` until it is among ``done``, or ask with ``?wait=true`` to
        be answered once it is (at most :data:`WAIT_S` plus 5 s a frame)."""
        body = body or RecordBody()
        try:
            cal.record(step, body.frames, body.pressure)
        except ParameterError as e:
            raise _http(e) from None
        deadline = time.monotonic() + WAIT_S + 5.0 * body.frames
        while wait and (cal.capture or cal.busy) and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
        return cal.state()

    @r.post("/api/calibration/fit")
    async def fit(body: FitBody | None = None) -> dict[str, Any]:
        """Check the two recordings and fit the chain for the material (refused: 422 with
        every reason; warnings in ``findings``)."""
        material = (body.material if body else None) or cal.default_material()
        if material is None:
            raise HTTPException(422, "choose the spacer's material (the device announced none)")
        try:
            await cal.fit(material)
        except ParameterError as e:
            raise _http(e) from None
        return cal.state()

    @r.post("/api/calibration/orientation")
    async def orientation(body: OrientationBody) -> dict[str, Any]:
        """Set how the mat lies (the live map at once, the calibration when saved)."""
        try:
            cal.set_orientation(body.kind, body.edge)
        except ParameterError as e:
            raise _http(e) from None
        return cal.state()

    @r.post("/api/calibration/save")
    async def save() -> dict[str, Any]:
        """Write the calibration and the step recordings; the monitor shows pressure."""
        try:
            await cal.save()
        except ParameterError as e:
            raise _http(e) from None
        except (OSError, WriteError) as e:
            raise HTTPException(507, f"cannot write the calibration: {e}") from None
        return cal.state()

    @r.post("/api/calibration/cancel")
    async def cancel() -> dict[str, Any]:
        """Stop a step's recording."""
        cal.cancel()
        return cal.state()

    @r.post("/api/calibration/reset")
    async def reset() -> dict[str, Any]:
        """Start over (a calibration in use stays in use)."""
        try:
            cal.reset()
        except ParameterError as e:
            raise _http(e) from None
        return cal.state()

    return r
