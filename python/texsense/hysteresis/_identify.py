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

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import lsq_linear
from scipy.sparse import csr_matrix, hstack, vstack

from texsense.exceptions import ParameterError
from texsense.hysteresis._segments import Branch, split_branches

__all__ = ["Identified", "find_thesis_curves", "identify_lsq", "identify_thesis", "make_monotone"]


@dataclass
class Identified:
    """An identified Everett table with its range and output offset."""

    everett: npt.NDArray[np.float64]
    u_min: float
    u_max: float
    offset: float
    method: str
    details: dict


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
    u: npt.NDArray[np.float64], tolerance: float, reach: float = 0.8
) -> tuple[Branch, list[Branch]] | None:
    """The designed curves in a record: a rising curve over the whole range (within 3 % at
    both ends) and at least two falling curves that go down to within ``1 - reach`` of the
    bottom (a spacer stops carrying load a little above zero compression). None if absent."""
    lo, hi = float(u.min()), float(u.max())
    span = hi - lo
    branches = split_branches(u, tolerance)
    rising = [
        b
        for b in branches
        if b.rising and u[b.start] - lo < 0.03 * span and hi - u[b.stop] < 0.03 * span
    ]
    falling = [b for b in branches if not b.rising and u[b.stop] - lo < (1 - reach) * span]
    if not rising or len(falling) < 2:
        return None
    return rising[0], falling


def identify_thesis(
    u: npt.ArrayLike, p: npt.ArrayLike, grid: int = 100, tolerance: float | None = None
) -> Identified:
    """The thesis's identification from a rising curve and falling curves (§4.4.2)."""
    u = np.asarray(u, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    tol = 0.01 * np.ptp(u) if tolerance is None else tolerance
    found = find_thesis_curves(u, tol)
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

    The extremum stack depends on the input alone (eq. 4.15/4.16 with wiping-out); each
    ``F(α, β)`` term is spread over the grid nodes with the interpolation weights of the Rust
    core (bilinear; linear on the lower triangle of a diagonal cell).
    """
    k = nodes.size
    u_min, step = nodes[0], nodes[1] - nodes[0]
    last = k - 1
    rows: list[int] = []
    cols: list[int] = []
    vals: list[float] = []

    def add(t: int, alpha: float, beta: float, c: float) -> None:
        a = min(max((alpha - u_min) / step, 0.0), last)
        b = min(max((beta - u_min) / step, 0.0), last)
        if b >= a:
            return
        i0 = min(int(a), k - 2)
        j0 = min(int(b), k - 2)
        wa, wb = a - i0, b - j0
        if i0 == j0:
            terms = [((i0 + 1) * k + j0, (wa - wb))]
        else:
            terms = [
                (i0 * k + j0, (1 - wa) * (1 - wb)),
                (i0 * k + j0 + 1, (1 - wa) * wb),
                ((i0 + 1) * k + j0, wa * (1 - wb)),
                ((i0 + 1) * k + j0 + 1, wa * wb),
            ]
        for col, w in terms:
            if w:
                rows.append(t)
                cols.append(col)
                vals.append(c * w)

    stack = [u_min]  # alternating extrema, m0 first
    prev = u_min
    for t, x in enumerate(u):
        x = min(max(float(x), nodes[0]), nodes[-1])
        update_extrema(stack, prev, x)
        prev = x
        # output = 2 Σ_k [F(M_k, m_{k-1}) - F(M_k, m_k)] + the branch now being traced
        for q in range(1, len(stack), 2):
            add(t, stack[q], stack[q - 1], 2.0)
            if q + 1 < len(stack):
                add(t, stack[q], stack[q + 1], -2.0)
        if len(stack) % 2 == 1:  # rising after the minimum on top
            add(t, x, stack[-1], 2.0)
        else:  # falling after the maximum on top
            add(t, stack[-1], x, -2.0)
    return csr_matrix((vals, (rows, cols)), shape=(u.size, k * k))


def _downsample(u: np.ndarray, p: np.ndarray, max_samples: int) -> tuple[np.ndarray, np.ndarray]:
    if u.size <= max_samples:
        return u, p
    # keep every turning point, thin the rest evenly
    d = np.sign(np.diff(u))
    turns = np.nonzero(d[1:] * d[:-1] < 0)[0] + 1
    keep = np.unique(np.concatenate([np.linspace(0, u.size - 1, max_samples).astype(int), turns]))
    return u[keep], p[keep]


def identify_lsq(
    u: npt.ArrayLike,
    p: npt.ArrayLike,
    cells: int = 30,
    smoothing: float = 1e-3,
    max_samples: int = 8000,
    prior: Identified | None = None,
    prior_weight: float = 0.05,
) -> Identified:
    """Least-squares identification of the Everett table from any record.

    The output of the numerical model is linear in the table (:func:`everett_design`), so
    the table values at ``cells + 1`` nodes per axis and the output offset are found by
    regularised linear least squares (second differences along α and β penalised with
    weight ``smoothing``), then made monotone. Parts of the Preisach triangle that the record
    never visits are only filled by the smoothness penalty: the record should hold reversals
    at many levels (a random or cyclic record), not just the thesis's falling curves.
    """
    u = np.asarray(u, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    ok = np.isfinite(u) & np.isfinite(p)
    u, p = u[ok], p[ok]
    if u.size < 10 or np.ptp(u) <= 0:
        raise ParameterError("least squares needs at least 10 samples over a non-zero input range")
    if cells < 3:
        raise ParameterError(f"cells must be >= 3, got {cells}")
    us, ps = _downsample(u, p, max_samples)
    u_min, u_max = float(u.min()), float(u.max())
    nodes = np.linspace(u_min, u_max, cells + 1)
    k = nodes.size
    a_full = everett_design(us, nodes)
    ii, jj = np.tril_indices(k, -1)
    free = ii * k + jj
    a = a_full[:, free]
    n = free.size
    # second-difference smoothness along α (rows) and β (columns) of the lower triangle
    index = {(i, j): c for c, (i, j) in enumerate(zip(ii, jj, strict=True))}
    rows, cols, vals = [], [], []
    r = 0
    for (i, j), c in index.items():
        for di, dj in ((1, 0), (0, 1)):
            a1, a2 = (i - di, j - dj), (i + di, j + dj)
            if a1 in index and a2 in index:  # curvature
                rows += [r, r, r]
                cols += [index[a1], c, index[a2]]
                vals += [1.0, -2.0, 1.0]
                r += 1

    scale = smoothing * np.sqrt(us.size)
    penalty = csr_matrix((np.array(vals) * scale * k, (rows, cols)), shape=(r, n + 1))
    design = hstack([a, csr_matrix(np.ones((a.shape[0], 1)))]).tocsr()  # + output offset
    blocks, rhs = [design, penalty], [ps, np.zeros(r)]
    if prior is not None:
        # pull towards a prior table (e.g. the thesis method's) where the data say little
        old = np.linspace(prior.u_min, prior.u_max, prior.everett.shape[0])
        from scipy.interpolate import RegularGridInterpolator

        interp = RegularGridInterpolator(
            (old, old), prior.everett, bounds_error=False, fill_value=None
        )
        target = interp(np.column_stack([nodes[ii], nodes[jj]]))
        weight = prior_weight * np.sqrt(us.size)
        blocks.append(
            csr_matrix((np.full(n, weight), (np.arange(n), np.arange(n))), shape=(n, n + 1))
        )
        rhs.append(weight * target)
    a_aug = vstack(blocks).tocsr()
    b_aug = np.concatenate(rhs)
    sol = lsq_linear(a_aug, b_aug, method="trf", lsmr_tol="auto", max_iter=200)
    table = np.zeros(k * k)
    table[free] = sol.x[:n]
    table = table.reshape(k, k)
    offset = float(sol.x[-1])
    fit = design @ sol.x
    return Identified(
        make_monotone(table),
        u_min,
        u_max,
        offset,
        "lsq",
        {
            "cells": cells,
            "smoothing": smoothing,
            "fit_rmse": float(np.sqrt(np.mean((fit - ps) ** 2))),
            "samples_used": int(us.size),
            "prior": None if prior is None else prior.method,
        },
    )
