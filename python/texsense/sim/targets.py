"""Measurements of the virtual spacer against what the thesis measured (targets 2a-2e).

These are the experiments of thesis §4.1 and §5.1 repeated on the simulator, returning the
numbers that the tests check and the documentation tables show:

- :func:`hysteresis_metrics`: 0 -> max -> 0 cycle; the largest pressure difference between
  rising and falling branch at equal compression, relative to the rising value, and the error
  of taking the mean of both branches (§4.1, fig. 4.1/4.2);
- :func:`step_metrics`: steps held at constant compression for an hour, normalised to the step
  size, with a fitted ``γ ln(t + 1)`` (eq. 5.2) — per step and common — and the spread between
  steps (proportionality, eq. 5.1);
- :func:`speed_metrics`: the same cycle at several platen speeds (fig. 4.3);
- :func:`cyclic_peaks`: the maximal compression of every cycle under 0 <-> p3 (fig. 5.5).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from texsense.sim.machine import TestMachine
from texsense.sim.spacer import Spacer

__all__ = [
    "LoopBranches",
    "StepMetrics",
    "cyclic_peaks",
    "fit_log_gamma",
    "hysteresis_metrics",
    "loop_branches",
    "speed_metrics",
    "step_metrics",
]


@dataclass
class LoopBranches:
    """Rising and falling branch of a 0 -> max -> 0 cycle on a common compression grid."""

    compression_mm: npt.NDArray[np.float64]
    rising_ncm2: npt.NDArray[np.float64]
    falling_ncm2: npt.NDArray[np.float64]


def _cycle(spacer: Spacer, max_ncm2: float, speed_mm_min: float) -> LoopBranches:
    m = TestMachine(spacer)
    m.ramp_to_pressure(max_ncm2, speed_mm_min)
    turn = m.trace().times_s.size - 1
    m.ramp_to_pressure(0.0, speed_mm_min)
    return loop_branches(m.trace().compression_mm, m.trace().pressure_ncm2, turn)


def loop_branches(
    compression_mm: npt.ArrayLike, pressure_ncm2: npt.ArrayLike, turn: int, points: int = 400
) -> LoopBranches:
    """Split a 0 -> max -> 0 record at sample ``turn`` and interpolate both branches onto one
    compression grid (the falling branch is 0 where the specimen no longer carries load)."""
    e = np.asarray(compression_mm, dtype=np.float64)
    p = np.asarray(pressure_ncm2, dtype=np.float64)
    grid = np.linspace(0.0, e[turn], points)
    rising = np.interp(grid, e[: turn + 1], p[: turn + 1])
    down_e, down_p = e[turn:][::-1], p[turn:][::-1]
    falling = np.interp(grid, down_e, down_p, left=0.0)
    return LoopBranches(grid, rising, falling)


def hysteresis_metrics(
    spacer: Spacer, max_ncm2: float = 10.0, speed_mm_min: float = 10.0, min_ncm2: float = 0.5
) -> dict[str, float]:
    """Branch difference and mean-of-branches error of a 0 -> max -> 0 cycle.

    Both are relative to the rising branch and taken where it is at least ``min_ncm2``.
    """
    b = _cycle(spacer.reset(), max_ncm2, speed_mm_min)
    ok = b.rising_ncm2 >= min_ncm2
    diff = (b.rising_ncm2 - b.falling_ncm2)[ok] / b.rising_ncm2[ok]
    return {
        "max_branch_difference": float(diff.max()),
        "max_mean_branch_error": float((diff / 2).max()),
        "compression_at_max_mm": float(b.compression_mm[-1]),
    }


def fit_log_gamma(t_s: npt.ArrayLike, relative_change: npt.ArrayLike) -> float:
    """Least-squares γ of ``relative_change = γ ln(t + 1)`` (eq. 5.2 normalised to the step)."""
    x = np.log(np.asarray(t_s, dtype=np.float64) + 1.0)
    y = np.asarray(relative_change, dtype=np.float64)
    return float(x @ y / (x @ x))


@dataclass
class StepMetrics:
    """Step responses at constant compression, normalised to the step size."""

    levels_ncm2: list[float]
    times_s: list[npt.NDArray[np.float64]]
    normalised: list[npt.NDArray[np.float64]]
    gamma_single: list[float]
    gamma_common: float
    max_error_single: float
    max_error_common: float
    proportionality_spread: float


def step_metrics(
    spacer: Spacer,
    levels: Sequence[float] = (2.5, 5.0, 7.5, 10.0),
    hold_s: float = 3600.0,
    speed_mm_min: float = 50.0,
) -> StepMetrics:
    """Rising steps from 0 (fresh specimen each) held at constant compression for ``hold_s``.

    The change after the step is normalised to the pressure reached at the end of the step
    (the step size s). Errors are the largest deviations from the fitted curves, as shares
    of s; the proportionality spread is the largest difference between the normalised curves
    at the end of the hold (thesis: < 4 %).
    """
    times, curves = [], []
    for level in levels:
        m = TestMachine(spacer.reset())
        m.ramp_to_pressure(level, speed_mm_min)
        t0, p0 = m.time_s, m.pressure_ncm2
        m.hold_compression(hold_s)
        tr = m.trace()
        after = tr.times_s > t0
        times.append(tr.times_s[after] - t0)
        curves.append((tr.pressure_ncm2[after] - p0) / p0)
    singles = [fit_log_gamma(t, y) for t, y in zip(times, curves, strict=True)]
    common = fit_log_gamma(np.concatenate(times), np.concatenate(curves))
    err_single = max(
        float(np.max(np.abs(y - g * np.log(t + 1))))
        for t, y, g in zip(times, curves, singles, strict=True)
    )
    err_common = max(
        float(np.max(np.abs(y - common * np.log(t + 1))))
        for t, y in zip(times, curves, strict=True)
    )
    ends = [float(y[-1]) for y in curves]
    return StepMetrics(
        list(levels),
        times,
        curves,
        singles,
        common,
        err_single,
        err_common,
        max(ends) - min(ends),
    )


def speed_metrics(
    spacer: Spacer,
    speeds_mm_min: Sequence[float] = (0.1, 1.0, 10.0, 50.0),
    reference_mm_min: float = 10.0,
    below_mm: float = 4.0,
    min_ncm2: float = 0.5,
    max_ncm2: float = 10.0,
) -> dict[float, float]:
    """Largest relative difference (both branches) of a cycle at each speed against the cycle
    at ``reference_mm_min``, below ``below_mm`` compression where the pressure is at least
    ``min_ncm2`` (fig. 4.3)."""
    ref = _cycle(spacer.reset(), max_ncm2, reference_mm_min)
    out = {}
    for speed in speeds_mm_min:
        b = _cycle(spacer.reset(), max_ncm2, speed)
        worst = 0.0
        for mine, theirs in ((b.rising_ncm2, ref.rising_ncm2), (b.falling_ncm2, ref.falling_ncm2)):
            here = np.interp(ref.compression_mm, b.compression_mm, mine)
            sel = (ref.compression_mm <= below_mm) & (theirs >= min_ncm2)
            worst = max(worst, float(np.max(np.abs(here[sel] - theirs[sel]) / theirs[sel])))
        out[float(speed)] = worst
    return out


def cyclic_peaks(
    spacer: Spacer, p3_ncm2: float, hours: float = 4.0, speed_mm_min: float = 10.0
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Times (s) and maximal compression (mm) of every cycle 0 <-> p3 over ``hours``."""
    m = TestMachine(spacer.reset())
    times, peaks = [], []
    while m.time_s < hours * 3600.0:
        m.ramp_to_pressure(p3_ncm2, speed_mm_min)
        times.append(m.time_s)
        peaks.append(m.compression_mm)
        m.ramp_to_pressure(0.0, speed_mm_min)
    return np.asarray(times), np.asarray(peaks)
