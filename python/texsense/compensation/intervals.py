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
  ``benchmarks/night_drift.py --calibrate``).

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
#: per context: ``mat`` (virtual 8-h nights of seed 100 of ``textile-3mm`` and ``iwan-6mm``, in
#: use and laboratory-only; ``bouc-wen-6mm``'s night of seed 100 was not simulated in time, so
#: its nights are judged with a multiplier taken from the other two laws) and ``record``
#: (test-machine records of specimens 12 and 13 of textile-6mm, bouc-wen-6mm, iwan-6mm). Made by
#: ``benchmarks/night_drift.py --calibrate --cache DIR``; replaced there, not by hand.
# fmt: off
SCORES: dict[str, tuple[float, ...]] = {
    "mat": (
        0.0, 0.0042, 0.0083, 0.0123, 0.0158, 0.0188, 0.0217, 0.0241, 0.0261, 0.0277, 0.0283,
        0.0285, 0.0287, 0.029, 0.0294, 0.0297, 0.0299, 0.03, 0.0301, 0.0323, 0.0358, 0.0393,
        0.0425, 0.0471, 0.051, 0.0553, 0.0599, 0.0634, 0.068, 0.0735, 0.0792, 0.0854,
        0.0925, 0.0991, 0.106, 0.1135, 0.1221, 0.1308, 0.1405, 0.1506, 0.1623, 0.1749,
        0.1883, 0.2026, 0.2175, 0.232, 0.2469, 0.2622, 0.2752, 0.2793, 0.2871, 0.2978,
        0.3014, 0.3027, 0.3041, 0.3068, 0.3101, 0.3155, 0.3238, 0.3355, 0.3488, 0.3643,
        0.3812, 0.3993, 0.4189, 0.4398, 0.4627, 0.4875, 0.5159, 0.55, 0.5893, 0.6368,
        0.6946, 0.7604, 0.8305, 0.904, 0.9747, 1.0438, 1.0855, 1.1268, 1.1868, 1.2572,
        1.3482, 1.452, 1.553, 1.5861, 1.612, 1.6418, 1.6835, 1.725, 1.7831, 1.852, 1.9191,
        2.0292, 2.1882, 2.3479, 2.7182, 3.1777, 3.7, 4.9502, 78.8003,
    ),
    "record": (
        0.0, 0.0175, 0.0324, 0.0461, 0.0583, 0.0734, 0.087, 0.1029, 0.1184, 0.1367, 0.1566,
        0.1767, 0.1979, 0.2224, 0.2471, 0.2711, 0.2962, 0.3188, 0.3425, 0.3618, 0.385,
        0.4081, 0.4353, 0.4633, 0.4965, 0.5284, 0.5645, 0.6008, 0.633, 0.6659, 0.6957,
        0.7288, 0.7633, 0.7914, 0.8223, 0.8557, 0.888, 0.9194, 0.9477, 0.9776, 1.0085,
        1.0404, 1.0696, 1.0987, 1.131, 1.1597, 1.1843, 1.2117, 1.2378, 1.2672, 1.2982,
        1.3283, 1.3582, 1.385, 1.4135, 1.4522, 1.4895, 1.5272, 1.559, 1.5974, 1.6399,
        1.6801, 1.7253, 1.7673, 1.8138, 1.8657, 1.9217, 1.9715, 2.0223, 2.0821, 2.1431,
        2.2133, 2.2852, 2.3584, 2.4538, 2.5566, 2.6585, 2.7805, 2.9243, 3.0754, 3.2483,
        3.4412, 3.6182, 3.8343, 4.0855, 4.3369, 4.6443, 4.9798, 5.2532, 5.6887, 6.2169,
        6.7695, 7.4839, 8.2763, 9.7432, 12.1191, 15.6214, 20.6995, 26.2611, 32.2894,
        107.4612,
    ),
}
# fmt: on


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
        for lack in np.flatnonzero(~np.isfinite(scale)):  # the nearest band with enough
            scale[lack] = scale[known[np.argmin(np.abs(known - lack))]]
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
        raise ParameterError(f"no calibrated scores for {context!r} (benchmarks/night_drift.py)")
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
