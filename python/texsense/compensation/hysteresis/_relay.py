"""Identification as a grid of smeared relays with non-negative weights (exact monotonicity).

The classical Preisach model (thesis eq. 4.6) is a weighted sum of relays; with a
non-negative density it is monotone between extrema and obeys wiping-out and congruent
minor loops by construction. Here the relays are grouped into cells of a **non-uniform**
grid in (α, β): nodes ``n_0 = u_min < n_1 < ... < n_{m-1} = u_max``; cell ``(a, b)``
(``a >= b``) holds relays whose up-switching input is spread uniformly over
``[n_a, n_{a+1}]`` and whose down-switching input over ``[n_b, n_{b+1}]`` (the diagonal
cells over the lower triangle). Its weight ``w_ab`` is the Preisach mass of the cell, and the
Everett function at the nodes is the mass of the triangle under them (eq. 4.12/4.14):

    F(n_i, n_j) = Σ_{j <= b <= a < i} w_ab,

bilinear in between (the smeared relays make it so), which is the interpolation of the Rust
core. The model's output along any record is linear in ``w`` (eq. 4.15/4.16: the extremum
stack depends on the input alone), so the weights are found by non-negative least squares
with a small ridge: **non-negative density per cell** — the exact condition, not a
sufficient one — and the unknowns are the cells of the Preisach triangle only.

- **Resolution where the data are.** The nodes are quantiles of a mixture of the record's
  inputs, its turning points and (where the output changes fastest) its output increments,
  blended with a uniform share so that no part of the range is left without a node.
- **Well conditioned.** The problem is formed once as a Gram matrix over the cells
  (``m (m - 1) / 2`` unknowns, 1770 for 60 nodes) and solved by projected Newton steps on the
  active set (:func:`nonnegative_qp`); held-out folds subtract their Gram matrix.
- **Signed density** (``signed=True``): the same grid without the bound (ridge only) — an
  interacting magnetic system's density has negative parts. It is a candidate only where the
  record's own cross-validation asks for it (see :mod:`._identify`).

A non-negative density gives counter-clockwise loops (the output on a rising branch below
the falling one, as for magnetisation against field). A spacer's loops run the other way
(loading above unloading): this identification is then not a candidate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits

from texsense._core import everett_terms
from texsense.compensation.hysteresis._lsq import spread_bilinear
from texsense.compensation.hysteresis._segments import reversal_indices

if TYPE_CHECKING:
    from scipy.sparse import csr_matrix

__all__ = [
    "RelayFit",
    "cell_map",
    "loop_orientation",
    "nonnegative_qp",
    "nonuniform_design",
    "record_nodes",
    "resample_table",
]


def loop_orientation(u: npt.NDArray[np.float64], p: npt.NDArray[np.float64]) -> float:
    """``-∮ p du`` over the record divided by ``ptp(u) ptp(p)``: positive for
    counter-clockwise loops (magnetisation against field), negative for clockwise ones (a
    spacer: loading above unloading), about 0 without hysteresis."""
    area = float(np.sum(0.5 * (p[1:] + p[:-1]) * np.diff(u)))
    scale = max(float(np.ptp(u)) * float(np.ptp(p)), 1e-300)
    return -area / scale


def record_nodes(
    u: npt.NDArray[np.float64],
    p: npt.NDArray[np.float64],
    count: int,
    uniform_share: float = 0.25,
    tolerance: float | None = None,
) -> np.ndarray:
    """``count`` nodes over ``[min u, max u]`` placed by the record: the quantile function of
    a mixture of the inputs, the turning points and the inputs weighted by the output's
    change there (where switching happens), blended with a uniform spread of weight
    ``uniform_share``. Strictly increasing; the ends are the range of the record."""
    lo, hi = float(u.min()), float(u.max())
    span = hi - lo
    tol = 0.01 * span if tolerance is None else tolerance
    turns = u[reversal_indices(u, tol)] if u.size > 2 else u[:0]
    dp = np.abs(np.diff(p, prepend=p[0]))
    q = np.linspace(0.0, 1.0, count)

    def quantiles(x: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
        if x.size == 0:
            return lo + q * span
        order = np.argsort(x)
        xs = x[order]
        ws = np.ones(xs.size) if w is None else w[order] + 1e-12
        c = np.cumsum(ws)
        c = (c - c[0]) / max(c[-1] - c[0], 1e-300)
        return np.interp(q, c, xs)

    mix = (quantiles(u) + quantiles(turns) + quantiles(u, dp)) / 3.0
    nodes = (1.0 - uniform_share) * mix + uniform_share * (lo + q * span)
    nodes[0], nodes[-1] = lo, hi
    gap = 1e-3 * span / count
    for k in range(1, count):  # strictly increasing, at least a small gap apart
        nodes[k] = max(nodes[k], nodes[k - 1] + gap)
    if nodes[-1] > hi:  # squeezed against the top: spread the last ones back below it
        nodes = lo + (nodes - lo) * (span / (nodes[-1] - lo))
    nodes[-1] = hi
    return nodes


def nonuniform_design(u: npt.NDArray[np.float64], nodes: npt.NDArray[np.float64]) -> csr_matrix:
    """Design (T x m(m-1)/2) over the node values ``F[i, j]`` (i > j, column
    ``i (i - 1) / 2 + j``) on non-uniform nodes: the Rust core's Everett terms (eq.
    4.15/4.16) interpolated bilinearly, linearly on the lower triangle of a diagonal cell.
    Output at ``u_min`` = 0."""
    from scipy.sparse import csr_matrix  # heavy: imported where a fit needs it

    m = nodes.size
    indptr, alpha, beta, coef = everett_terms(
        np.ascontiguousarray(u, dtype=np.float64), float(nodes[0]), float(nodes[-1])
    )
    counts: np.ndarray = np.diff(np.asarray(indptr, dtype=np.int64))
    row = np.repeat(np.arange(u.size), counts)
    i0 = np.clip(np.searchsorted(nodes, alpha, side="right") - 1, 0, m - 2)
    j0 = np.clip(np.searchsorted(nodes, beta, side="right") - 1, 0, m - 2)
    wa = np.clip((alpha - nodes[i0]) / (nodes[i0 + 1] - nodes[i0]), 0.0, 1.0)
    wb = np.clip((beta - nodes[j0]) / (nodes[j0 + 1] - nodes[j0]), 0.0, 1.0)
    r, ii, jj, ww = spread_bilinear(row, i0, j0, wa, wb, coef)
    return csr_matrix((ww, (r, ii * (ii - 1) // 2 + jj)), shape=(u.size, m * (m - 1) // 2))


def cell_map(m: int) -> csr_matrix:
    """``F = T w``: node values ``F[i, j]`` (i > j) from cell weights ``w[a, b]`` (a >= b,
    cell column ``a (a + 1) / 2 + b``), ``F[i, j] = Σ_{j <= b <= a < i} w[a, b]``."""
    from scipy.sparse import csr_matrix  # heavy: imported where a fit needs it

    rows, cols = [], []
    for i in range(1, m):
        for j in range(i):
            r = i * (i - 1) // 2 + j
            for a in range(j, i):
                b = np.arange(j, a + 1)
                rows.append(np.full(b.size, r))
                cols.append(a * (a + 1) // 2 + b)
    rr, cc = np.concatenate(rows), np.concatenate(cols)
    n = m * (m - 1) // 2
    return csr_matrix((np.ones(rr.size), (rr, cc)), shape=(n, n))


def _tri(m: int, diagonal: bool) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of the entries of an m x m lower triangle in packed order."""
    k = 0 if diagonal else 1
    i = np.repeat(np.arange(k, m), np.arange(1, m - k + 1))
    j = np.concatenate([np.arange(r + 1 - k) for r in range(k, m)]) if m > k else i[:0]
    return i, j


def cells_to_nodes(w: np.ndarray, m: int) -> np.ndarray:
    """``T w`` for columns of cell weights (n, K) or (n,): two cumulative sums."""
    one = w.ndim == 1
    w2 = w[:, None] if one else w
    a, b = _tri(m - 1, diagonal=True)
    W = np.zeros((m - 1, m - 1, w2.shape[1]))
    W[a, b] = w2
    C = np.cumsum(np.cumsum(W[:, ::-1], axis=1)[:, ::-1], axis=0)  # Σ_{a<=a'} Σ_{b>=j}
    i, j = _tri(m, diagonal=False)
    out = C[i - 1, j]
    return out[:, 0] if one else out


def nodes_to_cells(y: np.ndarray, m: int) -> np.ndarray:
    """``Tᵀ y`` for columns (n, K) or (n,) over the node values: the adjoint sums."""
    one = y.ndim == 1
    y2 = y[:, None] if one else y
    i, j = _tri(m, diagonal=False)
    Y = np.zeros((m - 1, m - 1, y2.shape[1]))
    Y[i - 1, j] = y2
    V = np.cumsum(np.cumsum(Y[::-1], axis=0)[::-1], axis=1)  # Σ_{a'>=a} Σ_{j<=b}
    a, b = _tri(m - 1, diagonal=True)
    out = V[a, b]
    return out[:, 0] if one else out


def nonnegative_qp(
    H: npt.NDArray[np.float64],
    g: npt.NDArray[np.float64],
    max_iter: int = 200,
    tol: float = 1e-10,
    start: np.ndarray | None = None,
) -> np.ndarray:
    """``min ½ wᵀHw - gᵀw`` subject to ``w >= 0`` (H symmetric positive definite) by a
    primal active-set method with Newton steps on the free set (Lawson–Hanson in Gram form,
    several variables freed at once): exact at convergence, each step one Cholesky
    factorisation of the free block. ``start`` (bool mask) warm-starts from the free set of
    a similar problem (a held-out fold of the same record)."""
    n = g.size
    w = np.zeros(n)
    free = np.zeros(n, dtype=bool)
    scale = max(float(np.abs(g).max()), 1e-300)
    if start is not None and start.any():  # warm start: the free set of a similar problem
        w, free = _inner(H, g, w, start.copy())
    for _ in range(max_iter):
        grad = g - H @ w  # negative gradient
        cand = (~free) & (grad > tol * scale)
        if not cand.any():
            break
        # free the bound variables whose gradient points inward (the strongest half first);
        # those whose Newton value comes out <= 0 go back to the bound at once, and if that
        # leaves none, only the strongest one is freed (the Lawson-Hanson step, which
        # always makes progress)
        idx = np.nonzero(cand)[0]
        if idx.size > 1:
            idx = idx[grad[idx] >= np.quantile(grad[idx], 0.5)]
        best = idx[np.argmax(grad[idx])]
        before = free.copy()
        w, free = _inner(H, g, w, free | np.isin(np.arange(n), idx))
        if not (free & ~before).any():  # the batch made no progress: one at a time
            before[best] = True
            w, free = _inner(H, g, w, before)
            if not free[best]:
                break
    return w


def _inner(
    H: np.ndarray, g: np.ndarray, w: np.ndarray, free: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Lawson-Hanson's inner loop: Newton step on the free set, back along the segment
    until the first free variable reaches its bound, which leaves the set; repeat."""
    free = free.copy()
    while free.any():
        z = _free_solve(H, g, free)
        f = np.nonzero(free)[0]
        if np.all(z[f] > 0):
            return z, free
        neg = f[z[f] <= 0]
        ratio = w[neg] / np.maximum(w[neg] - z[neg], 1e-300)
        k = int(np.argmin(ratio))
        w = w + float(ratio[k]) * (z - w)
        hit = neg[ratio <= ratio[k] * (1 + 1e-12) + 1e-300]
        free[hit] = False
        w[~free] = 0.0
        w = np.maximum(w, 0.0)
    return np.zeros_like(w), free


def _free_solve(H: np.ndarray, g: np.ndarray, free: np.ndarray) -> np.ndarray:
    """The unconstrained minimiser over the free variables (the others at 0)."""
    from scipy.linalg import cho_factor, cho_solve  # heavy: imported where a fit needs it

    z = np.zeros(g.size)
    f = np.nonzero(free)[0]
    if f.size:
        z[f] = cho_solve(cho_factor(H[np.ix_(f, f)], check_finite=False), g[f])
    return z


@dataclass
class RelayFit:
    """Cell weights on a node grid: the Everett node values, the offset and the fit RMSE."""

    nodes: np.ndarray
    weights: np.ndarray
    offset: float
    signed: bool

    def node_table(self) -> np.ndarray:
        """F on the node grid (m x m, zero on and above the diagonal)."""
        m = self.nodes.size
        f = cells_to_nodes(self.weights, m)
        table = np.zeros((m, m))
        i = np.repeat(np.arange(1, m), np.arange(1, m))
        j = np.concatenate([np.arange(k) for k in range(1, m)])
        table[i, j] = f
        return table


class RelayProblem:
    """The Gram matrices of one record on one node grid (whole and per held-out fold)."""

    def __init__(
        self,
        u: np.ndarray,
        p: np.ndarray,
        nodes: np.ndarray,
        fold: np.ndarray,
    ) -> None:
        self.nodes = nodes
        m = nodes.size
        A = nonuniform_design(u, nodes)
        self.m = m
        self.design = A  # over the node values: output = offset + A (T w)
        ones = np.ones(u.size)
        self.u, self.p, self.fold = u, p, fold
        self.n_folds = int(fold.max()) + 1
        self.active: dict[float, np.ndarray] = {}  # free set of the whole record's solve

        def gram(rows: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, int]:
            Ar = A if rows is None else A[rows]
            pr = p if rows is None else p[rows]
            o = ones if rows is None else ones[rows]
            M = (Ar.T @ Ar).toarray()
            MT = nodes_to_cells(np.ascontiguousarray(nodes_to_cells(M, m).T), m)  # Tᵀ M T
            at1 = nodes_to_cells(Ar.T @ o, m)
            n = MT.shape[0]
            G = np.empty((n + 1, n + 1))
            G[:n, :n] = 0.5 * (MT + MT.T)
            G[:n, n] = G[n, :n] = at1
            G[n, n] = float(o.size)
            b = np.concatenate([nodes_to_cells(Ar.T @ pr, m), [float(pr.sum())]])
            return G, b, int(o.size)

        with threadpool_limits(1, "blas"):
            self.whole = gram(None)
            self.folds = [gram(np.nonzero(fold == f)[0]) for f in range(self.n_folds)]

    def solve(self, ridge: float, signed: bool, exclude: int | None = None) -> np.ndarray:
        """Weights (cells, then the offset) without the held-out fold ``exclude``."""
        from scipy.linalg import cho_factor, cho_solve  # heavy: imported where a fit needs it

        G, b, count = self.whole
        if exclude is not None:
            G0, b0, n0 = self.folds[exclude]
            G, b, count = G - G0, b - b0, count - n0
        G = G / count
        b = b / count
        n = G.shape[0] - 1
        scale = np.trace(G[:n, :n]) / n
        H = G.copy()
        H[np.arange(n), np.arange(n)] += ridge * scale
        H[n, n] += 1e-12 * max(H[n, n], 1e-300)
        with threadpool_limits(1, "blas"):
            if signed:
                return cho_solve(cho_factor(H, check_finite=False), b, check_finite=False)
            # the offset is free: shift it to a bounded variable by eliminating it exactly
            # (Schur complement), then solve the bounded problem over the cells
            h = H[:n, n] / H[n, n]
            Hs = H[:n, :n] - np.outer(h, H[n, :n])
            gs = b[:n] - h * b[n]
            w = nonnegative_qp(0.5 * (Hs + Hs.T), gs, start=self.active.get(ridge))
            if exclude is None:
                self.active[ridge] = w > 0
            off = (b[n] - H[n, :n] @ w) / H[n, n]
            return np.concatenate([w, [off]])

    def sse(self, x: np.ndarray, rows: np.ndarray) -> float:
        """Sum of squared errors of solution ``x`` on the given samples."""
        pred = self.design[rows] @ cells_to_nodes(x[:-1], self.m) + x[-1]
        return float(np.sum((pred - self.p[rows]) ** 2))

    def fold_errors(self, ridge: float, signed: bool) -> np.ndarray:
        """Held-out mean squared error of every fold (the folds warm-started from the whole
        record's solution)."""
        if not signed and ridge not in self.active:
            self.solve(ridge, signed)
        out = []
        for f in range(self.n_folds):
            rows = np.nonzero(self.fold == f)[0]
            x = self.solve(ridge, signed, f)
            out.append(self.sse(x, rows) / max(rows.size, 1))
        return np.asarray(out)


def resample_table(fit: RelayFit, grid: int, u_min: float, u_max: float) -> np.ndarray:
    """The relay model's Everett function sampled on the uniform ``grid x grid`` table that
    the Rust core evaluates (bilinear on the node grid, as identified)."""
    table = fit.node_table()
    x = np.linspace(u_min, u_max, grid)
    nodes = fit.nodes
    m = nodes.size
    i0 = np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, m - 2)
    t = np.clip((x - nodes[i0]) / (nodes[i0 + 1] - nodes[i0]), 0.0, 1.0)
    out = np.zeros((grid, grid))
    ia, ib = np.meshgrid(np.arange(grid), np.arange(grid), indexing="ij")
    a0, b0 = i0[ia], i0[ib]
    ta, tb = t[ia], t[ib]
    diag = a0 == b0
    val = (
        (1 - ta) * (1 - tb) * table[a0, b0]
        + (1 - ta) * tb * table[a0, b0 + 1]
        + ta * (1 - tb) * table[a0 + 1, b0]
        + ta * tb * table[a0 + 1, b0 + 1]
    )
    # the diagonal cell: linear on its lower triangle, F(n_a+1, n_a) scaled by (ta - tb)
    val = np.where(diag, table[np.minimum(a0 + 1, m - 1), a0] * np.clip(ta - tb, 0, None), val)
    out[:] = val
    return np.tril(out, -1)
