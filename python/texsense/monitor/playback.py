"""The dashboard's views beyond the live frame: the mode and fixed scale of the live map, the
recordings in the monitor's folder, their playback frame by frame with the statistics and
events over time, regions of interest saved beside a recording, and its report
(docs/monitor.md "Playback", docs/report.md).

Routes (an :class:`fastapi.APIRouter`; :func:`playback_router`):

- ``GET /api/view``: the live mode (seat, bed, foot, generic), its words, fixed colour scale
  (N/cm²), threshold and orientation.
- ``GET /api/playback``: the recordings in the monitor's folder (newest first).
- ``GET /api/playback/{name}``: one recording: frames, times, layout, mode, scale, the
  statistics per frame (load, peak, contact area, centre of force; at most
  :data:`MAX_POINTS` points, each the max or mean of its frames), events, time per side,
  regions of interest.
- ``GET /api/playback/{name}/frames/{i}``: frame ``i`` (pressure in N/cm², as the live
  snapshot; other quantities in their unit).
- ``GET`` / ``PUT /api/playback/{name}/rois``: the regions of interest (sidecar
  ``<name>.rois.json``); a PUT answers with their statistics over time.
- ``GET /api/playback/{name}/report?format=pdf|html``: the report (:mod:`texsense.apps.report`),
  also kept in ``<folder>/reports/``.

A name is a plain file or folder name inside the recordings folder: anything with a path
separator, a leading dot, or that resolves elsewhere is 404, whatever its encoding. A file
texsense cannot read is a 422 with the reader's one-line message, a frame out of range 404.
"""

from __future__ import annotations

import asyncio
import json
import threading
from collections import OrderedDict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse

from texsense.apps import stats
from texsense.apps.report import write_report
from texsense.apps.roi import load_rois, parse_rois, roi_elements, save_rois
from texsense.data import units
from texsense.exceptions import FormatError, ParameterError, UnitError

if TYPE_CHECKING:
    from texsense.apps.review import Review
    from texsense.monitor.live import Monitor

__all__ = ["MAX_POINTS", "playback_router", "resolve_recording"]

#: The longest series sent to the page (longer recordings are reduced, max or mean per bin).
MAX_POINTS = 2000
#: Largest regions document a page may send.
MAX_ROI_BYTES = 256 * 1024
#: Reviews kept in memory (a reopened recording is not read again unless it changed).
CACHE = 3


def resolve_recording(folder: Path, name: str) -> Path | None:
    """``folder / name`` if ``name`` is a plain name of a file or folder inside ``folder``."""
    if (
        not name
        or len(name) > 255
        or any(c in name for c in "/\\\x00")
        or name.startswith(".")
        or name.endswith(".rois.json")
    ):
        return None
    base = folder.resolve()
    path = (base / name).resolve()
    if path.parent != base or not path.exists():
        return None
    return path


def _rounded(v: np.ndarray, nd: int = 3) -> list[Any]:
    a = np.asarray(v, dtype=np.float64)
    out = np.round(a, nd).astype(object)
    out[~np.isfinite(a)] = None
    return list(out.tolist())


class _Reviews:
    """A small cache of :class:`Review` objects keyed by path, size and modification time."""

    def __init__(self) -> None:
        self._items: OrderedDict[tuple[str, int, float], Review] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, path: Path) -> Review:
        from texsense.apps.review import open_review
        from texsense.io import load

        st = path.stat()
        key = (str(path), st.st_size, st.st_mtime)
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return self._items[key]
        rec = load(path)
        # the page converts pressure from N/cm², as for the live frames
        unit = "N/cm2" if rec.quantity == "pressure" else None
        review = open_review(rec, unit=unit, name=path.name)
        with self._lock:
            self._items[key] = review
            while len(self._items) > CACHE:
                self._items.popitem(last=False)
        return review


def _series(review: Review) -> dict[str, Any]:
    from texsense.apps.review import decimate

    s = review.series
    n = s["t"].size
    bins = min(n, MAX_POINTS)
    index = np.linspace(0, n, bins + 1).astype(int)[:-1]
    out: dict[str, Any] = {"i": index.tolist(), "t": _rounded(s["t"][index], 3)}
    for key in ("load_N", "peak", "area_cm2"):
        if key in s:
            out[key] = _rounded(decimate(s[key], bins, "max"), 4)
    for key in ("cof_x", "cof_y"):
        out[key] = _rounded(decimate(s[key], bins, "mean"), 2)
    return out


def _summary(review: Review, path: Path) -> dict[str, Any]:

    rec, lay = review.rec, review.rec.layout
    return {
        "name": path.name,
        "frames": rec.n_frames,
        "duration_s": round(rec.duration_s, 3),
        "started_at": review.started,
        "quantity": rec.quantity,
        "unit": review.unit,
        "mode": review.mode.to_dict(),
        "scale": list(review.scale),
        "threshold": review.threshold,
        "orientation": review.orientation,
        "layout": {
            "shape": lay.shape,
            "cells": None if lay.cells is None else lay.cells.tolist(),
            "pitch_cm": lay.pitch_cm,
            "xy_cm": lay.xy_cm.round(3).tolist(),
            "area_cm2": lay.area_cm2.round(4).tolist(),
        },
        "times": _rounded(review.series["t"], 3),
        "series": _series(review),
        "events": review.events[:2000],
        "sides": review.sides,
        "rois": load_rois(path),
        "interval": (review.rec.meta.get("interval") or {}).get("level"),
    }


def _roi_stats(review: Review, rois: list[dict[str, Any]]) -> list[dict[str, Any]]:
    from texsense.apps.review import BLOCK, decimate

    rec = review.rec
    regions = {r["name"]: roi_elements(r, rec.layout) for r in rois}
    out = []
    bins = min(rec.n_frames, MAX_POINTS)
    for name, idx in regions.items():
        entry: dict[str, Any] = {"name": name, "elements": idx.tolist()}
        if idx.size:
            parts: dict[str, list[np.ndarray]] = {}
            for start in range(0, rec.n_frames, BLOCK):
                block = rec.select(slice(start, start + BLOCK))
                for k, v in stats.region_stats(block, {name: idx})[name].items():
                    parts.setdefault(k, []).append(v)
            for k, pieces in parts.items():
                series = np.concatenate(pieces) * (
                    1.0 if k in ("load_N", "contact_area_cm2") else review.factor
                )
                entry[k] = _rounded(decimate(series, bins, "mean" if k == "mean" else "max"), 4)
        out.append(entry)
    return out


def _status_of(e: Exception) -> HTTPException:
    return HTTPException(422, str(e).splitlines()[0] if str(e) else type(e).__name__)


class _Folder:
    """The monitor's recordings folder: names resolved inside it, reviews cached."""

    def __init__(self, monitor: Monitor) -> None:
        self.monitor = monitor
        self.path = Path(monitor.record_dir)
        self.reviews = _Reviews()

    def path_of(self, name: str) -> Path:
        path = resolve_recording(self.path, name) if self.path.is_dir() else None
        if path is None:
            raise HTTPException(404, "no such recording")
        return path

    async def review_of(self, name: str) -> tuple[Path, Review]:
        path = self.path_of(name)
        try:
            return path, await asyncio.to_thread(self.reviews.get, path)
        except (FormatError, ParameterError, UnitError, OSError) as e:
            raise _status_of(e) from None

    def listing(self) -> list[dict[str, Any]]:
        if not self.path.is_dir():
            return []
        rec = self.monitor.recorder
        now = {Path(p).name for p in (rec.paths if rec else [])}
        rows = []
        for p in self.path.iterdir():
            if p.name.startswith(".") or p.name.endswith(".rois.json") or p.name == "reports":
                continue
            st = p.stat()
            rows.append({"name": p.name, "bytes": st.st_size, "modified": st.st_mtime,
                         "folder": p.is_dir(), "recording": p.name in now})  # fmt: skip
        return sorted(rows, key=lambda r: -r["modified"])


def _view(monitor: Monitor) -> dict[str, Any]:
    from texsense.apps.views import orientation_of

    mode = monitor.mode
    scale = None
    if mode.scale is not None:
        f = units.factor(mode.unit, "N/cm2")
        scale = [mode.scale[0] * f, mode.scale[1] * f]
    return {
        "mode": mode.to_dict(),
        "scale_ncm2": scale,
        "threshold_ncm2": monitor.tracker.threshold_ncm2 if mode.threshold_mmhg else None,
        "orientation": orientation_of(monitor.layout, mode=mode.name),
        "area_cm2": monitor.layout.area_cm2.round(4).tolist(),
    }


def _frame(review: Review, i: int) -> dict[str, Any]:
    if not 0 <= i < review.rec.n_frames:
        raise HTTPException(404, f"frame {i} is out of range 0..{review.rec.n_frames - 1}")
    repaired = [] if review.repaired is None else np.flatnonzero(review.repaired[i]).tolist()
    return {"i": i, "t": round(float(review.series["t"][i]), 3),
            "values": _rounded(review.frame(i), 4), "repaired": repaired}  # fmt: skip


async def _put_rois(folder: _Folder, name: str, request: Request) -> dict[str, Any]:

    path, review = await folder.review_of(name)
    body = await request.body()
    if len(body) > MAX_ROI_BYTES:
        raise HTTPException(413, f"regions: at most {MAX_ROI_BYTES // 1024} KiB")
    try:
        data = json.loads(body)
    except (ValueError, UnicodeDecodeError) as e:
        raise HTTPException(400, f"regions: not JSON ({e})") from None
    try:
        rois = parse_rois(data)
    except ParameterError as e:
        raise _status_of(e) from None
    save_rois(path, rois)
    return {"rois": rois, "stats": await asyncio.to_thread(_roi_stats, review, rois)}


async def _report(folder: _Folder, name: str, format: str) -> Any:

    if format not in ("pdf", "html"):
        raise HTTPException(422, "format must be pdf or html")
    path, review = await folder.review_of(name)
    out = folder.path / "reports" / f"{path.name}-report.{format}"
    try:
        rois = load_rois(path)
        out.parent.mkdir(exist_ok=True)
        await asyncio.to_thread(write_report, review.rec, out, name=path.name, rois=rois)
    except (FormatError, ParameterError, UnitError) as e:
        raise _status_of(e) from None
    media = "application/pdf" if format == "pdf" else "text/html"
    return FileResponse(out, media_type=media, filename=out.name)


def playback_router(monitor: Monitor) -> APIRouter:
    """The routes of this module for ``monitor`` (its recordings folder and mode)."""
    router = APIRouter()
    folder = _Folder(monitor)

    @router.get("/api/view")
    async def view() -> dict[str, Any]:
        """The live mode, its fixed scale (N/cm²), threshold and the map's orientation."""
        return _view(monitor)

    @router.get("/api/playback")
    async def recordings() -> list[dict[str, Any]]:
        """The recordings in the monitor's folder, newest first."""
        return folder.listing()

    @router.get("/api/playback/{name}")
    async def recording(name: str) -> dict[str, Any]:
        """One recording: layout, scale, statistics per frame, events, regions of interest."""
        path, review = await folder.review_of(name)
        try:
            return _summary(review, path)
        except ParameterError as e:
            raise _status_of(e) from None

    @router.get("/api/playback/{name}/frames/{i}")
    async def frame(name: str, i: int) -> dict[str, Any]:
        """Frame ``i``: its time, values (N/cm² for pressure; null: no value), the elements
        whose values are repairs, and the bounds of a recording that has them."""
        path, review = await folder.review_of(name)
        out = _frame(review, i)
        if review.pressure and path.suffix.lower() in (".h5", ".hdf5"):
            from texsense.io.hdf5 import read_bounds

            b = read_bounds(path, slice(i, i + 1))
            if b is not None:
                out["lower"] = _rounded(b[0][0] * review.factor, 4)
                out["upper"] = _rounded(b[1][0] * review.factor, 4)
        return out

    @router.get("/api/playback/{name}/rois")
    async def get_rois(name: str) -> list[dict[str, Any]]:
        """The regions of interest saved with the recording."""

        try:
            return load_rois(folder.path_of(name))
        except ParameterError as e:
            raise _status_of(e) from None

    @router.put("/api/playback/{name}/rois")
    async def put_rois(name: str, request: Request) -> dict[str, Any]:
        """Save the regions of interest (a JSON list of {name, kind, points}); answers with
        their elements and statistics over time."""
        return await _put_rois(folder, name, request)

    @router.get("/api/playback/{name}/report")
    async def report(name: str, format: str = "pdf") -> Any:
        """The report of the recording (PDF or HTML), kept in the folder ``reports``."""
        return await _report(folder, name, format)

    return router
