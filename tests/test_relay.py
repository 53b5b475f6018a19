"""The relay-grid identification (non-negative density on nodes placed by the record), the
default's one-standard-error rule, the fit diagnosis and the virtual FORC sample."""

import numpy as np
import pytest
from scipy.optimize import nnls

from texsense.compensation.hysteresis import HysteresisModel
from texsense.compensation.hysteresis._identify import _beats, identify_relay
from texsense.compensation.hysteresis._relay import (
    cell_map,
    cells_to_nodes,
    nodes_to_cells,
    nonnegative_qp,
    record_nodes,
)
from texsense.sim.magnetic import ParticleEnsemble, forc_protocol


def test_cell_operators_are_the_cumulative_map_and_its_adjoint():
    m = 8
    T = cell_map(m).toarray()
    rng = np.random.default_rng(0)
    w, y = rng.random((T.shape[0], 3)), rng.random((T.shape[0], 3))
    np.testing.assert_allclose(cells_to_nodes(w, m), T @ w, atol=1e-12)
    np.testing.assert_allclose(nodes_to_cells(y, m), T.T @ y, atol=1e-12)
    # F(n_i, n_j) is the mass of the cells of the triangle under (n_i, n_j)
    f = cells_to_nodes(np.ones(T.shape[0]), m)
    i = np.repeat(np.arange(1, m), np.arange(1, m))
    j = np.concatenate([np.arange(k) for k in range(1, m)])
    np.testing.assert_allclose(f, (i - j) * (i - j + 1) / 2)


def test_nonnegative_qp_matches_lawson_hanson():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((80, 30))
    b = A @ np.maximum(rng.standard_normal(30), 0) + 0.1 * rng.standard_normal(80)
    w = nonnegative_qp(A.T @ A, A.T @ b)
    ref, _ = nnls(A, b)
    assert np.all(w >= 0)
    np.testing.assert_allclose(w, ref, atol=1e-8)


def test_nodes_follow_the_record():
    u = np.concatenate([np.linspace(0, 1, 50), 0.8 + 0.01 * np.sin(np.linspace(0, 60, 3000))])
    nodes = record_nodes(u, u, 20)
    assert nodes[0] == u.min() and nodes[-1] == u.max() and np.all(np.diff(nodes) > 0)
    near = np.count_nonzero(np.abs(nodes - 0.8) < 0.05)
    assert near >= 5  # where the record dwells and turns, not 1 of a uniform 20


@pytest.fixture(scope="module")
def sharp_forcs():
    """A narrow switching-field distribution with interactions, measured as 100 FORCs."""
    return forc_protocol(100, 0.01, noise=1e-3, coercivity_spread=0.03, interaction=-0.1)


def test_sharp_switching_forcs_even_to_odd_within_one_percent(sharp_forcs):
    u, y, c = sharp_forcs
    train = (c < 0) | (c % 2 == 0)
    odd = (c >= 0) & (c % 2 == 1)
    m = HysteresisModel(method="relay", input_unit="1", output_unit="1").fit(u[train], y[train])
    assert m.method_ in ("relay", "relay-signed")
    pred = m.predict(u)
    nrmse = np.sqrt(np.mean((pred[odd] - y[odd]) ** 2)) / np.ptp(y)
    assert nrmse <= 0.01
    diag = m.fit_diagnosis(u[train], y[train])
    assert not diag["underfit"] and diag["validation_rmse"] is not None
    # four nodes cannot follow the sharp switching: the diagnosis says so
    coarse = HysteresisModel(method="relay", cells=4, input_unit="1", output_unit="1")
    coarse.fit(u[train], y[train])
    assert coarse.fit_diagnosis(u[train], y[train])["underfit"]


def test_relay_model_obeys_wiping_out_return_point_memory_and_congruency(sharp_forcs):
    u, y, _ = sharp_forcs
    ident = identify_relay(u, y, signed=False)  # a non-negative density (the signed one
    m = HysteresisModel(input_unit="1", output_unit="1")  # has no such guarantees)
    m.everett_, m.u_min_, m.u_max_, m.offset_, m.sign_ = (
        ident.everett,
        ident.u_min,
        ident.u_max,
        ident.offset,
        1.0,
    )
    f = m.everett_
    low = np.tril(np.ones_like(f, bool), -1)
    assert np.all(np.diff(f, axis=0)[low[1:]] >= -1e-12)
    # return-point memory and wiping-out: a minor loop closes where it started, and a
    # larger excursion erases it
    lo, hi = m.u_min_, m.u_max_
    a, b = lo + 0.6 * (hi - lo), lo + 0.4 * (hi - lo)
    path = np.concatenate([np.linspace(lo, a, 50), np.linspace(a, b, 30), np.linspace(b, a, 30)])
    out = m.predict(path)
    assert out[-1] == pytest.approx(out[49], abs=1e-9 * np.ptp(y))
    wiped = np.concatenate([path, np.linspace(a, hi, 30)])
    direct = np.concatenate([np.linspace(lo, hi, 80)])
    assert m.predict(wiped)[-1] == pytest.approx(m.predict(direct)[-1], abs=1e-9 * np.ptp(y))
    # congruency: the same minor loop between b and a from two different histories
    h1 = np.concatenate([np.linspace(lo, hi, 60), np.linspace(hi, b, 40)])
    h2 = np.concatenate([np.linspace(lo, a, 40), np.linspace(a, b, 40)])
    loop = np.concatenate([np.linspace(b, a, 30), np.linspace(a, b, 30)])
    r1 = m.predict(np.concatenate([h1, loop]))[-60:]
    r2 = m.predict(np.concatenate([h2, loop]))[-60:]
    np.testing.assert_allclose(r1 - r1[0], r2 - r2[0], atol=1e-9 * np.ptp(y))


def test_one_standard_error_rule():
    incumbent = np.array([1.0, 1.2, 0.9, 1.1])
    assert not _beats(incumbent - 0.01 * np.array([1, -1, 1, -1]), incumbent)  # noise
    assert _beats(incumbent * 0.5, incumbent)  # a clear gain on every fold
    assert not _beats(incumbent * 1.1, incumbent)


def test_particles_switch_sharply_and_interact():
    h = np.linspace(-1, 1, 201)

    def switching(interaction):
        e = ParticleEnsemble(500, 0.5, 0.01, 0.01, interaction=interaction, seed=1)
        up = e.apply(h)
        assert up[0] == -1 and up[-1] == 1
        return np.ptp(h[(up > -0.9) & (up < 0.9)])

    assert switching(0.0) < 0.1  # a narrow switching-field distribution
    assert switching(-0.2) > 0.3  # the demagnetising mean field shears the loop
