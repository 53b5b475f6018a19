import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from texsense import Layout
from texsense.exceptions import ParameterError
from texsense.monitor import EventStore, ExposureTracker


def run(tracker, schedule, dt=10.0):
    """schedule: list of (seconds, pressure vector); returns all events."""
    events = []
    t = 0.0 if tracker._last_t is None else tracker._last_t + dt
    for seconds, p in schedule:
        for _ in range(int(seconds / dt)):
            events += tracker.step(np.asarray(p, float), t)
            t += dt
    return events


def test_threshold_in_any_unit_and_exposure_accumulates_only_above_it():
    lay = Layout.grid(1, 3)
    tr = ExposureTracker(lay, threshold=4.266, unit="kPa", reposition_min=5)  # = 32 mmHg
    assert tr.threshold_ncm2 == pytest.approx(0.4266)
    run(tr, [(120, [0.5, 0.40, 0.0])])  # 0.5 above, 0.40 just below
    np.testing.assert_allclose(tr.exposure_s, [110.0, 0.0, 0.0])  # first step has dt = 0


def test_short_relief_does_not_reset_but_offloading_does():
    lay = Layout.grid(1, 1)
    tr = ExposureTracker(lay, reposition_min=20, offload_min=1)
    run(tr, [(600, [1.0]), (30, [0.0]), (300, [1.0])])
    # 30 s of relief kept the 590 s before (the first frame has no interval) and 300 s added
    assert tr.exposure_s[0] == pytest.approx(890.0)
    run(tr, [(70, [0.0])])
    assert tr.exposure_s[0] == 0.0  # 1 min offloaded: reset


def test_time_not_read_counts_as_loaded_where_either_frame_is():
    """Frames not read (a station behind skims them, a takeover, frames lost): the next frame
    read says so (skipped=True), and the time since the last frame read counts as loaded for
    an element loaded at either of them, never as relief; a state that held over the gap
    counts all of it, as between frames in a row. Frames 1 s apart, 10 not read."""
    lay = Layout.grid(1, 3)
    on, off = 1.0, 0.0
    whole, skim = (ExposureTracker(lay, reposition_min=20, offload_min=1) for _ in range(2))
    for t in range(100):  # loaded from 0 to 49 s: element 0 onsets at 50 s, element 1 offsets
        p = np.array([off if t < 50 else on, on if t < 50 else off, on])
        whole.step(p, float(t))
        if t <= 45 or t >= 56:  # 46 ... 55 s not read
            skim.step(p, float(t), skipped=t == 56)
    # every frame read: 0 counted 50 s, 1 counted 49 s (the first frame has no interval);
    # not read: the 11 s from 45 to 56 s loaded for both, 5-6 s more than they were
    np.testing.assert_allclose(whole.exposure_s, [50.0, 49.0, 99.0])
    np.testing.assert_allclose(skim.exposure_s, [11.0 + 43.0, 45.0 + 11.0, 99.0])
    assert (skim.exposure_s >= whole.exposure_s).all()
    old = ExposureTracker(lay, reposition_min=20, offload_min=1)  # (not said: all in the new)
    for t in [*range(46), *range(56, 100)]:
        old.step(np.array([off if t < 50 else on, on if t < 50 else off, on]), float(t))
    np.testing.assert_allclose(old.exposure_s, [11.0 + 43.0, 45.0, 99.0])  # 1: 4 s too few


def test_time_not_read_never_counts_as_relief():
    """An element loaded for 260 s, then relieved; the frames of 250-269 s are not read. Read
    every frame, 50 s of relief keep its exposure (under the minute that resets it). Not said
    (the gap in the next frame's state), the 21 s of the gap would count as relief and reset
    an exposure that is still there; said (skipped=True), they count as loaded."""
    lay = Layout.grid(1, 1)
    loads = [1.0] * 260 + [0.0] * 50  # 1 s frames, 0 ... 309 s
    whole, said, unsaid = (ExposureTracker(lay, reposition_min=20, offload_min=1)
                           for _ in range(3))  # fmt: skip
    for t, v in enumerate(loads):
        whole.step(np.array([v]), float(t))
        if not 250 <= t < 270:
            said.step(np.array([v]), float(t), skipped=t == 270)
            unsaid.step(np.array([v]), float(t))
    assert whole.exposure_s[0] == 259.0
    assert said.exposure_s[0] == 249.0 + 21.0  # 249 -> 270 s loaded, then 39 s of relief
    assert unsaid.exposure_s[0] == 0.0  # 21 + 39 s of relief: reset


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), hold=st.floats(5.0, 120.0), gaps=st.integers(1, 6),
       compiled=st.booleans())  # fmt: skip
def test_frames_not_read_never_make_exposure_smaller_or_an_alert_later(seed, hold, gaps, compiled):
    """Any loads (each element switching after ~``hold`` s), any frames not read: at every
    frame read, each element's exposure is at least that of reading every frame, and the first
    alert comes no later than the first frame read at or after reading every frame's alert,
    unless a load came and went wholly inside frames not read (nothing can know it)."""
    rng = np.random.default_rng(seed)
    n, frames = 4, 160
    t = np.cumsum(rng.uniform(1.0, 12.0, frames))
    flips = rng.random((frames, n)) < np.diff(t, prepend=0.0)[:, None] / hold
    loads = np.cumsum(flips, axis=0) % 2 == 1
    read = np.ones(frames, bool)
    for _ in range(gaps):
        k = int(rng.integers(1, frames - 1))
        read[k : k + int(rng.integers(1, 8))] = False
    read[-1] = True
    kept = np.flatnonzero(read)
    for a, b in itertools.pairwise(kept):  # a load wholly inside the frames not read
        hidden = loads[a + 1 : b].any(axis=0) & ~loads[a] & ~loads[b]  # : excluded
        if hidden.any():
            loads[a + 1 : b, hidden] = False
    lay = Layout.grid(1, n)
    whole, gapped = (ExposureTracker(lay, reposition_min=5, offload_min=1) for _ in range(2))
    whole.compiled = gapped.compiled = compiled
    first: dict[str, float | None] = {"whole": None, "gapped": None}
    last = 0
    for k in range(frames):
        p = loads[k].astype(float)
        for name, tr, skipped in (("whole", whole, False), ("gapped", gapped, k - last > 1)):
            if name == "gapped" and not read[k]:
                continue
            ev = tr.step(p, float(t[k]), skipped=skipped)
            if first[name] is None and any(e.kind == "reposition" for e in ev):
                first[name] = float(t[k])
        if read[k]:
            assert (gapped.exposure_s >= whole.exposure_s - 1e-9).all(), (
                k,
                gapped.exposure_s,
                whole.exposure_s,
            )
            last = k
    if first["whole"] is not None:
        due = t[kept[np.searchsorted(t[kept], first["whole"])]]
        assert first["gapped"] is not None and first["gapped"] <= due


def test_reposition_alert_opens_once_acknowledge_and_clear():
    lay = Layout.grid(2, 2)
    tr = ExposureTracker(lay, reposition_min=5, offload_min=1)
    seated = [1.0, 1.0, 0.0, 0.0]
    events = run(tr, [(290, seated)])
    assert [e.kind for e in events] == ["seated"]
    events = run(tr, [(600, seated)])
    kinds = [e.kind for e in events]
    assert kinds.count("reposition") == 1  # not again while open
    alert = tr.open_alert
    assert alert.elements == [0, 1] and alert.active
    ack = tr.acknowledge(alert.id, 900.0)
    assert ack.kind == "acknowledged" and not alert.active and tr.open_alert is alert
    events = run(tr, [(80, [0.0] * 4)])
    assert [e.kind for e in events] == ["left", "cleared"]
    assert tr.open_alert is None and alert.cleared_t is not None
    with pytest.raises(ParameterError, match="no alert"):
        tr.acknowledge(99, 1.0)


def test_an_adopted_alert_is_the_open_one_and_no_id_is_given_twice():
    """A takeover reads back an alert the mat's former holder raised after its last
    checkpoint (``station.checkpoint.replay``): the tracker takes it as its own, and its
    next alert's id comes after it."""
    from texsense.apps.alerts import Alert

    lay = Layout.grid(2, 2)
    tr = ExposureTracker(lay, reposition_min=5, offload_min=1)
    tr.adopt(Alert(7, 100.0, [0], 300.0))
    assert tr.open_alert.id == 7
    run(tr, [(80, [0.0] * 4)])
    assert tr.open_alert is None
    run(tr, [(400, [1.0, 0.0, 0.0, 0.0])])
    assert tr.open_alert.id == 8


def test_regions_track_mean_pressure():
    lay = Layout.grid(2, 2)
    regions = {"left": [0, 2], "right": [1, 3]}
    tr = ExposureTracker(lay, regions=regions, reposition_min=5)
    events = run(tr, [(400, [1.0, 0.2, 1.0, 0.9])])  # right mean 0.55 N/cm² > 32 mmHg
    assert events[-1].kind == "reposition" and events[-1].detail["where"] == ["left", "right"]
    np.testing.assert_allclose(tr.exposure_map(), [390.0] * 4)  # 40 steps, the first dt = 0


def test_bad_parameters_are_named():
    lay = Layout.grid(1, 2)
    with pytest.raises(ParameterError, match="5-120 min"):
        ExposureTracker(lay, reposition_min=3)
    with pytest.raises(ParameterError, match="not a pressure unit"):
        ExposureTracker(lay, unit="pF")
    with pytest.raises(ParameterError, match="threshold"):
        ExposureTracker(lay, threshold=-1)
    tr = ExposureTracker(lay)
    with pytest.raises(ParameterError, match="expected 2"):
        tr.step(np.zeros(3), 0.0)
    tr.step(np.zeros(2), 5.0)
    with pytest.raises(ParameterError, match="backwards"):
        tr.step(np.zeros(2), 4.0)


def test_event_store_keeps_sessions_and_events(tmp_path):
    from texsense.monitor import Event

    path = tmp_path / "m.sqlite"
    store = EventStore(path)
    sid = store.start_session("test")
    store.add_event(sid, Event("reposition", 10.0, 1, {"where": ["3"]}))
    store.set_recording(sid, ["a.h5"])
    store.end_session(sid)
    store.close()
    again = EventStore(path)  # a new process sees it all
    (s,) = again.sessions()
    assert s["source"] == "test" and s["recordings"] == ["a.h5"] and s["ended"] is not None
    assert again.events(kind="reposition")[0]["detail"] == {"where": ["3"]}
    assert again.events(kind="cleared") == []


def test_the_event_file_is_a_write_ahead_log_read_by_others_and_kept_by_a_killed_writer(
    tmp_path,
):
    """The file store commits to SQLite's write-ahead log (one sync a commit, issue 38):
    another process reads the events while the writer runs, and every event committed
    before the writer was killed (no close, no checkpoint of the log) is there after it."""
    import sqlite3
    import subprocess
    import sys

    path = tmp_path / "m.sqlite"
    writer = (
        "import os, sys\n"
        "from texsense.monitor import Event, EventStore\n"
        "store = EventStore(sys.argv[1])\n"
        "sid = store.start_session('mat')\n"
        "for k in range(5):\n"
        "    store.add_event(sid, Event('seated', float(k), None, {'k': k}))\n"
        "print(store._db.execute('PRAGMA journal_mode').fetchone()[0], flush=True)\n"
        "sys.stdin.readline()\n"  # held open until the test has read the file
        "os._exit(0)\n"  # killed: no close
    )
    with subprocess.Popen([sys.executable, "-c", writer, str(path)], stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, text=True) as proc:  # fmt: skip
        assert proc.stdout.readline().strip() == "wal"
        other = sqlite3.connect(path)  # another program, while the writer holds the file
        assert other.execute("SELECT count(*) FROM events").fetchone()[0] == 5
        other.close()
        proc.communicate("\n", timeout=30)
    again = EventStore(path)
    assert sorted(e["detail"]["k"] for e in again.events(kind="seated")) == [0, 1, 2, 3, 4]
    again.close()


def test_possibly_above_counts_only_when_the_user_chooses_so():
    # element 0: lower bound above 32 mmHg (confident); element 1: only its upper bound is
    lay = Layout.grid(1, 3)
    p, lo, hi = np.array([0.6, 0.4, 0.1]), np.array([0.5, 0.3, 0.0]), np.array([0.7, 0.5, 0.2])
    for count, expected in ((False, [50.0, 0.0, 0.0]), (True, [50.0, 50.0, 0.0])):
        tr = ExposureTracker(lay, reposition_min=5, count_possible=count)
        for k in range(6):
            tr.step(p, 10.0 * k, lo, hi)
        assert tr.confident.tolist() == [True, False, False]
        assert tr.possible.tolist() == [False, True, False]
        np.testing.assert_allclose(tr.exposure_s, expected)


def test_a_station_that_skims_frames_says_so_to_the_exposure(tmp_path):
    """The station's mat (MatEntry): frames skimmed while behind are followed (the exposure
    of every frame); frames only peeked at (far behind: their time read) make the next frame
    read count the time peeked at as loaded where either frame read is."""
    import json

    from texsense.station.ward import MatConfig, MatEntry

    for peek, expected in ((False, [20.0, 29.0]), (True, [11.0 + 14.0, 29.0])):
        entry = MatEntry(MatConfig("m", Layout.grid(1, 2), None, quantity="pressure"),
                         EventStore(":memory:"), tmp_path, 0.5)  # fmt: skip
        for t in range(30):  # element 0 loaded from 10 s; 5 ... 14 s skimmed
            p = [1.0 if t >= 10 else 0.0, 1.0]
            payload = json.dumps({"seq": t, "t": float(t), "values": p, "unit": "N/cm2"}).encode()
            assert entry.handle(payload, 1000.0 + t, skim=5 <= t < 15, peek=peek)
        assert entry.behind == 10 and entry.peeked == (10 if peek else 0)
        assert entry.monitor.frames == 20
        # peeked: the 11 s from 4 to 15 s loaded (it is at 15 s); then 14 more s
        np.testing.assert_allclose(entry.monitor.tracker.exposure_s, expected)
