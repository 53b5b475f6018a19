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

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from texsense._core import FailureDetector as _CoreDetector
from texsense.compensation.stage import Stage
from texsense.data.layout import Layout
from texsense.data.modelfile import Fields
from texsense.data.ranges import INF, Instance, Kind, Real, Whole
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

__all__ = ["FAILURE_KINDS", "ElementHealth", "FailureDetector", "health_report", "mean_reading"]

#: The largest magnitude of a reading a detector compares with (any unit: a ``linear`` mat's
#: detector reads counts up to its full scale).
READING_MAX = 1e16

#: Codes of the failure kinds (0 = healthy).
FAILURE_KINDS = {0: "ok", 1: "short/break", 2: "out of range", 3: "stuck", 4: "jump"}


def mean_reading(rec: Recording, name: str) -> np.ndarray:
    """Mean of every element over the recording's valid readings (the unloaded level of a
    zeroing recording); an element without any valid reading is an error naming it."""
    f = np.where(rec.valid, rec.frames.astype(np.float64), np.nan)
    with np.errstate(invalid="ignore"):
        n = np.sum(np.isfinite(f), axis=0)
        m = np.nansum(f, axis=0) / np.maximum(n, 1)
    if np.any(n == 0):
        raise ParameterError(
            f"elements {np.flatnonzero(n == 0).tolist()[:20]} have no valid reading in the "
            f"{name} recording"
        )
    return m


class FailureDetector(Stage):
    """The ``detect`` stage: failure codes of raw capacitance, streaming or batch.

    A reading that fails is marked invalid (its value passes unchanged); the codes of the
    last frames (see :data:`FAILURE_KINDS`) are in ``codes_`` after each call.

    Parameters
    ----------
    layout : Layout
        For the neighbours of the stuck test.
    min_pF, low_share, high_share, stuck_frames, stuck_pF, neighbour_change_pF,
    stuck_floor_pF, jump_share, jump_pF : float
        The thresholds of the module documentation.

    :meth:`fit` learns each element's unloaded level and the largest reading to expect;
    without them only the absolute tests run (short/break by ``min_pF``, saturation, stuck,
    jumps by ``jump_pF``).

    Examples
    --------
    >>> det = FailureDetector(Layout.grid(1, 3)).fit(baseline=[2.0, 2.0, 2.0])
    >>> values, valid = det.step([2.1, 0.0, 2.2], None, t=0.0)
    >>> valid.tolist(), det.codes_.tolist()
    ([True, False, True], [0, 1, 0])
    """

    name = "detect"
    _reads = ("capacitance", "pF")
    _gives = ("capacitance", "pF")

    #: the range of every parameter (:mod:`texsense.data.ranges`)
    ranges: ClassVar[Mapping[str, Kind]] = {
        "layout": Instance(Layout),
        "min_pF": Real(-INF, READING_MAX, unit="pF", note="-inf: no short/break test"),
        "low_share": Real(0.0, 1.0, lo_open=True, hi_open=True),
        "high_share": Real(0.0, 1e3, lo_open=True),
        "stuck_frames": Whole(2, 10**7),
        "stuck_pF": Real(0.0, 1e6, unit="pF"),
        "neighbour_change_pF": Real(0.0, 1e6, unit="pF"),
        "stuck_floor_pF": Real(-INF, READING_MAX, unit="pF", note="-inf: no floor"),
        "jump_share": Real(0.0, 1e3, lo_open=True),
        "jump_pF": Real(0.0, INF, lo_open=True, unit="pF", note="inf: no jump test"),
    }
    #: the learned levels' bounds in a file
    _READINGS = Real(-READING_MAX, READING_MAX, unit="pF")

    #: learned: each element's unloaded level and largest expected reading (pF), or None
    baseline_pF_: np.ndarray | None
    max_pF_: np.ndarray | None
    #: the failure codes of the last frames (see FAILURE_KINDS)
    codes_: np.ndarray

    def __init__(
        self,
        layout: Layout,
        min_pF: float = 0.05,
        low_share: float = 0.5,
        high_share: float = 1.2,
        stuck_frames: int = 20,
        stuck_pF: float = 1e-4,
        neighbour_change_pF: float = 0.05,
        stuck_floor_pF: float = -np.inf,
        jump_share: float = 0.6,
        jump_pF: float = 2.0,
    ) -> None:
        self.layout = layout
        self.min_pF = min_pF
        self.low_share = low_share
        self.high_share = high_share
        self.stuck_frames = stuck_frames
        self.stuck_pF = stuck_pF
        self.neighbour_change_pF = neighbour_change_pF
        self.stuck_floor_pF = stuck_floor_pF
        self.jump_share = jump_share
        self.jump_pF = jump_pF

    def fit(
        self,
        baseline: Recording | npt.ArrayLike | None = None,
        max_pF: npt.ArrayLike | None = None,
    ) -> FailureDetector:
        """Learn each element's unloaded level (an unloaded recording: the mean of its valid
        readings; or the levels themselves) and the largest reading to expect (e.g.
        :meth:`texsense.compensation.stages.Convert.expected_range_pF`)."""
        if isinstance(baseline, Recording):
            baseline = mean_reading(baseline, "baseline")
        as_array = lambda a: None if a is None else np.asarray(a, np.float64)  # noqa: E731
        return self.set_fitted(baseline_pF=as_array(baseline), max_pF=as_array(max_pF))

    def _prepare(self) -> None:
        n = self.layout.n_elements
        base, top = self.baseline_pF_, self.max_pF_
        for name, v in (("baseline_pF", base), ("max_pF", top)):
            if v is not None and v.shape != (n,):
                raise ParameterError(f"{name} needs {n} entries, got shape {v.shape}")
        if self.stuck_frames < 2 or not (self.jump_share > 0 and 0 < self.low_share < 1):
            raise ParameterError("stuck_frames >= 2, jump_share > 0 and 0 < low_share < 1 needed")
        if base is not None and top is not None:
            jump = self.jump_share * np.maximum(top - base, 1e-6)
        else:
            jump = np.full(n, float(self.jump_pF))
        indptr, indices = self.layout.neighbours
        c = np.ascontiguousarray
        self._core = _CoreDetector(
            c(indptr, dtype=np.int64), c(indices, dtype=np.int64), c(jump, dtype=np.float64),
            None if base is None else c(base), None if top is None else c(top),
            float(self.min_pF), float(self.low_share), float(self.high_share),
            int(self.stuck_frames), float(self.stuck_pF), float(self.neighbour_change_pF),
            float(self.stuck_floor_pF),
        )  # fmt: skip

    @property
    def core(self) -> _CoreDetector:
        """The compiled detector (the pipeline's chain runs a copy of it)."""
        self._check_fitted()
        return self._core

    def _reset_stream(self) -> None:
        self._core.reset()

    def _block(
        self, values: np.ndarray, valid: np.ndarray, dt: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        codes = self._core.run(values, valid)
        self.codes_ = codes
        return values, valid & (codes == 0)

    def step(
        self, values: npt.ArrayLike, valid: npt.ArrayLike | None, t: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """One frame (see :meth:`Stage.step`); its failure codes (N,) in ``codes_``."""
        out = super().step(values, valid, t)
        self.codes_ = self.codes_[0]
        return out

    def detect(self, frames_pF: npt.ArrayLike, valid: npt.ArrayLike | None = None) -> np.ndarray:
        """Failure codes (T, N) uint8 of frames (T, N), continuing from the present state
        (the array form of :meth:`run`, without frame times)."""
        self._check_fitted()
        c = np.ascontiguousarray(frames_pF, dtype=np.float64)
        n = self.layout.n_elements
        if c.ndim != 2 or c.shape[1] != n:
            raise ParameterError(f"expected frames of {n} elements, got shape {c.shape}")
        v = np.ones(c.shape, bool) if valid is None else np.ascontiguousarray(valid, dtype=bool)
        self.codes_ = self._core.run(c, v)
        return self.codes_

    def _fitted_json(self) -> dict[str, Any]:
        as_list = lambda a: None if a is None else a.tolist()  # noqa: E731
        return {"baseline_pF": as_list(self.baseline_pF_), "max_pF": as_list(self.max_pF_)}

    @classmethod
    def _fitted_from_json(cls, fields: Fields, params: Mapping[str, Any]) -> dict[str, Any]:
        return {
            k: None if fields.get(k, None) is None else fields.array(k, 1, within=cls._READINGS)
            for k in ("baseline_pF", "max_pF")
        }


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
