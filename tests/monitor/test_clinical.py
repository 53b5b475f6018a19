"""What the nurse saw live is what a recording's report says (issue 33): the clinical state a
recording started on a live mat carries (the exposure, the open alert, the wall clock of
every frame, the events raised while it ran), and a bed's turn handing the exposure to new
skin."""

import subprocess
import time

import numpy as np
import pytest

from report_layout import check_layout
from texsense import Layout, Recording, load
from texsense.apps.alerts import ExposureTracker
from texsense.apps.bed import TurningSchedule, exposure_with_turns
from texsense.apps.clinical import EVENTS_LABEL, WALL_LABEL, live_events
from texsense.apps.report import write_report
from texsense.apps.review import open_review
from texsense.data.protocol import Frame
from texsense.exceptions import ParameterError
from texsense.monitor import Monitor, ReplaySource
from texsense.sim.mat import VirtualMat

SPEED = 20.0  # the device runs 20 frame-seconds per wall-clock second (a simulated mat)
WALL0 = time.mktime((2026, 3, 2, 2, 39, 0, 0, 0, -1))  # 02:39:00 local time


def _monitor(tmp_path):
    seat = VirtualMat.seat().layout  # declares its orientation: front at the top
    rec = Recording(np.zeros((2, seat.n_elements)), [0.0, 1.0], seat)
    return Monitor(ReplaySource(rec, speed=0), record_dir=tmp_path / "rec", mode="seat",
                   tracker=ExposureTracker(seat, reposition_min=5))  # fmt: skip


def _feed(m, t0, t1, values):
    n = m.layout.n_elements
    for t in range(t0, t1):
        frame = Frame(t, np.full(n, float(t)), values.copy(), "N/cm2")
        m.process(frame, wall=WALL0 + t / SPEED)


def _clock(t):
    return time.strftime("%H:%M:%S", time.localtime(WALL0 + t / SPEED))


def test_an_alert_raised_before_the_recording_is_in_its_report(tmp_path):
    """The table's first row: a reposition alert fired live before the recording started;
    the recording's report lists it (open when it started, at the wall-clock time it fired,
    with its place), counts it, and shows the events the monitor raised while it recorded
    at their wall-clock times, with a span in wall-clock time for a device running at 20x."""
    m = _monitor(tmp_path)
    p = np.zeros(m.layout.n_elements)
    p[int(np.argmin(np.hypot(*(m.layout.xy_cm - [10, 22]).T)))] = 1.0  # sitter's left ischium
    _feed(m, 0, 320, p)
    alert = m.tracker.open_alert
    assert alert is not None and alert.opened_t == 300.0 and alert.where == ["ischium-l"]
    paths = m.start_recording("night")
    _feed(m, 320, 400, p)
    m.acknowledge(alert.id)
    _feed(m, 400, 480, np.zeros_like(p))  # stands up: cleared after 1 min offloaded
    m.stop_recording()

    rec = load(paths[0])
    assert rec.meta["clinical"]["exposure"]["alert"]["id"] == alert.id
    np.testing.assert_allclose(rec.labels[WALL_LABEL], WALL0 + np.arange(320, 480) / SPEED)
    assert [e["kind"] for e in live_events(rec)] == ["acknowledged", "left", "cleared"]

    review = open_review(paths[0])
    shown = [(e["source"], e["kind"]) for e in review.events]
    assert shown == [("before", "reposition"), ("live", "acknowledged"), ("live", "left"),
                     ("live", "cleared")]  # fmt: skip
    assert review.clock_rate == pytest.approx(SPEED, rel=1e-6)

    out = write_report(paths[0], tmp_path / "night.pdf")
    text = subprocess.run(["pdftotext", "-layout", str(out), "-"], capture_output=True,
                          text=True, check=True).stdout  # fmt: skip
    flat = " ".join(text.split())
    check_layout(out, tmp_path)  # a seat's report: no blank band, nothing off the page
    assert "1 reposition (1 open when the recording started)" in flat
    assert f"{_clock(300)} 20 s before open at start reposition alert (open when the recording " \
        "started): ischium-l" in flat  # fmt: skip
    assert f"{_clock(400)} 1 min 20 s live got up" in flat
    assert f"{_clock(459)} 2 min 19 s live alert cleared (skin offloaded)" in flat
    # the span is the wall clock's (8 s), not the device's 2 min 40 s from the start
    assert f"{time.strftime('%Y-%m-%d', time.localtime(WALL0))} {_clock(320)} to {_clock(479)}" \
        in flat  # fmt: skip
    assert "the device's clock ran 20 x the wall clock" in flat


def test_a_recording_of_a_mat_without_its_state_recomputes_and_says_so(tmp_path):
    """A file with no clinical state (not recorded live): every event recomputed, and the
    report's identity says so; a broken events label is one line naming the frame."""
    lay = Layout.grid(2, 2).with_orientation("seat")
    frames = np.ones((400, 4))
    rec = Recording(frames, np.arange(400.0), lay, "pressure", "N/cm2", meta={"mode": "seat"})
    review = open_review(rec, reposition_min=5)
    assert not review.live and {e["source"] for e in review.events} == {"recomputed"}
    assert [e["kind"] for e in review.events] == ["seated", "reposition"]
    broken = Recording(frames[:3], np.arange(3.0), lay, "pressure", "N/cm2",
                       labels={EVENTS_LABEL: np.array(["", "[{", ""])})  # fmt: skip
    with pytest.raises(ParameterError, match="label 'events' of frame 1 is not a list"):
        open_review(broken)


def test_a_confirmed_turn_hands_the_exposure_to_new_skin():
    """A sleeper lies on the right side, turns supine at t = 276 s; one element carries load
    in both positions. Without the turn rule the alert opened at t = 300 s and named what now
    lies there; with it no alert opens while the turn is being confirmed (60 s), and the
    exposure after the turn counts from the turn."""
    lay = Layout.grid(1, 3)
    right, supine = np.array([1.0, 1.0, 0.0]), np.array([0.0, 1.0, 1.0])
    tracker = ExposureTracker(lay, reposition_min=5, occupancy=None)
    schedule = TurningSchedule(interval_min=120)
    events = []
    for t in range(0, 500, 2):
        side, p = ("right", right) if t < 276 else ("supine", supine)
        step = schedule.step(side, float(t))
        events += [(t, e.kind) for e in exposure_with_turns(tracker, float(t), p, schedule, step)]
    assert [t for t, k in events if k == "turn"] == [336]  # confirmed after 60 s held
    assert "reposition" not in [k for t, k in events if t < 276 + 300]
    # the exposure of the element loaded in both positions restarted at the turn
    assert tracker.exposure_s[1] == pytest.approx(498 - 276, abs=2)
    # the same frames without the rule: the alert at t = 300 s
    plain = ExposureTracker(lay, reposition_min=5, occupancy=None)
    first = next(t for t in range(0, 500, 2)
                 if plain.step(right if t < 276 else supine, float(t)))  # fmt: skip
    assert first == 300
