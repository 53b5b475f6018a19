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
#: use and laboratory-only; ``bouc-wen-6mm``'s night of seed 100 was not simulated in time, so
#: its nights are judged with a multiplier taken from the other two laws) and ``record``
#: (test-machine records of specimens 12 and 13 of textile-6mm, bouc-wen-6mm, iwan-6mm). Made by
#: ``benchmarks/night_drift.py --calibrate --laws textile-3mm iwan-6mm --cache DIR``; replaced
#: there, not by hand.
# fmt: off
SCORES: dict[str, tuple[float, ...]] = {
    "mat": (
        0.0, 0.0042, 0.0082, 0.012, 0.0156, 0.0187, 0.0218, 0.0244, 0.0265, 0.0279, 0.0284,
        0.0286, 0.0288, 0.0291, 0.0295, 0.0297, 0.0299, 0.03, 0.0302, 0.034, 0.0382, 0.0423,
        0.048, 0.0528, 0.0581, 0.0624, 0.0675, 0.0738, 0.0796, 0.0856, 0.0927, 0.0995, 0.1067,
        0.1143, 0.1225, 0.1307, 0.1398, 0.1493, 0.1595, 0.1703, 0.1821, 0.194, 0.2063, 0.2198,
        0.2329, 0.2468, 0.2608, 0.2748, 0.28, 0.2895, 0.3003, 0.3031, 0.3042, 0.3067, 0.3095,
        0.3152, 0.3262, 0.3401, 0.3558, 0.3738, 0.3924, 0.4124, 0.4344, 0.4581, 0.4849, 0.5147,
        0.5516, 0.5938, 0.6436, 0.7069, 0.777, 0.8529, 0.9272, 0.9953, 1.0592, 1.0934, 1.137,
        1.1931, 1.254, 1.3113, 1.3893, 1.4828, 1.5612, 1.5883, 1.6135, 1.6415, 1.679, 1.7171,
        1.7692, 1.8324, 1.8866, 1.9638, 2.0538, 2.1262, 2.2044, 2.3232, 2.5654, 2.9778, 3.4517,
        4.1482, 134.375,
    ),
    "record": (
        0.0, 0.0175, 0.0324, 0.0461, 0.0583, 0.0734, 0.087, 0.1029, 0.1184, 0.1367, 0.1566,
        0.1767, 0.1979, 0.2224, 0.2471, 0.2711, 0.2962, 0.3188, 0.3425, 0.3618, 0.385, 0.4081,
        0.4353, 0.4633, 0.4965, 0.5284, 0.5645, 0.6008, 0.633, 0.6659, 0.6957, 0.7288, 0.7633,
        0.7914, 0.8223, 0.8557, 0.888, 0.9194, 0.9477, 0.9776, 1.0085, 1.0404, 1.0696, 1.0987,
        1.131, 1.1597, 1.1843, 1.2117, 1.2378, 1.2672, 1.2982, 1.3283, 1.3582, 1.385, 1.4135,
        1.4522, 1.4895, 1.5272, 1.559, 1.5974, 1.6399, 1.6801, 1.7253, 1.7673, 1.8138, 1.8657,
        1.9217, 1.9715, 2.0223, 2.0821, 2.1431, 2.2133, 2.2852, 2.3584, 2.4538, 2.5566, 2.6585,
        2.7805, 2.9243, 3.0754, 3.2483, 3.4412, 3.6182, 3.8343, 4.0855, 4.3369, 4.6443, 4.9798,
        5.2532, 5.6887, 6.2169, 6.7695, 7.4839, 8.2763, 9.7432, 12.1191, 15.6214, 20.6995,
        26.2611, 32.2894, 107.4612,
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
            0.2981, 0.3024, 0.3035, 0.3047, 0.3076, 0.3098, 0.3169, 0.3306, 0.3496, 0.3762,
            0.4063, 0.4446, 0.4922, 0.5483, 0.6174, 0.7011, 0.7827, 0.8741, 0.9535, 1.023,
            1.0723, 1.1023, 1.1445, 1.1958, 1.2506, 1.3019, 1.3675, 1.4458, 1.5235, 1.5714,
            1.5928, 1.6143, 1.6377, 1.668, 1.6999, 1.7378, 1.7844, 1.839, 1.8838, 1.9455,
            2.0203, 2.0917, 2.1466, 2.218, 2.3214, 2.4971, 2.8277, 3.1939, 3.6191, 4.4308,
            134.375,
        ),
        (  # band 1
            0.3087, 0.3148, 0.321, 0.3274, 0.3343, 0.3411, 0.3476, 0.3542, 0.3604, 0.3667,
            0.3729, 0.379, 0.3853, 0.3921, 0.3988, 0.4056, 0.4124, 0.4195, 0.4261, 0.4326,
            0.4392, 0.4466, 0.4542, 0.4612, 0.4686, 0.4765, 0.4861, 0.4957, 0.5053, 0.5177,
            0.5307, 0.5456, 0.5609, 0.5774, 0.5966, 0.6168, 0.6382, 0.6636, 0.6971, 0.7378,
            0.7781, 0.8169, 0.8577, 0.8985, 0.9463, 0.9958, 1.067, 1.1527, 1.2763, 1.4748,
            11.3394,
        ),
        (  # band 2
            0.3161, 0.322, 0.3287, 0.3355, 0.3421, 0.3486, 0.3553, 0.3622, 0.3688, 0.3754,
            0.3826, 0.3896, 0.3952, 0.4003, 0.4059, 0.412, 0.4182, 0.4238, 0.4295, 0.4363,
            0.4429, 0.4488, 0.4549, 0.4618, 0.469, 0.4756, 0.4826, 0.4901, 0.4973, 0.5046,
            0.5119, 0.5192, 0.5265, 0.5358, 0.5451, 0.5568, 0.568, 0.5784, 0.5884, 0.6008,
            0.6169, 0.6382, 0.6635, 0.6985, 0.7445, 0.7887, 0.8405, 0.8842, 0.9692, 1.1107,
            6.471,
        ),
        (  # band 3
            0.345, 0.3526, 0.3622, 0.3727, 0.3831, 0.3948, 0.4061, 0.42, 0.4341, 0.4476, 0.4587,
            0.4685, 0.4778, 0.4884, 0.4995, 0.5093, 0.5187, 0.5281, 0.5355, 0.5478, 0.5575,
            0.5662, 0.5747, 0.5808, 0.5874, 0.5955, 0.6036, 0.612, 0.6182, 0.6253, 0.6324,
            0.6395, 0.6454, 0.6512, 0.6576, 0.6665, 0.6744, 0.682, 0.6918, 0.7013, 0.7141,
            0.7333, 0.7702, 0.8123, 0.8506, 0.9208, 0.9811, 1.0514, 1.1706, 1.3589, 10.1322,
        ),
        (  # band 4
            0.4227, 0.4421, 0.4596, 0.4719, 0.4831, 0.4961, 0.5094, 0.5242, 0.538, 0.5508,
            0.5665, 0.5826, 0.5989, 0.6112, 0.6215, 0.6308, 0.6379, 0.6444, 0.6493, 0.6539,
            0.6594, 0.6643, 0.6692, 0.675, 0.6795, 0.6833, 0.6869, 0.6919, 0.6964, 0.7001,
            0.703, 0.7048, 0.7059, 0.7086, 0.7104, 0.7139, 0.7201, 0.726, 0.7326, 0.7448, 0.751,
            0.759, 0.7748, 0.8438, 0.9145, 1.0027, 1.1, 1.1636, 1.3041, 1.4052, 10.0233,
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
        per_band = np.array([multiplier(level, context, b) for b in range(len(BAND_EDGES))])
        m = per_band[band_of(v)]
    else:
        m = np.asarray(float(multiplier_value))
    hw = m * sigma
    return v - hw, v + hw
