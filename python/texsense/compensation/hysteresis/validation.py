"""Where does a hysteresis model fail on a record? Error by band, by branch, worst places.

A user should see this before trusting a model on a new sensor: the error overall, in
output bands (the thesis's 0.5-3.5 and 3.5-10 N/cm² for pressure, quartiles of the range
otherwise), on rising and on falling branches separately (a spacer's model is typically
worst when unloading near the bottom of the range, thesis §4.5), and the worst places of the
record (one per branch, so a single bad stretch does not fill the list).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from itertools import pairwise
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.compensation.drift import DriftModel
from texsense.compensation.hysteresis._model import HysteresisModel
from texsense.compensation.hysteresis._segments import split_branches
from texsense.data import units
from texsense.exceptions import ParameterError

__all__ = ["BandError", "Place", "ValidationReport", "validate"]

#: Pressure bands of the thesis's validation (§4.5), N/cm².
PRESSURE_BANDS = ((0.5, 3.5), (3.5, 10.0))


@dataclass
class BandError:
    """Errors of the samples whose measured output lies in ``[lo, hi)`` (or on a branch)."""

    name: str
    samples: int
    rmse: float | None
    mean_relative: float | None
    max_relative: float | None


@dataclass
class Place:
    """One of the worst places: the sample with the largest error on its branch."""

    index: int
    time_s: float | None
    input: float
    measured: float
    model: float
    branch: str


@dataclass
class ValidationReport:
    """The result of :func:`validate` (``to_dict`` for JSON)."""

    samples: int
    rmse: float
    nrmse: float
    bands: list[BandError]
    branches: list[BandError]
    worst: list[Place]
    clamped: int
    unit: str
    modelled: npt.NDArray[np.float64] = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (without the modelled series)."""
        d = asdict(self)
        d.pop("modelled")
        return d


def _errors(name: str, y: np.ndarray, m: np.ndarray, floor: float) -> BandError:
    if y.size == 0:
        return BandError(name, 0, None, None, None)
    err = m - y
    big = np.abs(y) >= floor
    rel = np.abs(err[big]) / np.abs(y[big]) if big.any() else np.zeros(0)
    return BandError(
        name,
        int(y.size),
        float(np.sqrt(np.mean(err**2))),
        float(rel.mean()) if rel.size else None,
        float(rel.max()) if rel.size else None,
    )


def _worst_places(
    branches: list[Any],
    index: np.ndarray,
    times: np.ndarray | None,
    u: np.ndarray,
    y: np.ndarray,
    m: np.ndarray,
) -> list[Place]:
    """The sample with the largest error of every branch (a turning sample belongs to the
    branch it ends), at its index in the record."""
    places = []
    for n, b in enumerate(branches):
        first = b.start + (1 if n else 0)
        if first > b.stop:
            continue
        seg = slice(first, b.stop + 1)
        k = first + int(np.argmax(np.abs(m[seg] - y[seg])))
        places.append(
            Place(
                int(index[k]),
                None if times is None else float(times[k]),
                float(u[k]),
                float(y[k]),
                float(m[k]),
                "rising" if b.rising else "falling",
            )
        )
    return places


def validate(
    model: HysteresisModel,
    inputs: npt.ArrayLike,
    outputs: npt.ArrayLike,
    times_s: npt.ArrayLike | None = None,
    bands: tuple[tuple[float, float], ...] | None = None,
    worst: int = 5,
    drift: DriftModel | None = None,
) -> ValidationReport:
    """Run ``model`` through a record (followed by the ``drift`` stage of eq. 5.8 when one is
    given with ``times_s``) and measure where it fails. Relative errors count samples whose
    measured output is at least 5 % of the output range (near zero a relative error means
    little)."""
    model._check_fitted()
    u = np.asarray(inputs, dtype=np.float64)
    y = np.asarray(outputs, dtype=np.float64)
    if u.ndim != 1 or u.shape != y.shape:
        raise ParameterError(
            f"inputs and outputs must be equal-length 1-D, got {u.shape}, {y.shape}"
        )
    ok = np.isfinite(u) & np.isfinite(y)
    if ok.sum() < 2:
        raise ParameterError("the record has fewer than 2 finite samples to validate on")
    st = model.state(1)
    m = np.full(u.shape, np.nan)
    m[ok] = st.run(u[ok])
    t = None if times_s is None else np.asarray(times_s, dtype=np.float64)
    if drift is not None and t is not None:
        m[ok] = drift.apply(m[ok], t[ok], inputs=u[ok])
    uo, yo, mo = u[ok], y[ok], m[ok]
    floor = 0.05 * float(np.ptp(yo)) if np.ptp(yo) > 0 else np.inf
    if bands is None:
        if units.canonical(model.output_unit) == units.canonical("N/cm2"):
            bands = PRESSURE_BANDS
        else:
            q = np.linspace(float(yo.min()), float(yo.max()), 5)
            bands = tuple((float(a), float(b)) for a, b in pairwise(q))
    band_errors = []
    for lo, hi in bands:
        sel = (yo >= lo) & (yo < hi)
        band_errors.append(_errors(f"{lo:g}-{hi:g}", yo[sel], mo[sel], floor))
    branches = split_branches(uo, 0.01 * float(np.ptp(uo)) if np.ptp(uo) > 0 else 1.0)
    rising = np.zeros(uo.size, bool)
    for b in branches:
        if b.rising:
            rising[b.start : b.stop + 1] = True
    branch_errors = [
        _errors("rising input", yo[rising], mo[rising], floor),
        _errors("falling input", yo[~rising], mo[~rising], floor),
    ]
    index = np.nonzero(ok)[0]
    times = None if t is None else t[index]
    places = _worst_places(branches, index, times, uo, yo, mo)
    places.sort(key=lambda p: -abs(p.model - p.measured))
    rmse = float(np.sqrt(np.mean((mo - yo) ** 2)))
    return ValidationReport(
        int(ok.sum()),
        rmse,
        rmse / float(np.ptp(yo)) if np.ptp(yo) > 0 else float("nan"),
        band_errors,
        branch_errors,
        places[:worst],
        int(st.clamped[0]),
        model.output_unit,
        m,
    )
