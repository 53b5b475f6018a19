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
        0.0, 0.0038, 0.0075, 0.0109, 0.0144, 0.0175, 0.0205, 0.0232, 0.0254, 0.0272, 0.0282, 0.0285,
        0.0286, 0.0289, 0.0293, 0.0296, 0.0298, 0.03, 0.03, 0.0314, 0.0352, 0.0391, 0.0429, 0.0483,
        0.0527, 0.0579, 0.0621, 0.0666, 0.0723, 0.0777, 0.0831, 0.0896, 0.0961, 0.1021, 0.109,
        0.1165, 0.124, 0.1321, 0.1412, 0.151, 0.1613, 0.1724, 0.1849, 0.1978, 0.2119, 0.2265,
        0.2407, 0.2561, 0.2683, 0.2736, 0.2855, 0.2912, 0.2935, 0.2952, 0.2974, 0.3007, 0.3094,
        0.3218, 0.337, 0.3542, 0.3727, 0.3922, 0.4134, 0.4359, 0.4617, 0.4884, 0.5189, 0.5564,
        0.6027, 0.655, 0.719, 0.7851, 0.8542, 0.9171, 0.983, 1.0491, 1.0882, 1.1279, 1.18, 1.2377,
        1.3078, 1.3929, 1.4911, 1.5657, 1.5919, 1.6177, 1.6481, 1.6874, 1.7225, 1.766, 1.8165,
        1.8687, 1.9273, 2.0113, 2.1207, 2.2751, 2.4374, 2.868, 3.3977, 4.0382, 116.8569,
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
            0.2816, 0.2907, 0.293, 0.2943, 0.296, 0.2982, 0.3024, 0.3133, 0.3304, 0.3527, 0.3806,
            0.413, 0.4555, 0.501, 0.5575, 0.6311, 0.7124, 0.7879, 0.8638, 0.9294, 0.9967, 1.0599,
            1.09, 1.1257, 1.1715, 1.2215, 1.2826, 1.3539, 1.4344, 1.5183, 1.5702, 1.592, 1.6138,
            1.6377, 1.6691, 1.6993, 1.7327, 1.7701, 1.8126, 1.8578, 1.9009, 1.9623, 2.0404, 2.1379,
            2.2701, 2.3767, 2.7047, 3.1022, 3.5753, 4.3234, 116.8569,
        ),
        (  # band 1
            0.2924, 0.299, 0.3055, 0.3121, 0.3193, 0.3267, 0.3341, 0.3413, 0.3484, 0.3551, 0.3617,
            0.368, 0.3743, 0.3804, 0.3871, 0.3946, 0.4018, 0.4087, 0.4163, 0.4235, 0.4303, 0.4369,
            0.4444, 0.4524, 0.4596, 0.4671, 0.475, 0.4843, 0.4937, 0.5033, 0.5153, 0.5279, 0.5426,
            0.5584, 0.5744, 0.5942, 0.6155, 0.638, 0.6642, 0.6983, 0.7408, 0.7824, 0.8267, 0.8757,
            0.922, 0.9772, 1.0442, 1.1399, 1.2657, 1.4646, 10.3224,
        ),
        (  # band 2
            0.2834, 0.2907, 0.2976, 0.3038, 0.3095, 0.3157, 0.3223, 0.3287, 0.3364, 0.3448, 0.3526,
            0.3603, 0.3681, 0.376, 0.3844, 0.3916, 0.3979, 0.404, 0.4109, 0.4179, 0.424, 0.4297,
            0.437, 0.4449, 0.4516, 0.4589, 0.4668, 0.4741, 0.4814, 0.4897, 0.4974, 0.5051, 0.5131,
            0.5207, 0.5292, 0.5403, 0.5524, 0.5667, 0.5777, 0.5885, 0.6026, 0.6254, 0.6561, 0.6928,
            0.7426, 0.7888, 0.8443, 0.8903, 0.9598, 1.1007, 5.4858,
        ),
        (  # band 3
            0.3242, 0.3324, 0.3406, 0.3483, 0.3567, 0.3669, 0.3794, 0.3912, 0.4017, 0.4139, 0.4262,
            0.4396, 0.4523, 0.4662, 0.4782, 0.4887, 0.5014, 0.5128, 0.5226, 0.5319, 0.5416, 0.5531,
            0.5619, 0.5707, 0.5782, 0.5839, 0.5921, 0.6005, 0.6087, 0.6164, 0.6233, 0.6316, 0.6389,
            0.6445, 0.6502, 0.6558, 0.6626, 0.6717, 0.6776, 0.6881, 0.6963, 0.7072, 0.722, 0.7427,
            0.7783, 0.8192, 0.8677, 0.929, 1.0321, 1.1929, 8.1543,
        ),
        (  # band 4
            0.4576, 0.4724, 0.4845, 0.4963, 0.5083, 0.5218, 0.5342, 0.5457, 0.5587, 0.5765, 0.5931,
            0.6056, 0.6141, 0.6208, 0.6275, 0.6347, 0.6411, 0.646, 0.6499, 0.6544, 0.6597, 0.6645,
            0.6698, 0.6759, 0.6804, 0.6841, 0.6878, 0.6924, 0.6967, 0.7001, 0.7029, 0.7047, 0.7059,
            0.708, 0.7101, 0.7117, 0.718, 0.7231, 0.7289, 0.7412, 0.7504, 0.755, 0.762, 0.7946,
            0.8247, 0.8787, 0.9441, 1.0592, 1.1501, 1.3753, 7.5456,
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
    bits; tests/test_intervals_frame.py): what a station runs for every frame of every mat."""
    edges, scale = held_out._arrays
    mult = _per_band(float(level), context)
    m = None if multiplier_value is None else float(multiplier_value)
    return _frame_bounds(np.ascontiguousarray(values, np.float64),
                         np.ascontiguousarray(measured, bool), float(drift), edges, scale,
                         _BAND_EDGES, mult, m, R_REPAIRED, range_max)  # fmt: skip
