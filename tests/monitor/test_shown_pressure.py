"""One rule for a pressure just below zero (an empty element's estimate, about -0.001
N/cm²): the live map, the statistics and the pressure file all show it as 0
(:func:`texsense.compensation.intervals.no_negative`), so a mat's map never reads a
negative pressure that its recording does not hold."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from texsense.compensation.intervals import NEAR_ZERO_NCM2
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
