"""The peak's bounds on the live charts (issue 37's bounds, drawn as a band around the peak
line) are the report's band of the same session: the live monitor and the report it
records say the same of how high the peak may be."""

from __future__ import annotations

import numpy as np

from texsense.apps.review import open_review
from texsense.apps.stats import peak_bounds
from texsense.monitor.store import EventStore
from texsense.station.ward import MatEntry


def test_the_live_peak_band_is_the_reports_band_of_the_recording(seat_mat, tmp_path):
    config, payloads = seat_mat
    entry = MatEntry(config, EventStore(":memory:"), tmp_path, 1.0)
    paths = entry.monitor.start_recording("seat")
    for payload, now in payloads:
        assert entry.handle(payload, now)
    assert entry.monitor.stop_recording() == len(payloads)
    rows = np.array(
        [[np.nan if v is None else v for v in r] for r in entry.monitor.history], dtype=float
    )
    assert rows.shape == (len(payloads), 10)
    peak, lower, upper = rows[:, 2], rows[:, 8], rows[:, 9]
    assert np.isfinite(lower).all() and np.isfinite(upper).all()
    assert (upper > lower).all() and (lower > 0).any()
    # the line is inside its band (both rounded to 0.001 N/cm²)
    assert ((lower <= peak + 1e-9) & (peak <= upper + 1e-9)).all()
    review = open_review(paths[1])
    to_ncm2 = 1.0 / review.factor  # the report's series are in its display unit
    for name, live in (("peak", peak), ("peak_lower", lower), ("peak_upper", upper)):
        report = review.series[name] * to_ncm2
        # the live numbers are rounded to 0.001 N/cm², the file's are float32
        np.testing.assert_allclose(live, report, atol=6e-4, rtol=0, err_msg=name)
    # and the playback of the file draws the same band (its series, a bin's highest of each)
    from texsense.monitor.playback import _series

    series = _series(review)
    got = {k: np.array(series[k], dtype=float) for k in ("peak", "peak_lower", "peak_upper")}
    assert len(got["peak_lower"]) == len(got["peak"]) == len(payloads)
    assert (got["peak_lower"] <= got["peak"] + 1e-3).all()
    assert (got["peak"] <= got["peak_upper"] + 1e-3).all()


def test_peak_bounds_counts_the_elements_with_a_pressure_and_never_shows_below_zero():
    p = np.array([0.0, 0.5, np.nan, 0.2])
    lower = np.array([-0.3, 0.4, 9.0, np.nan])
    upper = np.array([0.1, 0.9, 9.0, 0.3])
    assert peak_bounds(p, (lower, upper)) == {"peak_lower_ncm2": 0.4, "peak_upper_ncm2": 0.9}
    empty = np.array([0.0, 0.0])
    assert peak_bounds(empty, (np.array([-0.2, -0.1]), np.array([0.1, 0.05]))) == {
        "peak_lower_ncm2": 0.0,
        "peak_upper_ncm2": 0.1,
    }
    none = np.full(2, np.nan)
    assert peak_bounds(none, (np.zeros(2), np.ones(2))) == {
        "peak_lower_ncm2": None,
        "peak_upper_ncm2": None,
    }
