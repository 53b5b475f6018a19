"""The dashboard's views beyond the live frame: the mode and fixed scale of the live map, the
recordings in the monitor's folder, their playback frame by frame with the statistics and
events over time, regions of interest saved beside a recording, and its report
(docs/monitor.md "Playback", docs/report.md).

Routes (an :class:`fastapi.APIRouter`; :func:`playback_router`):

- ``GET /api/view``: the live mode (seat, bed, foot, generic), its words, fixed colour scale
  (N/cm²), threshold and orientation.
- ``GET /api/playback``: the recordings in the monitor's folder (newest first): the files and
  folders texsense reads as a recording (a calibration file, a report, a regions sidecar
  are not listed).
- ``GET /api/playback/{name}``: one recording: frames, times, layout, mode, scale, the
  statistics per frame (load, peak, contact area, centre of force; at most
  :data:`MAX_POINTS` points, each the max or mean of its frames), events, time per side,
  regions of interest.
- ``GET /api/playback/{name}/frames/{i}``: frame ``i`` (pressure in N/cm², as the live
  snapshot; other quantities in their unit).
- ``GET`` / ``PUT /api/playback/{name}/rois``: the regions of interest (sidecar
  ``<name>.rois.json``); a PUT answers with their statistics over time.
- ``POST /api/playback/{name}/report?format=pdf|html``: make the report
  (:mod:`texsense.apps.report`), kept in ``<folder>/reports/``, and answer with it. It writes
  a file, so it is a POST behind the same guard as every other write (a page of another site
  cannot have it made); ``GET`` of the same address answers with the report made last, if any.

A name is a plain file or folder name inside the recordings folder: anything with a path
separator, a leading dot, or that resolves elsewhere is 404, whatever its encoding; so is an
entry that is not a regular file or a folder (a FIFO, a device, a dangling link, a loop of
links), which the listing leaves out too (said once in the log). A file texsense cannot read
is a 422 with the reader's one-line message, a frame out of range 404.

Nothing here can starve the rest of the server: recordings are read and reports made in the
playback's own :class:`~texsense.monitor.web.Lane` (two at once, daemon threads, more are
refused with 503), never in the threads the calibration panel uses, and a stop does not wait
for them.

Memory: a texsense recording (``.h5``) is read on demand (:mod:`texsense.io.lazy`): opening
it reads its times and labels and makes the statistics, events and health in streaming
passes over its frames; a frame is read when it is asked for, through a cache of frames
bounded by a quarter of the memory budget (:mod:`texsense.data.budget`). So a recording of
any length plays, longer than the budget. The other formats are read from their start only:
they are read whole, within the budget, and one beyond it is refused in one line; they are
parsed in a child process (:mod:`texsense.io.apart`), so that the parsing never holds the
server's Python lock (it starved the calibration panel for seconds in a thread). The reviews
kept (:class:`_Reviews`: timelines, statistics per frame, whole recordings of other formats)
hold at most half of the budget, and the next one is opened within what is left.
"""

from __future__ import annotations

import logging
import os
import threading
from collections import OrderedDict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse

from texsense.apps import stats
from texsense.apps.clinical import POSTURE_LABEL
from texsense.apps.report import write_report
from texsense.apps.review import block_of, decimate, open_review
from texsense.apps.roi import load_rois, parse_rois, roi_elements, rois_path, save_rois
from texsense.apps.views import orientation_of
from texsense.data import budget, units
from texsense.data.files import (
    check_regular,
    json_loads,
    make_folder,
    real_path,
    regular_files,
)
from texsense.exceptions import FormatError, ParameterError, UnitError, WriteError
from texsense.io import open_recording, sniff_format
from texsense.io.hdf5 import read_bounds
from texsense.monitor.web import Lane

if TYPE_CHECKING:
    from texsense.apps.review import Review
    from texsense.data.recording import Recording
    from texsense.monitor.live import Monitor

__all__ = ["MAX_POINTS", "playback_router", "resolve_recording"]

log = logging.getLogger("texsense.web")

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
    base = real_path(folder)
    path = real_path(base / name)
    if path.parent != base:
        return None
    try:
        check_regular(path, folder_ok=True)  # a status only: nothing waits on a FIFO
    except FormatError:
        return None
    return path


def _rounded(v: np.ndarray, nd: int = 3) -> list[Any]:
    a = np.asarray(v, dtype=np.float64)
    out = np.round(a, nd).astype(object)
    out[~np.isfinite(a)] = None
    return list(out.tolist())


def _nbytes(review: Review) -> int:
    """The memory a review holds (its recording's arrays and what was computed from them)."""
    rec = review.rec
    arrays = [rec.frames, rec.valid, rec.times, rec.element_times, review.repaired,
              *rec.labels.values(), *review.series.values(), *review.health.values()]  # fmt: skip
    return sum(a.nbytes for a in arrays if a is not None)


class _Reviews:
    """A small cache of :class:`Review` objects keyed by path, size and modification time:
    at most :data:`CACHE` of them, holding at most half of the memory budget together. One
    recording is read at a time, within the budget less what the cache holds."""

    def __init__(self) -> None:
        self._items: OrderedDict[tuple[str, int, float], tuple[Review, int]] = OrderedDict()
        self._lock = threading.Lock()
        self._reading = threading.Lock()

    def held(self) -> int:
        """Bytes the cached reviews hold."""
        with self._lock:
            return sum(size for _, size in self._items.values())

    def get(self, path: Path) -> Review:
        st = path.stat()
        key = (str(path), st.st_size, st.st_mtime)
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return self._items[key][0]
        with self._reading:  # one at a time: their memory does not add up
            self._shrink(budget.max_memory() // 2)
            memory = budget.max_memory() - self.held()
            rec: Recording
            with budget.share(memory):
                # HDF5 read on demand; text read whole in a child process (parsing text holds
                # Python's lock), within the share
                rec = open_recording(path, apart=True)
                # the page converts pressure from N/cm², as for the live frames
                unit = "N/cm2" if rec.quantity == "pressure" else None
                review = open_review(rec, unit=unit, name=path.name)
        with self._lock:
            self._items[key] = (review, _nbytes(review))
        self._shrink(budget.max_memory() // 2, keep=key)
        return review

    def _shrink(self, limit: int, keep: Any = None) -> None:
        """Forget the oldest reviews (but ``keep``) until at most :data:`CACHE` hold at most
        ``limit`` bytes."""
        with self._lock:
            for key in list(self._items):
                size = sum(s for _, s in self._items.values())
                if key == keep or (len(self._items) <= CACHE and size <= limit):
                    continue
                review = self._items.pop(key)[0]
                close = getattr(review.rec, "close", None)  # a recording read on demand
                if close is not None:
                    close()


def _series(review: Review) -> dict[str, Any]:
    s = review.series
    n = s["t"].size
    bins = min(n, MAX_POINTS)
    index = np.linspace(0, n, bins + 1).astype(int)[:-1]
    out: dict[str, Any] = {"i": index.tolist(), "t": _rounded(s["t"][index], 3)}
    # the peak's bounds (a file with bounds) by the peak's rule: a bin's highest of each
    for key in ("load_N", "peak", "area_cm2", "peak_lower", "peak_upper"):
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
        "clock_rate": round(review.clock_rate, 6),  # frame s per wall-clock s (1: a real mat)
        "live": review.live,
        "notes": review.notes,
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
    rec = review.rec
    regions = {r["name"]: roi_elements(r, rec.layout) for r in rois}
    out = []
    bins = min(rec.n_frames, MAX_POINTS)
    for name, idx in regions.items():
        entry: dict[str, Any] = {"name": name, "elements": idx.tolist()}
        if idx.size:
            parts: dict[str, list[np.ndarray]] = {}
            step = block_of(rec)
            for start in range(0, rec.n_frames, step):
                block = rec.select(slice(start, start + step))
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
    """The monitor's recordings folder: names resolved inside it, reviews cached, read in
    the playback's own lane."""

    def __init__(self, monitor: Monitor) -> None:
        self.monitor = monitor
        self.path = Path(monitor.record_dir)
        self.reviews = _Reviews()
        self.lane = Lane("playback", workers=2, waiting=8)
        self._said: set[tuple[str, str]] = set()
        self._kinds: dict[tuple[str, int, float], bool] = {}  # (name, size, mtime) -> readable

    def is_recording(self, p: Path, size: int, mtime: float) -> bool:
        """Whether texsense reads ``p`` as a recording (by its content, as ``load`` would;
        remembered while the file is unchanged)."""
        key = (p.name, size, mtime)
        if key not in self._kinds:
            try:
                self._kinds[key] = sniff_format(p) != "folder"
            except (FormatError, OSError):
                self._kinds[key] = False
            if len(self._kinds) > 4096:
                self._kinds.clear()
        return self._kinds[key]

    def path_of(self, name: str) -> Path:
        path = resolve_recording(self.path, name) if self.path.is_dir() else None
        if path is None:
            raise HTTPException(404, "no such recording")
        return path

    async def review_of(self, name: str) -> tuple[Path, Review]:
        path = self.path_of(name)
        try:
            return path, await self.lane.run(self.reviews.get, path)
        except (FormatError, ParameterError, UnitError, OSError) as e:
            raise _status_of(e) from None

    def listing(self) -> list[dict[str, Any]]:
        """The regular files and real subfolders of the folder (no link out of it, no
        dangling link, loop, FIFO or device: each said once in the log)."""
        if not self.path.is_dir():
            return []
        rec = self.monitor.recorder
        now = {Path(p).name for p in (rec.paths if rec else [])}
        entries, passed = regular_files(self.path, folders=True)
        for p, why in passed:
            if (p.name, why) not in self._said:
                self._said.add((p.name, why))
                log.warning("playback: %s is not listed (%s)", p, why)
        rows = []
        for p in entries:
            if p.name.startswith(".") or p.name.endswith(".rois.json") or p.name == "reports":
                continue
            try:
                st = p.stat()
            except OSError:  # gone in between
                continue
            if p.name not in now and not self.is_recording(p, st.st_size, st.st_mtime):
                continue
            rows.append({"name": p.name, "bytes": st.st_size, "modified": st.st_mtime,
                         "folder": p.is_dir(), "recording": p.name in now})  # fmt: skip
        return sorted(rows, key=lambda r: -r["modified"])


def _view(monitor: Monitor) -> dict[str, Any]:
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


#: The per-frame labels that say a frame's posture or side, most telling first: what the
#: monitor showed live, a simulation's side, PMD's posture class, a recorded posture.
POSTURE_LABELS = (POSTURE_LABEL, "side", "posture_class", "posture")


def _frame(review: Review, i: int) -> dict[str, Any]:
    if not 0 <= i < review.rec.n_frames:
        raise HTTPException(404, f"frame {i} is out of range 0..{review.rec.n_frames - 1}")
    rec = review.rec
    repaired = review.repaired_at(i)
    out = {"i": i, "t": round(float(review.series["t"][i]), 3),
           "values": _rounded(review.frame(i), 4), "repaired": repaired}  # fmt: skip
    if review.pressure:  # the frame's peak pressure index, N/cm² (as the live snapshot's)
        one = rec.select(slice(i, i + 1)).to_unit("N/cm2")
        ppi = float(stats.peak_pressure_index(one)[0])
        out["ppi_ncm2"] = round(ppi, 4) if np.isfinite(ppi) else None
    for name in POSTURE_LABELS:
        if name in rec.labels:
            value = str(rec.labels[name][i])
            out["posture"] = {"label": value or None, "from": name}
            break
    return out


async def _put_rois(folder: _Folder, name: str, request: Request) -> dict[str, Any]:

    path, review = await folder.review_of(name)
    body = await request.body()
    if len(body) > MAX_ROI_BYTES:
        raise HTTPException(413, f"regions: at most {MAX_ROI_BYTES // 1024} KiB")
    try:
        data = json_loads(body)
    except (ValueError, UnicodeDecodeError) as e:
        raise HTTPException(400, f"regions: not JSON ({e})") from None
    try:
        rois = parse_rois(data)
    except ParameterError as e:
        raise _status_of(e) from None
    _named(rois_path(path))
    try:
        save_rois(path, rois)
    except (OSError, WriteError) as e:
        raise HTTPException(507, f"cannot write the regions: {e}") from None
    try:  # a recording read on demand: a damaged chunk is said, not a 500
        stats_ = await folder.lane.run(_roi_stats, review, rois)
    except (FormatError, ParameterError) as e:
        raise _status_of(e) from None
    return {"rois": rois, "stats": stats_}


def _report_path(folder: _Folder, name: str, format: str) -> Path:
    if format not in ("pdf", "html"):
        raise HTTPException(422, "format must be pdf or html")
    return _named(folder.path / "reports" / f"{folder.path_of(name).name}-report.{format}")


def _named(out: Path) -> Path:
    """``out``, a file named after a recording (its report, its regions), if the file system
    can hold its name; else a 422 (an OSError would be a 500)."""
    if len(os.fsencode(out.name)) > 255:
        raise HTTPException(422, f"the recording's name is too long to name {out.name[-24:]!r}")
    return out


async def _make_report(folder: _Folder, name: str, format: str) -> Any:
    out = _report_path(folder, name, format)
    path, review = await folder.review_of(name)
    try:
        rois = load_rois(path)
        make_folder(out.parent, "reports folder")
        # a recording read on demand is read whole for its report, within the memory budget
        source = path if review.on_demand else review.rec
        await folder.lane.run(write_report, source, out, name=path.name, rois=rois)
    except (FormatError, ParameterError, UnitError) as e:
        raise _status_of(e) from None
    except (OSError, WriteError) as e:
        raise HTTPException(507, f"cannot write the report: {e}") from None
    return _report_file(out, format)


def _report_file(out: Path, format: str) -> Any:
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
        try:  # read on demand: a damaged chunk is a 422 naming the file
            out = _frame(review, i)
        except (FormatError, ParameterError) as e:
            raise _status_of(e) from None
        if review.pressure and path.suffix.lower() in (".h5", ".hdf5"):
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

    @router.post("/api/playback/{name}/report")
    async def make_report(name: str, format: str = "pdf") -> Any:
        """Make the report of the recording (PDF or HTML), keep it in the folder
        ``reports`` and answer with it."""
        return await _make_report(folder, name, format)

    @router.get("/api/playback/{name}/report")
    async def report(name: str, format: str = "pdf") -> Any:
        """The report made last (``POST`` makes it; nothing is written here)."""
        out = _report_path(folder, name, format)
        if not out.is_file():
            raise HTTPException(404, "no report made yet: POST to this address makes it")
        return _report_file(out, format)

    return router
