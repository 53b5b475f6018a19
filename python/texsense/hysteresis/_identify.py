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

**Least squares.** For any record: the output is modelled as an offset, a reversible part
``R(u)`` (piecewise linear, free increments) and a Preisach part from relays on a grid
(``α_i > β_j``), whose weights all have one sign — the orientation of the loops measured from
the data (counter-clockwise: positive, as a classical Preisach density; clockwise, as the
spacers' loading branch above their unloading branch: negative). Relay states are computed for
every sample, and the weights are found by bounded least squares with a smoothness penalty.
The Everett table is ``F = F_relays + (R(α) - R(β)) / 2``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import lsq_linear
from scipy.sparse import csr_matrix, diags, vstack

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
    u: npt.NDArray[np.float64], tolerance: float, reach: float = 0.9
) -> tuple[Branch, list[Branch]] | None:
    """The designed curves in a record: a rising curve over (nearly) the whole range and at
    least two falling curves that go (nearly) down to the bottom. None if absent."""
    lo, hi = float(u.min()), float(u.max())
    span = hi - lo
    branches = split_branches(u, tolerance)
    rising = [
        b
        for b in branches
        if b.rising and u[b.start] - lo < (1 - reach) * span and hi - u[b.stop] < (1 - reach) * span
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


def relay_states(u: npt.NDArray[np.float64], nodes: npt.NDArray[np.float64]) -> np.ndarray:
    """States (T, n_relays) of the relays (α_i = nodes[i] > β_j = nodes[j]), all down at the
    start: up once the input reached α_i, down once it fell to β_j, whichever was last."""
    t = np.arange(u.size)
    last_up = np.array([np.maximum.accumulate(np.where(u >= a, t, -1)) for a in nodes])
    last_down = np.array([np.maximum.accumulate(np.where(u <= b, t, -1)) for b in nodes])
    ii, jj = np.tril_indices(nodes.size, -1)
    return (last_up[ii] > last_down[jj]).T


def _reversible_basis(u: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    width = np.diff(nodes)
    return np.clip((u[:, None] - nodes[None, :-1]) / width[None, :], 0.0, 1.0)


def _downsample(u: np.ndarray, p: np.ndarray, max_samples: int) -> tuple[np.ndarray, np.ndarray]:
    if u.size <= max_samples:
        return u, p
    # keep every turning point, thin the rest evenly
    d = np.sign(np.diff(u))
    turns = np.nonzero(d[1:] * d[:-1] < 0)[0] + 1
    keep = np.unique(np.concatenate([np.linspace(0, u.size - 1, max_samples).astype(int), turns]))
    return u[keep], p[keep]


def loop_orientation(u: npt.NDArray[np.float64], p: npt.NDArray[np.float64]) -> int:
    """+1 for counter-clockwise loops in (u, p) (output lags input, ∮ p du < 0), -1 for
    clockwise (loading branch above unloading, as spacers)."""
    area = float(np.sum(0.5 * (p[1:] + p[:-1]) * np.diff(u)))
    return 1 if area < 0 else -1


def identify_lsq(
    u: npt.ArrayLike,
    p: npt.ArrayLike,
    cells: int = 30,
    smoothing: float = 1e-3,
    max_samples: int = 6000,
) -> Identified:
    """Least-squares identification from any record (see the module docstring)."""
    u = np.asarray(u, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    ok = np.isfinite(u) & np.isfinite(p)
    u, p = u[ok], p[ok]
    if u.size < 10 or np.ptp(u) <= 0:
        raise ParameterError("least squares needs at least 10 samples over a non-zero input range")
    if cells < 3:
        raise ParameterError(f"cells must be >= 3, got {cells}")
    orientation = loop_orientation(u, p)
    us, ps = _downsample(u, p, max_samples)
    u_min, u_max = float(u.min()), float(u.max())
    nodes = np.linspace(u_min, u_max, cells + 1)
    relays = relay_states(us, nodes).astype(np.float64)
    rev = _reversible_basis(us, nodes)
    n_rel, n_rev = relays.shape[1], rev.shape[1]
    a = np.hstack([relays, rev, np.ones((us.size, 1))])
    # smoothness: differences of neighbouring relay weights (along α and β) and increments
    ii, jj = np.tril_indices(nodes.size, -1)
    index = {(i, j): k for k, (i, j) in enumerate(zip(ii, jj, strict=True))}
    rows, cols, vals = [], [], []
    r = 0
    for (i, j), k in index.items():
        for nb in ((i + 1, j), (i, j + 1)):
            if nb in index:
                rows += [r, r]
                cols += [k, index[nb]]
                vals += [1.0, -1.0]
                r += 1
    for k in range(n_rev - 1):
        rows += [r, r]
        cols += [n_rel + k, n_rel + k + 1]
        vals += [1.0, -1.0]
        r += 1
    scale = np.sqrt(us.size) * smoothing * cells
    penalty = csr_matrix((np.array(vals) * scale, (rows, cols)), shape=(r, a.shape[1]))
    ridge = diags(np.full(a.shape[1], 1e-6 * np.sqrt(us.size)))
    a_aug = vstack([csr_matrix(a), penalty, ridge]).tocsr()
    b_aug = np.concatenate([ps, np.zeros(r + a.shape[1])])
    inf = np.inf
    lower = np.concatenate(
        [np.zeros(n_rel) if orientation > 0 else np.full(n_rel, -inf), np.full(n_rev + 1, -inf)]
    )
    upper = np.concatenate(
        [np.full(n_rel, inf) if orientation > 0 else np.zeros(n_rel), np.full(n_rev + 1, inf)]
    )
    sol = lsq_linear(
        a_aug,
        b_aug,
        bounds=(lower, upper),
        method="bvls" if a.shape[1] < 400 else "trf",
        lsmr_tol="auto",
        max_iter=2000,
    )
    w = sol.x[:n_rel]
    incr = sol.x[n_rel : n_rel + n_rev]
    offset = float(sol.x[-1])
    # Everett on the nodes: ½ Σ_{j <= j' < i' <= i} w  +  ½ (R(α) - R(β))
    k = nodes.size
    wm = np.zeros((k, k))
    wm[ii, jj] = w
    # cumulative: rows (α) upward, columns (β) from the diagonal downward
    cum = np.cumsum(np.cumsum(wm[:, ::-1], axis=1)[:, ::-1], axis=0)
    table = 0.5 * cum  # relays with α_i' <= α_i and β_j' >= β_j
    rev_nodes = np.concatenate([[0.0], np.cumsum(incr)])
    table += 0.5 * (rev_nodes[:, None] - rev_nodes[None, :])
    table = np.tril(table, -1)
    fit = a @ sol.x
    return Identified(
        table,
        u_min,
        u_max,
        offset,
        "lsq",
        {
            "cells": cells,
            "smoothing": smoothing,
            "orientation": "counter-clockwise" if orientation > 0 else "clockwise",
            "fit_rmse": float(np.sqrt(np.mean((fit - ps) ** 2))),
            "samples_used": int(us.size),
        },
    )
