"""One rule for a pressure just below zero (an empty element's estimate, about -0.001
N/cm²): the live map, the statistics and the pressure file all show it as 0
(:func:`texsense.compensation.pipeline.no_negative`), so a mat's map never reads a
negative pressure that its recording does not hold."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from texsense.compensation.pipeline import NEAR_ZERO_NCM2
from texsense.monitor.store import EventStore
from texsense.station.ward import MatEntry


def test_the_live_map_shows_an_empty_elements_estimate_as_zero(seat_mat):
    config, payloads = seat_mat
    entry = MatEntry(config, EventStore(":memory:"), Path("recordings-unused"), 1.0)
    pipeline = entry.monitor.pipeline
    step, raw = pipeline.step, []

    def tapped(*args, **kwargs):
        out = step(*args, **kwargs)
        raw.append(np.array(out[0]))
        return out

    pipeline.step = tapped
    near_seen = 0
    for payload, now in payloads:
        assert entry.handle(payload, now)
        p, shown = raw[-1], entry.monitor.last_pressure
        near = (p < 0) & (p >= -NEAR_ZERO_NCM2)
        near_seen += int(near.sum())
        np.testing.assert_array_equal(shown, np.where(near, 0.0, p))
    assert near_seen > 0  # the pipeline did give estimates just below zero


def test_a_seat_sessions_pressure_file_holds_the_rule_applied_once(seat_mat, tmp_path):
    """The recording of a seat session through the ward's pipeline (in-use drift, bounds):
    its pressure is the pipeline's with the rule applied (no_negative, NaN as 0) and its
    lower bounds the pipeline's never below zero, to the bit: the monitor clips the pressure
    once, the recorder only the lower bounds (before, the recorder applied the rule again to
    the pressure the monitor had clipped: the same file)."""
    from texsense import load
    from texsense.io.hdf5 import read_bounds

    config, payloads = seat_mat
    entry = MatEntry(config, EventStore(":memory:"), tmp_path, 1.0)
    pipeline = entry.monitor.pipeline
    step, got = pipeline.step, []

    def tapped(*args, **kwargs):
        out = step(*args, **kwargs)
        got.append((np.array(out[0]), np.array(out[1]), *map(np.array, pipeline.bounds_)))
        return out

    pipeline.step = tapped
    paths = entry.monitor.start_recording("seat")
    for payload, now in payloads:
        assert entry.handle(payload, now)
    assert entry.monitor.stop_recording() == len(payloads) == len(got)
    p, measured, lo, hi = (np.array(a) for a in zip(*got, strict=True))
    lo, hi = lo[:, 0], hi[:, 0]  # a step's bounds: (1, N)
    assert lo.shape == p.shape
    near = (p < 0) & (p >= -NEAR_ZERO_NCM2)
    assert near.any() and (lo < 0).any()  # estimates and lower bounds below zero to clip
    want = np.where(near, 0.0, np.nan_to_num(p)).astype(np.float32)
    rec = load(paths[1])
    file_lo, file_hi = read_bounds(paths[1])
    assert rec.frames.view(np.uint32).tolist() == want.view(np.uint32).tolist()
    np.testing.assert_array_equal(rec.valid, measured & (want >= 0))
    want_lo = np.maximum(np.nan_to_num(lo), 0).astype(np.float32)
    assert file_lo.view(np.uint32).tolist() == want_lo.view(np.uint32).tolist()
    want_hi = np.nan_to_num(hi).astype(np.float32)
    assert file_hi.view(np.uint32).tolist() == want_hi.view(np.uint32).tolist()
