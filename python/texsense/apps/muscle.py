"""Contractions from a sensor sleeve: onsets, counts and relative intensity (docs/muscle.md).

The activation is the sum over the sleeve's elements of the pressure above each element's
baseline. The baseline is the element's running low level: the 10th percentile of the last
5 s, so the sleeve's preload and any slow drift drop out. The first two windows (10 s) have
no settled baseline yet, and their activation is 0: that is when the sleeve is pulled on.
A contraction starts where the activation rises above ``on_ncm2`` and ends where it falls
below half of it. Contractions shorter than ``min_s`` are not counted, and neither are starts
within ``refractory_s`` of the last end. Each contraction's intensity is its peak activation
relative to the session's strongest.

Examples
--------
>>> import numpy as np
>>> t = np.arange(0, 20, 0.05)
>>> act = np.where((t > 5) & (t < 6), 0.4, 0.0) + np.where((t > 12) & (t < 13.5), 0.2, 0.0)
>>> found = detect(t, act)
>>> [round(o, 2) for o in found.onsets_s], [round(v, 2) for v in found.intensity]
([5.05, 12.05], [1.0, 0.5])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.ndimage import percentile_filter

from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

__all__ = ["Contractions", "activation", "detect"]


@dataclass
class Contractions:
    """What :func:`detect` found."""

    onsets_s: list[float]
    ends_s: list[float]
    intensity: list[float]  # peak activation / the session's strongest

    @property
    def count(self) -> int:
        """Number of contractions."""
        return len(self.onsets_s)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready."""
        return {
            "count": self.count,
            "onsets_s": [round(v, 3) for v in self.onsets_s],
            "ends_s": [round(v, 3) for v in self.ends_s],
            "intensity": [round(v, 3) for v in self.intensity],
        }


def activation(pressure: Recording, baseline_s: float = 5.0) -> np.ndarray:
    """The activation (N/cm²) of a pressure recording of the sleeve: per element the pressure
    above its running 10th percentile of the last ``baseline_s``, summed over elements."""
    if pressure.quantity != "pressure":
        raise ParameterError(f"activation reads pressure, not {pressure.quantity}")
    rec = pressure.to_unit("N/cm2") if pressure.unit != "N/cm2" else pressure
    p = np.nan_to_num(np.where(rec.valid, rec.frames, np.nan).astype(np.float64))
    width = max(3, rec.frames_in(baseline_s))  # at most the recording's frames
    # the window ends at the present frame (a positive origin shifts it back): only the past
    past = ((width - 1) // 2, 0)
    base = percentile_filter(p, 10, size=(width, 1), mode="nearest", origin=past)
    act = np.clip(p - base, 0.0, None).sum(axis=1)
    # no baseline yet: the first window holds the sleeve being pulled on, the second still
    # looks back into it
    act[: min(2 * width, act.size)] = 0.0
    return act


def detect(
    times_s: npt.ArrayLike,
    act: npt.ArrayLike,
    *,
    on_ncm2: float = 0.06,
    min_s: float = 0.2,
    refractory_s: float = 0.3,
) -> Contractions:
    """Contractions in an activation signal (see the module documentation)."""
    t = np.asarray(times_s, dtype=np.float64)
    a = np.asarray(act, dtype=np.float64)
    if t.shape != a.shape or t.ndim != 1:
        raise ParameterError("times and activation must be (T,) arrays of one length")
    if not on_ncm2 > 0:
        raise ParameterError(f"the onset threshold must be > 0, got {on_ncm2}")
    onsets, ends, peaks = [], [], []
    active, start, peak, last_end = False, 0.0, 0.0, -np.inf
    for ti, ai in zip(t, a, strict=True):
        if not active and ai > on_ncm2 and ti - last_end >= refractory_s:
            active, start, peak = True, ti, ai
        elif active:
            peak = max(peak, ai)
            if ai < on_ncm2 / 2:
                active, last_end = False, ti
                if ti - start >= min_s:
                    onsets.append(float(start))
                    ends.append(float(ti))
                    peaks.append(float(peak))
    top = max(peaks) if peaks else 1.0
    return Contractions(onsets, ends, [p / top for p in peaks])
