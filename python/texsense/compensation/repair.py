"""Repair of failed elements (thesis §6.5.2.5): the ``repair`` stage, :class:`Repair`.

Every method of :data:`METHODS` behind one stage:

- ``zero``: failed elements read 0 (what an unrepaired mat shows);
- ``last-value``: hold the last value seen (real or repaired);
- ``neighbour-mean``: eq. 6.14, ``p_i = (p_l + p_r + p_t + p_b) / n_a``, the mean of the
  available 4-neighbours;
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
("missing") where there is none yet. The four local methods run in the compiled kernel that
the pipeline's chain runs too (``crates/core/src/repair.rs``); the harmonic ones solve their
sparse systems in scipy. A repaired reading stays marked invalid in the output, so it is
never mistaken for a measured one; what happened to each reading is in ``outcome_``
(:data:`OUTCOME`).

Examples
--------
>>> import numpy as np
>>> from texsense import Layout
>>> rep = Repair(Layout.grid(3, 3), "neighbour-mean").fit()
>>> frame = np.array([0, 1, 0, 2, 99, 4, 0, 5, 0], dtype=float)
>>> valid = np.ones(9, bool); valid[4] = False
>>> values, measured = rep.step(frame, valid, t=0.0)
>>> float(values[4]), bool(measured[4])
(3.0, False)
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from texsense._core import LocalRepair
from texsense._progress import progress
from texsense.compensation.stage import Stage
from texsense.data.layout import Layout
from texsense.data.modelfile import Fields
from texsense.data.ranges import Instance, Kind, OneOf, Real
from texsense.exceptions import ParameterError

__all__ = ["METHODS", "OUTCOME", "Repair", "idw_weights", "local_repair"]

#: The repair methods of :class:`Repair`.
METHODS = ("zero", "last-value", "neighbour-mean", "idw8", "harmonic", "harmonic-temporal")

#: Methods that solve for all failed elements of a frame together (scipy, per frame).
GLOBAL_METHODS = ("harmonic", "harmonic-temporal")

#: Outcome codes per element and frame.
OUTCOME = {0: "measured", 1: "interpolated", 2: "last value", 3: "missing"}


def local_repair(layout: Layout, method: str) -> LocalRepair:
    """The compiled kernel of a local method (``zero``, ``last-value``, ``neighbour-mean``,
    ``idw8``) for ``layout``."""
    c = np.ascontiguousarray
    n = layout.n_elements
    if method == "neighbour-mean":
        indptr, indices = layout.neighbours
        return LocalRepair(method, n, c(indptr, dtype=np.int64), c(indices, dtype=np.int64))
    if method == "idw8":
        w = idw_weights(layout)
        return LocalRepair(
            "weighted", n, c(w.indptr, dtype=np.int64), c(w.indices, dtype=np.int64),
            c(w.data, dtype=np.float64),
        )  # fmt: skip
    if method in ("zero", "last-value"):
        return LocalRepair(method, n)
    raise ParameterError(f"{method!r} is not a local repair method")


class Repair(Stage):
    """The ``repair`` stage: failed readings filled by one of :data:`METHODS`, marked invalid
    in the output. Nothing to learn: :meth:`fit` prepares the method for the layout.

    Examples
    --------
    >>> import numpy as np
    >>> from texsense import Layout
    >>> lay = Layout.grid(3, 3)
    >>> frame = np.full(9, 2.0); frame[[1, 4]] = 0.0   # two neighbouring elements failed
    >>> valid = frame > 0
    >>> out, measured = Repair(lay, "harmonic").fit().step(frame, valid, t=0.0)
    >>> out.tolist(), np.flatnonzero(~measured).tolist()
    ([2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0], [1, 4])
    """

    name = "repair"

    #: the range of every parameter (:mod:`texsense.data.ranges`)
    ranges: ClassVar[Mapping[str, Kind]] = {"layout": Instance(Layout), "method": OneOf(METHODS)}

    #: learned: the number of elements the method was prepared for
    n_elements_: int
    #: what happened to each reading of the last frames (see OUTCOME)
    outcome_: np.ndarray

    def __init__(self, layout: Layout, method: str = "harmonic") -> None:
        self.layout = layout
        self.method = method

    def fit(self) -> Repair:
        """Nothing to learn: prepares the method for the layout."""
        return self.set_fitted(n_elements=self.layout.n_elements)

    def _prepare(self) -> None:
        if self.method not in METHODS:
            raise ParameterError(
                f"unknown repair method {self.method!r}; known: {', '.join(METHODS)}"
            )
        if self.n_elements_ != self.layout.n_elements:
            raise ParameterError(f"the layout has {self.layout.n_elements} elements")
        self._kernel = (
            None if self.method in GLOBAL_METHODS else local_repair(self.layout, self.method)
        )
        if self.method in GLOBAL_METHODS:
            self._harmonic = _Harmonic(self.layout)

    def _reset_stream(self) -> None:
        n = self.layout.n_elements
        self._last = np.full(n, np.nan)
        self._prev = np.full(n, np.nan)  # the previous output frame
        if self._kernel is not None:
            self._kernel.reset()

    def _block(
        self, values: np.ndarray, valid: np.ndarray, dt: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        if self._kernel is not None:
            out, self.outcome_ = self._kernel.run(values, valid)
            return out, valid.copy()
        out = np.empty_like(values)
        outcome = np.empty(values.shape, np.uint8)
        rows: Iterable[int] = range(values.shape[0])
        if values.shape[0] > 100:  # a bar for long recordings, nothing per live frame
            rows = progress(rows, total=values.shape[0], desc="repair", unit="frame")
        for k in rows:
            out[k], outcome[k] = self._fill(values[k], valid[k])
        self.outcome_ = outcome
        return out, valid.copy()

    def _fill(self, x: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One frame of a harmonic method."""
        if ok.all() and np.isfinite(x).all():  # nothing to fill (a station's every frame)
            out = x.copy()
            self._last = out.copy()
            self._prev = out.copy()
            return out, np.zeros(x.shape, np.uint8)
        out = np.where(ok, x, np.nan)
        outcome = np.where(ok, 0, 1).astype(np.uint8)
        bad = ~ok
        if bad.any():
            self._harmonic.solve(out, ok)
            if self.method == "harmonic-temporal" and np.all(np.isfinite(self._prev)):
                prev = np.where(ok, self._prev, np.nan)
                self._harmonic.solve(prev, ok)
                step = bad & np.isfinite(out) & np.isfinite(prev)
                out[step] = self._prev[step] + (out[step] - prev[step])
                if np.all(x[ok] >= 0):
                    out[step] = np.maximum(out[step], 0.0)
            left = bad & ~np.isfinite(out)
            out[left] = self._last[left]
            outcome[left] = 2
            outcome[left & ~np.isfinite(out)] = 3
        self._last = np.where(np.isfinite(out), out, self._last)
        self._prev = out.copy()
        return out, outcome

    def _fitted_json(self) -> dict[str, Any]:
        return {"n_elements": int(self.n_elements_)}

    @classmethod
    def _fitted_from_json(cls, fields: Fields, params: Mapping[str, Any]) -> dict[str, Any]:
        layout = params["layout"]
        n = fields.number("n_elements", layout.n_elements, within=Real(1, 2**31))
        return {"n_elements": int(n)}


class _Harmonic:
    """Laplace inpainting of the failed elements of a frame: solve ``L_FF x_F = A_FV v_V``
    for the failed elements connected to a valid one (a factorisation per failure pattern,
    reused while the pattern stays).

    The system of a new pattern is built from the neighbour graph's arrays (numpy index
    arithmetic, no sparse slicing) and the right-hand side is one product with the whole
    graph: the matrix, its factorisation and the solution are the same to the bit as those
    of slicing the graph's sparse matrix (``tests/test_repair_harmonic.py``), at a fraction
    of the cost (a failure pattern that changes every frame, as on a mat with intermittent
    contacts, is factorised every frame). ``factorisations`` and ``hits`` count the work."""

    #: failure patterns kept (the oldest go first)
    CACHE_MAX = 64

    def __init__(self, layout: Layout) -> None:
        import scipy.sparse as sp

        n = layout.n_elements
        indptr, indices = layout.neighbours
        adj = sp.csr_matrix((np.ones(indices.size), indices, indptr), shape=(n, n))
        self._adj = ((adj + adj.T) > 0).astype(np.float64).tocsr()
        self._adj.sort_indices()
        self._deg = np.asarray(self._adj.sum(axis=1)).ravel()
        # the graph's edges (both directions), by row then column
        self._rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(self._adj.indptr))
        self._cols = self._adj.indices.astype(np.int64)
        self._n = n
        self._cache: dict[bytes, tuple[Any, Any]] = {}
        self.factorisations = 0
        self.hits = 0

    def solve(self, out: np.ndarray, ok: npt.NDArray[np.bool_]) -> None:
        """Fill ``out`` where not ``ok`` (in place), from its values where ``ok``."""
        key = np.packbits(ok).tobytes()
        entry = self._cache.pop(key, None)
        if entry is None:
            if len(self._cache) >= self.CACHE_MAX:
                del self._cache[next(iter(self._cache))]
            entry = self._factorise(ok)
            self.factorisations += 1
        else:
            self.hits += 1
        self._cache[key] = entry  # the most recent last
        solvable, solver = entry
        if solver is not None:
            # A_FV v_V: the sum of each element's valid neighbours (failed ones add 0)
            rhs = self._adj @ np.where(ok, out, 0.0)
            out[solvable] = solver(rhs[solvable])

    def _solvable(self, ok: np.ndarray) -> np.ndarray:
        """The failed elements connected to a valid one through failed ones (sorted)."""
        bad = ~ok
        from_bad = bad[self._rows]
        reach = np.zeros(self._n, bool)
        reach[self._rows[from_bad & ok[self._cols]]] = True  # next to a valid element
        rows, cols = self._rows[from_bad & bad[self._cols]], self._cols[from_bad & bad[self._cols]]
        while True:  # spread through failed neighbours (as many rounds as a cluster is wide)
            more = rows[reach[cols] & ~reach[rows]]
            if not more.size:
                return np.flatnonzero(reach)
            reach[more] = True

    def _factorise(self, ok: np.ndarray) -> tuple[Any, Any]:
        import scipy.sparse as sp
        import scipy.sparse.linalg as spla

        solvable = self._solvable(ok)
        m = solvable.size
        if not m:
            return solvable, None
        pos = np.full(self._n, -1, dtype=np.int64)
        pos[solvable] = np.arange(m)
        r, c = pos[self._rows], pos[self._cols]
        inner = (r >= 0) & (c >= 0)
        # L_FF = diag(deg) - A_FF: symmetric, so its rows are its columns (CSC = CSR)
        rr = np.concatenate([r[inner], np.arange(m)])
        cc = np.concatenate([c[inner], np.arange(m)])
        data = np.concatenate([np.full(int(inner.sum()), -1.0), self._deg[solvable]])
        order = np.argsort(rr * m + cc, kind="stable")
        indptr = np.concatenate([[0], np.cumsum(np.bincount(rr, minlength=m))])
        lap = sp.csc_matrix((data[order], cc[order].astype(np.int32), indptr.astype(np.int32)),
                            shape=(m, m))  # fmt: skip
        return solvable, spla.splu(lap).solve


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
