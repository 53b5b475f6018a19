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
    "no_negative",
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
        0.0, 0.003, 0.0069, 0.0107, 0.0143, 0.0176, 0.0206, 0.0233, 0.0255, 0.0273, 0.0282, 0.0285,
        0.0287, 0.0289, 0.0293, 0.0296, 0.0298, 0.0299, 0.03, 0.0318, 0.0357, 0.0398, 0.0442,
        0.0497, 0.0551, 0.06, 0.0634, 0.0688, 0.0747, 0.0804, 0.0863, 0.0925, 0.099, 0.106, 0.1138,
        0.122, 0.1305, 0.1396, 0.1492, 0.1591, 0.1699, 0.1817, 0.1941, 0.207, 0.2203, 0.2338,
        0.2482, 0.2631, 0.2737, 0.2873, 0.2929, 0.2995, 0.3121, 0.3292, 0.348, 0.3675, 0.388,
        0.4101, 0.4336, 0.4593, 0.4866, 0.5178, 0.5548, 0.5994, 0.6503, 0.7121, 0.7808, 0.8506,
        0.9018, 0.9424, 0.9846, 1.038, 1.0794, 1.1136, 1.1558, 1.1971, 1.2315, 1.2664, 1.304,
        1.3287, 1.3695, 1.4104, 1.4728, 1.5519, 1.584, 1.609, 1.636, 1.6719, 1.7076, 1.7479, 1.7929,
        1.8448, 1.8915, 1.9589, 2.0485, 2.1716, 2.3262, 2.6459, 3.1975, 3.8304, 124.4583,
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
            0.2953, 0.303, 0.323, 0.3481, 0.3785, 0.4136, 0.4564, 0.5025, 0.5584, 0.6274, 0.706,
            0.7843, 0.8596, 0.9075, 0.9442, 0.9847, 1.0347, 1.0752, 1.1029, 1.1387, 1.1797, 1.2082,
            1.242, 1.2705, 1.3031, 1.3236, 1.3556, 1.3901, 1.4302, 1.4943, 1.5603, 1.5838, 1.6048,
            1.6267, 1.6544, 1.6875, 1.7169, 1.7513, 1.7892, 1.8335, 1.8725, 1.9189, 1.9828, 2.0617,
            2.1668, 2.3078, 2.4746, 2.8998, 3.4079, 3.9904, 124.4583,
        ),
        (  # band 1
            0.2849, 0.2911, 0.2983, 0.3053, 0.3125, 0.3203, 0.3282, 0.3364, 0.3442, 0.3515, 0.358,
            0.3646, 0.3707, 0.3771, 0.3837, 0.3911, 0.3984, 0.4055, 0.4129, 0.4208, 0.428, 0.4349,
            0.4424, 0.4505, 0.4583, 0.466, 0.474, 0.4834, 0.493, 0.5026, 0.5145, 0.5273, 0.5425,
            0.5584, 0.5751, 0.5952, 0.6171, 0.6399, 0.665, 0.6962, 0.7363, 0.7788, 0.8227, 0.8716,
            0.9176, 0.9732, 1.0393, 1.1357, 1.2599, 1.4624, 3.9453,
        ),
        (  # band 2
            0.2522, 0.2604, 0.2691, 0.2768, 0.2845, 0.292, 0.2991, 0.3056, 0.3122, 0.3192, 0.3262,
            0.3351, 0.3439, 0.3521, 0.3607, 0.3693, 0.3779, 0.3865, 0.3937, 0.3998, 0.4067, 0.4139,
            0.4211, 0.427, 0.4339, 0.443, 0.4502, 0.4576, 0.4661, 0.4739, 0.4817, 0.4906, 0.4992,
            0.5074, 0.5164, 0.5242, 0.5348, 0.5455, 0.5601, 0.5727, 0.5844, 0.5963, 0.6192, 0.6515,
            0.692, 0.7455, 0.8003, 0.8596, 0.9404, 1.0859, 2.1967,
        ),
        (  # band 3
            0.2694, 0.2753, 0.2813, 0.2883, 0.2952, 0.3021, 0.3092, 0.3167, 0.324, 0.3317, 0.339,
            0.3468, 0.3549, 0.3632, 0.3752, 0.3876, 0.4007, 0.4167, 0.4328, 0.4507, 0.4682, 0.4825,
            0.4968, 0.5109, 0.5224, 0.5324, 0.5425, 0.5537, 0.563, 0.5726, 0.5799, 0.5865, 0.595,
            0.6032, 0.6123, 0.6194, 0.6284, 0.6366, 0.6433, 0.6497, 0.6558, 0.6641, 0.6733, 0.6812,
            0.6916, 0.7012, 0.7148, 0.7371, 0.801, 0.8963, 2.2085,
        ),
        (  # band 4
            0.4056, 0.4164, 0.4273, 0.4376, 0.4471, 0.4569, 0.4662, 0.4757, 0.4875, 0.4999, 0.5117,
            0.5245, 0.5376, 0.5498, 0.5661, 0.5818, 0.5944, 0.6054, 0.6143, 0.6223, 0.6296, 0.6368,
            0.6424, 0.6476, 0.6514, 0.6567, 0.6622, 0.668, 0.6744, 0.6794, 0.6836, 0.6873, 0.692,
            0.6963, 0.6998, 0.7028, 0.7047, 0.7059, 0.7082, 0.7103, 0.7127, 0.7195, 0.725, 0.7309,
            0.7452, 0.7511, 0.7602, 0.7772, 0.8259, 0.9553, 2.3531,
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


#: A compensated pressure down to this far below zero (N/cm², about 7.5 mmHg: the level under
#: which the in-use correction calls an element empty) is an unloaded element's estimate.
NEAR_ZERO_NCM2 = 0.1


def no_negative(
    values: np.ndarray, lower: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """What a pressure file gets: ``values`` with those at most :data:`NEAR_ZERO_NCM2` below
    zero written as 0 (an empty element: its conversion reads about -0.001 N/cm², which a
    file would otherwise mark invalid, so an empty mat read "100 % invalid" and its load not a
    number; further below zero stays, and is flagged invalid by the writer: a fault to see),
    and ``lower`` bounds never below zero (no pressure is)."""
    v = np.asarray(values)
    near = (v < 0) & (v >= -NEAR_ZERO_NCM2)
    if near.any():
        v = np.where(near, np.zeros((), v.dtype), v)
    lo = None if lower is None else np.maximum(lower, 0)
    return v, lo
