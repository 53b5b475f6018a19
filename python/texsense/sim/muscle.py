"""Muscle activity under a sensor sleeve: a virtual forearm whose muscle bulges during
contractions, read by four textile elements at a high rate (docs/muscle.md).

Thesis §2.1: muscle activity for movement analysis needs 0 to about 1 N/cm² at 10 Hz or more
per element on 1-4 elements, so 40 Hz or more for the system. The virtual readout runs the
AD7745 at its fastest conversion rate (90.9 Hz, 11 ms a conversion) with 1 ms multiplexer
settling: four elements take 48 ms, about 21 Hz per element and 83 conversions a second.

The sleeve presses with ``preload`` everywhere (it sits on the arm all the time, so the
spacer creeps under it). A contraction adds a bulge over the muscle belly: a smooth rise and
fall (raised-cosine ramps of 0.15 s) to ``intensity`` x 0.6 N/cm² on the elements over the
belly, weighted 1, 0.8, 0.5, 0.3 around the arm. Contractions come at random (every 3-9 s,
0.4-2 s long, intensity 0.2-1), with rest periods without any.

Examples
--------
>>> s = session(minutes=3.0, seed=1)
>>> s.pressure.shape[1], len(s.onsets_s) > 3, s.frame_s < 0.05
(4, True, True)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from texsense.data.layout import Layout
from texsense.exceptions import ParameterError
from texsense.sensor.readout import CDC
from texsense.sim.mat import MatScan, VirtualMat

__all__ = ["HIGH_RATE_CDC", "MuscleSession", "session", "sleeve_layout"]

#: The readout's high-rate mode: the fastest conversion, short settling.
HIGH_RATE_CDC = CDC(rate_hz=90.9, settle_ms=1.0)
#: Bulge weights of the four elements around the arm (the belly under the first).
WEIGHTS = np.array([1.0, 0.8, 0.5, 0.3])
PEAK_NCM2 = 0.6
RAMP_S = 0.15


def sleeve_layout() -> Layout:
    """Four 2 x 2 cm elements around a forearm (8 cm apart along the circumference)."""
    xy = np.column_stack([np.arange(4) * 8.0, np.zeros(4)])
    return Layout.points(xy, size_cm=2.0, names=["e1", "e2", "e3", "e4"])


@dataclass
class MuscleSession:
    """A simulated session: frame times, true pressure (T, 4), the contractions (onset s,
    end s, intensity), the rest periods, and the sleeve's scan (capacitance)."""

    times: np.ndarray
    pressure: np.ndarray
    onsets_s: np.ndarray
    ends_s: np.ndarray
    intensity: np.ndarray
    rest: list[tuple[float, float]]
    frame_s: float
    scan: MatScan


def _envelope(t: np.ndarray, on: float, off: float) -> np.ndarray:
    rise = np.clip((t - on) / RAMP_S, 0.0, 1.0)
    fall = np.clip((off - t) / RAMP_S, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * np.minimum(rise, fall))


def session(
    minutes: float = 10.0,
    *,
    preload_ncm2: float = 0.15,
    rest_every_min: float = 3.0,
    rest_min: float = 1.0,
    seed: int = 0,
) -> MuscleSession:
    """``minutes`` of activity: contractions at random, a rest of ``rest_min`` every
    ``rest_every_min`` (the first minute is rest: the sleeve is put on)."""
    if minutes <= 0 or preload_ncm2 < 0:
        raise ParameterError("minutes must be > 0 and preload_ncm2 >= 0")
    rng = np.random.default_rng(seed)
    mat = VirtualMat(sleeve_layout(), "textile-3mm", cdc=HIGH_RATE_CDC, seed=seed)
    frame_s = mat.cdc.frame_time_s(4)
    times = np.arange(0.0, minutes * 60.0, frame_s)
    rest = [(0.0, 60.0)]
    t = 60.0 + rest_every_min * 60.0
    while t < minutes * 60.0:
        rest.append((t, t + rest_min * 60.0))
        t += (rest_every_min + rest_min) * 60.0
    onsets, ends, intensity = [], [], []
    t = 60.0 + rng.uniform(1.0, 3.0)
    while t < minutes * 60.0 - 3.0:
        length = rng.uniform(0.4, 2.0)
        if not any(a - 1.0 < t < b + 1.0 or a < t + length < b for a, b in rest):
            onsets.append(t)
            ends.append(t + length)
            intensity.append(rng.uniform(0.2, 1.0))
        t += length + rng.uniform(3.0, 9.0)
    p = np.full((times.size, 4), preload_ncm2)
    p *= np.clip(times / 2.0, 0.0, 1.0)[:, None]  # the sleeve is pulled on
    for on, off, k in zip(onsets, ends, intensity, strict=True):
        p += (k * PEAK_NCM2 * _envelope(times, on, off))[:, None] * WEIGHTS[None, :]
    return MuscleSession(
        times, p, np.array(onsets), np.array(ends), np.array(intensity), rest, frame_s,
        mat.scan(times, p),
    )  # fmt: skip
