"""Every value with a bound (issue 37, docs/drift.md "Bounds").

A pressure texsense gives is a prediction; how far it can be trusted depends on what produced
it. The bound is split conformal prediction with a normalised score (Vovk et al. 2005; Lei et
al. 2018): no distributional assumption, only that the data it is judged on are exchangeable
with the data its multiplier was taken from.

- **The scale** of the error of a value ``v``: ``σ = a(v) + |v| (d + R·repaired) + excess``,
  - ``a(v)``: the median absolute error of the calibration's *held-out* residuals in the
    pressure band of ``v`` (:class:`HeldOut`: a record the hysteresis model was not fitted on
    — for a spacer preset the first hour of its validation cycles, for a mat calibrated with
    held steps those steps; thesis §4.5 reports errors per band the same way);
  - ``d``: the drift the value may still carry — with the in-use correction
    (:mod:`texsense.compensation.inuse`) ``K_IN_USE`` times the share by which it has
    corrected the mat's load (the drift it found), before its first correction and without it
    ``K_TIME · ln(1 + hours since calibration)``;
  - ``R``: a repaired element (its value is its neighbours', eq. 6.14) is uncertain by
    ``R_REPAIRED`` of its value;
  - ``excess``: a reading beyond the calibration's range (its input clamped) is uncertain by
    at least how far it lies beyond.
- **The multiplier** at level ``1 - α`` is the conformal quantile of the score ``|y - v| / σ``
  over calibration data that nothing here was fitted on (virtual nights and test-machine records
  of other seeds than those the benchmarks judge; :data:`SCORES`, made by
  ``benchmarks/night_intervals.py --calibrate``).

The half-width is ``m(1 - α) σ``; the bound is ``[v - hw, v + hw]``.

Examples
--------
>>> import numpy as np
>>> h = HeldOut.from_residuals(np.array([0.1, 0.5, 1.0, 2.0] * 50), np.full(200, 0.02))
>>> lo, hi = bounds(np.array([0.5, 2.0]), 0.95, h, drift=0.0)
>>> bool(np.all(lo < [0.5, 2.0])) and bool(np.all(hi > [0.5, 2.0]))
True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError

__all__ = [
    "BAND_EDGES",
    "K_IN_USE",
    "K_TIME",
    "R_REPAIRED",
    "SCORES",
    "HeldOut",
    "bounds",
    "drift_share",
    "multiplier",
]

#: Bands of the predicted pressure (N/cm²) the held-out residuals are split by; the last is open.
BAND_EDGES = (0.0, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0)
#: The drift a value in use may still carry, per share of load the in-use correction removed.
K_IN_USE = 0.5
#: The drift a value may carry without an in-use correction, per ln(1 + hours since calibration).
K_TIME = 0.1
#: The relative uncertainty of a repaired element.
R_REPAIRED = 0.3
#: Quantiles (at 0, 1, ..., 100 %) of the normalised score ``|y - v| / σ`` on calibration data,
#: per context: ``mat`` (virtual nights, seeds 100 and 101 of every spacer law, in use and
#: laboratory-only) and ``record`` (test-machine records of specimens 12 and 13). Made by
#: ``benchmarks/night_intervals.py --calibrate``; replaced there, not by hand.
SCORES: dict[str, tuple[float, ...]] = {}


@dataclass(frozen=True)
class HeldOut:
    """The calibration's held-out residuals, summarised by band of the predicted value: the
    median absolute error and the count per band (bands with too few residuals take their
    neighbour's)."""

    edges: tuple[float, ...]
    scale: tuple[float, ...]
    counts: tuple[int, ...]
    source: str = ""

    @classmethod
    def from_residuals(
        cls,
        predicted: npt.ArrayLike,
        true: npt.ArrayLike,
        edges: tuple[float, ...] = BAND_EDGES,
        source: str = "",
        min_count: int = 20,
    ) -> HeldOut:
        """From predictions and the true values of a record the model was not fitted on."""
        v = np.asarray(predicted, dtype=np.float64).ravel()
        y = np.asarray(true, dtype=np.float64).ravel()
        if v.shape != y.shape:
            raise ParameterError("predicted and true values differ in length")
        ok = np.isfinite(v) & np.isfinite(y)
        v, r = v[ok], np.abs(v[ok] - y[ok])
        if r.size < min_count:
            raise ParameterError(f"{r.size} held-out residuals: too few for a bound")
        band = np.clip(np.searchsorted(edges, v, side="right") - 1, 0, len(edges) - 1)
        scale = np.full(len(edges), np.nan)
        counts = np.bincount(band, minlength=len(edges))
        for b in range(len(edges)):
            if counts[b] >= min_count:
                scale[b] = float(np.median(r[band == b]))
        known = np.flatnonzero(np.isfinite(scale))
        for b in np.flatnonzero(~np.isfinite(scale)):  # the nearest band with enough
            scale[b] = scale[known[np.argmin(np.abs(known - b))]]
        return cls(tuple(float(e) for e in edges), tuple(scale.tolist()),
                   tuple(int(c) for c in counts), source)  # fmt: skip

    def scale_of(self, values: npt.ArrayLike) -> np.ndarray:
        """``a(v)``: the band scale of every value."""
        v = np.asarray(values, dtype=np.float64)
        band = np.clip(np.searchsorted(self.edges, np.abs(v), side="right") - 1, 0,
                       len(self.edges) - 1)  # fmt: skip
        return np.asarray(self.scale, dtype=np.float64)[band]

    def to_dict(self) -> dict[str, Any]:
        """JSON-able."""
        return {"edges": list(self.edges), "scale": list(self.scale),
                "counts": list(self.counts), "source": self.source}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> HeldOut:
        """Inverse of :meth:`to_dict` (raises :class:`ParameterError` on a bad field)."""
        try:
            edges = tuple(float(e) for e in d["edges"])
            scale = tuple(float(s) for s in d["scale"])
            counts = tuple(int(c) for c in d["counts"])
        except (KeyError, TypeError, ValueError) as e:
            raise ParameterError(f"held-out residuals: {e}") from None
        if not (len(edges) == len(scale) == len(counts)) or not all(s >= 0 for s in scale):
            raise ParameterError("held-out residuals: edges, scale and counts must match, >= 0")
        return cls(edges, scale, counts, str(d.get("source", "")))


def multiplier(level: float, context: str = "mat") -> float:
    """The conformal multiplier of the score at ``level`` (e.g. 0.95) for ``context``."""
    if not 0.5 <= level < 1.0:
        raise ParameterError(f"the interval level must lie in [0.5, 1), got {level}")
    if context not in SCORES or not SCORES[context]:
        raise ParameterError(
            f"no calibrated scores for {context!r} (benchmarks/night_intervals.py)"
        )
    q = np.asarray(SCORES[context], dtype=np.float64)
    return float(np.interp(100.0 * level, np.arange(q.size, dtype=np.float64), q))


def drift_share(hours_since_calibration: float, in_use_correction: float | None) -> float:
    """``d``: the relative drift a value may still carry (see the module documentation)."""
    if in_use_correction is not None:
        return K_IN_USE * abs(float(in_use_correction))
    return K_TIME * float(np.log1p(max(float(hours_since_calibration), 0.0)))


def bounds(
    values: npt.ArrayLike,
    level: float,
    held_out: HeldOut,
    *,
    drift: float | npt.ArrayLike = 0.0,
    repaired: npt.ArrayLike | None = None,
    range_max: float | None = None,
    context: str = "mat",
    multiplier_value: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of ``values`` at ``level`` (see the module documentation);
    ``drift`` is ``d`` (:func:`drift_share`), ``repaired`` marks repaired values,
    ``range_max`` the largest pressure of the calibration's range."""
    v = np.asarray(values, dtype=np.float64)
    sigma = held_out.scale_of(v) + np.abs(v) * np.asarray(drift, dtype=np.float64)
    if repaired is not None:
        sigma = sigma + R_REPAIRED * np.abs(v) * np.asarray(repaired, dtype=bool)
    if range_max is not None:
        sigma = sigma + np.clip(v - range_max, 0.0, None)
    m = multiplier(level, context) if multiplier_value is None else float(multiplier_value)
    hw = m * sigma
    return v - hw, v + hw
