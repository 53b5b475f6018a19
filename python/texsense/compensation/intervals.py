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
  ``benchmarks/night_drift.py --calibrate``), taken per band of ``v`` (:data:`BAND_EDGES`:
  Mondrian conformal prediction, Vovk et al. 2005 §4.5): the scores of an empty element differ
  from those of a loaded one, and one pooled quantile covers the loaded ones at 99-100 %
  (docs/drift.md, Bounds). A band with too few calibration scores takes the pooled quantile.

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

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError

__all__ = [
    "BAND_EDGES",
    "BAND_SCORES",
    "K_IN_USE",
    "K_TIME",
    "R_REPAIRED",
    "SCORES",
    "HeldOut",
    "band_of",
    "bounds",
    "conformal_quantiles",
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
#: use and laboratory-only; ``bouc-wen-6mm``'s night of seed 100 is left out, so that its nights
#: judge the bounds on a law family the scores never saw: docs/drift.md "Bounds") and ``record``
#: (test-machine records of specimens 12 and 13 of textile-6mm, bouc-wen-6mm, iwan-6mm). Made by
#: ``benchmarks/night_drift.py --calibrate --laws textile-3mm iwan-6mm --cache DIR``; replaced
#: there, not by hand.
# fmt: off
SCORES: dict[str, tuple[float, ...]] = {
    "mat": (
        0.0, 0.0041, 0.008, 0.0116, 0.0151, 0.0181, 0.0212, 0.0239, 0.026, 0.0277, 0.0283, 0.0286,
        0.0287, 0.029, 0.0294, 0.0297, 0.0299, 0.03, 0.0301, 0.0328, 0.0367, 0.0407, 0.0456, 0.0504,
        0.0553, 0.0603, 0.0643, 0.07, 0.0759, 0.0813, 0.0878, 0.0949, 0.1015, 0.1085, 0.1163,
        0.1243, 0.1323, 0.1411, 0.1506, 0.1607, 0.1718, 0.1838, 0.1962, 0.2095, 0.2238, 0.2381,
        0.2535, 0.2683, 0.2782, 0.2844, 0.2981, 0.3026, 0.3038, 0.3055, 0.3088, 0.3128, 0.3229,
        0.3367, 0.3522, 0.3706, 0.3895, 0.4098, 0.4325, 0.4568, 0.4835, 0.5134, 0.55, 0.592, 0.6427,
        0.7061, 0.7758, 0.8513, 0.9254, 0.9945, 1.0583, 1.0931, 1.1365, 1.1927, 1.2536, 1.311,
        1.3892, 1.4827, 1.5611, 1.5883, 1.6135, 1.6415, 1.679, 1.7171, 1.7692, 1.8324, 1.8866,
        1.9638, 2.0538, 2.1262, 2.2043, 2.3232, 2.5654, 2.9778, 3.4517, 4.1482, 134.375,
    ),
    "record": (
        0.0, 0.0175, 0.0324, 0.0461, 0.0583, 0.0734, 0.087, 0.1029, 0.1184, 0.1367, 0.1566, 0.1767,
        0.1979, 0.2224, 0.2471, 0.2711, 0.2962, 0.3188, 0.3425, 0.3618, 0.385, 0.4081, 0.4353,
        0.4633, 0.4965, 0.5284, 0.5645, 0.6008, 0.633, 0.6659, 0.6957, 0.7288, 0.7633, 0.7914,
        0.8223, 0.8557, 0.888, 0.9194, 0.9477, 0.9776, 1.0085, 1.0404, 1.0696, 1.0987, 1.131,
        1.1597, 1.1843, 1.2117, 1.2378, 1.2672, 1.2982, 1.3283, 1.3582, 1.385, 1.4135, 1.4522,
        1.4895, 1.5272, 1.559, 1.5974, 1.6399, 1.6801, 1.7253, 1.7673, 1.8138, 1.8657, 1.9217,
        1.9715, 2.0223, 2.0821, 2.1431, 2.2133, 2.2852, 2.3584, 2.4538, 2.5566, 2.6585, 2.7805,
        2.9243, 3.0754, 3.2483, 3.4412, 3.6182, 3.8343, 4.0855, 4.3369, 4.6443, 4.9798, 5.2532,
        5.6887, 6.2169, 6.7695, 7.4839, 8.2763, 9.7432, 12.1191, 15.6214, 20.6995, 26.2611, 32.2894,
        107.4612,
    ),
}
# fmt: on


#: The same quantiles per band of the predicted value (:data:`BAND_EDGES`), at 50, 51, ..., 100 %
#: (``None``: fewer than 200 scores in the band, the pooled table serves: on the calibration
#: nights no value above 2 N/cm²). Made with :data:`SCORES`. Only for ``mat``: per band, the
#: records' tables under-covered a record of a model fitted another way (81 % at 95 %,
#: tests/test_night.py), so records keep the pooled table.
# fmt: off
BAND_SCORES: dict[str, tuple[tuple[float, ...] | None, ...]] = {
    "mat": (
        (  # band 0
            0.2928, 0.3013, 0.3033, 0.3043, 0.3066, 0.3092, 0.3141, 0.3268, 0.3454, 0.3713, 0.4013,
            0.4406, 0.4885, 0.5431, 0.6114, 0.6967, 0.7791, 0.8703, 0.9501, 1.0202, 1.0713, 1.1011,
            1.143, 1.1943, 1.2491, 1.3008, 1.366, 1.4439, 1.5219, 1.5709, 1.5924, 1.6139, 1.6372,
            1.6674, 1.6994, 1.7372, 1.7837, 1.8384, 1.8833, 1.9448, 2.0197, 2.0912, 2.1462, 2.2174,
            2.3207, 2.4955, 2.8264, 3.1927, 3.6183, 4.4294, 134.375,
        ),
        (  # band 1
            0.3077, 0.3141, 0.3208, 0.3276, 0.3348, 0.3417, 0.3484, 0.355, 0.3615, 0.3677, 0.3739,
            0.3799, 0.3864, 0.3932, 0.4, 0.4067, 0.4138, 0.421, 0.4276, 0.4341, 0.4408, 0.448,
            0.4555, 0.4625, 0.4698, 0.4777, 0.4871, 0.4966, 0.506, 0.5183, 0.5313, 0.5461, 0.5614,
            0.5781, 0.5973, 0.6179, 0.6389, 0.6647, 0.6974, 0.7374, 0.778, 0.8169, 0.8584, 0.8987,
            0.9462, 0.9962, 1.0644, 1.151, 1.2768, 1.4756, 10.5248,
        ),
        (  # band 2
            0.3054, 0.3115, 0.3176, 0.3238, 0.3311, 0.3385, 0.3456, 0.3527, 0.3601, 0.3671, 0.3737,
            0.3813, 0.3885, 0.3949, 0.4006, 0.407, 0.4136, 0.4205, 0.4261, 0.4325, 0.4404, 0.447,
            0.4533, 0.4606, 0.468, 0.4753, 0.4827, 0.4908, 0.4986, 0.5062, 0.5146, 0.522, 0.5305,
            0.5406, 0.5503, 0.5619, 0.5724, 0.5834, 0.5933, 0.6078, 0.6276, 0.6503, 0.6776, 0.7198,
            0.7549, 0.7951, 0.8423, 0.8872, 0.9705, 1.1063, 6.471,
        ),
        (  # band 3
            0.3289, 0.3377, 0.3465, 0.3556, 0.3671, 0.3797, 0.3915, 0.4023, 0.4159, 0.4294, 0.4462,
            0.4608, 0.4739, 0.4858, 0.4979, 0.5082, 0.5184, 0.5275, 0.5348, 0.5458, 0.555, 0.5636,
            0.5724, 0.5794, 0.5853, 0.5938, 0.6018, 0.61, 0.6171, 0.624, 0.6318, 0.639, 0.6448,
            0.6506, 0.6569, 0.6654, 0.6742, 0.6827, 0.6926, 0.7018, 0.7145, 0.734, 0.7701, 0.8098,
            0.8469, 0.9132, 0.9774, 1.0497, 1.1552, 1.346, 10.6828,
        ),
        (  # band 4
            0.3831, 0.4071, 0.4258, 0.4458, 0.4642, 0.4771, 0.4916, 0.5051, 0.5163, 0.531, 0.5452,
            0.5578, 0.5719, 0.5872, 0.5996, 0.6119, 0.6215, 0.6312, 0.638, 0.6444, 0.6492, 0.6536,
            0.6594, 0.6654, 0.672, 0.6775, 0.6825, 0.6859, 0.6911, 0.6957, 0.6994, 0.7027, 0.7045,
            0.7058, 0.708, 0.7102, 0.7122, 0.719, 0.7248, 0.7299, 0.7429, 0.7508, 0.7574, 0.7691,
            0.9208, 0.9853, 1.0186, 1.1396, 1.2534, 1.4932, 10.5797,
        ),
        None,  # band 5: too few scores
        None,  # band 6: too few scores
    ),
}
# fmt: on


def band_of(values: npt.ArrayLike, edges: tuple[float, ...] = BAND_EDGES) -> np.ndarray:
    """The band (index into ``edges``) of every ``|value|``; the last band is open."""
    v = np.abs(np.asarray(values, dtype=np.float64))
    return np.clip(np.searchsorted(edges, v, side="right") - 1, 0, len(edges) - 1)


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
        return np.asarray(self.scale, dtype=np.float64)[band_of(values, self.edges)]

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


def multiplier(level: float, context: str = "mat", band: int | None = None) -> float:
    """The conformal multiplier of the score at ``level`` (e.g. 0.95) for ``context``: of the
    values in ``band`` (:data:`BAND_SCORES`) when it was calibrated, else pooled."""
    if not 0.5 <= level < 1.0:
        raise ParameterError(f"the interval level must lie in [0.5, 1), got {level}")
    if context not in SCORES or not SCORES[context]:
        raise ParameterError(f"no calibrated scores for {context!r} (benchmarks/night_drift.py)")
    per_band = BAND_SCORES.get(context, ())
    if band is not None and band < len(per_band) and per_band[band] is not None:
        qb = np.asarray(per_band[band], dtype=np.float64)  # at 50, 51, ..., 100 %
        return float(np.interp(100.0 * level, 50.0 + np.arange(qb.size, dtype=np.float64), qb))
    q = np.asarray(SCORES[context], dtype=np.float64)
    return float(np.interp(100.0 * level, np.arange(q.size, dtype=np.float64), q))


@functools.lru_cache(maxsize=64)
def _per_band(level: float, context: str, tables: Any) -> np.ndarray:
    """The multiplier of every band at ``level`` (made once per ``tables``, the context's
    scores, which are part of the key: a station bounds every frame)."""
    out = np.array([multiplier(level, context, b) for b in range(len(BAND_EDGES))])
    out.setflags(write=False)
    return out


def conformal_quantiles(scores: npt.ArrayLike, levels: range) -> tuple[float, ...]:
    """The split-conformal quantile of ``scores`` at every level (%): the ⌈(n + 1) p⌉-th
    smallest score (Lei et al. 2018), so that a new exchangeable score lies at or below it
    with probability at least p; what :data:`SCORES` and :data:`BAND_SCORES` hold."""
    s = np.sort(np.asarray(scores, dtype=np.float64).ravel())
    if s.size == 0:
        raise ParameterError("no scores to take quantiles of")
    n = s.size
    return tuple(
        round(float(s[min(n - 1, int(np.ceil((n + 1) * p / 100)) - 1)]), 4) if p else 0.0
        for p in levels
    )


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
    if multiplier_value is None:  # the band's multiplier (Mondrian)
        tables = (SCORES.get(context), BAND_SCORES.get(context))
        m = _per_band(float(level), context, tables)[band_of(v)]
    else:
        m = np.asarray(float(multiplier_value))
    hw = m * sigma
    return v - hw, v + hw
