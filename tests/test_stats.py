import numpy as np
import pytest

from texsense import Layout, Recording
from texsense.apps import stats
from texsense.exceptions import ParameterError


def grid_rec(maps, pitch=1.0, unit="N/cm2", valid=None, quantity="pressure"):
    maps = np.asarray(maps, dtype=float)
    t, rows, cols = maps.shape
    lay = Layout.grid(rows, cols, pitch_cm=pitch)
    v = None if valid is None else np.asarray(valid).reshape(t, -1)
    return Recording(maps.reshape(t, -1), np.arange(t) * 0.1, lay, quantity, unit, valid=v)


def test_load_area_peak_on_a_known_map():
    m = np.zeros((1, 4, 5))
    m[0, 1, 1] = 2.0
    m[0, 2, 3] = 1.0
    rec = grid_rec(m, pitch=2.0)  # 4 cm² per element
    assert stats.total_load(rec)[0] == pytest.approx(12.0)
    assert stats.contact_area(rec)[0] == pytest.approx(8.0)
    assert stats.contact_area(rec, threshold=1.5)[0] == pytest.approx(4.0)
    assert stats.peak_pressure(rec)[0] == 2.0


def test_centre_of_force_of_known_maps():
    m = np.zeros((2, 3, 3))
    m[0, 0, 0] = 1.0
    m[0, 2, 2] = 1.0  # symmetric: centre at the middle cell
    m[1, 0, 2] = 3.0
    m[1, 2, 2] = 1.0  # x at column 2, y weighted 3:1 towards row 0
    rec = grid_rec(m, pitch=1.0)
    cof = stats.centre_of_force(rec)
    np.testing.assert_allclose(cof[0], [1.5, 1.5])
    np.testing.assert_allclose(cof[1], [2.5, (3 * 0.5 + 1 * 2.5) / 4])
    empty = stats.centre_of_force(grid_rec(np.zeros((1, 2, 2))))
    assert np.isnan(empty).all()


def test_the_load_is_in_newton_and_the_values_in_the_recordings_unit():
    """Issue 33: ``peak_pressure(rec.to_unit("mmHg"))`` returned N/cm²."""
    m = np.full((1, 2, 2), 10.0)  # kPa = 1 N/cm²
    assert stats.total_load(grid_rec(m, unit="kPa"))[0] == pytest.approx(4.0)
    assert stats.peak_pressure(grid_rec(m, unit="kPa"))[0] == pytest.approx(10.0)
    in_mmhg = grid_rec(np.full((1, 2, 2), 1.0)).to_unit("mmHg")
    assert stats.peak_pressure(in_mmhg)[0] == pytest.approx(75.006, abs=1e-3)
    assert stats.peak_pressure_index(in_mmhg)[0] == pytest.approx(75.006, abs=1e-3)
    assert stats.contact_area(in_mmhg, threshold=70.0)[0] == pytest.approx(4.0)


def test_invalid_readings_are_left_out():
    m = np.array([[[1.0, 100.0], [1.0, 1.0]]])
    valid = np.array([[[True, False], [True, True]]])
    rec = grid_rec(m, valid=valid)
    assert stats.peak_pressure(rec)[0] == 1.0
    assert stats.total_load(rec)[0] == 3.0
    all_bad = grid_rec(m, valid=np.zeros_like(valid))
    assert np.isnan(stats.total_load(all_bad)[0]) and np.isnan(stats.peak_pressure(all_bad)[0])


def test_peak_pressure_index_is_the_best_3x3_mean():
    m = np.zeros((1, 6, 6))
    m[0, 0, 0] = 20.0  # isolated spike: its best 3x3 mean is 20/9
    m[0, 3:6, 3:6] = 4.0  # a 3x3 block of 4: mean 4
    rec = grid_rec(m)
    assert stats.peak_pressure_index(rec)[0] == pytest.approx(4.0)
    assert stats.peak_pressure_index(rec, window=1)[0] == pytest.approx(20.0)
    # windows larger than the grid shrink to the grid
    assert stats.peak_pressure_index(grid_rec(np.ones((1, 2, 2))), window=5)[0] == 1.0
    with pytest.raises(ParameterError):
        stats.peak_pressure_index(rec, window=0)


def test_peak_pressure_index_matches_brute_force_with_empty_cells():
    rng = np.random.default_rng(1)
    active = rng.random((7, 9)) > 0.2
    lay = Layout.grid(7, 9, active=active)
    frames = rng.random((4, lay.n_elements))
    rec = Recording(frames, np.arange(4.0), lay)
    maps = lay.to_grid(frames)
    expected = [
        max(
            np.nanmean(maps[t, r : r + 3, c : c + 3])
            for r in range(5)
            for c in range(7)
            if np.isfinite(maps[t, r : r + 3, c : c + 3]).any()
        )
        for t in range(4)
    ]
    np.testing.assert_allclose(stats.peak_pressure_index(rec), expected)


def test_peak_pressure_index_on_points_uses_nearest_elements():
    xy = np.array([[0, 0], [1, 0], [2, 0], [10, 0]], float)
    lay = Layout.points(xy, size_cm=1.0)
    rec = Recording([[3.0, 1.0, 2.0, 9.0]], [0.0], lay)
    # window 1 -> 1 element: the peak itself
    assert stats.peak_pressure_index(rec, window=1)[0] == 9.0
    # window 2 -> 4 nearest of the peak (element 3): all four
    assert stats.peak_pressure_index(rec, window=2)[0] == pytest.approx(15 / 4)


def test_coefficient_of_variation():
    rec = grid_rec(np.array([[[2.0, 4.0], [0.0, 0.0]]]))
    assert stats.coefficient_of_variation(rec)[0] == pytest.approx(1.0 / 3.0)
    assert np.isnan(stats.coefficient_of_variation(grid_rec(np.ones((1, 1, 1))))[0])


def test_region_stats_and_raw_data():
    lay = Layout.grid(2, 2).with_regions({"top": [0, 1], "bottom": [2, 3]})
    rec = Recording([[1.0, 3.0, 0.0, 0.0]], [0.0], lay)
    rs = stats.region_stats(rec)
    assert rs["top"]["load_N"][0] == 4.0 and rs["top"]["mean"][0] == 2.0
    assert rs["top"]["peak"][0] == 3.0 and rs["bottom"]["contact_area_cm2"][0] == 0.0
    raw = Recording([[1.0, 3.0, 0.0, 0.0]], [0.0], lay, "raw", "count")
    with pytest.raises(ParameterError, match="calibrate"):
        stats.total_load(raw)
    assert "load_N" not in stats.region_stats(raw)["top"]
    fs = stats.frame_stats(raw)
    assert fs.load_N is None and fs.peak[0] == 3.0
    with pytest.raises(ParameterError, match="no regions"):
        stats.region_stats(Recording([[1.0]], [0.0], Layout.grid(1, 1)))


@pytest.mark.parametrize("unit", ["N/cm2", "kPa"])
@pytest.mark.parametrize("gaps", [False, True], ids=["all-valid", "gaps"])
def test_frame_stats_are_one_computation_and_match_brute_force(monkeypatch, unit, gaps):
    """frame_stats and one_frame_stats are one computation (stats._block_stats, called once
    by each), right on frames with every reading valid (the plain reductions a station's
    frames take) and on frames with invalid readings (left out): load, contact area, peak,
    3 x 3 PPI, centre of force and coefficient of variation against loops over the elements
    and windows."""
    rng = np.random.default_rng(3)
    lay = Layout.grid(6, 5, pitch_cm=1.5)
    frames = rng.gamma(1.0, 20.0, (6, lay.n_elements)) * (rng.random((6, lay.n_elements)) < 0.7)
    valid = np.ones(frames.shape, bool)
    if gaps:  # frames 1 and 4 with invalid readings, 5 with none valid
        valid[1, [0, 7, 8]] = False
        valid[4, ::3] = False
        valid[5] = False
    rec = Recording(frames, np.arange(6.0), lay, "pressure", unit, valid=valid)
    frames = rec.frames.astype(np.float64)  # (a recording stores float32)
    calls = []
    block = stats._block_stats
    monkeypatch.setattr(stats, "_block_stats", lambda *a, **k: calls.append(1) or block(*a, **k))
    got = stats.frame_stats(rec, threshold=5.0)
    assert len(calls) == 1
    f = 0.1 if unit == "kPa" else 1.0  # N/cm² of the unit, for the load
    area, xy = lay.area_cm2, lay.xy_cm
    maps = lay.to_grid(np.where(valid, frames, np.nan))
    for t in range(6):
        v, ok = frames[t], valid[t]
        if not ok.any():
            assert np.isnan(got.load_N[t]) and np.isnan(got.peak[t]) and np.isnan(got.ppi[t])
            continue
        assert got.load_N[t] == pytest.approx(sum(v[i] * f * area[i] for i in np.flatnonzero(ok)))
        assert got.contact_area_cm2[t] == pytest.approx(area[ok & (v > 5.0)].sum())
        assert got.peak[t] == v[ok].max()
        windows = [maps[t, r : r + 3, c : c + 3] for r in range(4) for c in range(3)]
        assert got.ppi[t] == pytest.approx(max(np.nanmean(w) for w in windows))
        w = np.where(ok, np.maximum(v * area, 0.0), 0.0)
        np.testing.assert_allclose(got.cof_cm[t], (w @ xy) / w.sum())
        loaded = v[ok & (v > 5.0)]
        assert got.cov[t] == pytest.approx(loaded.std() / loaded.mean())
    one = stats.one_frame_stats(frames[0] * f, lay, threshold=5.0 * f)
    assert len(calls) == 2
    assert one["peak"] == pytest.approx(got.peak[0] * f)
    assert one["load_N"] == pytest.approx(got.load_N[0])
    assert one["ppi"] == pytest.approx(got.ppi[0] * f)


@pytest.mark.parametrize("layout", [Layout.grid(6, 5, pitch_cm=1.5),
                                    Layout.points(np.random.default_rng(1).uniform(0, 9, (12, 2)))],
                         ids=["grid", "points"])  # fmt: skip
def test_one_frame_stats_are_frame_stats_of_that_frame(layout):
    rng = np.random.default_rng(0)
    for k in range(20):
        v = rng.gamma(1.0, 1.0, layout.n_elements) * (k % 4 != 0)  # an empty frame sometimes
        v[rng.random(layout.n_elements) < 0.2] = 0.0
        if k % 3 == 0:
            v[rng.integers(layout.n_elements)] = np.nan  # read as 0, as the station does
        one = stats.one_frame_stats(v, layout, threshold=0.05)
        full = stats.frame_stats(
            Recording(np.nan_to_num(v)[None, :], [0.0], layout, "pressure", "N/cm2"), 0.05
        )
        assert one["load_N"] == full.load_N[0]
        assert one["contact_area_cm2"] == full.contact_area_cm2[0]
        assert one["peak"] == full.peak[0] and one["ppi"] == full.ppi[0]
        np.testing.assert_array_equal(one["cof_cm"], full.cof_cm[0])


@pytest.mark.parametrize("layout", [Layout.grid(32, 32), Layout.grid(6, 5, pitch_cm=1.5),
                                    Layout.grid(4, 6, active=np.arange(24).reshape(4, 6) % 5 != 0),
                                    Layout.points(np.random.default_rng(1).uniform(0, 9, (12, 2)))],
                         ids=["32x32", "6x5", "gaps", "points"])  # fmt: skip
def test_live_stats_are_one_frame_stats(layout):
    """The station's per-frame statistics (compiled on a grid) are one_frame_stats of the
    frame, and the centre of force in cells the pressure-weighted mean of the elements' rows
    and columns, to the last few bits: on loaded, empty, negative and NaN frames; a frame with
    an infinite value takes one_frame_stats itself."""
    rng = np.random.default_rng(7)
    live = stats.LiveStats(layout, threshold=0.05)
    assert (live._grid is None) == (layout.shape is None)
    n = layout.n_elements
    if layout.cells is not None:
        rows, cols = np.divmod(layout.cells, layout.shape[1])
        where = np.stack([rows, cols], axis=1).astype(float)
    else:
        where = layout.xy_cm
    for k in range(24):
        v = rng.gamma(1.0, 2.0, n) * (k % 6 != 0) - 0.3 * (k % 5 == 1)
        if k % 3 == 0:
            v[rng.integers(n, size=3)] = np.nan
        if k == 23:  # (float32 overflows: numpy warns, in either path)
            v[0] = np.inf
            with np.errstate(over="ignore", invalid="ignore"):
                fs, _ = live(v)
                ref = stats.one_frame_stats(v, layout, threshold=0.05)
            assert fs["load_N"] == ref["load_N"] and fs["peak"] == ref["peak"] == np.inf
            continue
        fs, cell = live(v)
        ref = stats.one_frame_stats(v, layout, threshold=0.05)
        for key in ("load_N", "contact_area_cm2", "peak", "ppi"):
            assert fs[key] == pytest.approx(ref[key], rel=1e-12, abs=1e-12, nan_ok=True), key
        np.testing.assert_allclose(fs["cof_cm"], ref["cof_cm"], rtol=1e-12)
        w = np.maximum(np.nan_to_num(v), 0.0)
        want = (w @ where) / w.sum() if w.sum() > 0 else [np.nan, np.nan]
        np.testing.assert_allclose(cell, want, rtol=1e-12)
