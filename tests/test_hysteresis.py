import json

import numpy as np
import pytest

from texsense._core import PreisachBank
from texsense.compensation.hysteresis import HysteresisModel, scale_hysteresis
from texsense.compensation.hysteresis._identify import everett_design, make_monotone
from texsense.data.modelfile import envelope
from texsense.exceptions import FormatError, NotFittedError, ParameterError, UnitError
from texsense.sim.protocols import run_protocol

K = 51
NODES = np.linspace(0.0, 1.0, K)


def true_table(k=K):
    """A clockwise Everett table (loading branch above unloading, as a spacer): a reversible
    part (R(α) - R(β)) / 2 with R = 3u + u³ minus 0.3 (α - β)²; monotone in α and β."""
    a = np.linspace(0, 1, k)
    aa, bb = np.meshgrid(a, a, indexing="ij")
    r = 3 * a + a**3
    f = 0.5 * (r[:, None] - r[None, :]) - 0.3 * (aa - bb) ** 2
    return np.tril(f, -1)


def simulate(u, table=None):
    table = true_table() if table is None else table
    bank = PreisachBank(0.0, 1.0, np.ascontiguousarray(table), 1, 256)
    return bank.run(
        np.ascontiguousarray(np.asarray(u, float)[:, None]), np.ones((len(u), 1), bool)
    )[:, 0]


def thesis_record():
    """Rising to 1, falling to 0; rising to 0.7 / 0.3 and falling back (grid nodes)."""
    parts = []
    for top in (1.0, 0.7, 0.3):
        parts += [np.linspace(0, top, 200), np.linspace(top, 0, 200)]
    return np.concatenate(parts)


@pytest.mark.parametrize(
    ("method", "expected"),
    [
        ("thesis", {"thesis"}),
        ("auto", {"thesis", "lsq", "lsq+thesis-prior", "thesis/lsq average"}),
        ("lsq", {"lsq"}),
    ],
)
def test_identified_table_is_monotone_and_zero_on_the_diagonal(method, expected):
    u = thesis_record()
    m = HysteresisModel(method=method, grid=K).fit(u, simulate(u))
    f = m.everett_
    assert m.method_ in expected
    if method == "auto" and m.method_.startswith("lsq"):  # the prior weight was cross-validated
        tried = {c["prior_weight"] for c in m.details_["cv"]}
        assert tried == {0.0, 1e-3, 1e-2}
        assert (m.details_["prior_weight"] > 0) == (m.method_ == "lsq+thesis-prior")
    assert np.all(np.diag(f) == 0) and np.all(np.triu(f) == 0)
    low = np.tril(np.ones_like(f, bool), -1)
    assert np.all(np.diff(f, axis=0)[low[1:]] >= -1e-12)  # non-decreasing in α
    assert np.all((f[:, :-1] - f[:, 1:])[low[:, :-1] & low[:, 1:]] >= -1e-12)  # non-increasing in β


def test_thesis_method_reproduces_the_identification_curves_at_grid_points():
    u = thesis_record()
    p = simulate(u)
    m = HysteresisModel(method="thesis", grid=K).fit(u, p)
    at_nodes = np.isclose(u[:, None], NODES[None, :], atol=1e-12).any(axis=1)
    rising = np.arange(u.size) < 200
    falling_top = (np.arange(u.size) >= 200) & (np.arange(u.size) < 400)
    pm = m.predict(u)
    for part in (rising, falling_top):
        sel = part & at_nodes
        np.testing.assert_allclose(pm[sel], p[sel], atol=1e-9)


def test_least_squares_recovers_a_known_model_from_a_random_record():
    rng = np.random.default_rng(4)
    ext = np.concatenate([[0.0], rng.random(80), [0.0]])
    u = np.concatenate([np.linspace(ext[i], ext[i + 1], 30) for i in range(ext.size - 1)])
    m = HysteresisModel(method="lsq", cells=25, smoothing=1e-5).fit(u, simulate(u))
    test_u = np.concatenate(
        [np.linspace(0, 0.9, 50), np.linspace(0.9, 0.2, 50), np.linspace(0.2, 0.6, 50)]
    )
    err = np.abs(m.predict(test_u) - simulate(test_u))
    assert err.max() < 0.02 * np.ptp(simulate(test_u))
    assert m.method_ == "lsq"


def test_auto_picks_least_squares_without_the_designed_curves():
    t = np.linspace(0, 60, 3000)
    u = 0.5 + 0.45 * np.sin(t) * np.exp(-t / 30)  # decaying oscillation: no designed curves
    m = HysteresisModel().fit(u, simulate(u))
    assert m.method_ == "lsq"
    with pytest.raises(ParameterError, match="thesis's calibration curves"):
        HysteresisModel(method="thesis").fit(u, simulate(u))


def test_everett_design_matches_the_rust_evaluation():
    rng = np.random.default_rng(3)
    u = rng.random(400)
    table = true_table()
    np.testing.assert_allclose(
        everett_design(u, NODES) @ table.ravel(), simulate(u, table), atol=1e-12
    )


def test_streaming_equals_batch_bit_for_bit_and_invalid_keeps_state():
    u = thesis_record()
    m = HysteresisModel(grid=K).fit(u, simulate(u))
    rng = np.random.default_rng(0)
    frames = rng.random((300, 8))
    batch = m.predict(frames)
    st = m.state(8)
    for t in range(300):
        np.testing.assert_array_equal(st.step(frames[t]), batch[t])
    valid = rng.random(frames.shape) > 0.2
    out = m.state(8).run(frames, valid)
    assert np.all(np.isnan(out[~valid]))
    # an element skipped in a frame continues as if that frame had not been there
    ref = m.predict(frames[valid[:, 0], 0])
    np.testing.assert_array_equal(out[valid[:, 0], 0], ref)


def test_clamping_is_counted_and_set_state():
    u = thesis_record()
    m = HysteresisModel(grid=K).fit(u, simulate(u))
    st = m.state(1)
    st.run(np.array([0.5, 1.5, -0.2, 0.4]))
    assert st.clamped[0] == 2
    st = m.state(3)
    rising, falling = m.predict(np.array([0.5]))[0], m.predict(np.array([1.0, 0.5]))[1]
    target = np.array([rising + 0.3 * (falling - rising), rising - 1.0, falling + 1.0])
    got = st.set_state(0.5, target)
    assert got[0] == pytest.approx(target[0], abs=1e-6)
    assert got[1] == pytest.approx(min(rising, falling), abs=1e-6)  # clamped to the loop
    assert got[2] == pytest.approx(max(rising, falling), abs=1e-6)


def test_scaling_eq_6_12():
    p = np.linspace(0, 10, 60)
    m = HysteresisModel(grid=K, input_name="pressure_ncm2", input_unit="N/cm2").fit(
        np.concatenate([p, p[::-1], p[:42], p[:42][::-1], p[:18], p[:18][::-1]]),
        np.concatenate([p, p[::-1] * 0.8, p[:42], p[:42][::-1] * 0.85, p[:18], p[:18][::-1] * 0.9]),
    )
    start, end = np.array([2.0, 8.0]), np.array([6.0, 3.0])
    zero = scale_hysteresis(m, start, end, 0.0)
    np.testing.assert_allclose(zero, end)  # no hysteresis: the destination pattern
    one = scale_hysteresis(m, start, end, 1.0)
    two = scale_hysteresis(m, start, end, 2.0)
    assert abs(one[1] - end[1]) > 0.1  # unloading departs from the destination pattern
    np.testing.assert_allclose(two - end, 2 * (one - end))


def test_model_file_round_trip_and_errors(tmp_path):
    u = thesis_record()
    m = HysteresisModel(grid=K).fit(u, simulate(u), provenance={"specimen": 3})
    path = m.save(tmp_path / "m.json")
    back = HysteresisModel.load(path)
    np.testing.assert_array_equal(back.everett_, m.everett_)
    np.testing.assert_array_equal(back.predict(u), m.predict(u))
    assert back.provenance_["specimen"] == 3
    d = json.loads(path.read_text())
    d["version"] = 7
    (tmp_path / "v.json").write_text(json.dumps(d))
    with pytest.raises(FormatError, match=r"texsense\.hysteresis version 7; this texsense reads"):
        HysteresisModel.load(tmp_path / "v.json")
    d = json.loads(path.read_text())
    d["content"]["input"]["unit"] = "parsec"
    (tmp_path / "u.json").write_text(json.dumps(envelope("texsense.hysteresis", d["content"])))
    with pytest.raises(FormatError, match="unknown unit 'parsec'"):
        HysteresisModel.load(tmp_path / "u.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(FormatError, match="not JSON"):
        HysteresisModel.load(tmp_path / "bad.json")
    (tmp_path / "list.json").write_text("[]")
    with pytest.raises(FormatError, match="holds a JSON list, expected a hysteresis model"):
        HysteresisModel.load(tmp_path / "list.json")
    with pytest.raises(UnitError, match="takes compression_mm in mm"):
        back.check_units("kPa")
    with pytest.raises(NotFittedError):
        HysteresisModel().predict([0.1])


def test_decreasing_outputs_and_bad_input():
    u = thesis_record()
    m = HysteresisModel(grid=K).fit(u, -simulate(u))  # e.g. force of a stretched sample
    np.testing.assert_allclose(m.predict(u), -simulate(u), atol=0.05)
    with pytest.raises(ParameterError, match="does not vary"):
        HysteresisModel().fit(np.ones(50), np.arange(50.0))
    with pytest.raises(ParameterError, match="differ in length"):
        HysteresisModel().fit(np.ones(50), np.arange(49.0))
    assert np.all(make_monotone(-np.ones((4, 4))) == 0)


def test_virtual_spacer_thesis_protocol_within_the_thesis_error():
    """§4.5: identified from the calibration protocol, validated on 10 validation cycles."""
    cal = run_protocol("calibration", "textile-6mm", seed=2, sample_hz=None)
    m = HysteresisModel().fit(cal.labels["compression_mm"], cal.labels["pressure_ncm2"])
    val = run_protocol("validation", "textile-6mm", seed=2, sample_hz=None, cycles=10)
    p = val.labels["pressure_ncm2"]
    pm = m.predict(val.labels["compression_mm"])
    low = (p >= 0.5) & (p < 3.5)
    high = (p >= 3.5) & (p < 10)
    rel = np.abs(pm - p) / np.where(p > 0, p, 1)
    assert rel[low].mean() <= 0.05 and rel[high].mean() <= 0.08
    # and much better than taking the mean of the two branches (20-30 %)
    assert rel[low].mean() < 0.1


def test_cli_fit_apply_plot(tmp_path, capsys):
    from texsense.cli import main
    from texsense.io.columns_csv import read_columns_csv

    cal, val = tmp_path / "cal.csv", tmp_path / "val.csv"
    assert main(["simulate", "calibration", "--seed", "1", "--csv", str(cal)]) == 0
    assert main(["simulate", "validation", "--cycles", "3", "--seed", "1", "--csv", str(val)]) == 0
    model = tmp_path / "m.json"
    assert main(["hysteresis", "fit", str(cal), "-o", str(model)]) == 0
    capsys.readouterr()
    assert (
        main(["hysteresis", "apply", str(model), str(val), "-o", str(tmp_path / "o.csv"), "--json"])
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert summary["error"]["0.5-3.5"]["mean_relative_error"] < 0.05
    out = read_columns_csv(tmp_path / "o.csv")
    assert list(out)[-1] == "pressure_ncm2_model" and "capacitance_pF" in out
    assert main(["hysteresis", "plot", str(model), "-o", str(tmp_path / "m.png")]) == 0
    assert (tmp_path / "m.png").read_bytes()[:4] == b"\x89PNG"
    assert main(["hysteresis", "fit", str(cal), "-o", str(model), "--input", "nope"]) == 1


def test_monotone_qp_solves_isotonic_regression():
    """The interior-point solver against a known answer: least squares under x non-decreasing
    is isotonic regression (pool adjacent violators, scikit-learn)."""
    from scipy.sparse import diags
    from sklearn.isotonic import IsotonicRegression

    from texsense.compensation.hysteresis._qp import solve_monotone_qp

    rng = np.random.default_rng(7)
    y = np.cumsum(rng.normal(0.02, 1.0, 60))
    n = y.size
    C = diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n)).tocsr()
    x0 = np.linspace(-1.0, 1.0, n)  # strictly increasing: strictly feasible
    x, it = solve_monotone_qp(np.eye(n), y, C, x0)
    expected = IsotonicRegression().fit(np.arange(n), y).predict(np.arange(n))
    np.testing.assert_allclose(x, expected, atol=1e-6)
    assert np.all(np.diff(x) > 0) and it < 80  # strictly feasible, converged
    with pytest.raises(ParameterError, match="strictly"):
        solve_monotone_qp(np.eye(n), y, C, np.zeros(n))


def random_record(seed, n=60, per=30):
    rng = np.random.default_rng(seed)
    ext = np.concatenate([[0.0], rng.random(n), [0.0]])
    return np.concatenate([np.linspace(ext[i], ext[i + 1], per) for i in range(ext.size - 1)])


def test_least_squares_table_is_monotone_by_construction_on_noisy_data():
    """Noise that an unconstrained fit would follow into a non-monotone table: the
    constrained identification keeps every fine-table difference non-negative, with no
    clipping step (there is none to hide behind)."""
    u = random_record(11)
    p = simulate(u) + np.random.default_rng(1).normal(0, 0.05, u.size)
    m = HysteresisModel(method="lsq", cells=24, smoothing=1e-8).fit(u, p)
    f = m.everett_
    low = np.tril(np.ones_like(f, bool), -1)
    scale = np.abs(f).max()
    assert np.all(np.diff(f, axis=0)[low[1:]] >= -1e-12 * scale)
    assert np.all((f[:, :-1] - f[:, 1:])[low[:, :-1] & low[:, 1:]] >= -1e-12 * scale)
    assert np.all(np.diag(f) == 0)


def test_cross_validation_is_reported_and_chooses_the_best_candidate():
    u = random_record(4)
    m = HysteresisModel(method="lsq").fit(u, simulate(u))
    d = m.details_
    assert d["validation_folds"] == 4
    scores = d["cv"]
    assert len(scores) >= 5  # smoothings and sizes were tried
    best = min(scores, key=lambda s: s["rmse"])
    assert (d["alpha_cells"], d["smoothing"]) == (best["alpha_cells"], best["smoothing"])
    assert m.validation_rmse_ == pytest.approx(best["rmse"])
    assert 0 < m.validation_rmse_ < 0.02 * np.ptp(simulate(u))


def uniform_density_table(k=K):
    """Non-negative uniform Preisach density: counter-clockwise loops (magnetic material)."""
    a = np.linspace(0, 1, k)
    return np.tril(0.5 * (a[:, None] - a[None, :]) ** 2, -1)


def forcs(reversals, n=40):
    """Ascending first-order reversal curves: from positive saturation down to each reversal
    point, then back up (the mirror of the thesis's protocol)."""
    parts = []
    for r in reversals:
        parts += [np.linspace(1.0, r, n), np.linspace(r, 1.0, n)]
    return np.concatenate(parts)


@pytest.mark.parametrize("table", ["clockwise", "counter-clockwise"])
def test_forcs_fit_on_even_curves_predict_the_odd_ones(table):
    tab = true_table() if table == "clockwise" else uniform_density_table()
    rev = np.linspace(0.0, 0.95, 24)
    train, test = forcs(rev[::2]), forcs(rev[1::2])
    m = HysteresisModel().fit(train, simulate(train, tab))
    y = simulate(test, tab)
    nrmse = np.sqrt(np.mean((m.predict(test) - y) ** 2)) / np.ptp(y)
    # a spacer's clockwise loops never get the relay grid; counter-clockwise may
    expected = {"lsq"} if table == "clockwise" else {"lsq", "relay", "relay-signed"}
    assert m.method_ in expected and nrmse < 0.01


def test_cli_validate_reports_bands_branches_and_worst_places(tmp_path, capsys):
    from texsense.cli import main

    cal, val = tmp_path / "cal.csv", tmp_path / "val.csv"
    assert main(["simulate", "calibration", "--seed", "2", "--csv", str(cal)]) == 0
    assert main(["simulate", "validation", "--cycles", "2", "--seed", "2", "--csv", str(val)]) == 0
    model = tmp_path / "m.json"
    assert main(["hysteresis", "fit", str(cal), "-o", str(model)]) == 0
    capsys.readouterr()
    plot = tmp_path / "v.png"
    assert (
        main(["hysteresis", "validate", str(model), str(val), "--plot", str(plot), "--json"]) == 0
    )
    report = json.loads(capsys.readouterr().out)
    assert [b["name"] for b in report["bands"]] == ["0.5-3.5", "3.5-10"]
    rising, falling = report["branches"]
    assert rising["samples"] + falling["samples"] == report["samples"]
    assert 0 < report["bands"][0]["mean_relative"] < 0.05
    worst = report["worst"]
    assert len(worst) == 5
    errs = [abs(w["model"] - w["measured"]) for w in worst]
    assert errs == sorted(errs, reverse=True) and errs[0] > 0
    assert plot.read_bytes()[:4] == b"\x89PNG"
    # the text report names the worst place; a missing column names the file and the column
    assert main(["hysteresis", "validate", str(model), str(val)]) == 0
    assert "worst places" in capsys.readouterr().out
    assert main(["hysteresis", "validate", str(model), str(val), "--output", "nope"]) == 1
    assert "nope" in capsys.readouterr().err
