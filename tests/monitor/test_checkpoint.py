"""A mat's checkpoint (texsense.station.checkpoint, docs/station.md "A group of stations"):
what a member takes on its event loop and packs in the journal's thread is what a taking
member goes on from. One virtual seat, fed the same frames as `texsense station` would."""

from __future__ import annotations

import json

import numpy as np
import pytest

from texsense.exceptions import ParameterError
from texsense.monitor.store import EventStore
from texsense.station import checkpoint
from texsense.station.ward import MatEntry


def test_a_taken_checkpoint_restores_the_mat_where_it_was(seat_mat, tmp_path):
    config, payloads = seat_mat
    a = MatEntry(config, EventStore(":memory:"), tmp_path / "a", 1.0)
    for p, now in payloads[:40]:
        a.handle(p, now)
    often, rarely = checkpoint.take(a, often=True), checkpoint.take(a, often=False)
    assert callable(often.parts["monitor"])  # its JSON-ready rows made later, off the loop
    a.handle(*payloads[40])  # the mat goes on before the journal packs what was taken
    blobs = [rarely.pack(), often.pack()]
    b = MatEntry(config, EventStore(":memory:"), tmp_path / "b", 1.0)
    done = checkpoint.restore(b, blobs)
    assert sorted(done["parts"]) == ["monitor", "pipeline"], done
    assert b.monitor.frames == 40
    # the one frame after the checkpoint, on both: the same exposure, pressure and clock
    c = MatEntry(config, EventStore(":memory:"), tmp_path / "c", 1.0)
    checkpoint.restore(c, blobs)
    c.handle(*payloads[40])
    # (the checkpoint keeps each exposure to the millisecond)
    ours, theirs = c.monitor.tracker.state(), a.monitor.tracker.state()
    np.testing.assert_allclose(ours.pop("exposed"), theirs.pop("exposed"), atol=1.5e-3)
    assert ours == theirs
    np.testing.assert_array_equal(c.monitor.last_pressure, a.monitor.last_pressure)
    assert c.monitor.clock.state() == a.monitor.clock.state()
    assert c.state == "live" and b.state == "live" and b.last_seen is not None


def test_the_frames_never_seen_go_with_the_mat_and_say_which(seat_mat, tmp_path):
    """Frames lost (seq 10-11 on the way, 20 at a takeover) are counted (``missed``) and named
    as runs (``missed_runs``: the group's fault test tells a run two stations missed alike
    from two runs of the same count), and both go over a checkpoint."""
    config, payloads = seat_mat
    a = MatEntry(config, EventStore(":memory:"), tmp_path / "a", 1.0)
    for k in [*range(10), *range(12, 20)]:
        a.handle(*payloads[k])
    b = MatEntry(config, EventStore(":memory:"), tmp_path / "b", 1.0)
    checkpoint.restore(b, [checkpoint.save(a, often=False), checkpoint.save(a)])
    b.handle(*payloads[21])
    assert b.monitor.missed == 3 and list(b.monitor.missed_runs) == [(10, 11), (20, 20)]
    assert b.status()["missed_runs"] == [[10, 11], [20, 20]]
    state = {**b.monitor.resume_state(), "missed_runs": [1, 2, 3]}  # not pairs: refused
    with pytest.raises(ParameterError, match="missed_runs"):
        b.monitor.resume(state)


def test_the_tracker_s_packed_state_is_its_state_exactly(seat_mat, tmp_path):
    config, payloads = seat_mat
    a = MatEntry(config, EventStore(":memory:"), tmp_path / "a", 1.0)
    for p, now in payloads[:30]:
        a.handle(p, now)
    tracker = a.monitor.tracker
    rows, packed = tracker.state(), tracker.state_packed()
    exposure = tracker.exposure_s.copy()
    a.handle(*payloads[30])  # copies were taken: what the tracker does next is not in it
    assert set(packed["exposed"]) == {"index", "exposure_s", "relief_s"}
    b = MatEntry(config, EventStore(":memory:"), tmp_path / "b", 1.0)
    b.monitor.tracker.restore(json.loads(json.dumps(packed)))
    assert np.count_nonzero(exposure) > 0
    np.testing.assert_array_equal(b.monitor.tracker.exposure_s, exposure)  # exact
    assert b.monitor.tracker.state() == rows  # and the rows' form says the same
    c = MatEntry(config, EventStore(":memory:"), tmp_path / "c", 1.0)
    c.monitor.tracker.restore(rows)  # a checkpoint of version 1 (rows) is read too
    np.testing.assert_allclose(c.monitor.tracker.exposure_s, exposure, atol=1e-3)
    with pytest.raises(ParameterError, match="exposure state"):
        c.monitor.tracker.restore({**packed, "exposed": {**packed["exposed"], "index": "AA"}})
