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
    corrected the mat's load (the drift it found), plus ``K_UNCHECKED · ln(1 + hours since a
    still load last agreed with the person's weight)`` (a correction nothing has checked for
    hours may have missed drift), before its first correction and without it
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

from texsense._core import frame_bounds as _frame_bounds
from texsense.exceptions import ParameterError

__all__ = [
    "BAND_EDGES",
    "BAND_SCORES",
    "K_IN_USE",
    "K_TIME",
    "K_UNCHECKED",
    "R_REPAIRED",
    "SCORES",
    "HeldOut",
    "band_of",
    "bounds",
    "conformal_quantiles",
    "drift_share",
    "frame_bounds",
    "multiplier",
]

#: Bands of the predicted pressure (N/cm²) the held-out residuals are split by; the last is open.
BAND_EDGES = (0.0, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0)
#: The drift a value in use may still carry, per share of load the in-use correction removed.
K_IN_USE = 0.5
#: The drift a value may carry without an in-use correction, per ln(1 + hours since calibration).
K_TIME = 0.1
#: The drift an in-use correction may have missed, per ln(1 + hours since a still load last
#: agreed with the person's weight): the same rate as without a correction.
K_UNCHECKED = K_TIME
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
        0.0, 0.0032, 0.0071, 0.0108, 0.0145, 0.0178, 0.021, 0.0236, 0.0258, 0.0275, 0.0283, 0.0285,
        0.0287, 0.0289, 0.0294, 0.0296, 0.0298, 0.03, 0.03, 0.0323, 0.0363, 0.0403, 0.0451, 0.0504,
        0.0561, 0.0609, 0.0646, 0.0707, 0.0766, 0.0823, 0.0886, 0.0952, 0.1019, 0.1094, 0.1175,
        0.1259, 0.1349, 0.1443, 0.1543, 0.1647, 0.176, 0.1881, 0.2003, 0.2135, 0.2271, 0.2409,
        0.2556, 0.2685, 0.2795, 0.2904, 0.2954, 0.3029, 0.3179, 0.3356, 0.3546, 0.3745, 0.3959,
        0.4183, 0.4419, 0.4675, 0.4955, 0.5274, 0.5661, 0.6121, 0.6658, 0.7296, 0.7983, 0.8654,
        0.9119, 0.9473, 0.9926, 1.0507, 1.0858, 1.1218, 1.1645, 1.2056, 1.2406, 1.275, 1.297,
        1.3289, 1.3678, 1.4134, 1.4945, 1.5647, 1.5907, 1.6161, 1.6447, 1.6825, 1.7169, 1.7587,
        1.806, 1.857, 1.9071, 1.9803, 2.0753, 2.2056, 2.3424, 2.7403, 3.3123, 3.9777, 149.3947,
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
            0.2963, 0.3069, 0.3286, 0.3555, 0.3881, 0.4251, 0.4693, 0.5176, 0.5779, 0.6483, 0.7271,
            0.8056, 0.8753, 0.9173, 0.9503, 0.9937, 1.049, 1.0815, 1.1111, 1.1481, 1.1895, 1.2185,
            1.2512, 1.2788, 1.2964, 1.323, 1.3559, 1.3899, 1.4446, 1.5191, 1.5693, 1.5908, 1.6122,
            1.6349, 1.6648, 1.6957, 1.7269, 1.7627, 1.8023, 1.8465, 1.885, 1.9374, 2.0055, 2.09,
            2.2015, 2.3272, 2.5717, 3.0032, 3.52, 4.3156, 149.3947,
        ),
        (  # band 1
            0.2885, 0.2949, 0.3015, 0.3081, 0.3149, 0.3222, 0.3296, 0.337, 0.3443, 0.3512, 0.3579,
            0.3646, 0.371, 0.3775, 0.3843, 0.3918, 0.3991, 0.406, 0.4135, 0.4215, 0.4285, 0.4352,
            0.4425, 0.4504, 0.4579, 0.4655, 0.4732, 0.4823, 0.4921, 0.5018, 0.5134, 0.5262, 0.541,
            0.5565, 0.5721, 0.5921, 0.6133, 0.6358, 0.6605, 0.6954, 0.738, 0.78, 0.8251, 0.8743,
            0.9207, 0.9754, 1.0433, 1.1401, 1.2666, 1.4632, 5.5641,
        ),
        (  # band 2
            0.2805, 0.2868, 0.2935, 0.3001, 0.3065, 0.3125, 0.3188, 0.3251, 0.3324, 0.3402, 0.3481,
            0.3554, 0.3634, 0.3707, 0.3788, 0.3867, 0.3934, 0.3993, 0.4058, 0.4125, 0.4199, 0.4257,
            0.4318, 0.4403, 0.448, 0.4548, 0.4628, 0.4707, 0.4781, 0.4861, 0.4946, 0.5029, 0.511,
            0.5189, 0.5272, 0.5382, 0.5497, 0.5639, 0.5755, 0.5871, 0.5997, 0.6219, 0.65, 0.6827,
            0.7337, 0.7801, 0.8393, 0.887, 0.9589, 1.0979, 2.7953,
        ),
        (  # band 3
            0.3147, 0.3224, 0.3312, 0.3401, 0.3479, 0.3558, 0.3651, 0.3761, 0.3875, 0.3993, 0.4133,
            0.4256, 0.439, 0.4515, 0.4639, 0.4763, 0.4882, 0.4999, 0.5109, 0.521, 0.5313, 0.5388,
            0.5488, 0.5578, 0.5665, 0.5747, 0.5808, 0.5876, 0.5958, 0.6038, 0.6125, 0.6187, 0.6268,
            0.6346, 0.6416, 0.6472, 0.6528, 0.6589, 0.6676, 0.6754, 0.6844, 0.6936, 0.7027, 0.715,
            0.7326, 0.7627, 0.807, 0.8572, 0.9434, 1.104, 4.3341,
        ),
        (  # band 4
            0.4614, 0.4749, 0.4868, 0.4959, 0.5046, 0.5131, 0.5227, 0.535, 0.5468, 0.5636, 0.5774,
            0.5869, 0.596, 0.6067, 0.6161, 0.626, 0.6346, 0.6414, 0.6468, 0.6507, 0.6557, 0.6612,
            0.6673, 0.6733, 0.6781, 0.6825, 0.6859, 0.691, 0.6954, 0.6991, 0.7023, 0.7042, 0.7057,
            0.7073, 0.7099, 0.711, 0.7175, 0.7227, 0.7289, 0.7404, 0.7492, 0.7529, 0.7619, 0.7886,
            0.8137, 0.8457, 0.8913, 0.9802, 1.1405, 1.3456, 1.8647,
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


_BAND_EDGES = np.asarray(BAND_EDGES, dtype=np.float64)


def _bands(magnitudes: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """:func:`band_of` of values' magnitudes with the edges as an array (a search never
    gives more than the last band: only the lower end is clipped)."""
    band = np.searchsorted(edges, magnitudes, side="right") - 1
    return np.maximum(band, 0, out=band)


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

    @functools.cached_property
    def _arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The edges and scales as arrays (made once: a station bounds every frame)."""
        return np.asarray(self.edges, dtype=np.float64), np.asarray(self.scale, dtype=np.float64)

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
        if not all(abs(x) <= 1e12 for x in (*edges, *scale)) or min(counts, default=0) < 0:
            raise ParameterError(
                "held-out residuals: edges and scale must be finite numbers within 1e12, "
                "counts >= 0"
            )
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


#: (level, context) -> (the context's score tables, the multiplier of every band)
_PER_BAND: dict[tuple[float, str], tuple[Any, Any, np.ndarray]] = {}


def _per_band(level: float, context: str) -> np.ndarray:
    """The multiplier of every band at ``level``, made once per level and score tables (the
    tables are looked up by identity: replacing a context's scores, as a test does, makes
    them anew; hashing them took longer than a station's bounds of a frame)."""
    scores, banded = SCORES.get(context), BAND_SCORES.get(context)
    hit = _PER_BAND.get((level, context))
    if hit is not None and hit[0] is scores and hit[1] is banded:
        return hit[2]
    out = np.array([multiplier(level, context, b) for b in range(len(BAND_EDGES))])
    out.setflags(write=False)
    _PER_BAND[(level, context)] = (scores, banded, out)
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


def drift_share(
    hours_since_calibration: float,
    in_use_correction: float | None,
    hours_unchecked: float = 0.0,
) -> float:
    """``d``: the relative drift a value may still carry (see the module documentation);
    ``hours_unchecked``: since the in-use correction was last checked against a still
    person's weight."""
    if in_use_correction is not None:
        age = float(np.log1p(max(float(hours_unchecked), 0.0)))
        return K_IN_USE * abs(float(in_use_correction)) + K_UNCHECKED * age
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
    a = np.abs(v)
    edges, scale = held_out._arrays
    band = _bands(a, edges)  # (band_of, the edges made an array once)
    sigma = scale[band] + a * np.asarray(drift, dtype=np.float64)
    if repaired is not None:
        sigma = sigma + R_REPAIRED * a * np.asarray(repaired, dtype=bool)
    if range_max is not None:
        sigma = sigma + np.maximum(v - range_max, 0.0)
    if multiplier_value is None:  # the band's multiplier (Mondrian)
        if held_out.edges != BAND_EDGES:
            band = _bands(a, _BAND_EDGES)
        m = _per_band(float(level), context)[band]
    else:
        m = np.asarray(float(multiplier_value))
    hw = m * sigma
    return v - hw, v + hw


def frame_bounds(
    values: np.ndarray,
    measured: np.ndarray,
    level: float,
    held_out: HeldOut,
    *,
    drift: float,
    range_max: float | None = None,
    context: str = "mat",
    multiplier_value: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`bounds` of one frame (N,) whose unmeasured values are repaired, in one compiled
    pass (``texsense._core.frame_bounds``: the same operations in the same order, so the same
    bits; tests/test_frame_compiled.py): what a station runs for every frame of every mat."""
    edges, scale = held_out._arrays
    mult = _per_band(float(level), context)
    m = None if multiplier_value is None else float(multiplier_value)
    return _frame_bounds(np.ascontiguousarray(values, np.float64),
                         np.ascontiguousarray(measured, bool), float(drift), edges, scale,
                         _BAND_EDGES, mult, m, R_REPAIRED, range_max)  # fmt: skip
