"""Regions of interest drawn on a pressure map: a box or a lasso (polygon) in the layout's
cm, the elements whose centres lie inside, and the sidecar file that keeps them with a
recording (``<recording>.rois.json``, written atomically; docs/monitor.md, docs/report.md).

A region is a dict ``{"name": "left heel", "kind": "box" | "lasso", "points": [[x, y],
...]}`` with the points in cm (x along a row, y down the columns, as :class:`Layout`); a
box has two corners, a lasso 3 to 500 vertices. Anything else is refused with one line
naming the region and what is wrong (the page posts them, so they are checked like any
input).

Examples
--------
>>> from texsense import Layout
>>> lay = Layout.grid(4, 4, pitch_cm=1.0)
>>> rois = parse_rois([{"name": "top left", "kind": "box", "points": [[0, 0], [2, 2]]}])
>>> roi_elements(rois[0], lay).tolist()
[0, 1, 4, 5]
>>> tri = {"name": "t", "kind": "lasso", "points": [[0, 0], [4, 0], [0, 4]]}
>>> roi_elements(parse_rois([tri])[0], lay).tolist()
[0, 1, 2, 4, 5, 8]
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.data.files import json_loads, read_regular, write_text
from texsense.data.layout import Layout
from texsense.exceptions import ParameterError

__all__ = [
    "MAX_ROIS",
    "load_rois",
    "parse_rois",
    "roi_elements",
    "rois_path",
    "save_rois",
]

#: At most this many regions per recording, and this many lasso vertices per region.
MAX_ROIS = 32
MAX_VERTICES = 500
_MAX_NAME = 60


def _point(p: Any, where: str) -> tuple[float, float]:
    if not isinstance(p, list | tuple) or len(p) != 2:
        raise ParameterError(f"{where}: a point must be [x, y] in cm")
    try:
        x, y = float(p[0]), float(p[1])
    except (TypeError, ValueError):
        raise ParameterError(f"{where}: a point must be two numbers (cm)") from None
    if not (np.isfinite(x) and np.isfinite(y)) or max(abs(x), abs(y)) > 1e5:
        raise ParameterError(f"{where}: coordinates must be finite cm within ±100000")
    return x, y


def parse_rois(data: Any) -> list[dict[str, Any]]:
    """Check a list of regions (parsed JSON) and return it in its canonical form; raises
    :class:`ParameterError` naming the region and the fault."""
    if not isinstance(data, list):
        raise ParameterError("regions: expected a list of {name, kind, points}")
    if len(data) > MAX_ROIS:
        raise ParameterError(f"regions: at most {MAX_ROIS}, got {len(data)}")
    out: list[dict[str, Any]] = []
    names: set[str] = set()
    for k, r in enumerate(data):
        where = f"region {k + 1}"
        if not isinstance(r, dict):
            raise ParameterError(f"{where}: expected an object {{name, kind, points}}")
        name = r.get("name")
        if not isinstance(name, str) or not name.strip() or len(name) > _MAX_NAME:
            raise ParameterError(f"{where}: 'name' must be a text of 1-{_MAX_NAME} characters")
        name = name.strip()
        where = f"region {name!r}"
        if name in names:
            raise ParameterError(f"{where}: two regions have this name")
        kind = r.get("kind")
        if kind not in ("box", "lasso"):
            raise ParameterError(f"{where}: 'kind' must be 'box' or 'lasso', got {kind!r}")
        pts = r.get("points")
        if not isinstance(pts, list):
            raise ParameterError(f"{where}: 'points' must be a list of [x, y]")
        n_ok = len(pts) == 2 if kind == "box" else 3 <= len(pts) <= MAX_VERTICES
        if not n_ok:
            want = "2 corners" if kind == "box" else f"3-{MAX_VERTICES} vertices"
            raise ParameterError(f"{where}: a {kind} needs {want}, got {len(pts)} points")
        unknown = set(r) - {"name", "kind", "points"}
        if unknown:
            raise ParameterError(f"{where}: unknown field(s) {', '.join(sorted(unknown))}")
        out.append({"name": name, "kind": kind, "points": [_point(p, where) for p in pts]})
        names.add(name)
    return out


def _inside(xy: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule: which points ``xy`` (M, 2) lie inside the polygon ``poly`` (K, 2)."""
    x, y = xy[:, 0][:, None], xy[:, 1][:, None]
    x0, y0 = poly[:, 0][None, :], poly[:, 1][None, :]
    x1, y1 = np.roll(poly[:, 0], -1)[None, :], np.roll(poly[:, 1], -1)[None, :]
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return (np.sum(crosses & (x < x_at), axis=1) % 2) == 1


def roi_elements(roi: dict[str, Any], layout: Layout) -> npt.NDArray[np.int64]:
    """Indices of the elements whose centres lie inside ``roi`` (a checked region)."""
    pts = np.asarray(roi["points"], dtype=np.float64)
    xy = layout.xy_cm
    if roi["kind"] == "box":
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        ok = np.all((xy >= lo) & (xy <= hi), axis=1)
    else:
        ok = _inside(xy, pts)
    return np.flatnonzero(ok).astype(np.int64)


def rois_path(recording: str | Path) -> Path:
    """The sidecar file of a recording: ``<file name>.rois.json`` beside it."""
    p = Path(recording)
    if not p.name:  # ".", "..", "/": a folder named by where it is
        p = p.resolve()
    return p.with_name(p.name + ".rois.json") if p.name else p / ".rois.json"


def load_rois(recording: str | Path) -> list[dict[str, Any]]:
    """The regions saved with a recording (none when there is no sidecar); a broken sidecar
    raises :class:`ParameterError` naming it."""
    path = rois_path(recording)
    if not os.path.lexists(path):
        return []
    try:
        data = json_loads(read_regular(path, "a regions file").decode("utf-8"))
    except (ValueError, UnicodeDecodeError) as e:
        raise ParameterError(f"{path}: not a regions file ({e})") from None
    except OSError as e:
        raise ParameterError(f"{path}: cannot read the regions ({e.strerror or e})") from None
    if not isinstance(data, dict) or data.get("format") != "texsense.rois":
        raise ParameterError(f"{path}: not a texsense regions file")
    try:
        return parse_rois(data.get("regions"))
    except ParameterError as e:
        raise ParameterError(f"{path}: {e}") from None


def save_rois(recording: str | Path, rois: list[dict[str, Any]]) -> Path:
    """Write the regions of a recording to its sidecar (atomically; :mod:`texsense.data.files`)."""

    doc = {"format": "texsense.rois", "version": 1, "recording": Path(recording).name}
    doc["regions"] = parse_rois(rois)
    return write_text(rois_path(recording), json.dumps(doc, indent=1))
