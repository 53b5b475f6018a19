"""A mat's time line, safe from glitching clocks (docs/monitor.md, "Faults").

The stages downstream of a source (the pipeline's drift and hysteresis state, the exposure
tracker, the recorder) need frame times that never go backwards, and a frame time far in the
future would make them believe that hours have passed: exposure would reset and an open
reposition alert would clear. :class:`FrameClock` stands between a source and those stages:

- A frame is **in step** when its time is not before the last accepted frame's and not
  further ahead than the wall clock allows: ``limit = max(slack_s, 3 x frame period,
  3 x rate x wall time since the last frame)``, where ``rate`` is the source's seconds per
  wall second (1 for a live mat; more for a sped-up virtual mat or a replay). In-step frames
  pass with the clock's offset added (0 until a re-synchronisation).
- A frame **out of step** (backwards, or ahead by more than ``limit``) is skipped. If the
  next frame is in step again, that was a glitch (one bad time stamp): nothing else happens.
- If the next frame is out of step too but follows the skipped one:

  - by about the step from the last accepted frame to the skipped one (half to twice it, at
    most :data:`MAX_PERIOD_S`), the source just has longer steps than the clock had seen (a
    replay of a slow recording as fast as possible): the frame passes, and the period is
    learnt;
  - otherwise, if it is not before the skipped one and at most :data:`MAX_PERIOD_S` after it,
    the source's clock jumped (a device that restarted its clock, or a clock that was set):
    the clock **re-synchronises**, choosing its offset so that the time line goes on from the
    last accepted frame by the wall time that passed, and the frame passes. The caller
    reports this as an event.

So a glitch costs one frame, and so does a real jump; two frames in a row of any sane clock
get a mat going again, and no time ever goes backwards downstream.

A frame is placed with :meth:`FrameClock.place_frame`, the one door of every live frame (the
monitor's, and through it the station's mats, and ``texsense record``'s): a frame any of whose
element times no clock has (not a number, beyond 1e12 s: :func:`texsense.data.times.off_scale`,
the readers' scale rule) is ``unclocked``: refused before the clock sees it (it neither moves
the clock nor counts as the first frame of a jump), counted in ``unclocked``; the caller
counts it with the source's errors and says it in one line naming the source. A time on the
scale that goes back by years is a clock that was set: the rules above (skipped, then
re-synchronised).

Examples
--------
>>> clock = FrameClock()
>>> [clock.place(t, wall=t)[0] for t in (0.0, 1.0, 2.0)]
['ok', 'ok', 'ok']
>>> clock.place(1e9, wall=3.0)[0]            # one frame from the future: skipped
'ahead'
>>> clock.place(4.0, wall=4.0)               # and the mat goes on
('ok', 4.0, 0.0)
>>> clock.place(0.0, wall=5.0)[0], clock.place(1.0, wall=6.0)[:2]   # it restarted at 0
('backwards', ('resync', 6.0))
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from typing import TYPE_CHECKING, Any

from texsense.data.times import off_scale
from texsense.exceptions import ParameterError

if TYPE_CHECKING:
    from texsense.data.protocol import Frame

__all__ = ["FrameClock", "Quiet"]


#: The longest frame period the clock learns from two frames, s (see :class:`FrameClock`).
MAX_PERIOD_S = 600.0


def _similar(a: float, b: float) -> bool:
    return 0 < b <= MAX_PERIOD_S and a > 0 and 0.5 <= a / b <= 2.0


class FrameClock:
    """Keeps a source's frame times in step (see the module docstring).

    Parameters
    ----------
    slack_s : float
        The least jump ahead that counts as out of step, s of source time.
    rate : float
        The source's seconds per wall second until the frames tell (default 1: a live mat;
        a replay's or a virtual mat's ``--speed``): a sped-up source whose frames are further
        apart than ``slack_s`` does not lose its second frame as "from the future".
    """

    def __init__(self, slack_s: float = 5.0, rate: float = 1.0) -> None:
        self.slack_s = float(slack_s)
        self.rate_hint = float(rate) if rate > 0 and rate == rate else 1.0
        self.offset = 0.0
        self.last_t: float | None = None  # last accepted time, on the monitor's time line
        self._last: tuple[float, float] | None = None  # (source time, wall) of that frame
        self._history: deque[tuple[float, float]] = deque(maxlen=32)
        self._period: float | None = None
        self._pending: tuple[float, float] | None = None  # the frame skipped last
        self.skipped = 0
        self.resyncs = 0
        self.unclocked = 0  # frames refused for times no clock has (place_frame)
        self.fault: str | None = None  # why the last of them was

    @property
    def rate(self) -> float:
        """Source seconds per wall second over the recent accepted frames (``rate`` of the
        constructor until known)."""
        if len(self._history) < 2:
            return self.rate_hint
        (s0, w0), (s1, w1) = self._history[0], self._history[-1]
        if w1 - w0 < 0.05 or s1 <= s0:  # too short to tell
            return self.rate_hint
        return (s1 - s0) / (w1 - w0)

    def _limit(self, wall_gap: float) -> float:
        return max(self.slack_s, 3.0 * (self._period or 0.0), 3.0 * self.rate * max(wall_gap, 0))

    def _in_step(self, t: float, wall: float, ref: tuple[float, float]) -> bool:
        dt = t - ref[0]
        return 0.0 <= dt <= self._limit(wall - ref[1])

    def place_frame(self, frame: Frame, wall: float | None = None) -> tuple[str, float, float]:
        """Where ``frame`` goes (see :meth:`place`), or ``("unclocked", nan, nan)`` when one
        of its element times is not on any clock's scale (its reason in :attr:`fault`): the
        one door of every live frame (the module's docstring)."""
        fault = off_scale(frame.element_times)
        if fault is None and frame.element_times.size == 0:
            fault = off_scale([frame.t])
        if fault is not None:
            self.unclocked += 1
            self.fault = fault
            return "unclocked", math.nan, math.nan
        return self.place(frame.t, wall)

    def place(self, t: float, wall: float | None = None) -> tuple[str, float, float]:
        """Where a frame of source time ``t`` (arrived at ``wall``, Unix s) goes.

        Returns
        -------
        (verdict, time, jump)
            ``verdict`` is ``ok`` (pass it at ``time``), ``resync`` (the clock re-synchronised:
            pass it at ``time``; ``jump`` is how far the source's clock jumped, s),
            ``ahead`` or ``backwards`` (skip it; ``jump`` is how far it is off).
        """
        wall = time.time() if wall is None else float(wall)
        if self._last is None or self._in_step(t, wall, self._last):
            self._pending = None
            return self._accept(t, wall, "ok", 0.0)
        last_t, last_wall = self._last
        pending, self._pending = self._pending, (t, wall)
        if pending is not None:
            step, first = t - pending[0], pending[0] - last_t
            if _similar(first, step):  # longer steps than seen so far, not a jump
                self._period = step
                self._pending = None
                return self._accept(t, wall, "ok", 0.0)
            if 0.0 <= step <= max(MAX_PERIOD_S, self._limit(wall - pending[1])):  # they agree
                expected = last_t + self.rate * max(wall - last_wall, 0.0)
                base = self.last_t if self.last_t is not None else t
                self.offset = base + (expected - last_t) - t
                self._pending = None
                self._history.clear()
                self.resyncs += 1
                return self._accept(t, wall, "resync", t - expected)
        self.skipped += 1
        jump = t - last_t
        return "ahead" if jump > 0 else "backwards", t + self.offset, jump

    def state(self) -> dict[str, Any]:
        """Where the clock stands, JSON-ready (see :meth:`restore`): a mat handed to another
        station goes on on the same time line."""
        return {
            "offset": self.offset,
            "last_t": self.last_t,
            "last": None if self._last is None else list(self._last),
            "history": [list(h) for h in self._history],
            "period": self._period,
            "pending": None if self._pending is None else list(self._pending),
            "skipped": self.skipped,
            "resyncs": self.resyncs,
        }

    def restore(self, state: dict[str, Any]) -> FrameClock:
        """Go on from a :meth:`state`; one that does not fit raises ``ValueError`` naming
        what (a :class:`~texsense.exceptions.ParameterError`)."""

        def finite(v: Any) -> float:
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ValueError(f"a time of {v!r}")
            return float(v)

        def pair(v: Any) -> tuple[float, float] | None:
            return None if v is None else (finite(v[0]), finite(v[1]))

        def opt(v: Any) -> float | None:
            return None if v is None else finite(v)

        def count(v: Any) -> int:
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"a count of {v!r}")
            return v

        try:
            if not isinstance(state["history"], list):
                raise TypeError("a history that is not a list")
            history = [(finite(t), finite(w)) for t, w in state["history"]]
            values = (finite(state["offset"]), opt(state["last_t"]), pair(state["last"]),
                      opt(state["period"]), pair(state["pending"]), count(state["skipped"]),
                      count(state["resyncs"]))  # fmt: skip
        except (KeyError, TypeError, ValueError, IndexError, OverflowError) as e:
            raise ParameterError(f"the stored frame clock lacks or mangles {e}") from None
        self._history = deque(history, maxlen=self._history.maxlen)
        (self.offset, self.last_t, self._last, self._period, self._pending, self.skipped,
         self.resyncs) = values  # fmt: skip
        return self

    def _accept(self, t: float, wall: float, verdict: str, jump: float) -> tuple[str, float, float]:
        if self._last is not None and verdict == "ok":
            dt = t - self._last[0]
            if dt > 0:
                self._period = dt if self._period is None else 0.8 * self._period + 0.2 * dt
        self._last = (t, wall)
        self._history.append((t, wall))
        placed = max(t + self.offset, self.last_t if self.last_t is not None else -1e300)
        self.last_t = placed
        return verdict, placed, jump


class Quiet:
    """Log a kind of trouble once, then at most once a minute with how often it happened
    meanwhile (a mat that sends garbage 10 times a second must not fill the disk).

    >>> import logging
    >>> q = Quiet(logging.getLogger("texsense.doctest"))
    >>> [q.warn("mat a", "clock", "t jumped") for _ in range(3)]
    [True, False, False]
    >>> q.count("mat a", "clock")
    3
    """

    def __init__(self, logger: logging.Logger, every_s: float = 60.0) -> None:
        self.logger = logger
        self.every_s = every_s
        self._seen: dict[tuple[str, str], list[float]] = {}  # key -> [count, last log, logged]

    def count(self, who: str, kind: str) -> int:
        """How often ``kind`` happened to ``who``."""
        return int(self._seen.get((who, kind), [0, 0, 0])[0])

    def warn(self, who: str, kind: str, text: str) -> bool:
        """Count it; log ``who: text`` if it is the first or a minute has passed since the
        last line of this kind; True when a line was written."""
        now = time.monotonic()
        entry = self._seen.setdefault((who, kind), [0.0, -1e12, 0.0])
        entry[0] += 1
        if now - entry[1] < self.every_s:
            return False
        more = int(entry[0] - entry[2] - 1)
        note = f" ({more} more since the last line)" if entry[2] and more > 0 else ""
        self.logger.warning("%s: %s%s", who, text, note)
        entry[1], entry[2] = now, entry[0]
        return True
