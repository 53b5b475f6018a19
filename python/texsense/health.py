"""Failure detection on raw capacitance and a per-element health report (thesis §6.5.2.5).

The thesis's textile mat lost 12 of 96 elements for good, and more than half failed at least
once in a session: lint or sweat shorts an element to its neighbour line, a cracked line
breaks it. :class:`FailureDetector` flags, frame by frame (streaming) or over a recording:

- ``short/break``: a reading at or below ``min_pF`` (a short or an open line reads about
  0 pF on an AD7745 with CAPDAC) or below ``low_share`` of the element's unloaded value;
- ``out of range``: the converter saturated (``valid`` False in the input), or a reading
  beyond ``high_share`` times the largest capacitance the calibration expects;
- ``stuck``: no change larger than ``stuck_pF`` for ``stuck_frames`` frames while the
  median 4-neighbour changed by more than ``neighbour_change_pF`` meanwhile;
- ``jump``: a change between two frames larger than ``jump_share`` of the element's span
  (unloaded to fully compressed) — faster than a body on a seat can move the spacer.

Every flagged reading is a failure at that frame; an element can fail and recover any number
of times (intermittent failures). :func:`health_report` counts episodes per element.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError
from texsense.layout import Layout
from texsense.recording import Recording

__all__ = ["FAILURE_KINDS", "ElementHealth", "FailureDetector", "health_report"]

#: Codes of the failure kinds (0 = healthy).
FAILURE_KINDS = {0: "ok", 1: "short/break", 2: "out of range", 3: "stuck", 4: "jump"}


@dataclass
class FailureDetector:
    """Streaming failure detector for one mat.

    Parameters
    ----------
    layout : Layout
        For the neighbours of the stuck test.
    baseline_pF, max_pF : array_like (N,), optional
        Unloaded and largest expected capacitance per element (from a
        :class:`~texsense.calibration.MatCalibration`); without them only the absolute
        tests run (short/break by ``min_pF``, saturation, stuck, jumps by ``jump_pF``).
    """

    layout: Layout
    baseline_pF: npt.ArrayLike | None = None
    max_pF: npt.ArrayLike | None = None
    min_pF: float = 0.05
    low_share: float = 0.5
    high_share: float = 1.2
    stuck_frames: int = 20
    stuck_pF: float = 1e-4
    neighbour_change_pF: float = 0.05
    jump_share: float = 0.6
    jump_pF: float = 2.0

    def __post_init__(self) -> None:
        n = self.layout.n_elements
        self._base = None if self.baseline_pF is None else np.asarray(self.baseline_pF, float)
        self._max = None if self.max_pF is None else np.asarray(self.max_pF, float)
        for name, v in (("baseline_pF", self._base), ("max_pF", self._max)):
            if v is not None and v.shape != (n,):
                raise ParameterError(f"{name} needs {n} entries, got shape {v.shape}")
        if self.stuck_frames < 2 or not (self.jump_share > 0 and 0 < self.low_share < 1):
            raise ParameterError("stuck_frames >= 2, jump_share > 0 and 0 < low_share < 1 needed")
        if self._base is not None and self._max is not None:
            self._jump = self.jump_share * np.maximum(self._max - self._base, 1e-6)
        else:
            self._jump = np.full(n, self.jump_pF)
        indptr, indices = self.layout.neighbours
        counts = np.diff(indptr)
        self._has_nb = counts > 0
        # neighbours as a padded (N, max degree) table: a padded slot points at an extra
        # +inf entry, so a row sort puts it last and the median reads positions
        # (count - 1) // 2 and count // 2 — one small sort per frame instead of a lexsort
        width = int(counts.max()) if counts.size else 0
        self._nb_table = np.full((n, width), n, dtype=np.int64)
        rows = np.repeat(np.arange(n), counts)
        slots = np.arange(indices.size) - np.repeat(indptr[:-1], counts)
        self._nb_table[rows, slots] = indices
        self._nb_lo = np.maximum(counts - 1, 0) // 2
        self._nb_hi = counts // 2
        self.reset()

    def reset(self) -> FailureDetector:
        """Forget the history (the start of a new recording)."""
        n = self.layout.n_elements
        self._last = np.full(n, np.nan)
        self._still = np.zeros(n, dtype=np.int64)  # frames without change
        self._moved = np.zeros(n)  # neighbours' median change accumulated since then
        return self

    def _neighbour_median(self, x: np.ndarray) -> np.ndarray:
        """Median over the 4-neighbours of every element (0 where it has none)."""
        n = self.layout.n_elements
        if self._nb_table.shape[1] == 0:
            return np.zeros(n)
        vals = np.append(x, np.inf)[self._nb_table]
        vals.sort(axis=1)
        rows = np.arange(n)
        out = 0.5 * (vals[rows, self._nb_lo] + vals[rows, self._nb_hi])
        out[~self._has_nb] = 0.0
        return out

    def step(self, frame_pF: npt.ArrayLike, valid: npt.ArrayLike | None = None) -> np.ndarray:
        """Failure codes (N,) uint8 of one frame (see :data:`FAILURE_KINDS`)."""
        c = np.asarray(frame_pF, dtype=np.float64)
        n = self.layout.n_elements
        if c.shape != (n,):
            raise ParameterError(f"expected a frame of {n} elements, got shape {c.shape}")
        ok_in = np.ones(n, bool) if valid is None else np.asarray(valid, bool)
        code = np.zeros(n, dtype=np.uint8)
        # change since the last frame; the stuck counter and the neighbours' movement
        delta = np.abs(c - self._last)
        first = np.isnan(delta)
        delta = np.where(first, 0.0, delta)
        nb_move = self._neighbour_median(delta)
        still = (delta <= self.stuck_pF) & ~first
        self._still = np.where(still, self._still + 1, 0)
        self._moved = np.where(still, self._moved + nb_move, 0.0)
        stuck = (
            (self._still >= self.stuck_frames)
            & (self._moved > self.neighbour_change_pF)
            & self._has_nb
        )
        code[stuck] = 3
        jump = ~first & (delta > self._jump)
        code[jump] = 4
        low = ~np.isfinite(c) | (c <= self.min_pF)
        if self._base is not None:
            low |= c < self.low_share * self._base
        high = ~ok_in
        if self._max is not None:
            high |= c > self.high_share * self._max
        code[high] = 2
        code[low] = 1
        self._last = np.where(np.isfinite(c), c, self._last)
        return code

    def run(self, rec: Recording) -> np.ndarray:
        """Failure codes (T, N) of a capacitance recording (from the detector's present state)."""
        if rec.quantity != "capacitance":
            raise ParameterError(f"failure detection reads capacitance, not {rec.quantity}")
        return np.stack(
            [self.step(rec.frames[k], rec.valid[k]) for k in range(rec.n_frames)]
        ) if rec.n_frames else np.zeros((0, rec.n_elements), np.uint8)  # fmt: skip


@dataclass(frozen=True)
class ElementHealth:
    """Health of one element over a recording."""

    element: int
    name: str
    episodes: int
    failed_share: float
    first_failed_s: float | None
    last_failed_s: float | None
    kinds: dict[str, int]

    @property
    def status(self) -> str:
        """``ok``, ``dead`` (failed at least 99 % of the time) or ``intermittent``."""
        if self.episodes == 0:
            return "ok"
        return "dead" if self.failed_share >= 0.99 else "intermittent"


def health_report(
    codes: npt.ArrayLike, times_s: npt.ArrayLike, layout: Layout
) -> list[ElementHealth]:
    """Per element: failure episodes (runs of failed frames), share of frames failed, first and
    last time failed, frames per failure kind."""
    c = np.asarray(codes)
    t = np.asarray(times_s, dtype=np.float64)
    if c.ndim != 2 or c.shape != (t.size, layout.n_elements):
        raise ParameterError(f"codes must be (T, N) = ({t.size}, {layout.n_elements})")
    failed = c > 0
    starts = failed & ~np.vstack([np.zeros((1, c.shape[1]), bool), failed[:-1]])
    out = []
    for i in range(c.shape[1]):
        f = failed[:, i]
        where = np.flatnonzero(f)
        kinds = {FAILURE_KINDS[k]: int(np.sum(c[:, i] == k)) for k in range(1, 5)}
        out.append(
            ElementHealth(
                i,
                layout.names[i] if layout.names else f"e{i}",
                int(starts[:, i].sum()),
                float(f.mean()) if f.size else 0.0,
                float(t[where[0]]) if where.size else None,
                float(t[where[-1]]) if where.size else None,
                {k: v for k, v in kinds.items() if v},
            )
        )
    return out
