"""What a pressure map means to the person reading it: the monitoring **mode** of a mat (seat,
bed, foot or generic) with its clinical words, units and fixed colour scale, the orientation
of the drawn map, names for places on the mat, and times written for people (docs/monitor.md,
docs/report.md).

The dashboard, the ward station and ``texsense report`` share these rules, so that a number,
a colour and a word mean the same on every page:

- **Fixed colour scale.** A map is coloured on a scale fixed for the mode (seat and bed:
  0-100 mmHg with the 32 mmHg threshold of thesis §1.1 marked; foot: 0-600 kPa), never
  re-ranged frame by frame, so one colour is one pressure throughout a session. The user
  may set another range.
- **The mode's words.** A seat tells to *reposition* (shift weight or stand up), a bed to
  *turn* the patient; a foot sensor raises no exposure alerts and no seated/left events
  (an insole is loaded and unloaded at every step).
- **Places, not indices.** Elements are named by the region the bed or seat mode knows
  (sacrum, heel-l, ischium-r, ...), otherwise by row and column counted from 1 at the top
  left of the drawn map.

Examples
--------
>>> mode = MODES["bed"]
>>> mode.unit, mode.scale, mode.threshold_mmhg, mode.action
('mmHg', (0.0, 100.0), 32.0, 'turn')
>>> format_duration(5400), format_duration(75), format_duration(8)
('1 h 30 min', '1 min 15 s', '8 s')
>>> from texsense import Layout
>>> lay = Layout.grid(4, 5)
>>> place_names([6, 7, 12], lay)
['rows 2-3, columns 2-3']
"""

from __future__ import annotations

import datetime as _dt
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.data import units
from texsense.data.layout import ORIENTATIONS, Layout
from texsense.exceptions import ParameterError

__all__ = [
    "MODES",
    "Mode",
    "alert_places",
    "checked_words",
    "format_clock",
    "format_duration",
    "guess_mode",
    "orientation_of",
    "outline_segments",
    "place_names",
    "recording_scale",
    "seat_zones",
    "started_at",
    "threshold_mask",
    "times_words",
]


@dataclass(frozen=True)
class Mode:
    """How a kind of mat is monitored and shown.

    Attributes
    ----------
    name : str
        ``seat``, ``bed``, ``foot`` or ``generic``.
    unit : str
        The unit pages show by default (a viewer may choose another).
    scale : (float, float) or None
        The fixed colour scale in ``unit``; None: fixed per recording from its values
        (:func:`recording_scale`).
    threshold_mmhg : float or None
        The exposure threshold marked on the legend and drawn as a contour (None: none).
    occupancy : (str, str) or None
        Event kinds when the mat becomes loaded / unloaded; None: no such events.
    occupancy_hold_s : float
        A change of occupancy counts once it has held this long (a replay of a gait or a
        fidgeting sitter does not make a storm of events).
    alerts : bool
        Exposure (reposition) alerts.
    action : str
        The word for what relieves the skin: ``reposition``, ``turn``, ``offload``.
    advice : str
        The alert's sentence of what to do.
    """

    name: str
    unit: str
    scale: tuple[float, float] | None
    threshold_mmhg: float | None
    occupancy: tuple[str, str] | None
    occupancy_hold_s: float
    alerts: bool
    action: str
    advice: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (what the pages read from ``/api/status``)."""
        return {
            "name": self.name,
            "unit": self.unit,
            "scale": None if self.scale is None else list(self.scale),
            "threshold_mmhg": self.threshold_mmhg,
            "alerts": self.alerts,
            "action": self.action,
            "advice": self.advice,
        }


#: The modes. Seat and bed follow the pressure-injury rule of thesis §1.1 (32 mmHg).
MODES: dict[str, Mode] = {
    "seat": Mode(
        "seat",
        "mmHg",
        (0.0, 100.0),
        32.0,
        ("seated", "left"),
        0.0,
        True,
        "reposition",
        "shift weight or stand up",
    ),
    "bed": Mode(
        "bed",
        "mmHg",
        (0.0, 100.0),
        32.0,
        ("in-bed", "out-of-bed"),
        0.0,
        True,
        "turn",
        "turn the patient onto another side",
    ),
    "foot": Mode("foot", "kPa", (0.0, 600.0), None, None, 0.0, False, "offload", ""),
    "generic": Mode(
        "generic",
        "N/cm2",
        None,
        32.0,
        ("loaded", "unloaded"),
        5.0,
        True,
        "offload",
        "offload the area",
    ),
}


def _header(meta: Mapping[str, Any]) -> Mapping[str, Any]:
    h = meta.get("header")
    return h if isinstance(h, Mapping) else {}


def guess_mode(layout: Layout, meta: Mapping[str, Any] | None = None) -> str:
    """The mode of a recording or source: what it declares (``meta["mode"]``, written by the
    monitor's recorder), what its file says (PhysioNet PMD: a bed; a Tekscan F-Scan or an
    XSENSOR foot sensor: foot), its declared orientation, else its size: 120 cm or longer is
    a bed, an elongated sensor up to 40 cm (long side at least 1.8 x the short one) a foot,
    25-70 cm and squarer a seat, anything else generic.

    >>> from texsense import Layout
    >>> bed, insole = Layout.grid(64, 32, pitch_cm=2.54), Layout.grid(60, 21, pitch_cm=0.508)
    >>> guess_mode(bed), guess_mode(insole)
    ('bed', 'foot')
    """
    meta = meta or {}
    declared = meta.get("mode")
    if isinstance(declared, str) and declared in MODES:
        return declared
    fmt = str(meta.get("format", ""))
    if fmt == "physionet-pmd":
        return "bed"
    if "FSCAN" in str(_header(meta).get("SENSOR_TYPE", "")).upper():
        return "foot"
    sensors = meta.get("sensors")
    if isinstance(sensors, list) and any(re.search(r"-[LR]F\b", str(s)) for s in sensors):
        return "foot"  # XSENSOR foot sensors name the foot
    top = layout.orientation.get("top")
    for name, preset in ORIENTATIONS.items():
        if top is not None and preset.get("top") == top:
            return name
    x0, x1, y0, y1 = layout.extent_cm
    long_cm, short_cm = max(x1 - x0, y1 - y0), min(x1 - x0, y1 - y0)
    if long_cm >= 120:
        return "bed"
    if long_cm <= 40 and short_cm > 0 and long_cm / short_cm >= 1.8 and long_cm >= 15:
        return "foot"
    if 25 <= long_cm <= 70:
        return "seat"
    return "generic"


def orientation_of(layout: Layout, meta: Mapping[str, Any] | None = None, mode: str = "") -> dict:
    """The edge labels to draw: the layout's own, else the recording's (``meta``), else, for
    a bed, the head at row 0 (what :mod:`texsense.apps.bed` assumes of every bed mat). The result
    says ``assumed: True`` when it is the last."""
    own = layout.orientation
    if own:
        return {**own, "assumed": False}
    stored = (meta or {}).get("orientation")
    if isinstance(stored, Mapping) and stored:
        return {**{k: str(v) for k, v in stored.items() if k != "assumed"}, "assumed": False}
    if mode == "bed":
        return {"top": "head", "bottom": "foot", "assumed": True}
    return {}


# ---------------------------------------------------------------------------- places
def _rc(layout: Layout, elements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if layout.cells is None or layout.shape is None:
        raise ParameterError("rows and columns need a grid layout")
    return np.divmod(layout.cells[elements], layout.shape[1])


def _span(lo: int, hi: int, word: str) -> str:
    return f"{word} {lo + 1}" if lo == hi else f"{word}s {lo + 1}-{hi + 1}"


def _grid_groups(elements: np.ndarray, layout: Layout) -> list[str]:
    """Connected groups of elements as 'row r, column c' or 'rows a-b, columns c-d'."""
    from scipy import ndimage  # (a second of import: only where groups are named)

    assert layout.shape is not None
    rows, cols = _rc(layout, elements)
    mask = np.zeros(layout.shape, bool)
    mask[rows, cols] = True
    labels, n = ndimage.label(mask, structure=np.ones((3, 3)))
    out = []
    for k in range(1, n + 1):
        r, c = np.nonzero(labels == k)
        if r.size == 1:
            out.append(f"row {r[0] + 1}, column {c[0] + 1}")
        else:
            out.append(f"{_span(r.min(), r.max(), 'row')}, {_span(c.min(), c.max(), 'column')}")
    return out


def seat_zones(layout: Layout) -> dict[str, np.ndarray]:
    """Zones of a seat by position (not found anatomy): with the front edge at the top, the
    back 18 % of the depth in the middle fifth is the ``sacrum`` (leaning back), the rest of
    the back half ``ischium-l`` / ``ischium-r``, the front half ``thigh-l`` / ``thigh-r``;
    ``-l`` is the sitter's left. Only what the orientation declares is named: a seat whose
    front is not declared has no zones (its back half cannot be told from its front), one
    whose left and right are not declared has ``ischium`` and ``thigh`` without a side. A seat
    drawn with its back at the top is turned round first.

    >>> from texsense import Layout
    >>> sorted(seat_zones(Layout.grid(10, 10, pitch_cm=4).with_orientation("seat")))
    ['ischium-l', 'ischium-r', 'sacrum', 'thigh-l', 'thigh-r']
    >>> seat_zones(Layout.grid(10, 10, pitch_cm=4))
    {}
    """
    o = layout.orientation
    if {o.get("top"), o.get("bottom")} & {"front", "back"} == set():
        return {}
    x0, x1, y0, y1 = layout.extent_cm
    fx = (layout.xy_cm[:, 0] - x0) / max(x1 - x0, 1e-9)
    fy = (layout.xy_cm[:, 1] - y0) / max(y1 - y0, 1e-9)
    if o.get("top") == "back" or o.get("bottom") == "front":
        fy = 1 - fy
    sides = {o.get("left"), o.get("right")} == {"left", "right"}
    if o.get("left") == "right":
        fx = 1 - fx
    back = fy >= 0.5
    mid = np.abs(fx - 0.5) <= 0.1
    sacrum = back & mid & (fy >= 0.82)
    if not sides:
        zones = {"sacrum": sacrum, "ischium": back & ~sacrum, "thigh": ~back}
    else:
        zones = {
            "sacrum": sacrum,
            "ischium-l": back & (fx < 0.5) & ~sacrum,
            "ischium-r": back & (fx >= 0.5) & ~sacrum,
            "thigh-l": ~back & (fx < 0.5),
            "thigh-r": ~back & (fx >= 0.5),
        }
    return {k: np.flatnonzero(v) for k, v in zones.items()}


def place_names(
    elements: Iterable[int],
    layout: Layout,
    regions: Mapping[str, npt.ArrayLike] | None = None,
    *,
    near_cm: float = 6.0,
) -> list[str]:
    """Names for the places of ``elements``: the region each lies in or lies within
    ``near_cm`` of (``regions``: name -> element indices, e.g. the bed's at-risk regions or
    :func:`seat_zones`), the rest as connected groups by row and column (counted from 1 at the
    top left of the drawn map), or element names on a layout without a grid."""
    idx = np.unique(np.asarray(list(elements), dtype=np.int64))
    if idx.size == 0:
        return []
    if idx.min() < 0 or idx.max() >= layout.n_elements:
        raise ParameterError(f"element indices must lie in 0..{layout.n_elements - 1}")
    names: list[str] = []
    left = idx
    if regions:
        xy = layout.xy_cm
        keys = [k for k, v in regions.items() if np.asarray(v).size]
        members = {k: np.asarray(regions[k], dtype=np.int64) for k in keys}
        centres = np.array([xy[members[k]].mean(axis=0) for k in keys]) if keys else None
        taken = np.zeros(idx.size, bool)
        for j, e in enumerate(idx):
            hit = [k for k in keys if e in members[k]]
            if not hit and centres is not None:
                d = np.hypot(*(centres - xy[e]).T)
                if d.min() <= near_cm:
                    hit = [keys[int(np.argmin(d))]]
            if hit:
                taken[j] = True
                if hit[0] not in names:
                    names.append(hit[0])
        left = idx[~taken]
    if left.size:
        if layout.shape is not None:
            names += _grid_groups(left, layout)
        else:
            labels = layout.names or tuple(f"element {i}" for i in range(layout.n_elements))
            names += [labels[i] for i in left]
    return names


def alert_places(
    elements: Iterable[int],
    layout: Layout,
    regions: Mapping[str, npt.ArrayLike] | None = None,
) -> tuple[list[str], list[str]]:
    """Where an alert is, in two parts: the regions (anatomy, seat zones) its elements lie in
    or near — what the alert says — and the rest as rows and columns — its details line.

    >>> from texsense import Layout
    >>> lay = Layout.grid(8, 8, pitch_cm=2)
    >>> alert_places([0, 36, 37], lay, {"heel": [0, 1]})
    (['heel'], ['row 5, columns 5-6'])
    """
    idx = np.unique(np.asarray(list(elements), dtype=np.int64))
    named = [k for k, v in (regions or {}).items() if np.asarray(v).size]
    names = place_names(idx, layout, regions)
    return [n for n in names if n in named], [n for n in names if n not in named]


def threshold_mask(grid: npt.ArrayLike, active: npt.ArrayLike, threshold: float) -> np.ndarray:
    """The cells of a map (rows x cols) inside the region above ``threshold``: the elements
    above it, and an empty cell (no element, ``active`` False: a checkerboard's gaps) when at
    least half of the elements among its 4 neighbours, and at least two, are above — so that
    the outline follows the loaded area rather than each cell of a checkerboard. The page
    draws the same region (``aboveMask`` in mapview.js).

    >>> active = np.indices((3, 3)).sum(axis=0) % 2 == 0     # a 3 x 3 checkerboard
    >>> threshold_mask(np.where(active, 1.0, np.nan), active, 0.5).astype(int)
    array([[1, 1, 1],
           [1, 1, 1],
           [1, 1, 1]])
    """
    g = np.asarray(grid, dtype=np.float64)
    act = np.asarray(active, dtype=bool)
    with np.errstate(invalid="ignore"):
        above = act & (np.nan_to_num(g, nan=-np.inf) > threshold)
    padded_a = np.pad(above, 1).astype(int)
    padded_n = np.pad(act, 1).astype(int)
    up = padded_a[:-2, 1:-1] + padded_a[2:, 1:-1] + padded_a[1:-1, :-2] + padded_a[1:-1, 2:]
    n = padded_n[:-2, 1:-1] + padded_n[2:, 1:-1] + padded_n[1:-1, :-2] + padded_n[1:-1, 2:]
    return above | (~act & (up >= 2) & (2 * up >= n))


def outline_segments(mask: npt.ArrayLike) -> np.ndarray:
    """The boundary of a region of cells as line segments (K, 2, 2) of (column, row) corner
    coordinates: the cell edges between a cell inside and one outside (or the map's edge)."""
    m = np.pad(np.asarray(mask, dtype=bool), 1)
    segs = []
    r, c = np.nonzero(m[1:-1, 1:-1] & ~m[:-2, 1:-1])  # top edges
    segs += [((x, y), (x + 1, y)) for y, x in zip(r, c, strict=True)]
    r, c = np.nonzero(m[1:-1, 1:-1] & ~m[2:, 1:-1])  # bottom edges
    segs += [((x, y + 1), (x + 1, y + 1)) for y, x in zip(r, c, strict=True)]
    r, c = np.nonzero(m[1:-1, 1:-1] & ~m[1:-1, :-2])  # left edges
    segs += [((x, y), (x, y + 1)) for y, x in zip(r, c, strict=True)]
    r, c = np.nonzero(m[1:-1, 1:-1] & ~m[1:-1, 2:])  # right edges
    segs += [((x + 1, y), (x + 1, y + 1)) for y, x in zip(r, c, strict=True)]
    return np.array(segs, dtype=np.float64).reshape(-1, 2, 2)


# ---------------------------------------------------------------------------- scale
def recording_scale(values: npt.ArrayLike, unit: str, mode: str) -> tuple[float, float]:
    """The fixed colour scale of a recording in ``unit``: the mode's own for pressure
    (converted from its unit), else 0 to the 99.5th percentile of the loaded values rounded
    up to a round number (one scale for every frame, whatever its peak)."""
    m = MODES.get(mode, MODES["generic"])
    if m.scale is not None and units.is_pressure_unit(unit):
        f = units.factor(m.unit, unit)
        return (m.scale[0] * f, m.scale[1] * f)
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v) & (v > 0)]
    if v.size == 0:
        return (0.0, 1.0)
    top = float(np.percentile(v, 99.5))
    step = 10 ** np.floor(np.log10(top)) if top > 0 else 1.0
    for k in (1, 2, 2.5, 5, 10):
        if k * step >= top:
            return (0.0, float(k * step))
    return (0.0, float(10 * step))  # pragma: no cover


# ---------------------------------------------------------------------------- times
def format_duration(seconds: float | None) -> str:
    """A duration for people: ``8 s``, ``1 min 15 s``, ``1 h 30 min`` (``–`` for None)."""
    if seconds is None or not np.isfinite(seconds):
        return "–"
    s = round(abs(float(seconds)))
    sign = "-" if seconds < 0 else ""
    if s < 60:
        return f"{sign}{s} s"
    m, s = divmod(s, 60)
    if m < 60:
        return f"{sign}{m} min {s} s" if s else f"{sign}{m} min"
    h, m = divmod(m, 60)
    return f"{sign}{h} h {m:02d} min"


def times_words(n: int) -> str:
    """How often, in words: ``never``, ``once``, ``twice``, ``3 times``."""
    return {0: "never", 1: "once", 2: "twice"}.get(int(n), f"{int(n)} times")


def checked_words(status: dict[str, Any], when: str) -> str:
    """How long before the last frame a still load last agreed with the weight, from the
    in-use drift correction's status (``checked_t``, ``checked_age_s``; the bounds widen with
    that age), in words; ``when`` ends the phrase (``before the end``, ``ago``)."""
    age = status.get("checked_age_s")
    if status.get("checked_t") is None:
        since = "" if age is None else f" ({format_duration(age)} since the first correction)"
        return "never checked against a still weight" + since
    if age is None:
        return f"last checked against the weight at t = {status['checked_t']:.0f} s"
    return f"last checked against the weight {format_duration(age)} {when}"


def format_clock(start: float | None, t: float) -> str:
    """The wall-clock time ``t`` s after ``start`` (Unix s), local time ``HH:MM:SS``; without
    a start, the time since the start as ``+H:MM:SS``."""
    if start is None:
        s = round(max(t, 0.0))
        return f"+{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"
    return _dt.datetime.fromtimestamp(start + t).strftime("%H:%M:%S")


def started_at(meta: Mapping[str, Any]) -> float | None:
    """When a recording started (Unix s), if it says: the monitor's ``started_at``, an
    XSENSOR ``start_time`` or a Tekscan ``TIME`` header; None otherwise."""
    for key in ("started_at", "start_time"):
        v = meta.get(key)
        if isinstance(v, int | float):
            return float(v)
        if isinstance(v, str):
            try:
                return _dt.datetime.fromisoformat(v).timestamp()
            except ValueError:
                pass
    text = str(_header(meta).get("TIME", "")).strip()
    for fmt in ("%A, %d %B %Y %I:%M:%S %p", "%m/%d/%Y %I:%M:%S.%f%p"):
        try:
            return _dt.datetime.strptime(
                text.replace("a.m.", "AM").replace("p.m.", "PM"), fmt
            ).timestamp()
        except ValueError:
            continue
    return None
