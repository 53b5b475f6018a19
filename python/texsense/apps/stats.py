"""Frame statistics that pressure-mapping users expect.

All functions take a :class:`~texsense.Recording` and return one value per frame. Values
(the peak, the PPI, a contact threshold) are in the recording's own unit:
``peak_pressure(rec.to_unit("mmHg"))`` is in mmHg; forces are in N (the load converts the
pressure to N/cm² first), areas in cm², positions in cm in the layout's coordinates.
Readings flagged invalid are left out.

- :func:`total_load`: sum of pressure x element area (N).
- :func:`contact_area`: area of the elements whose value exceeds a threshold (cm²).
- :func:`peak_pressure`: the highest element value.
- :func:`peak_pressure_index`: mean of the highest-loaded k x k window of elements (3 x 3 by
  default, the convention of seating-clinic pressure mapping).
- :func:`centre_of_force`: force-weighted mean of the element centres (x, y in cm).
- :func:`coefficient_of_variation`: standard deviation / mean of the loaded elements.
- :func:`region_stats`: load, mean, peak and contact area per named region.
- :func:`raw_rise`: what a mat without a calibration can say of a frame (the live monitor's).
- :class:`LiveStats`: :func:`one_frame_stats` and the centre of force in grid cells of one
  frame after another, in one compiled call on a grid (a station's every frame).

Statistics other than the load also work on raw counts (``quantity="raw"``); the centre of
force is then the centre of the raw values.

Examples
--------
>>> import numpy as np
>>> from texsense import Layout, Recording
>>> from texsense.apps import stats
>>> lay = Layout.grid(2, 2, pitch_cm=2.0)                 # 4 elements of 4 cm²
>>> rec = Recording([[1.0, 0.0, 0.0, 1.0]], [0.0], lay)    # N/cm²
>>> stats.total_load(rec).tolist(), stats.centre_of_force(rec).tolist()
([8.0], [[2.0, 2.0]])
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense._core import GridStats
from texsense.data import units
from texsense.data.layout import Layout
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

__all__ = [
    "FrameStats",
    "centre_of_force",
    "centre_of_force_values",
    "coefficient_of_variation",
    "contact_area",
    "frame_stats",
    "highest_bound",
    "one_frame_stats",
    "peak_bounds",
    "peak_pressure",
    "peak_pressure_index",
    "raw_rise",
    "region_stats",
    "total_load",
]

_Array = npt.NDArray[np.float64]
_BLOCK = 1024  # frames per block in the windowed statistics (bounds memory)


def _values(rec: Recording, *, need_pressure: bool = False) -> _Array:
    """Frames as float64 with invalid readings as NaN; with ``need_pressure`` (the load),
    pressure converted to N/cm²; otherwise in the recording's unit."""
    if rec.quantity == "pressure" and need_pressure:
        f = units.factor(rec.unit, "N/cm2")
    elif need_pressure:
        raise ParameterError(
            f"this statistic needs pressure, but the recording holds {rec.quantity} in "
            f"{rec.unit}; calibrate it to pressure first"
        )
    else:
        f = 1.0
    v = rec.frames.astype(np.float64) * f
    v[~rec.valid] = np.nan
    return v


def _nan_if_empty(total: _Array, count: npt.NDArray[np.int64]) -> _Array:
    return np.where(count > 0, total, np.nan)


def total_load(rec: Recording) -> _Array:
    """Total force per frame in N: sum of pressure (N/cm²) x element area (cm²), eq. 2.1 of a
    pressure map. Frames without any valid reading give NaN."""
    v = _values(rec, need_pressure=True)
    return _load_of(v, rec.layout.area_cm2, np.isfinite(v))


def contact_area(rec: Recording, threshold: float = 0.0) -> _Array:
    """Area in cm² of the elements whose value is above ``threshold`` (in the recording's
    unit)."""
    v = _values(rec)
    with np.errstate(invalid="ignore"):
        loaded = v > threshold
    return (loaded * rec.layout.area_cm2).sum(axis=1)


def peak_pressure(rec: Recording) -> _Array:
    """Highest valid element value per frame, in the recording's unit; NaN if none is
    valid."""
    v = _values(rec)
    out = np.full(rec.n_frames, np.nan)
    ok = np.isfinite(v).any(axis=1)
    out[ok] = np.nanmax(v[ok], axis=1)
    return out


def centre_of_force(rec: Recording) -> _Array:
    """Centre of force (T, 2): x and y in cm, weights pressure x area; NaN when unloaded."""
    return centre_of_force_values(_values(rec), rec.layout)


def centre_of_force_values(values: npt.ArrayLike, layout: Layout) -> _Array:
    """:func:`centre_of_force` of plain frames (T, N) on ``layout`` (NaN readings count 0)."""
    v = np.asarray(values, dtype=np.float64)
    if not np.isfinite(v).all():
        v = np.nan_to_num(v, nan=0.0)
    w = np.maximum(v * layout.area_cm2, 0.0)  # (np.clip's lower end, without its wrapper)
    total = w.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        xy = (w @ layout.xy_cm) / total[:, None]
    xy[total <= 0] = np.nan
    return xy


def coefficient_of_variation(rec: Recording, threshold: float = 0.0) -> _Array:
    """Standard deviation / mean of the element values above ``threshold`` per frame; NaN
    with fewer than two loaded elements."""
    return _cov_of(_values(rec), threshold)


def _window_means_grid(maps: _Array, k: int) -> _Array:
    """Max over all k x k windows of the mean of the valid cells in the window, per map."""
    t, rows, cols = maps.shape
    kr, kc = min(k, rows), min(k, cols)
    finite = np.isfinite(maps)
    if finite.all():  # every window full: the count is kr x kc (as counted below)
        means = _window_sums(maps, kr, kc) / float(kr * kc)
    else:
        sums = _window_sums(np.where(finite, maps, 0.0), kr, kc)
        counts = _window_sums(finite.astype(np.float64), kr, kc)
        with np.errstate(invalid="ignore", divide="ignore"):
            means = np.where(counts > 0, sums / counts, -np.inf)
    best = means.reshape(t, -1).max(axis=1)
    return np.where(np.isfinite(best), best, np.nan)


def _window_sums(a: _Array, kr: int, kc: int) -> _Array:
    """The sum of every kr x kc window of maps (T, R, C) -> (T, R - kr + 1, C - kc + 1): kc
    columns added, then kr rows of those (kr + kc - 2 additions of shifted maps, no running
    sums whose differences would cancel)."""
    c = a.shape[2] - kc + 1
    across = a[:, :, :c].copy()
    for j in range(1, kc):
        across += a[:, :, j : j + c]
    r = a.shape[1] - kr + 1
    out = across[:, :r].copy()
    for i in range(1, kr):
        out += across[:, i : i + r]
    return out


def peak_pressure_index(rec: Recording, window: int = 3) -> _Array:
    """Peak pressure index: the highest mean over a ``window`` x ``window`` group of elements.

    On a grid the windows are all k x k blocks of cells (empty cells and invalid readings are
    left out of the mean; the window shrinks on grids smaller than k). On a points layout the
    group is the peak element and its k² - 1 nearest elements.
    """
    return _ppi_of(_values(rec), rec.layout, window)


def _ppi_of(v: _Array, lay: Layout, window: int) -> _Array:
    """:func:`peak_pressure_index` of frames with invalid readings NaN."""
    if window < 1:
        raise ParameterError(f"window must be >= 1, got {window}")
    out = np.empty(v.shape[0])
    if lay.shape is not None:
        for start in range(0, v.shape[0], _BLOCK):
            block = lay.to_grid(v[start : start + _BLOCK])
            out[start : start + _BLOCK] = _window_means_grid(block, window)
        return out
    k = min(window * window, lay.n_elements)
    d = np.linalg.norm(lay.xy_cm[:, None, :] - lay.xy_cm[None, :, :], axis=2)
    nearest = np.argsort(d, axis=1, kind="stable")[:, :k]
    for t in range(v.shape[0]):
        row = v[t]
        if not np.isfinite(row).any():
            out[t] = np.nan
            continue
        peak = int(np.nanargmax(row))
        out[t] = np.nanmean(row[nearest[peak]])
    return out


@dataclass(frozen=True)
class FrameStats:
    """Per-frame statistics of a recording (arrays of length T)."""

    load_N: _Array | None
    contact_area_cm2: _Array
    peak: _Array
    ppi: _Array
    cof_cm: _Array
    cov: _Array


def frame_stats(rec: Recording, threshold: float = 0.0, ppi_window: int = 3) -> FrameStats:
    """All frame statistics at once (``load_N`` is None unless the recording holds pressure):
    :func:`_block_stats` of its values, read once."""
    pressure = rec.quantity == "pressure"
    factor = units.factor(rec.unit, "N/cm2") if pressure else None
    got = _block_stats(_values(rec), rec.layout, threshold, ppi_window, load=factor, cov=True)
    return FrameStats(
        load_N=got.get("load_N"),
        contact_area_cm2=got["contact_area_cm2"],
        peak=got["peak"],
        ppi=got["ppi"],
        cof_cm=got["cof_cm"],
        cov=got["cov"],
    )


def one_frame_stats(
    pressure_ncm2: npt.ArrayLike, layout: Layout, threshold: float = 0.0, ppi_window: int = 3
) -> dict[str, Any]:
    """:func:`frame_stats` of one frame of pressure in N/cm² (NaN read as 0) without a
    :class:`~texsense.data.recording.Recording`: ``load_N``, ``contact_area_cm2``, ``peak``,
    ``ppi`` as floats and ``cof_cm`` (x, y; NaN when unloaded). The same computation
    (:func:`_block_stats`) on the frame's values stored as float32 first, as a recording
    stores them; a station computes it for every frame of hundreds of mats (without the
    coefficient of variation, which it does not show)."""
    v = np.asarray(pressure_ncm2, dtype=np.float64)
    if not np.isfinite(v).all():
        v = np.nan_to_num(v)
    v = v.astype(np.float32).astype(np.float64)[None, :]
    got = _block_stats(v, layout, threshold, ppi_window, load=1.0)
    return {
        "load_N": float(got["load_N"][0]),
        "contact_area_cm2": float(got["contact_area_cm2"][0]),
        "peak": float(got["peak"][0]),
        "ppi": float(got["ppi"][0]),
        "cof_cm": got["cof_cm"][0],
    }


def highest_bound(counted: np.ndarray, maps: np.ndarray) -> np.ndarray:
    """The highest value of a bound's map over the readings the peak counts (``counted``),
    along the last axis (one frame, or frames x elements): every element's true pressure
    between its lower and upper map puts the peak between the highest lower and the highest
    upper value. NaN where no counted reading has a bound. The one rule of the peak's band,
    live (:func:`peak_bounds`) and in the report (``texsense.apps.review``)."""
    m = np.asarray(maps, dtype=np.float64)
    top = np.where(counted & np.isfinite(m), m, -np.inf).max(axis=-1, initial=-np.inf)
    return np.where(np.isfinite(top), top, np.nan)


def peak_bounds(pressure: np.ndarray, bounds: tuple[np.ndarray, np.ndarray]) -> dict[str, Any]:
    """The bounds of a frame's peak (N/cm², rounded as the peak) by :func:`highest_bound`
    over the elements with a pressure, the lower one at least 0 as the map shows it
    (``no_negative``). None for a bound no counted element has.

    >>> lower, upper = np.array([0.1, 0.7, 5.0]), np.array([0.4, 1.3, 9.0])
    >>> peak_bounds(np.array([0.2, 1.0, np.nan]), (lower, upper))
    {'peak_lower_ncm2': 0.7, 'peak_upper_ncm2': 1.3}
    """
    counted = np.isfinite(pressure)
    lo, hi = (float(highest_bound(counted, m)) for m in bounds)
    lo = max(lo, 0.0) if lo == lo else lo
    return {
        f"peak_{name}_ncm2": round(v, 3) if v == v else None
        for name, v in (("lower", lo), ("upper", hi))
    }


class LiveStats:
    """:func:`one_frame_stats` of frames of pressure (N/cm², NaN read as 0) on one layout, with
    the centre of force in grid cells (row, column; weights: the pressure, not rounded) that
    the live dashboard draws: what a station computes for every frame of every mat.

    On a grid layout the compiled core computes them in one pass
    (``texsense._core.GridStats``): the same numbers up to the order of the additions (a few
    units in the last place). A points layout, or a frame with a value infinite as float32,
    takes :func:`one_frame_stats` (the centre in cells is then the layout's x, y in cm
    weighted by pressure, as :meth:`cof_cell` says).
    """

    def __init__(self, layout: Layout, threshold: float = 0.0, ppi_window: int = 3) -> None:
        self.layout, self.threshold, self.ppi_window = layout, float(threshold), int(ppi_window)
        self._grid = None
        if layout.shape is not None and layout.cells is not None and ppi_window >= 1:
            self._grid = GridStats(
                np.ascontiguousarray(layout.area_cm2, dtype=np.float64),
                np.ascontiguousarray(layout.xy_cm, dtype=np.float64),
                np.ascontiguousarray(layout.cells, dtype=np.int64),
                int(layout.shape[0]),
                int(layout.shape[1]),
                int(ppi_window),
            )
        self._cells_rc: tuple[_Array, _Array] | None = None

    def __call__(self, pressure_ncm2: npt.ArrayLike) -> tuple[dict[str, Any], _Array]:
        """(:func:`one_frame_stats` of the frame, its centre of force in cells)."""
        p = np.ascontiguousarray(pressure_ncm2, dtype=np.float64)
        got = self._grid.frame(p, self.threshold) if self._grid is not None else None
        if got is None:
            fs = one_frame_stats(p, self.layout, self.threshold, self.ppi_window)
            return fs, self.cof_cell(p)
        load, area, peak, ppi, x, y, row, col = got
        fs = {"load_N": load, "contact_area_cm2": area, "peak": peak, "ppi": ppi,
              "cof_cm": np.array([x, y])}  # fmt: skip
        return fs, np.array([row, col])

    def cof_cell(self, pressure: _Array) -> _Array:
        """Centre of force in grid cells (row, col), weighted by the pressure (NaN and below 0
        count 0), or in the elements' (x, y) cm for a points layout; NaN when unloaded."""
        w = np.maximum(pressure if np.isfinite(pressure).all() else np.nan_to_num(pressure), 0.0)
        total = w.sum()
        if total <= 0:
            return np.array([np.nan, np.nan])
        lay = self.layout
        if lay.cells is not None and lay.shape is not None:
            if self._cells_rc is None:  # the elements' rows and columns (made once)
                rows, cols = np.divmod(lay.cells, lay.shape[1])
                self._cells_rc = (rows.astype(np.float64), cols.astype(np.float64))
            rows, cols = self._cells_rc
            return np.array([w @ rows, w @ cols]) / total
        return np.asarray((w @ lay.xy_cm) / total)


def _block_stats(
    v: _Array,
    layout: Layout,
    threshold: float,
    ppi_window: int,
    *,
    load: float | None,
    cov: bool = False,
) -> dict[str, _Array]:
    """The frame statistics of frames ``v`` (T, N; NaN: an invalid reading, left out): what
    :func:`frame_stats` and :func:`one_frame_stats` both are. Frames with no NaN or infinity
    (every frame of a station) take the plain reductions, which give the NaN-aware ones'
    numbers to the bit on such frames. The load when ``load`` is the factor from the values'
    unit to N/cm² (eq. 2.1 of a pressure map), the coefficient of variation when ``cov``."""
    area = layout.area_cm2
    finite = np.isfinite(v)
    clean = bool(finite.all()) and v.shape[1] > 0
    out: dict[str, _Array] = {}
    if load is not None:
        p = v * load if load != 1.0 else v
        out["load_N"] = (p * area).sum(axis=1) if clean else _load_of(p, area, np.isfinite(p))
    with np.errstate(invalid="ignore"):
        out["contact_area_cm2"] = ((v > threshold) * area).sum(axis=1)
    if clean:
        out["peak"] = v.max(axis=1)
    else:
        out["peak"] = np.full(v.shape[0], np.nan)
        ok = finite.any(axis=1)
        out["peak"][ok] = np.nanmax(v[ok], axis=1)
    out["ppi"] = _ppi_of(v, layout, ppi_window)
    out["cof_cm"] = centre_of_force_values(v if clean else np.nan_to_num(v, nan=0.0), layout)
    if cov:
        out["cov"] = _cov_of(v, threshold)
    return out


def _load_of(v: _Array, area: _Array, finite: npt.NDArray[np.bool_]) -> _Array:
    """:func:`total_load` of frames in N/cm² with invalid readings NaN."""
    return _nan_if_empty(np.nansum(v * area, axis=1), np.sum(finite, axis=1))


def _cov_of(v: _Array, threshold: float) -> _Array:
    """:func:`coefficient_of_variation` of frames with invalid readings NaN."""
    with np.errstate(invalid="ignore"):
        loaded = np.where(v > threshold, v, np.nan)
    count = np.sum(np.isfinite(loaded), axis=1)
    out = np.full(v.shape[0], np.nan)
    ok = count >= 2
    if ok.any():
        out[ok] = np.nanstd(loaded[ok], axis=1) / np.nanmean(loaded[ok], axis=1)
    return out


def region_stats(
    rec: Recording,
    regions: dict[str, npt.ArrayLike] | None = None,
    threshold: float = 0.0,
) -> dict[str, dict[str, _Array]]:
    """Statistics per named region.

    Parameters
    ----------
    rec : Recording
        The recording.
    regions : mapping of str to element indices, optional
        Default: the layout's named regions.
    threshold : float
        Contact threshold.

    Returns
    -------
    dict
        region name -> {"load_N" (pressure only), "mean", "peak", "contact_area_cm2"}, each an
        array of length T. ``mean`` is the mean over the region's valid elements.
    """
    named: Mapping[str, npt.ArrayLike] = rec.layout.regions if regions is None else regions
    if not named:
        raise ParameterError("no regions: the layout has none and none were given")
    v = _values(rec)
    area = rec.layout.area_cm2
    out: dict[str, dict[str, _Array]] = {}
    for name, members in named.items():
        idx = np.asarray(members, dtype=np.int64)
        if idx.size == 0:
            raise ParameterError(f"region {name!r} has no elements")
        sub = v[:, idx]
        count = np.sum(np.isfinite(sub), axis=1)
        with np.errstate(invalid="ignore"):
            entry = {
                "mean": _nan_if_empty(np.nansum(sub, axis=1), count) / np.maximum(count, 1),
                "peak": np.where(
                    count > 0, np.nanmax(np.where(count[:, None] > 0, sub, 0), axis=1), np.nan
                ),
                "contact_area_cm2": ((sub > threshold) * area[idx]).sum(axis=1),
            }
        if rec.quantity == "pressure":
            entry["load_N"] = _nan_if_empty(np.nansum(sub * area[idx], axis=1), count)
        out[name] = entry
    return out


#: Without a calibration an element "responds" when it reads above its lowest reading so far
#: by more than this fraction of the mat's typical (median) lowest reading (unit-free). On the
#: virtual seat behind a serial line (`texsense simulate device`, 3.3-4.0 pF empty): 1 N/cm²
#: on every element -> 96 of 96 respond (threshold 0.0125 pF, highest rise 2.5 pF); the mat
#: emptied again -> 0 of 96 (highest rise 0.003 pF, what the spacer's hysteresis leaves).
RESPOND_FRACTION = 0.005


def raw_rise(raw: np.ndarray, floor: np.ndarray) -> dict[str, Any]:
    """What a mat without a calibration can honestly say of a frame, in its raw unit: each
    element's rise above its lowest reading so far (``floor``), the highest rise and how
    many elements respond (rise above :data:`RESPOND_FRACTION` of the median floor)."""
    rise = raw - floor
    finite = np.isfinite(rise)
    if not finite.any():
        return {"peak_rise": None, "responding": 0, "working": 0, "respond_above": None}
    typical = float(np.median(np.abs(floor[np.isfinite(floor)])))
    above = RESPOND_FRACTION * typical
    return {
        "peak_rise": round(float(np.max(rise[finite])), 4),
        "responding": int(np.count_nonzero(rise[finite] > above)),
        "working": int(np.count_nonzero(finite)),
        "respond_above": round(above, 4),
    }
