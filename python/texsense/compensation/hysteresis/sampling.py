"""Is a record sampled finely enough for a Preisach model? Turning points between samples.

A Preisach model remembers the input's extrema (the staircase of thesis eq. 4.15-4.17): the
output after a reversal depends on how far the input went before it turned. When the input
turns sharply (a test machine reversing at full speed), the true extremum falls between two
samples and the sampled record reports a smaller one: the model then follows the branch of
the wrong extremum until the memory is wiped out, and where the output is steep (near the
top of a spacer's loop) a few hundredths of a millimetre make N/cm² of error.

:func:`coarse_turns` estimates, at each turning point of the input, the extremum the
samples missed: the straight lines through the two samples before and the two after the
turning sample are intersected (exact for a reversal at constant speed, second order for a
smooth one), and the distance of the intersection beyond the turning sample is the missed
excursion. A turning point is *unresolved* when that exceeds ``tolerance`` (by default
:data:`TOLERANCE` of the input range). For a reversal at constant speed ``v`` sampled every
``dt`` the missed excursion is up to ``v dt / 2``; the rate that keeps it under the
tolerance is therefore ``v / (2 tolerance)``, the rate the warning names.

Examples
--------
>>> import numpy as np
>>> t = np.arange(0, 60, 0.1)                      # 10 Hz
>>> u = 4 - np.abs((t * 0.83) % 8 - 4)             # a triangle at 0.83 mm/s, 0..4 mm
>>> c = coarse_turns(u, t)
>>> c.unresolved, c.turns, round(c.needed_hz)
(10, 12, 42)
>>> t = np.arange(0, 60, 0.02)                     # 50 Hz resolves it
>>> coarse_turns(4 - np.abs((t * 0.83) % 8 - 4), t).unresolved
0
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from texsense._progress import logger
from texsense.compensation.hysteresis._model import HysteresisModel
from texsense.compensation.hysteresis._segments import reversal_indices

__all__ = ["TOLERANCE", "CoarseTurns", "check_sampling", "coarse_turns", "sampling_warning"]

#: Missed excursion at a turning point that counts as unresolved: this share of the range.
TOLERANCE = 0.0025
#: Reversals smaller than this share of the range are noise, not turning points.
_NOISE = 0.02


@dataclass(frozen=True)
class CoarseTurns:
    """What :func:`coarse_turns` found.

    Attributes
    ----------
    turns : int
        Turning points of the input (reversals larger than 2 % of its range).
    unresolved : int
        Turning points whose extremum the samples missed by more than the tolerance.
    max_missed : float
        The largest missed excursion, in the input's unit.
    tolerance : float
        The tolerance used, in the input's unit.
    sample_hz : float
        The record's sampling rate (median; 1 per sample without times).
    needed_hz : float
        The rate at which every turning point found would be resolved (the record's rate
        when all are).
    """

    turns: int
    unresolved: int
    max_missed: float
    tolerance: float
    sample_hz: float
    needed_hz: float


def _line_crossing(t: npt.NDArray[np.float64], u: npt.NDArray[np.float64], k: int) -> float:
    """The input where the lines through samples k-2, k-1 and k+1, k+2 cross."""
    s1 = (u[k - 1] - u[k - 2]) / (t[k - 1] - t[k - 2])
    s2 = (u[k + 2] - u[k + 1]) / (t[k + 2] - t[k + 1])
    if not (math.isfinite(s1) and math.isfinite(s2)) or s1 == s2:
        return float(u[k])
    tc = (u[k + 1] - u[k - 1] + s1 * t[k - 1] - s2 * t[k + 1]) / (s1 - s2)
    return float(u[k - 1] + s1 * (tc - t[k - 1]))


def coarse_turns(
    u: npt.ArrayLike,
    times_s: npt.ArrayLike | None = None,
    *,
    tolerance: float | None = None,
    span: float | None = None,
) -> CoarseTurns:
    """Turning points of ``u`` that fall between samples (see the module's docstring).

    Parameters
    ----------
    u : array_like (T,)
        The model's input (e.g. compression in mm).
    times_s : array_like (T,), optional
        Sample times in s (default: one sample per second).
    tolerance : float, optional
        Missed excursion that counts as unresolved, in the input's unit (default
        :data:`TOLERANCE` of ``span``).
    span : float, optional
        The input range the tolerance refers to (default: the record's; pass the model's).
    """
    x = np.asarray(u, dtype=np.float64)
    t = np.arange(x.size, dtype=np.float64) if times_s is None else np.asarray(times_s, float)
    ok = np.isfinite(x) & np.isfinite(t)
    x, t = x[ok], t[ok]
    steps = np.diff(t)
    steps = steps[steps > 0]
    rate = float(1.0 / np.median(steps)) if steps.size else 0.0
    rng = float(np.ptp(x)) if x.size else 0.0
    span = rng if span is None else float(span)
    tol = TOLERANCE * span if tolerance is None else float(tolerance)
    if x.size < 5 or rng <= 0 or tol <= 0 or rate <= 0:
        return CoarseTurns(0, 0, 0.0, tol, rate, rate)
    turns = [k for k in reversal_indices(x, _NOISE * rng) if 2 <= k < x.size - 2]
    missed, speeds = [], []
    for k in turns:
        sign = 1.0 if x[k] >= x[k - 1] else -1.0  # a maximum or a minimum
        missed.append(max(0.0, sign * (_line_crossing(t, x, k) - x[k])))
        v_in = abs(x[k - 1] - x[k - 2]) / (t[k - 1] - t[k - 2])
        v_out = abs(x[k + 2] - x[k + 1]) / (t[k + 2] - t[k + 1])
        speeds.append(max(v_in, v_out))
    bad = [i for i, m in enumerate(missed) if m > tol]
    needed = float(max([rate] + [speeds[i] / (2.0 * tol) for i in bad]))
    return CoarseTurns(len(turns), len(bad), float(max(missed, default=0.0)), tol, rate, needed)


def _nice_rate(hz: float) -> float:
    """``hz`` rounded up to 1, 2 or 5 times a power of ten."""
    power = 10.0 ** math.floor(math.log10(hz))
    return next(m * power for m in (1, 2, 5, 10) if m * power >= hz - 1e-9)


def sampling_warning(
    u: npt.ArrayLike,
    times_s: npt.ArrayLike | None,
    *,
    name: str = "input",
    unit: str = "",
    span: float | None = None,
) -> str | None:
    """One warning line when turning points of ``u`` fall between samples, else None.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(0, 60, 0.1)
    >>> print(sampling_warning(4 - np.abs((t * 0.83) % 8 - 4), t, name="compression_mm",
    ...                        unit="mm"))  # doctest: +NORMALIZE_WHITESPACE
    warning: 10 of 12 turning points of compression_mm fall between samples (the extremum
    missed by up to 0.038 mm at 10 Hz): the Preisach memory follows the wrong branch after
    them; sample at 50 Hz or more (docs/hysteresis.md#sampling)
    """
    c = coarse_turns(u, times_s, span=span)
    if c.unresolved == 0:
        return None
    unit = f" {unit}" if unit and unit != "1" else ""
    return (
        f"warning: {c.unresolved} of {c.turns} turning points of {name} fall between samples "
        f"(the extremum missed by up to {c.max_missed:.3g}{unit} at {c.sample_hz:.3g} Hz): "
        "the Preisach memory follows the wrong branch after them; sample at "
        f"{_nice_rate(c.needed_hz):g} Hz or more (docs/hysteresis.md#sampling)"
    )


def check_sampling(
    model: HysteresisModel, u: npt.ArrayLike, times_s: npt.ArrayLike | None, name: str
) -> str | None:
    """Warn (the package logger, one line) when ``u``, the input ``model`` is about to run
    on, turns between samples; the tolerance refers to the model's input range. Returns the
    line, or None."""
    line = sampling_warning(
        u, times_s, name=name, unit=model.input_unit, span=model.u_max_ - model.u_min_
    )
    if line:
        logger.warning(line)
    return line
