"""Failure detection on raw capacitance and a per-element health report (thesis §6.5.2.5).

The thesis's textile mat lost 12 of 96 elements for good, and more than half failed at least
once in a session: lint or sweat shorts an element to its neighbour line, a cracked line
breaks it. :class:`FailureDetector` flags, frame by frame (streaming) or over a recording:

- ``short/break``: a reading at or below ``min_pF`` (a short or an open line reads about
  0 pF on an AD7745 with CAPDAC) or below ``low_share`` of the element's unloaded value;
- ``out of range``: the converter saturated (``valid`` False in the input), or a reading
  beyond ``high_share`` times the largest capacitance the calibration expects;
- ``stuck``: no change larger than ``stuck_pF`` for ``stuck_frames`` frames while the
  median 4-neighbour changed by more than ``neighbour_change_pF`` meanwhile (readings at or
  below ``stuck_floor_pF`` are never stuck: on a mat that reads 0 without load, an unloaded
  element holds still legitimately);
- ``jump``: a change between two frames larger than ``jump_share`` of the element's span
  (unloaded to fully compressed) — faster than a body on a seat can move the spacer.

Every flagged reading is a failure at that frame; an element can fail and recover any number
of times (intermittent failures). :func:`health_report` counts episodes per element. The
detector runs in the Rust core (``crates/core/src/detect.rs``), over blocks of elements in
parallel for a batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from texsense._core import FailureDetector as _CoreDetector
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
    stuck_floor_pF: float = -np.inf
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
            jump = self.jump_share * np.maximum(self._max - self._base, 1e-6)
        else:
            jump = np.full(n, self.jump_pF)
        indptr, indices = self.layout.neighbours
        contiguous = np.ascontiguousarray
        self._core = _CoreDetector(
            contiguous(indptr, dtype=np.int64),
            contiguous(indices, dtype=np.int64),
            contiguous(jump, dtype=np.float64),
            None if self._base is None else contiguous(self._base),
            None if self._max is None else contiguous(self._max),
            self.min_pF,
            self.low_share,
            self.high_share,
            int(self.stuck_frames),
            self.stuck_pF,
            self.neighbour_change_pF,
            float(self.stuck_floor_pF),
        )

    def reset(self) -> FailureDetector:
        """Forget the history (the start of a new recording)."""
        self._core.reset()
        return self

    @property
    def core(self) -> _CoreDetector:
        """The compiled detector (the pipeline's chain runs a copy of it)."""
        return self._core

    def detect(self, frames_pF: npt.ArrayLike, valid: npt.ArrayLike | None = None) -> np.ndarray:
        """Failure codes (T, N) uint8 of frames (T, N), continuing from the present state."""
        c = np.ascontiguousarray(frames_pF, dtype=np.float64)
        n = self.layout.n_elements
        if c.ndim != 2 or c.shape[1] != n:
            raise ParameterError(f"expected frames of {n} elements, got shape {c.shape}")
        v = np.ones(c.shape, bool) if valid is None else np.ascontiguousarray(valid, dtype=bool)
        return self._core.run(c, v)

    def step(self, frame_pF: npt.ArrayLike, valid: npt.ArrayLike | None = None) -> np.ndarray:
        """Failure codes (N,) uint8 of one frame (see :data:`FAILURE_KINDS`)."""
        c = np.asarray(frame_pF, dtype=np.float64)
        n = self.layout.n_elements
        if c.shape != (n,):
            raise ParameterError(f"expected a frame of {n} elements, got shape {c.shape}")
        return self.detect(c[None, :], None if valid is None else np.asarray(valid)[None, :])[0]

    def run(self, rec: Recording) -> np.ndarray:
        """Failure codes (T, N) of a capacitance recording (from the detector's present state)."""
        if rec.quantity != "capacitance":
            raise ParameterError(f"failure detection reads capacitance, not {rec.quantity}")
        cap = rec.to_unit("pF").frames if rec.unit != "pF" else rec.frames
        return self.detect(cap, rec.valid)


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
