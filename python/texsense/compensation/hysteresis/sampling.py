"""Is a record sampled finely enough for a Preisach model? Turning points between samples.

A Preisach model remembers the input's extrema (the staircase of thesis eq. 4.15-4.17): the
output after a reversal depends on how far the input went before it turned. When the input
turns sharply (a test machine reversing at full speed), the true extremum falls between two
samples and the sampled record reports a smaller one: the model then follows the branch of
the wrong extremum until the memory is wiped out, and where the output is steep (near the
top of a spacer's loop) a few hundredths of a millimetre make N/cm² of error.

**What is measured.** At each turning point of the input, :func:`coarse_turns` estimates how
far the input went beyond its sampled extremum: the straight lines through the two samples
before and the two after the turning sample — the input's speed on either side — are
intersected (exact for a reversal at constant speed, second order for a smooth one), and the
distance of the intersection beyond the turning sample is the *missed excursion*. The
reversal happens between the turning sample's neighbours, so the intersection is held to
that interval: the estimate never exceeds the input's travel over those two sample intervals
at the speed of either side, nor the input's range. A turning point is *unresolved* when the
estimate exceeds ``tolerance`` (by default :data:`TOLERANCE` of the input range). For a
reversal at constant speed ``v`` sampled every ``dt`` the missed excursion is up to
``v dt / 2``; the rate that keeps it under the tolerance is ``v / (2 tolerance)``, the rate
the warning names, and without a clock the input step per sample that does,
``2 tolerance``.

**What is not estimated.** A turning point with fewer than two samples on a branch next to
it (the samples either side do not approach it and recede from it, or another turning point
is among them: the input *jumped* there) has no speed to extrapolate; it is counted in
``jumps`` and not judged. Measured first-order reversal curves are such records: from
saturation the field is brought to the next reversal field unrecorded, and the reversal
field is itself the curve's first sample.

**Sampled in time or not.** A rate is named only for a record with a clock: times given, and
not the row numbers 0, 1, 2, ... (a FORC file exported with its row index as ``time_s`` is
sampled in field steps, not in time). Without a clock the warning names the input step.

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

__all__ = [
    "TOLERANCE",
    "CoarseTurns",
    "check_sampling",
    "coarse_turns",
    "is_row_count",
    "sampling_warning",
]

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
        The largest missed excursion, in the input's unit: how far the input went beyond its
        sampled extremum, from the speeds either side (at most its travel over the two
        sample intervals around the turning point).
    tolerance : float
        The tolerance used, in the input's unit.
    sample_hz : float or None
        The record's sampling rate (median); None without a clock (no times, or times that
        count rows).
    needed_hz : float or None
        The rate at which every turning point found would be resolved (the record's rate
        when all are); None without a clock.
    jumps : int
        Turning points next to a branch of fewer than two samples: not estimated.
    needed_step : float
        The input step per sample at a reversal that keeps the missed excursion within the
        tolerance (``2 x tolerance``), in the input's unit.
    """

    turns: int
    unresolved: int
    max_missed: float
    tolerance: float
    sample_hz: float | None
    needed_hz: float | None
    jumps: int = 0
    needed_step: float = 0.0


def is_row_count(times_s: npt.ArrayLike) -> bool:
    """Times that are the row numbers 0, 1, 2, ... (an index exported as time, not a clock).

    >>> is_row_count([0, 1, 2, 3]), is_row_count([0.0, 0.1, 0.2])
    (True, False)
    """
    t = np.asarray(times_s, dtype=np.float64)
    return bool(t.size >= 2 and t[0] == 0.0 and np.all(np.diff(t) == 1.0))


def _missed(t: npt.NDArray[np.float64], u: npt.NDArray[np.float64], k: int) -> float | None:
    """How far the input went beyond the sample ``k`` of a turning point, from the lines
    through samples k-2, k-1 (approaching) and k+1, k+2 (receding); None when those samples
    do not approach and recede (a jump: nothing to extrapolate)."""
    sign = 1.0 if u[k] >= u[k - 1] else -1.0  # a maximum or a minimum
    a, b, c, d, e = (sign * u[k + i] for i in (-2, -1, 0, 1, 2))
    if not (a < b <= c and c >= d > e) or not (t[k - 2] < t[k - 1] < t[k + 1] < t[k + 2]):
        return None
    s1 = (b - a) / (t[k - 1] - t[k - 2])  # > 0: towards the extremum
    s2 = (e - d) / (t[k + 2] - t[k + 1])  # < 0: away from it
    # the lines b + s1 (τ - t[k-1]) and d + s2 (τ - t[k+1]) cross at τ; the reversal lies
    # between the neighbours of k, so τ is held to [t[k-1], t[k+1]], and the lower line there
    # bounds the extremum (it cannot lie above either side's extrapolation)
    tau = (d - b + s1 * t[k - 1] - s2 * t[k + 1]) / (s1 - s2)
    tau = min(max(tau, float(t[k - 1])), float(t[k + 1]))
    top = min(b + s1 * (tau - t[k - 1]), d + s2 * (tau - t[k + 1]))
    return max(0.0, float(top - c))


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
        Sample times in s. Without them (or with times that are the row numbers 0, 1, 2,
        ...) the record has no clock: the estimate runs on sample numbers and no rate is
        named.
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
    clock = times_s is not None and not is_row_count(t)
    if not clock:
        t = np.arange(x.size, dtype=np.float64)
    steps = np.diff(t)
    steps = steps[steps > 0]
    rate = float(1.0 / np.median(steps)) if steps.size else 0.0
    rng = float(np.ptp(x)) if x.size else 0.0
    span = rng if span is None else float(span)
    tol = TOLERANCE * span if tolerance is None else float(tolerance)
    hz = rate if clock else None
    if x.size < 5 or rng <= 0 or tol <= 0 or rate <= 0:
        return CoarseTurns(0, 0, 0.0, tol, hz, hz, 0, 2.0 * tol)
    turns = [k for k in reversal_indices(x, _NOISE * rng) if 2 <= k < x.size - 2]
    missed, speeds = [], []
    for n, k in enumerate(turns):
        # the two samples either side must lie on the branches into and out of this turning
        # point: another turning point among them makes it a jump
        near = (n > 0 and k - turns[n - 1] < 3) or (n + 1 < len(turns) and turns[n + 1] - k < 3)
        m = None if near else _missed(t, x, k)
        if m is None:
            continue
        missed.append(min(m, rng))
        v_in = (x[k - 1] - x[k - 2]) / (t[k - 1] - t[k - 2])
        v_out = (x[k + 2] - x[k + 1]) / (t[k + 2] - t[k + 1])
        speeds.append(max(abs(v_in), abs(v_out)))
    bad = [i for i, m in enumerate(missed) if m > tol]
    needed = float(max([rate] + [speeds[i] / (2.0 * tol) for i in bad]))
    return CoarseTurns(
        len(turns),
        len(bad),
        float(max(missed, default=0.0)),
        tol,
        hz,
        needed if clock else None,
        len(turns) - len(missed),
        2.0 * tol,
    )


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
    warning: 10 of 12 turning points of compression_mm fall between samples (the input
    turned up to 0.038 mm beyond its sampled extremum at 10 Hz): the Preisach memory follows
    the wrong branch after them; sample at 50 Hz or more (docs/hysteresis.md#sampling)
    """
    c = coarse_turns(u, times_s, span=span)
    if c.unresolved == 0:
        return None
    unit = f" {unit}" if unit and unit != "1" else ""
    head = (
        f"warning: {c.unresolved} of {c.turns} turning points of {name} fall between samples "
        f"(the input turned up to {c.max_missed:.3g}{unit} beyond its sampled extremum"
    )
    tail = "the Preisach memory follows the wrong branch after them; "
    if c.sample_hz is None or c.needed_hz is None:
        return (
            f"{head}; no clock: sample numbers, not times): {tail}sample the reversals in "
            f"input steps of {c.needed_step:.3g}{unit} or less (docs/hysteresis.md#sampling)"
        )
    return (
        f"{head} at {c.sample_hz:.3g} Hz): {tail}sample at {_nice_rate(c.needed_hz):g} Hz or "
        "more (docs/hysteresis.md#sampling)"
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
