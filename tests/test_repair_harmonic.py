"""The harmonic repair's solver (:class:`texsense.compensation.repair._Harmonic`): its system
is built from the neighbour graph's arrays, and it must give the same numbers to the bit as
the straightforward construction by slicing the graph's sparse matrix (kept here as the
oracle: what the repair did before, commit a3b3882), for every failure pattern, also clusters
and regions cut off from every valid element; a pattern seen again reuses its factorisation.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from texsense import Layout
from texsense.compensation.repair import Repair, _Harmonic


def sliced(layout: Layout, out: np.ndarray, ok: np.ndarray) -> None:
    """The oracle: L_FF x_F = A_FV v_V over the failed elements connected to a valid one, by
    slicing the sparse graph (fill ``out`` in place)."""
    n = layout.n_elements
    indptr, indices = layout.neighbours
    adj = sp.csr_matrix((np.ones(indices.size), indices, indptr), shape=(n, n))
    adj = ((adj + adj.T) > 0).astype(np.float64).tocsr()
    deg = np.asarray(adj.sum(axis=1)).ravel()
    bad, good = np.flatnonzero(~ok), np.flatnonzero(ok)
    if not bad.size:
        return
    ncomp, comp = connected_components(adj[bad][:, bad], directed=False)
    touches = np.asarray(adj[bad][:, good].sum(axis=1)).ravel() > 0
    reach = np.zeros(ncomp, bool)
    reach[comp[touches]] = True
    solvable = bad[reach[comp]]
    if solvable.size:
        lap = sp.diags(deg[solvable]) - adj[solvable][:, solvable]
        rhs = adj[solvable][:, good] @ out[ok]
        out[solvable] = spla.factorized(lap.tocsc())(rhs)


def seat_layout() -> Layout:
    from texsense.monitor.virtual import VirtualSeatSource

    return VirtualSeatSource().layout


def patterns(layout: Layout, rng: np.random.Generator, count: int):
    """Failure patterns: scattered at several rates, blocks, a ring around a cut-off island,
    everything failed and nothing failed."""
    n = layout.n_elements
    for k in range(count):
        yield rng.random(n) > (0.05, 0.125, 0.4, 0.8)[k % 4]
    xy = np.asarray(layout.xy_cm)
    c = np.unique(xy[:, 0], return_inverse=True)[1].ravel()  # each element's column, row
    r = np.unique(xy[:, 1], return_inverse=True)[1].ravel()
    rows, cols = r.max() + 1, c.max() + 1
    block = (r >= rows // 4) & (r < rows // 2) & (c >= 1) & (c < cols - 1)
    ring = np.maximum(abs(r - rows // 2), abs(c - cols // 2)) == 2
    yield ~block
    yield ring  # only the ring is valid: inside and outside of it filled from it ...
    yield ~ring  # ... and the ring failed: the inside is an island cut off the outside
    yield ~(ring | (np.maximum(abs(r - rows // 2), abs(c - cols // 2)) < 2))  # all inside cut off
    yield np.zeros(n, bool)
    yield np.ones(n, bool)


@pytest.mark.parametrize(
    "make", [lambda: Layout.grid(64, 32), lambda: Layout.grid(5, 7), seat_layout]
)
def test_same_numbers_to_the_bit_as_slicing_the_graph(make):
    layout = make()
    h = _Harmonic(layout)
    rng = np.random.default_rng(3)
    checked = cut_off = 0
    for ok in patterns(layout, rng, 40):
        x = rng.uniform(0.0, 5.0, layout.n_elements)
        want = np.where(ok, x, np.nan)
        got = want.copy()
        sliced(layout, want, ok)
        h.solve(got, ok)
        np.testing.assert_array_equal(got, want)  # NaN where nothing valid is connected
        checked += int((~ok).sum())
        cut_off += int(np.isnan(got).sum())
    assert checked > 0 and cut_off > 0 and h.factorisations > 40


def test_a_pattern_seen_again_reuses_its_factorisation():
    layout = Layout.grid(16, 8)
    h = _Harmonic(layout)
    rng = np.random.default_rng(0)
    dead = rng.random(layout.n_elements) > 0.1  # dead elements that stay dead
    other = rng.random(layout.n_elements) > 0.1
    first = None
    for k in range(6):
        out = np.where(dead, rng.uniform(0, 5, layout.n_elements), np.nan)
        want = out.copy()
        sliced(layout, want, dead)
        h.solve(out, dead)
        np.testing.assert_array_equal(out, want)
        first = first if first is not None else h.factorisations
        if k == 2:
            h.solve(np.where(other, 1.0, np.nan), other)  # another pattern between
    assert (first, h.factorisations, h.hits) == (1, 2, 5)


def test_the_cache_keeps_the_most_recent_patterns():
    layout = Layout.grid(4, 4)
    h = _Harmonic(layout)
    pats = [np.arange(16) != k for k in range(16)] + [np.arange(16) % 2 == 0]
    h.CACHE_MAX = 4
    for ok in pats[:4]:
        h.solve(np.where(ok, 1.0, np.nan), ok)
    h.solve(np.where(pats[0], 1.0, np.nan), pats[0])  # used again: now the most recent
    h.solve(np.where(pats[4], 1.0, np.nan), pats[4])  # a new one: pats[1] goes
    assert (h.factorisations, h.hits, len(h._cache)) == (5, 1, 4)
    h.solve(np.where(pats[0], 1.0, np.nan), pats[0])
    h.solve(np.where(pats[1], 1.0, np.nan), pats[1])
    assert (h.factorisations, h.hits) == (6, 2)


def test_the_stage_on_a_stream_of_new_patterns_matches_the_oracle():
    """Both harmonic methods, frame by frame, where every frame fails other elements."""
    layout = seat_layout()
    rng = np.random.default_rng(7)
    frames = rng.uniform(0.0, 4.0, (25, layout.n_elements))
    valid = rng.random(frames.shape) > 0.125
    for method in ("harmonic", "harmonic-temporal"):
        rep = Repair(layout, method).fit()
        prev = None
        for x, ok in zip(frames, valid, strict=True):
            got, _ = rep.step(x, ok, t=0.0)
            want = np.where(ok, x, np.nan)
            sliced(layout, want, ok)
            if method == "harmonic-temporal" and prev is not None:
                before = np.where(ok, prev, np.nan)
                sliced(layout, before, ok)
                want[~ok] = np.maximum(prev[~ok] + (want[~ok] - before[~ok]), 0.0)
            np.testing.assert_array_equal(got, want)
            prev = got
        assert rep._harmonic.factorisations == 25
