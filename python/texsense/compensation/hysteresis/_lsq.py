"""Least-squares identification of a monotone Everett table from any record.

The output of the numerical Preisach model is linear in the Everett function (eq. 4.15/4.16:
the extremum stack depends on the input alone), so a table is identified by linear least
squares. Three choices make it hold on records nobody here designed:

- **Where the resolution goes.** The unknowns are values of ``F`` on a coarse grid in
  ``(α, d)``, ``d = α - β`` the distance fallen since the maximum, with the d-nodes denser next
  to the diagonal (``spacing`` > 1): a spacer's falling branch starts steeply over a fixed
  compression distance (friction reversing), which a uniform ``(α, β)`` grid of a few dozen
  cells cannot resolve. The coarse values are interpolated bilinearly onto the fine
  ``grid x grid`` table that the Rust core evaluates; ``F(α, α) = 0`` holds by construction.
- **Monotone by construction.** The fine table must be non-decreasing in α and
  non-increasing in β (the output is then monotone between extrema, eq. 4.16/4.17). These
  are linear inequalities on the unknowns, and the quadratic program is solved by an
  interior-point method whose iterates stay strictly feasible (:mod:`._qp`): no clipping
  after the fact. The orientation of the loops is free (clockwise for a spacer, whose
  loading branch lies above unloading; counter-clockwise for magnetic material).
- **Chosen by the record itself.** The grid, the node spacing and the curvature penalty are
  chosen by cross-validation on held-out reversal curves of the same record: the record's
  monotone branches (every turning point) are dealt to ``folds`` folds in turn; a candidate
  is fitted with the whole input history (so every sample keeps its true extremum stack) but
  only the other folds' samples in the loss, and scored by the RMSE on the held-out branches.
  The chosen candidate is refitted on all samples. A prior table (the thesis method's, when
  the record holds its curves) can fill the parts of the Preisach triangle that the record
  never visits, with a small fixed weight.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits

from texsense._core import everett_terms
from texsense.compensation.hysteresis._qp import solve_monotone_qp
from texsense.compensation.hysteresis._segments import split_branches
from texsense.exceptions import ParameterError

if TYPE_CHECKING:
    from scipy.sparse import csr_matrix

__all__ = ["Candidate", "LsqResult", "design_entries", "fit_everett_lsq", "lower_design"]

# the cross-validated search (coordinate-wise, from the middle candidate)
SIZES: tuple[tuple[int, int], ...] = ((10, 10), (16, 16), (24, 24))
SMOOTHINGS: tuple[float, ...] = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2)
PRIOR_WEIGHTS: tuple[float, ...] = (0.0, 1e-3, 1e-2)


@dataclass(frozen=True)
class Candidate:
    """One setting of the identification: coarse grid, node spacing, curvature penalty."""

    alpha_cells: int
    d_cells: int
    spacing: float
    smoothing: float
    prior_weight: float = 0.0

    def as_dict(self) -> dict[str, float]:
        """JSON-able form."""
        return {
            "alpha_cells": self.alpha_cells,
            "d_cells": self.d_cells,
            "spacing": self.spacing,
            "smoothing": self.smoothing,
            "prior_weight": self.prior_weight,
        }

    def but(self, **changes: Any) -> Candidate:
        """A copy with some settings changed."""
        return replace(self, **changes)


@dataclass
class LsqResult:
    """The identified fine table (lower triangle filled), output offset and how it was chosen."""

    table: npt.NDArray[np.float64]
    offset: float
    chosen: Candidate
    validation_rmse: float | None
    scores: list[tuple[Candidate, float]]
    fit_rmse: float
    folds: int
    fold_mse: list[float] | None = None  # held-out MSE of every fold, chosen setting
    #: the chosen setting's prediction of every held-out sample by the fit without its fold
    #: (NaN for samples that always train); None when nothing was held out
    held_out: npt.NDArray[np.float64] | None = None


def _lower_index(k: int) -> tuple[np.ndarray, np.ndarray]:
    """Row (α) and column (β) of the free entries ``i > j`` of a k x k table, in the order
    of the column index ``i (i - 1) / 2 + j``."""
    i = np.repeat(np.arange(1, k), np.arange(1, k))
    j = np.concatenate([np.arange(n) for n in range(1, k)]) if k > 1 else np.zeros(0, int)
    return i, j


def design_entries(
    u: npt.NDArray[np.float64], nodes: npt.NDArray[np.float64]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The model's output along ``u`` as weighted table entries: (sample, i, j, weight) with
    ``output[t] = Σ weight F[i, j]`` over the entries of sample t (i > j), from the Rust
    core's Everett terms (eq. 4.15/4.16) and its interpolation (bilinear; linear on the lower
    triangle of the diagonal cells); output at ``u_min`` = 0."""
    k = nodes.size
    indptr, alpha, beta, coef = everett_terms(
        np.ascontiguousarray(u, dtype=np.float64), float(nodes[0]), float(nodes[-1])
    )
    row = np.repeat(np.arange(u.size), np.diff(indptr.astype(np.int64)).astype(np.intp))
    step = nodes[1] - nodes[0]
    a = np.clip((alpha - nodes[0]) / step, 0.0, k - 1)
    b = np.clip((beta - nodes[0]) / step, 0.0, k - 1)
    i0 = np.minimum(a.astype(np.int64), k - 2)
    j0 = np.minimum(b.astype(np.int64), k - 2)
    wa, wb = a - i0, b - j0
    return spread_bilinear(row, i0, j0, wa, wb, coef)


def spread_bilinear(
    row: np.ndarray,
    i0: np.ndarray,
    j0: np.ndarray,
    wa: np.ndarray,
    wb: np.ndarray,
    coef: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each term ``coef`` at the point (α, β) in the cell (i0, j0) of a node grid, with
    fractions ``wa``, ``wb`` across the cell, spread bilinearly over the cell's corners:
    (row, node i, node j, weight) for the corners strictly inside the Preisach triangle
    (i > j). A point in a diagonal cell (i0 == j0) lies on the triangle's edge, where the
    Everett function is 0: it falls on the corner (i0 + 1, j0) with weight wa - wb."""
    on_diag = i0 == j0
    off = ~on_diag
    parts = [(row[on_diag], i0[on_diag] + 1, j0[on_diag], coef[on_diag] * (wa - wb)[on_diag])]
    for di, dj, w in (
        (0, 0, (1 - wa) * (1 - wb)),
        (0, 1, (1 - wa) * wb),
        (1, 0, wa * (1 - wb)),
        (1, 1, wa * wb),
    ):
        parts.append((row[off], i0[off] + di, j0[off] + dj, coef[off] * w[off]))
    r, ii, jj, ww = (np.concatenate(x) for x in zip(*parts, strict=True))
    keep = (ii > jj) & (ww != 0)
    return r[keep], ii[keep], jj[keep], ww[keep]


def lower_design(u: npt.NDArray[np.float64], nodes: npt.NDArray[np.float64]) -> csr_matrix:
    """Design matrix (T x K(K-1)/2) over the free table entries ``F[i, j]`` (i > j, column
    ``i (i - 1) / 2 + j``); see :func:`design_entries`."""
    from scipy.sparse import csr_matrix  # heavy: imported where a fit needs it

    k = nodes.size
    r, i, j, w = design_entries(u, nodes)
    return csr_matrix((w, (r, i * (i - 1) // 2 + j)), shape=(u.size, k * (k - 1) // 2))


def _shape_constraints(alpha_cells: int, d_nodes: np.ndarray) -> csr_matrix:
    """Rows ``c`` with ``c · θ >= 0`` on the coarse unknowns that make the interpolated
    surface ``B(α, d)`` (``F(α, β) = B(α, α - β)``) monotone everywhere, hence every table
    sampled from it:

    - ``B`` non-decreasing in d at every α node (bilinear interpolation keeps it within
      cells): ``F`` non-increasing in β;
    - ``∂B/∂α + ∂B/∂d >= 0`` at the four corners of every cell (the sum is affine in the
      cell, so its minimum is at a corner): ``F`` non-decreasing in α at fixed β.
    """
    from scipy.sparse import csr_matrix  # heavy: imported where a fit needs it

    na, nd = alpha_cells + 1, d_nodes.size - 1
    h_a = 1.0 / alpha_cells

    def idx(a: int, b: int) -> int:
        return a * nd + b - 1  # b >= 1; node b = 0 is the fixed zero

    rows: list[int] = []
    cols: list[int] = []
    vals: list[float] = []
    r = 0

    def add(terms: dict[tuple[int, int], float]) -> None:
        nonlocal r
        for (a, b), v in terms.items():
            if b >= 1 and v != 0.0:
                rows.append(r)
                cols.append(idx(a, b))
                vals.append(v)
        r += 1

    for a in range(na):
        for b in range(1, nd + 1):
            add({(a, b): 1.0, (a, b - 1): -1.0})
    for a in range(na - 1):
        for b in range(nd):
            h_d = d_nodes[b + 1] - d_nodes[b]
            for ca in (0, 1):  # corner (a + ca, b + cb)
                for cb in (0, 1):
                    t: dict[tuple[int, int], float] = {}
                    # ∂B/∂α along the d-edge of the corner, ∂B/∂d along its α-edge
                    for key, v in (
                        ((a + 1, b + cb), 1.0 / h_a),
                        ((a, b + cb), -1.0 / h_a),
                        ((a + ca, b + 1), 1.0 / h_d),
                        ((a + ca, b), -1.0 / h_d),
                    ):
                        t[key] = t.get(key, 0.0) + v
                    add(t)
    return csr_matrix((vals, (rows, cols)), shape=(r, na * nd))


def _d_nodes(cells: int, spacing: float) -> np.ndarray:
    """Fall distances as fractions of the input span, 0 .. 1, denser near 0 for spacing > 1."""
    return np.linspace(0.0, 1.0, cells + 1) ** spacing


def _shape_map(k: int, alpha_cells: int, d_nodes: np.ndarray) -> csr_matrix:
    """Fine free entries <- coarse unknowns on (α node, d node ≥ 1); bilinear in (α, d)."""
    from scipy.sparse import csr_matrix  # heavy: imported where a fit needs it

    i, j = _lower_index(k)
    x = np.linspace(0.0, 1.0, k)
    a = np.clip(x[i] * alpha_cells, 0.0, alpha_cells * (1 - 1e-12))
    a0 = a.astype(np.int64)
    wa = a - a0
    d = x[i] - x[j]
    nd = d_nodes.size
    b0 = np.clip(np.searchsorted(d_nodes, d, side="right") - 1, 0, nd - 2)
    wb = (d - d_nodes[b0]) / (d_nodes[b0 + 1] - d_nodes[b0])
    r = np.arange(i.size)
    rows, cols, vals = [], [], []
    for da, db, w in (
        (0, 0, (1 - wa) * (1 - wb)),
        (1, 0, wa * (1 - wb)),
        (0, 1, (1 - wa) * wb),
        (1, 1, wa * wb),
    ):
        bb = b0 + db
        keep = (bb >= 1) & (w != 0)  # d node 0 is the diagonal, where F = 0
        rows.append(r[keep])
        cols.append((a0[keep] + da) * (nd - 1) + bb[keep] - 1)
        vals.append(w[keep])
    return csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(i.size, (alpha_cells + 1) * (nd - 1)),
    )


def _curvature(alpha_cells: int, d_nodes: np.ndarray) -> csr_matrix:
    """Second differences of the coarse unknowns along α and along d (divided differences on
    the non-uniform d-nodes, scaled to a uniform step), one row each."""
    from scipy.sparse import csr_matrix  # heavy: imported where a fit needs it

    na, nd = alpha_cells + 1, d_nodes.size - 1
    h = (d_nodes[-1] - d_nodes[0]) / nd
    rows, cols, vals = [], [], []
    r = 0

    def idx(a: int, b: int) -> int:
        return a * nd + b - 1

    for a in range(na):
        for b in range(1, nd + 1):
            if 0 < a < na - 1:
                rows += [r, r, r]
                cols += [idx(a - 1, b), idx(a, b), idx(a + 1, b)]
                vals += [1.0, -2.0, 1.0]
                r += 1
            if b < nd:
                h1 = d_nodes[b] - d_nodes[b - 1]
                h2 = d_nodes[b + 1] - d_nodes[b]
                c1, c2 = 2 * h * h / (h1 * (h1 + h2)), 2 * h * h / (h2 * (h1 + h2))
                if b > 1:  # the d = 0 node is the fixed zero on the diagonal
                    rows.append(r)
                    cols.append(idx(a, b - 1))
                    vals.append(c1)
                rows += [r, r]
                cols += [idx(a, b), idx(a, b + 1)]
                vals += [-(c1 + c2), c2]
                r += 1
    return csr_matrix((vals, (rows, cols)), shape=(r, na * nd))


def branch_folds(u: npt.NDArray[np.float64], folds: int, tolerance: float) -> np.ndarray:
    """Fold of every sample, -1 for samples that always stay in training.

    Branches that span at least 97 % of the input range (the major loop: no model can
    extrapolate it, and holding it out measures nothing about interpolation between reversal
    curves) always train. The other branches, taken in consecutive pairs (a reversal curve
    and the branch that follows it), are dealt to the folds in turn; fewer pairs than folds
    give fewer folds, and fewer than two pairs none.
    """
    branches = split_branches(u, tolerance)
    fold = np.full(u.size, -1, dtype=np.int64)
    span = float(np.ptp(u))
    minor = [b for b in branches if abs(u[b.stop] - u[b.start]) < 0.97 * span]
    pairs = [minor[k : k + 2] for k in range(0, len(minor), 2)]
    n_folds = min(folds, len(pairs))
    if n_folds < 2:
        return fold
    for n, pair in enumerate(pairs):
        for b in pair:
            fold[b.start : b.stop + 1] = n % n_folds
    return fold


@dataclass
class _System:
    """What one grid setting of a record needs: the design over the coarse unknowns (plus the
    offset column), the map onto the fine table, the per-fold and whole Gram matrices, the
    curvature and prior penalties, the shape constraints and a strictly feasible start."""

    design: csr_matrix
    shape_map: csr_matrix
    grams: list[tuple[np.ndarray, np.ndarray, int]]
    gram: np.ndarray
    rhs: np.ndarray
    curvature: np.ndarray
    prior_gram: np.ndarray
    constraints: csr_matrix
    start: np.ndarray


class _Problem:
    """Everything of one record that the candidates share: the fine design, the folds, the
    prior of each fold; the per-candidate systems are cached."""

    def __init__(
        self,
        u: np.ndarray,
        p: np.ndarray,
        grid: int,
        fold: np.ndarray,
        prior: Callable[[np.ndarray | None], np.ndarray | None] | None,
    ) -> None:
        self.u, self.p, self.k = u, p, grid
        self.nodes = np.linspace(float(u.min()), float(u.max()), grid)
        self.fine = lower_design(u, self.nodes)
        self.fold = fold
        self.n_folds = int(fold.max()) + 1
        i, j = _lower_index(grid)
        # the prior of the whole record (key None) and of each fold without its held-out part
        self.priors: dict[int | None, np.ndarray | None] = {}
        if prior is not None:
            for f in [None, *range(self.n_folds)]:
                table = prior(None if f is None else fold == f)
                self.priors[f] = None if table is None else table[i, j]
        self._cache: dict[tuple[int, int, float], _System] = {}
        self.fold_mse: dict[Candidate, list[float]] = {}
        self.held_out: dict[Candidate, np.ndarray] = {}

    def system(self, alpha_cells: int, d_cells: int, spacing: float) -> _System:
        from scipy.sparse import csr_matrix, hstack  # heavy: imported where a fit needs it

        key = (alpha_cells, d_cells, spacing)
        if key not in self._cache:
            d_nodes = _d_nodes(d_cells, spacing)
            P = _shape_map(self.k, alpha_cells, d_nodes)
            A = hstack([self.fine @ P, csr_matrix(np.ones((self.u.size, 1)))]).tocsr()
            n = P.shape[1]
            # one Gram matrix per fold; samples of fold -1 (the major loop) always train
            grams = []
            for f in range(self.n_folds):
                rows = np.nonzero(self.fold == f)[0]
                Af = A[rows]
                grams.append(((Af.T @ Af).toarray(), Af.T @ self.p[rows], rows.size))
            D = _curvature(alpha_cells, d_nodes)
            DD = np.zeros((n + 1, n + 1))
            DD[:n, :n] = (D.T @ D).toarray()
            PP = np.zeros((n + 1, n + 1))
            PP[:n, :n] = (P.T @ P).toarray()
            shape_c = _shape_constraints(alpha_cells, d_nodes)
            # strictly feasible: F = 1e-3 ptp(p) (α - β) / span. The system is nearly singular
            # along directions the record does not determine (unknowns outside the Preisach
            # triangle, the curvature penalty's affine null space), so the solution there
            # depends on this start; it is kept fixed so that results are reproducible
            x0 = np.zeros(n + 1)
            x0[:n] = (
                1e-3 * max(float(np.ptp(self.p)), 1e-12) * np.tile(d_nodes[1:], alpha_cells + 1)
            )
            x0[n] = float(self.p.mean())
            self._cache[key] = _System(
                design=A,
                shape_map=P,
                grams=grams,
                gram=(A.T @ A).toarray(),
                rhs=A.T @ self.p,
                curvature=DD,
                prior_gram=PP,
                constraints=hstack([shape_c, csr_matrix((shape_c.shape[0], 1))]).tocsr(),
                start=x0,
            )
        return self._cache[key]

    def solve(self, c: Candidate, exclude: int | None, tol: float = 1e-7) -> np.ndarray:
        sys_ = self.system(c.alpha_cells, c.d_cells, c.spacing)
        if exclude is None:
            G, b, count = sys_.gram, sys_.rhs, self.u.size
        else:
            G0, b0, n0 = sys_.grams[exclude]
            G, b, count = sys_.gram - G0, sys_.rhs - b0, self.u.size - n0
        G = G / count
        b = b / count
        scale = np.trace(G)
        DD, PP = sys_.curvature, sys_.prior_gram
        H = G + c.smoothing * scale / max(np.trace(DD), 1e-300) * DD
        target = self.priors.get(exclude)
        if c.prior_weight > 0 and target is not None:
            w = c.prior_weight * scale / max(np.trace(PP), 1e-300)
            H = H + w * PP
            b = b.copy()
            b[:-1] += w * (sys_.shape_map.T @ target)
        with threadpool_limits(1, "blas"):  # small matrices: threads only spin-wait
            x, _ = solve_monotone_qp(H, b, sys_.constraints, sys_.start, tol=tol)
        return x

    def cv_rmse(self, c: Candidate) -> float:
        A = self.system(c.alpha_cells, c.d_cells, c.spacing).design
        pred = np.full(self.u.size, np.nan)

        def one(f: int) -> tuple[float, int]:
            x = self.solve(c, f, tol=1e-6)
            rows = np.nonzero(self.fold == f)[0]
            pred[rows] = A[rows] @ x
            return float(np.sum((pred[rows] - self.p[rows]) ** 2)), rows.size

        parts = [one(f) for f in range(self.n_folds)]
        self.fold_mse[c] = [s / max(n, 1) for s, n in parts]
        self.held_out[c] = pred
        sse = sum(s for s, _ in parts)
        return float(np.sqrt(sse / np.count_nonzero(self.fold >= 0)))


def _search(problem: _Problem, start: Candidate, free: dict[str, bool]) -> list:
    """Coordinate-wise search over the settings that are free (prior weight, smoothing, grid
    size, then the smoothing's neighbours again); returns every (candidate, CV RMSE) tried, best
    first. The d-node spacing stays as given (default 3: dense next to the diagonal)."""
    scores: dict[Candidate, float] = {}

    def score(c: Candidate) -> float:
        if c not in scores:
            scores[c] = problem.cv_rmse(c)
        return scores[c]

    best = start
    score(best)
    if free["prior"]:
        best = min((best.but(prior_weight=w) for w in PRIOR_WEIGHTS), key=score)
    if free["smoothing"]:
        best = min(
            (best.but(smoothing=s) for s in SMOOTHINGS),
            key=score,
        )
    if free["size"]:
        best = min((best.but(alpha_cells=a, d_cells=d) for a, d in SIZES), key=score)
        if free["smoothing"]:  # the neighbours of the smoothing chosen for the first size
            k = SMOOTHINGS.index(best.smoothing)
            near = SMOOTHINGS[max(k - 1, 0) : k + 2]
            best = min(
                (best.but(smoothing=s) for s in near),
                key=score,
            )
    return sorted(scores.items(), key=lambda kv: kv[1])


def fit_everett_lsq(
    u: npt.NDArray[np.float64],
    p: npt.NDArray[np.float64],
    grid: int = 100,
    cells: int | None = None,
    smoothing: float | None = None,
    spacing: float | None = None,
    folds: int = 4,
    tolerance: float | None = None,
    prior: Callable[[np.ndarray | None], np.ndarray | None] | None = None,
    prior_weight: float | None = None,
) -> LsqResult:
    """Identify a monotone ``grid x grid`` Everett table and an output offset from a record
    (see the module docstring). ``cells`` (α cells and as many d-cells),
    ``smoothing``, ``spacing`` and ``prior_weight`` fix a setting instead of choosing it by
    cross-validation. ``prior(held_out)`` returns a prior table on the same fine grid built
    without the samples marked held out (None: all samples), or None when it cannot."""
    if grid < 3:
        raise ParameterError(f"grid must be >= 3, got {grid}")
    if cells is not None and cells < 2:
        raise ParameterError(f"cells must be >= 2, got {cells}")
    if smoothing is not None and not smoothing >= 0:
        raise ParameterError(f"smoothing must be >= 0, got {smoothing}")
    if folds < 2:
        raise ParameterError(f"folds must be >= 2, got {folds}")
    tol = 0.01 * float(np.ptp(u)) if tolerance is None else tolerance
    fold = branch_folds(u, folds, tol)
    problem = _Problem(u, p, grid, fold, prior)
    has_prior = problem.priors.get(None) is not None
    size = (16, 16) if cells is None else (cells, cells)
    weight = prior_weight if prior_weight is not None else (1e-3 if has_prior else 0.0)
    start = Candidate(
        size[0], size[1], 3.0 if spacing is None else spacing, smoothing or 1e-4, weight
    )
    free = {
        "smoothing": smoothing is None,
        "size": cells is None,
        "prior": has_prior and prior_weight is None,
    }
    if problem.n_folds >= 2:
        scores = _search(problem, start, free)
        chosen, validation = scores[0]
    else:  # too few reversal curves to hold any out
        scores, chosen, validation = [], start, None
    x = problem.solve(chosen, None)
    chosen_system = problem.system(chosen.alpha_cells, chosen.d_cells, chosen.spacing)
    A, P = chosen_system.design, chosen_system.shape_map
    i, j = _lower_index(grid)
    table = np.zeros((grid, grid))
    table[i, j] = P @ x[:-1]
    fit_rmse = float(np.sqrt(np.mean((A @ x - p) ** 2)))
    return LsqResult(
        table,
        float(x[-1]),
        chosen,
        validation,
        scores,
        fit_rmse,
        max(problem.n_folds, 0),
        problem.fold_mse.get(chosen),
        problem.held_out.get(chosen),
    )
