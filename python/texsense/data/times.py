"""The one check of a recording's times, under every reader (:class:`~texsense.io._base.
RecordingReader` checks each block of frames it reads with a :class:`TimeCheck`, and the file's
end with :meth:`TimeCheck.finish`), a column table's ``time_s`` and frames read out of order:
a time is a number, does not go back, and lies on a scale that a clock of a sensor session
has. Its scale rule (:func:`off_scale`) is also the door of every live frame
(:meth:`texsense.monitor.clock.FrameClock.place_frame`): this module is in the data layer so
that the monitor uses it without loading the file formats (harden15; it was ``io._times``).

The scale's limits, and why:

- :data:`MAX_TIME_S` (1e12 s, about 31,700 years): no time stamp is further from zero. Times
  are seconds from the start of a session or from 1970 (1.8e9 s now); beyond 1e12 s a time is
  in another unit or damaged, and float64 no longer resolves a frame at a kHz (0.1 ms there).
- :data:`MAX_SPAN_S` (ten years, 3.16e8 s): no frame is further from the file's first. The
  longest sessions a textile mat records (a bed, months on end) are far shorter; a stray stamp
  of 1e9 s in a 10 Hz file, or times x 1e300, are not a session's. An app that sizes its work
  from time (rows per hour, windows in s) is bounded by the frame count besides
  (``Recording.frames_in``, ``apps.stocking``), so a long real session costs what its frames cost.
- :data:`MIN_MEAN_STEP_S` (1 us): frames are at least this far apart **on average** over the
  file. No textile sensor samples a whole frame at 1 MHz (the fastest scan a few kHz); steps
  of 1e-300 s, or every frame at one time, are no clock. Single steps may be shorter, or zero
  (frames that arrive in a burst share a stamp of a coarse clock): only the mean is bounded,
  at the file's end (when the last frame is read).

Each refusal is one :class:`~texsense.exceptions.FormatError` naming the file, the line (text
formats) or frame, and the time.

>>> import numpy as np
>>> check = TimeCheck("r.h5")
>>> check.block(np.array([0.0, 0.1, 0.2]))
>>> check.finish()
>>> try:
...     TimeCheck("r.h5").block(np.array([0.0, 1e300]))
... except Exception as e:
...     print(e)  # doctest: +ELLIPSIS
r.h5: frame 2: the time 1e+300 s is beyond any clock (|t| over 1e12 s, ...)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

from texsense._core import first_off_scale
from texsense.exceptions import FormatError

__all__ = ["MAX_SPAN_S", "MAX_TIME_S", "MIN_MEAN_STEP_S", "TimeCheck", "off_scale"]

#: No time stamp is further from zero (s): about 31,700 years (see the module's docstring).
MAX_TIME_S = 1e12
#: No frame is further from the file's first (s): ten years.
MAX_SPAN_S = 10 * 365.25 * 86400.0
#: Frames are at least this far apart on average over a file (s): 1 us (1 MHz).
MIN_MEAN_STEP_S = 1e-6


def off_scale(t: npt.ArrayLike) -> str | None:
    """What is wrong with the first of the times ``t`` that no clock has (not a number, or
    beyond :data:`MAX_TIME_S`), or None: the scale rule of :class:`TimeCheck` for times that
    come one frame at a time (a live frame's element times, :class:`~texsense.monitor.clock.
    FrameClock`), where going back is the frame clock's to judge.

    >>> off_scale([0.0, 0.1]) is None, off_scale([0.0, float("nan")])
    (True, 'the time nan is not a number')
    >>> off_scale([1e300])
    'the time 1e+300 s is beyond any clock (|t| over 1e12 s)'
    """
    t = np.ascontiguousarray(t, dtype=np.float64).ravel()
    i = first_off_scale(t, MAX_TIME_S)  # one compiled pass (every live frame comes here)
    if i is None:
        return None
    ti = t[i]
    if not np.isfinite(ti):
        return f"the time {ti} is not a number"
    return f"the time {ti:.9g} s is beyond any clock (|t| over 1e12 s)"


class TimeCheck:
    """The times of one file's frames, checked block by block as a reader reads them.

    Parameters
    ----------
    path : str or Path
        The file, named in every error.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.first: float | None = None
        self.last = -np.inf
        self.count = 0

    def block(
        self,
        t: npt.NDArray[np.float64],
        lines: npt.NDArray[np.int64] | None = None,
        element_times: npt.NDArray[np.float64] | None = None,
    ) -> None:
        """Check the next frames' times ``t`` (``lines``: where each frame starts, in a text
        file) and their elements' (``element_times``, (frames, elements), if the file holds
        them: each on a clock's scale, :func:`off_scale`); raise :class:`FormatError` naming
        the first bad one."""
        t = np.asarray(t, dtype=np.float64)
        if not t.size:
            return
        if element_times is not None:
            self._elements(np.asarray(element_times, dtype=np.float64), lines)
        first = float(t[0]) if self.first is None else self.first
        previous = np.concatenate(([self.last], t[:-1]))
        with np.errstate(invalid="ignore", over="ignore"):
            bad = ~np.isfinite(t) | (t < previous) | (np.abs(t) > MAX_TIME_S)
            bad |= t - first > MAX_SPAN_S
        if bad.any():
            self._refuse(t, previous, first, int(np.argmax(bad)), lines)
        self.first = first
        self.last = float(t[-1])
        self.count += t.size

    def _elements(self, et: npt.NDArray[np.float64], lines: npt.NDArray[np.int64] | None) -> None:
        with np.errstate(invalid="ignore"):
            bad = ~(np.abs(et) <= MAX_TIME_S)
        if not bad.any():
            return
        i, j = (int(k) for k in np.unravel_index(int(np.argmax(bad)), bad.shape))
        line = None if lines is None else int(lines[i])
        where = "" if line is not None else f"frame {self.count + i + 1}: "
        raise FormatError(self.path, f"{where}element {j + 1}: {off_scale(et[i, j])}", line)

    def _refuse(
        self,
        t: npt.NDArray[np.float64],
        previous: npt.NDArray[np.float64],
        first: float,
        i: int,
        lines: npt.NDArray[np.int64] | None,
    ) -> None:
        line = None if lines is None else int(lines[i])
        where = "" if line is not None else f"frame {self.count + i + 1}: "
        ti = t[i]
        if not np.isfinite(ti):
            message = f"the time is {ti}, not a number"
        elif ti < previous[i]:
            message = (
                f"the time {ti:.9g} s goes back from {previous[i]:.9g} s (times must not decrease)"
            )
        elif abs(ti) > MAX_TIME_S:
            message = f"the time {ti:.9g} s is beyond any clock (|t| over 1e12 s, "
            message += "31,700 years: another unit, or a damaged stamp?)"
        else:
            message = (
                f"the time {ti:.9g} s is {ti - first:.3g} s after the first frame's "
                f"({first:.9g} s): no sensor session spans over ten years (a damaged stamp, "
                "or times in another unit?)"
            )
        raise FormatError(self.path, where + message, line)

    def finish(self) -> None:
        """At the file's end: refuse frames that are closer than :data:`MIN_MEAN_STEP_S` on
        average (every frame at one time, steps of 1e-300 s)."""
        if self.count < 2 or self.first is None:
            return
        span = self.last - self.first
        if span >= MIN_MEAN_STEP_S * (self.count - 1):
            return
        if span == 0:
            what = f"all {self.count} frames have the time {self.first:.9g} s"
        else:
            what = (
                f"the {self.count} frames' times run from {self.first:.9g} s to "
                f"{self.last:.9g} s, {span / (self.count - 1):.3g} s apart on average"
            )
        raise FormatError(
            self.path,
            f"{what}: no sensor samples a frame faster than every 1 us (times that do not "
            "advance, or in another unit?)",
        )
