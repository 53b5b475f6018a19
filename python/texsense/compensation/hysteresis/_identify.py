"""Identification of the Everett function (thesis §4.4.2, eq. 4.12-4.14) and by least squares.

Both return an Everett table on a uniform grid over ``[u_min, u_max]`` plus an output offset
(the output at ``u_min``), in the convention of the Rust core: rising from ``u_min`` gives
``offset + 2 F(u, u_min)``.

**Thesis method.** The record holds the rising curve from ``u_min`` to ``u_max`` and falling
curves from a few maxima ``α_j`` back to ``u_min`` (the thesis used 100, 70 and 30 % of the
maximum pressure). The rising curve fixes the boundary ``F(α, u_min) = (h_α - h_min) / 2``;
each falling curve gives ``F(α_j, β) = (h_αj - h_αj,β) / 2`` (eq. 4.12). For an α between two
measured curves, each neighbouring curve is read along the *distance fallen* ``d = α - β``
(truncated at ``α - u_min`` for a shorter fall) and scaled so that it meets the rising curve at
``β = u_min``; the two are blended linearly in α. This keeps both boundary conditions exact —
``F(α, α) = 0`` on the diagonal and the rising curve on ``β = u_min`` — and keeps the steep
start of a falling curve (the friction reversing, over a fixed compression distance) at the
right width even for α below the lowest measured curve. Interpolating raw values along
constant β instead would break ``F(α, α) = 0``; interpolating shapes normalised to the whole
fall (tried first) stretched that steep start for small α and raised the validation error
at low pressure from 13 % to 17 % (max, virtual textile spacer). Finally the table is made
monotone (non-decreasing in α, non-increasing in β) so the output is monotone between
extrema.

**Least squares.** For any record: the extremum stack depends on the input alone, so the
model's output is linear in the Everett table values (:func:`everett_design`). The table on a
coarser grid and an output offset are found by linear least squares with a curvature penalty
(and optionally a prior table), then made monotone. Unlike a non-negative Preisach density,
this covers loops of either orientation (a spacer's loading branch lies above its unloading
branch, which a non-negative density cannot produce).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from texsense._core import PreisachBank
from texsense.compensation.hysteresis._lsq import branch_folds, design_entries, fit_everett_lsq
from texsense.compensation.hysteresis._relay import (
    RelayFit,
    RelayProblem,
    cells_to_nodes,
    record_nodes,
    resample_table,
)
from texsense.compensation.hysteresis._segments import Branch, split_branches
from texsense.exceptions import ParameterError

if TYPE_CHECKING:
    from scipy.sparse import csr_matrix

__all__ = [
    "Identified",
    "find_thesis_curves",
    "fold_mse",
    "held_out_of_table",
    "identify_lsq",
    "identify_relay",
    "identify_thesis",
    "make_monotone",
]


@dataclass
class Identified:
    """An identified Everett table with its range and output offset."""

    everett: npt.NDArray[np.float64]
    u_min: float
    u_max: float
    offset: float
    method: str
    details: dict[str, Any]
    #: prediction of every held-out sample by the identification without its fold (NaN for
    #: samples that always train): what the default compares candidates on; not saved
    held_out: npt.NDArray[np.float64] | None = field(default=None, repr=False)


def make_monotone(table: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Smallest raise of an Everett table that makes it non-increasing in β (towards u_min)
    and non-decreasing in α, with 0 on and above the diagonal."""
    k = table.shape[0]
    f = np.tril(np.clip(table, 0.0, None), -1)
    for j in range(k - 2, -1, -1):  # along β towards u_min: running max
        f[:, j] = np.maximum(f[:, j], f[:, j + 1] * (np.arange(k) > j + 1))
    f = np.maximum.accumulate(f, axis=0)  # along α
    return np.tril(f, -1)


def find_thesis_curves(
    u: npt.NDArray[np.float64],
    tolerance: float,
    reach: float = 0.8,
    exclude: npt.NDArray[np.bool_] | None = None,
    outputs: npt.NDArray[np.float64] | None = None,
) -> tuple[Branch, list[Branch]] | None:
    """The designed curves in a record: a rising curve over the whole range (within 3 % at
    both ends) and falling curves from at least two different maxima (5 % of the range
    apart; the first curve from each) that go down to within ``1 - reach`` of the bottom (a
    spacer stops carrying load a little above zero compression). Where the whole record
    holds no such curves, with ``outputs``, falling curves that go down to the record's
    lowest output (within 3 % of its range: the machine unloads to zero load, which a spacer
    with a large set reaches while still compressed). None if absent — ascending first-order
    reversal curves, which all fall from the top, are not the thesis's protocol. Falling
    curves that touch a sample in ``exclude`` are left out (the criterion is the whole
    record's, so that a fold does not change it)."""
    by_output = (
        outputs is not None
        and np.ptp(outputs) > 0
        and _thesis_curves(u, tolerance, reach, None, None) is None
    )
    return _thesis_curves(u, tolerance, reach, exclude, outputs if by_output else None)


def _thesis_curves(
    u: npt.NDArray[np.float64],
    tolerance: float,
    reach: float,
    exclude: npt.NDArray[np.bool_] | None,
    outputs: npt.NDArray[np.float64] | None,
) -> tuple[Branch, list[Branch]] | None:
    """:func:`find_thesis_curves` with falls that end low in the input, or (``outputs``
    given) in the input or the output."""
    lo, hi = float(u.min()), float(u.max())
    span = hi - lo
    branches = split_branches(u, tolerance)
    rising = [
        b
        for b in branches
        if b.rising and u[b.start] - lo < 0.03 * span and hi - u[b.stop] < 0.03 * span
    ]

    def down(b: Branch) -> bool:
        if u[b.stop] - lo < (1 - reach) * span:
            return True
        if outputs is None:
            return False
        return bool(outputs[b.stop] - outputs.min() < 0.03 * np.ptp(outputs))

    falling = [b for b in branches if not b.rising and down(b)]
    if exclude is not None:  # held-out curves (cross-validation) are not used
        falling = [b for b in falling if not exclude[b.start + 1 : b.stop].any()]
    # the thesis's curves fall from *different* maxima (100, 70, 30 %); first-order reversal
    # curves that all fall from the top to different minima are the mirror protocol
    distinct: list[Branch] = []
    for b in falling:
        if all(abs(u[b.start] - u[c.start]) > 0.05 * span for c in distinct):
            distinct.append(b)
    if not rising or len(distinct) < 2:
        return None
    return rising[0], distinct


def identify_thesis(
    u: npt.ArrayLike,
    p: npt.ArrayLike,
    grid: int = 100,
    tolerance: float | None = None,
    exclude: npt.NDArray[np.bool_] | None = None,
) -> Identified:
    """The thesis's identification from a rising curve and falling curves (§4.4.2); falling
    curves touching ``exclude`` are not used (a held-out fold)."""
    u = np.asarray(u, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    tol = 0.01 * np.ptp(u) if tolerance is None else tolerance
    found = find_thesis_curves(u, tol, exclude=exclude, outputs=p)
    if found is None:
        raise ParameterError(
            "the record does not hold the thesis's calibration curves (a rising curve over "
            "the whole range and >= 2 falling curves back to the bottom); use method='lsq'"
        )
    rising, falling = found
    u_min, u_max = float(u.min()), float(u.max())
    nodes = np.linspace(u_min, u_max, grid)
    ur, pr = _monotone_xy(u[rising.start : rising.stop + 1], p[rising.start : rising.stop + 1])
    offset = float(np.interp(u_min, ur, pr))
    boundary = 0.5 * (np.interp(nodes, ur, pr) - offset)  # F(α, u_min)
    curves = []  # (α_j, distances d = α_j - β, F(α_j, α_j - d))
    for b in falling:
        uf, pf = _monotone_xy(u[b.start : b.stop + 1][::-1], p[b.start : b.stop + 1][::-1])
        alpha = float(u[b.start])
        d = np.linspace(0.0, alpha - u_min, 400)
        f = 0.5 * (float(p[b.start]) - np.interp(alpha - d, uf, pf, left=pf[0]))
        f = np.maximum.accumulate(np.clip(f, 0.0, None))
        if f[-1] > 0:
            curves.append((alpha, d, f))
    if len(curves) < 2:
        raise ParameterError("fewer than two usable falling curves in the record")
    curves.sort(key=lambda c: c[0])
    alphas = np.array([c[0] for c in curves])

    def from_curve(j: int, i: int) -> np.ndarray:
        # curve j's F along the distance α - β, scaled to meet the rising curve at β = u_min
        _, d, f = curves[j]
        reach = min(nodes[i] - u_min, d[-1])
        at_end = np.interp(reach, d, f)
        dist = np.minimum(nodes[i] - nodes[:i], d[-1])
        return np.interp(dist, d, f) * (boundary[i] / at_end if at_end > 0 else 0.0)

    table = np.zeros((grid, grid))
    for i in range(1, grid):
        w = float(np.interp(nodes[i], alphas, np.arange(alphas.size)))
        j0 = int(np.floor(w))
        j1 = min(j0 + 1, alphas.size - 1)
        frac = w - j0
        table[i, :i] = (1 - frac) * from_curve(j0, i) + frac * from_curve(j1, i)
    return Identified(
        make_monotone(table),
        u_min,
        u_max,
        offset,
        "thesis",
        {"falling_from": alphas.tolist(), "grid": grid},
    )


def _monotone_xy(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sort a branch by input and drop repeated inputs (for interpolation)."""
    order = np.argsort(x, kind="stable")
    x, y = x[order], y[order]
    keep = np.concatenate([[True], np.diff(x) > 0])
    return x[keep], y[keep]


def update_extrema(stack: list[float], prev: float, x: float) -> None:
    """Advance an extremum stack ``[m_0, M_1, m_1, ...]`` from input ``prev`` to ``x``: push
    ``prev`` when the input turns there, then wipe out the extrema ``x`` passes (the same rule
    as the Rust core)."""
    if x == prev:
        return
    rising = x > prev
    if rising != (len(stack) % 2 == 1):
        stack.append(prev)
    if rising:
        while len(stack) >= 3 and x >= stack[-2]:
            del stack[-2:]
    else:
        while len(stack) >= 3 and x <= stack[-2]:
            del stack[-2:]
        if len(stack) == 2 and x <= stack[0]:
            del stack[1:]


def everett_design(u: npt.NDArray[np.float64], nodes: npt.NDArray[np.float64]) -> csr_matrix:
    """The model's output for an input history is linear in the Everett table: return the
    sparse matrix A (T x K²) with ``output = A @ F.ravel()`` (output at u_min = 0).

    The extremum stack depends on the input alone (eq. 4.15/4.16 with wiping-out; the terms
    come from the Rust core, :func:`texsense._core.everett_terms`); each ``F(α, β)`` term is
    spread over the grid nodes with the interpolation weights of the core (bilinear; linear on
    the lower triangle of a diagonal cell).
    """
    from scipy.sparse import csr_matrix  # heavy: imported where a fit needs it

    k = nodes.size
    r, i, j, w = design_entries(np.asarray(u, dtype=np.float64), nodes)
    return csr_matrix((w, (r, i * k + j)), shape=(np.size(u), k * k))


def identify_lsq(
    u: npt.ArrayLike,
    p: npt.ArrayLike,
    grid: int = 100,
    cells: int | None = None,
    smoothing: float | None = None,
    spacing: float | None = None,
    folds: int = 4,
    thesis_prior: bool = False,
    prior_weight: float | None = None,
) -> Identified:
    """Constrained least-squares identification of a monotone Everett table from any record
    (:mod:`texsense.compensation.hysteresis._lsq`): the grid, curvature penalty and (with
    ``thesis_prior``) the weight of the thesis method's table as a prior are chosen by
    cross-validation on held-out reversal curves unless given. The prior of each fold is
    identified without that fold's held-out falling curves."""
    u_all = np.asarray(u, dtype=np.float64)
    p_all = np.asarray(p, dtype=np.float64)
    ok = np.isfinite(u_all) & np.isfinite(p_all)
    x, y = u_all[ok], p_all[ok]
    if x.size < 10 or np.ptp(x) <= 0:
        raise ParameterError("least squares needs at least 10 samples over a non-zero input range")
    u_min, u_max = float(x.min()), float(x.max())

    def thesis_table(exclude: np.ndarray | None) -> np.ndarray | None:
        try:
            return identify_thesis(x, y, grid, exclude=exclude).everett
        except ParameterError:  # the fold holds out too many of the curves
            return None

    res = fit_everett_lsq(
        x,
        y,
        grid=grid,
        cells=cells,
        smoothing=smoothing,
        spacing=spacing,
        folds=folds,
        prior=thesis_table if thesis_prior else None,
        prior_weight=prior_weight,
    )
    weight = res.chosen.prior_weight
    return Identified(
        res.table,
        u_min,
        u_max,
        res.offset,
        "lsq+thesis-prior" if weight else "lsq",
        {
            "grid": grid,
            **res.chosen.as_dict(),
            "validation_rmse": res.validation_rmse,
            "validation_folds": res.folds,
            "fit_rmse": res.fit_rmse,
            "fold_mse": res.fold_mse,
            "samples_used": int(x.size),
            "prior": "thesis" if weight else None,
            "cv": [{**c.as_dict(), "rmse": r} for c, r in res.scores],
        },
        res.held_out,
    )


RELAY_RIDGES: tuple[float, ...] = (1e-7, 1e-5, 1e-3)


def _relay_nodes(u: np.ndarray, requested: int | None, tol: float) -> int:
    """Nodes of the relay grid: 60, fewer for a record with few turning points (about two
    nodes per reversal) or few samples (about √T nodes: no more cells than half the
    samples), at least 12."""
    if requested is not None:
        return max(int(requested), 3)
    turns = len(split_branches(u, tol))
    return int(np.clip(min(2 * turns, np.sqrt(u.size)), 12, 60))


def identify_relay(
    u: npt.ArrayLike,
    p: npt.ArrayLike,
    grid: int = 100,
    nodes: int | None = None,
    ridge: float | None = None,
    folds: int = 4,
    signed: bool | None = False,
) -> Identified:
    """Non-negative relay-grid identification on nodes placed by the record
    (:mod:`texsense.compensation.hysteresis._relay`). The ridge is chosen by cross-validation on
    held-out reversal curves unless given. ``signed=None`` lets the cross-validation also
    try a signed density, which replaces the non-negative one only when it is better by
    more than one standard error over the folds; ``True`` forces it. The evaluated table is
    at least 200 x 200 so that narrow cells keep their resolution."""
    u = np.asarray(u, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    tol = 0.01 * float(np.ptp(u))
    node_x = record_nodes(u, p, _relay_nodes(u, nodes, tol), tolerance=tol)
    fold = branch_folds(u, folds, tol)
    problem = RelayProblem(u, p, node_x, fold)
    kinds = [True] if signed is True else ([False, True] if signed is None else [False])
    ridges = RELAY_RIDGES if ridge is None else (ridge,)
    cv: list[dict] = []
    chosen = (kinds[0], ridges[0])
    plain: np.ndarray | None = None
    errors: np.ndarray | None = None
    if problem.n_folds >= 2:
        best: dict[bool, tuple[float, np.ndarray]] = {}
        for kind in kinds:
            for r in ridges:
                e = problem.fold_errors(r, kind)
                cv.append({"signed": kind, "ridge": r, "rmse": float(np.sqrt(e.mean()))})
                if kind not in best or e.mean() < best[kind][1].mean():
                    best[kind] = (r, e)
        chosen = (kinds[0], best[kinds[0]][0])
        errors = best[kinds[0]][1]
        plain = best[False][1] if False in best else None
        if len(kinds) == 2 and _beats(best[True][1], best[False][1]):
            chosen, errors = (True, best[True][0]), best[True][1]
    x = problem.solve(chosen[1], chosen[0])
    fit = RelayFit(node_x, x[:-1], float(x[-1]), chosen[0])
    u_min, u_max = float(u.min()), float(u.max())
    k = max(grid, 200)
    pred = problem.design @ cells_to_nodes(x[:-1], node_x.size) + x[-1]
    return Identified(
        resample_table(fit, k, u_min, u_max),
        u_min,
        u_max,
        fit.offset,
        "relay-signed" if chosen[0] else "relay",
        {
            "grid": k,
            "nodes": node_x.tolist(),
            "ridge": chosen[1],
            "signed": chosen[0],
            "validation_rmse": None if errors is None else float(np.sqrt(errors.mean())),
            "validation_folds": problem.n_folds,
            "fold_mse": None if errors is None else errors.tolist(),
            "plain_fold_mse": None if plain is None else plain.tolist(),
            "fit_rmse": float(np.sqrt(np.mean((pred - p) ** 2))),
            "cv": cv,
        },
    )


def _beats(challenger: np.ndarray, incumbent: np.ndarray) -> bool:
    """The one-standard-error rule over folds: the challenger replaces the incumbent only
    when its mean held-out error is lower by more than the standard error of the per-fold
    differences (and lower at all when there is no spread)."""
    d = np.asarray(challenger) - np.asarray(incumbent)
    se = float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else 0.0
    return bool(d.mean() < -se) and bool(d.mean() < 0)


def held_out_of_table(
    u: np.ndarray,
    fold: np.ndarray,
    table_of: Callable[[np.ndarray], tuple[np.ndarray, float] | None],
) -> np.ndarray | None:
    """Prediction of every held-out sample by an identification given as
    ``table_of(held_out_mask) -> (Everett table, offset)`` (None if it cannot) without that
    sample's fold, the table evaluated by the Rust core over the whole input history; NaN
    for samples that always train. None if the identification cannot do without some fold."""
    n_folds = int(fold.max()) + 1
    u_min, u_max = float(u.min()), float(u.max())
    out = np.full(u.size, np.nan)
    for f in range(n_folds):
        held = fold == f
        got = table_of(held)
        if got is None:
            return None
        table, offset = got
        bank = PreisachBank(u_min, u_max, np.ascontiguousarray(table), 1, 256, offset, 1.0)
        pred = bank.run(np.ascontiguousarray(u[:, None]), np.ones((u.size, 1), bool))[:, 0]
        out[held] = pred[held]
    return out


def fold_mse(pred: np.ndarray, p: np.ndarray, fold: np.ndarray) -> np.ndarray:
    """Held-out mean squared error of every fold from held-out predictions."""
    return np.asarray(
        [float(np.mean((pred[fold == f] - p[fold == f]) ** 2)) for f in range(int(fold.max()) + 1)]
    )
