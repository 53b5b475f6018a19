"""Repair of failed elements (thesis §6.5.2.5).

:class:`NeighbourMeanRepair` implements eq. 6.14: a failed element gets the mean of its
available 4-neighbours, ``p_i = (p_l + p_r + p_t + p_b) / n_a``; when none of them is
available, the last value of the element (real or repaired) is held. The kernel runs in the
Rust core (``texsense._core``), streaming (:meth:`~NeighbourMeanRepair.step`) or batch
(:meth:`~NeighbourMeanRepair.run`); both give identical results.

:class:`Repair` offers every method behind one interface (``METHODS``):

- ``zero``: failed elements read 0 (what an unrepaired mat shows);
- ``last-value``: hold the last value seen (real or repaired);
- ``neighbour-mean``: eq. 6.14 (the Rust kernel above);
- ``idw8``: inverse-distance-weighted mean (1/d²) of the valid elements within 1.5 pitches —
  the 8-neighbourhood on a grid, so diagonals help where the 4-neighbours failed too;
- ``harmonic``: Laplace inpainting — the failed elements jointly take the values that make
  each of them the mean of its 4-neighbours, valid or failed, so clusters of failures are
  filled smoothly from their whole border (a sparse linear system per failure pattern,
  factorised once and reused while the pattern stays);
- ``harmonic-temporal``: a temporal prior — the element's previous value plus the change of
  its harmonic interpolation since the previous frame (both with the present failure
  pattern). A static load keeps the element's own last reading (which neighbours cannot
  know); a moving one moves it like its surroundings.

All fall back to the last value where nothing valid is connected, and start with NaN
("missing") where there is none yet.

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

from typing import Any

import numpy as np
import numpy.typing as npt

from texsense._core import LocalRepair as _CoreRepair
from texsense.exceptions import ParameterError
from texsense.layout import Layout
from texsense.recording import Recording

__all__ = ["METHODS", "OUTCOME", "NeighbourMeanRepair", "Repair"]

#: The repair methods of :class:`Repair`.
METHODS = ("zero", "last-value", "neighbour-mean", "idw8", "harmonic", "harmonic-temporal")

#: Outcome codes returned per element and frame by the kernel.
OUTCOME = {0: "measured", 1: "interpolated", 2: "last value", 3: "missing"}


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
            "neighbour-mean",
            layout.n_elements,
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
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint8]]:
        f = np.ascontiguousarray(frames, dtype=np.float64)
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


class Repair:
    """Any repair method of :data:`METHODS` with state (the last value of every element).

    Examples
    --------
    >>> import numpy as np
    >>> from texsense import Layout
    >>> lay = Layout.grid(3, 3)
    >>> frame = np.full(9, 2.0); frame[[1, 4]] = 0.0   # two neighbouring elements failed
    >>> valid = frame > 0
    >>> out, repaired = Repair(lay, "harmonic").step(frame, valid)
    >>> out.tolist(), repaired.nonzero()[0].tolist()
    ([2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0], [1, 4])
    """

    def __init__(self, layout: Layout, method: str = "harmonic") -> None:
        if method not in METHODS:
            raise ParameterError(f"unknown repair method {method!r}; known: {', '.join(METHODS)}")
        self.layout = layout
        self.method = method
        n = layout.n_elements
        self._last = np.full(n, np.nan)
        self._prev = np.full(n, np.nan)  # the previous output frame
        self._core = NeighbourMeanRepair(layout) if method == "neighbour-mean" else None
        if method == "idw8":
            self._weights = idw_weights(layout)
        if method in ("harmonic", "harmonic-temporal"):
            import scipy.sparse as sp

            indptr, indices = layout.neighbours
            adj = sp.csr_matrix((np.ones(indices.size), indices, indptr), shape=(n, n))
            self._adj = ((adj + adj.T) > 0).astype(np.float64).tocsr()
            self._deg = np.asarray(self._adj.sum(axis=1)).ravel()
            self._cache: dict[bytes, tuple] = {}
        self.outcome_: npt.NDArray[np.uint8] | None = None

    def reset(self) -> Repair:
        """Forget the last values."""
        self._last[:] = np.nan
        self._prev[:] = np.nan
        if self._core is not None:
            self._core.reset()
        return self

    def step(
        self, frame: npt.ArrayLike, valid: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
        """Repair one frame (N,); returns the repaired frame and a mask of repaired elements.
        Non-finite readings count as failed too."""
        x = np.asarray(frame, dtype=np.float64)
        n = self.layout.n_elements
        if x.shape != (n,):
            raise ParameterError(f"expected a frame of {n} elements, got shape {x.shape}")
        ok = np.asarray(valid, dtype=bool) & np.isfinite(x)
        if self._core is not None:
            out32, _ = self._core.step(np.where(ok, x, 0.0), ok)
            out = out32.astype(np.float64)
            outcome = self._core.outcome_
        else:
            out, outcome = self._fill(x, ok)
        self._last = np.where(np.isfinite(out), out, self._last)
        self._prev = out.copy()
        self.outcome_ = outcome
        return out, ~ok

    def _fill(self, x: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out = np.where(ok, x, np.nan)
        outcome = np.where(ok, 0, 1).astype(np.uint8)
        bad = ~ok
        if not bad.any():
            return out, outcome
        if self.method == "zero":
            out[bad] = 0.0
            return out, outcome
        if self.method == "idw8":
            v = np.where(ok, x, 0.0)
            num = self._weights @ v
            den = self._weights @ ok.astype(np.float64)
            have = bad & (den > 0)
            out[have] = num[have] / den[have]
        elif self.method == "harmonic":
            self._harmonic(out, ok)
        elif self.method == "harmonic-temporal":
            self._harmonic(out, ok)
            prev = np.where(ok, self._prev, np.nan)
            if np.all(np.isfinite(self._prev)):
                self._harmonic(prev, ok)
                step = bad & np.isfinite(out) & np.isfinite(prev)
                out[step] = self._prev[step] + (out[step] - prev[step])
                if np.all(x[ok] >= 0):
                    out[step] = np.maximum(out[step], 0.0)
        left = bad & ~np.isfinite(out)
        out[left] = self._last[left]
        outcome[left] = 2
        outcome[left & ~np.isfinite(out)] = 3
        return out, outcome

    def _harmonic(self, out: np.ndarray, ok: np.ndarray) -> None:
        """Solve L_FF x_F = A_FV v_V for the failed elements connected to a valid one."""
        import scipy.sparse as sp
        import scipy.sparse.linalg as spla
        from scipy.sparse.csgraph import connected_components

        key = np.packbits(ok).tobytes()
        if key not in self._cache:
            bad = np.flatnonzero(~ok)
            sub = self._adj[bad][:, bad]
            ncomp, comp = connected_components(sub, directed=False)
            touches = np.asarray(self._adj[bad][:, np.flatnonzero(ok)].sum(axis=1)).ravel() > 0
            reach = np.zeros(ncomp, bool)
            reach[comp[touches]] = True
            solvable = bad[reach[comp]]
            if solvable.size:
                lap = sp.diags(self._deg[solvable]) - self._adj[solvable][:, solvable]
                solver = spla.factorized(lap.tocsc())
                rhs_op = self._adj[solvable][:, np.flatnonzero(ok)]
            else:
                solver, rhs_op = None, None
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = (solvable, solver, rhs_op)
        solvable, solver, rhs_op = self._cache[key]
        if solver is not None:
            out[solvable] = solver(rhs_op @ out[ok])

    def run(self, rec: Recording) -> Recording:
        """Repair every frame of ``rec`` whose ``valid`` is False (continuing from the state).

        The result keeps ``valid`` False where values were repaired (marked), and the outcome
        codes (see :data:`OUTCOME`) in ``outcome_`` (T, N).
        """
        from texsense._progress import progress

        frames = np.empty(rec.frames.shape, dtype=np.float32)
        outcome = np.empty(rec.frames.shape, dtype=np.uint8)
        if self._core is not None:
            out = self._core.run(rec)
            self._last = np.where(np.isfinite(out.frames[-1]), out.frames[-1], self._last)
            self.outcome_ = self._core.outcome_
            return out._with(meta={**rec.meta, "repair": self.method})
        for k in progress(range(rec.n_frames), total=rec.n_frames, desc="repair", unit="frame"):
            frames[k], _ = self.step(rec.frames[k], rec.valid[k])
            outcome[k] = self.outcome_
        self.outcome_ = outcome
        return rec._with(
            frames=frames, valid=outcome == 0, meta={**rec.meta, "repair": self.method}
        )


def idw_weights(layout: Layout, reach: float = 1.5) -> Any:
    """Sparse (N, N) CSR weights 1/d² to the elements within ``reach`` pitches (no self;
    the ``idw8`` repair), with sorted indices per row."""
    import scipy.sparse as sp
    from scipy.spatial import cKDTree

    xy = np.asarray(layout.xy_cm, dtype=np.float64)
    n = xy.shape[0]
    if n < 2:
        return sp.csr_matrix((n, n))
    tree = cKDTree(xy)
    if layout.pitch_cm is not None:
        pitch = float(max(layout.pitch_cm))
    else:
        d, _ = tree.query(xy, k=2)
        pitch = float(np.median(d[:, 1]))
    pairs = tree.query_pairs(reach * pitch * (1 + 1e-9), output_type="ndarray")
    if pairs.size == 0:
        return sp.csr_matrix((n, n))
    d2 = np.sum((xy[pairs[:, 0]] - xy[pairs[:, 1]]) ** 2, axis=1)
    w = 1.0 / d2
    rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
    m = sp.csr_matrix((np.concatenate([w, w]), (rows, cols)), shape=(n, n))
    m.sort_indices()
    return m
