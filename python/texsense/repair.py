"""Repair of failed elements (thesis §6.5.2.5).

:class:`NeighbourMeanRepair` implements eq. 6.14: a failed element gets the mean of its
available 4-neighbours, ``p_i = (p_l + p_r + p_t + p_b) / n_a``; when none of them is
available, the last value of the element (real or repaired) is held. The kernel runs in the
Rust core (``texsense._core``), streaming (:meth:`~NeighbourMeanRepair.step`) or batch
(:meth:`~NeighbourMeanRepair.run`); both give identical results.

Examples
--------
>>> import numpy as np
>>> from texsense import Layout, Recording
>>> from texsense.repair import NeighbourMeanRepair
>>> lay = Layout.grid(3, 3)
>>> frame = np.array([[0, 1, 0, 2, 99, 4, 0, 5, 0]], dtype=float)
>>> valid = np.ones((1, 9), bool); valid[0, 4] = False
>>> rec = Recording(frame, [0.0], lay, valid=valid)
>>> NeighbourMeanRepair(lay).run(rec).frames[0, 4]
np.float32(3.0)
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from texsense._core import NeighbourMeanRepair as _CoreRepair
from texsense.exceptions import ParameterError
from texsense.layout import Layout
from texsense.recording import Recording

__all__ = ["OUTCOME", "NeighbourMeanRepair"]

#: Outcome codes returned per element and frame by the kernel.
OUTCOME = {0: "measured", 1: "neighbour mean", 2: "last value", 3: "missing"}


class NeighbourMeanRepair:
    """Eq. 6.14 repair with state (the last value of every element).

    Parameters
    ----------
    layout : Layout
        Supplies the 4-neighbour graph.
    """

    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        indptr, indices = layout.neighbours
        self._core = _CoreRepair(
            np.ascontiguousarray(indptr, dtype=np.int64),
            np.ascontiguousarray(indices, dtype=np.int64),
        )
        self.outcome_: npt.NDArray[np.uint8] | None = None

    def reset(self) -> NeighbourMeanRepair:
        """Forget the last values."""
        self._core.reset()
        return self

    @property
    def last_values(self) -> npt.NDArray[np.float32]:
        """Last value (real or repaired) of each element; NaN where none was seen yet."""
        return self._core.last_values()

    def _repair(
        self, frames: npt.ArrayLike, valid: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
        f = np.ascontiguousarray(frames, dtype=np.float32)
        v = np.ascontiguousarray(valid, dtype=bool)
        if f.ndim != 2 or f.shape[1] != self.layout.n_elements:
            raise ParameterError(
                f"expected frames of {self.layout.n_elements} elements, got shape {f.shape}"
            )
        return self._core.run(f, v)

    def step(
        self, frame: npt.ArrayLike, valid: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
        """Repair one frame (N,); returns the repaired frame and a mask of repaired elements."""
        out, outcome = self._repair(np.asarray(frame)[None, :], np.asarray(valid)[None, :])
        self.outcome_ = outcome[0]
        return out[0], outcome[0] != 0

    def run(self, rec: Recording) -> Recording:
        """Repair every frame of ``rec`` in order (continuing from the current state).

        Returns a recording whose ``valid`` mask is True only for measured readings, so that
        repaired values stay marked; the outcome codes (see :data:`OUTCOME`) are kept in
        ``outcome_``.
        """
        out, outcome = self._repair(rec.frames, rec.valid)
        self.outcome_ = outcome
        meta = {**rec.meta, "repair": "neighbour-mean (eq. 6.14)"}
        return rec._with(frames=out, valid=outcome == 0, meta=meta)
