"""A glitch never blinds a mat (issue 28): frames from the future or the past, clocks that
jump, wrong element counts, oversized payloads, floods of unknown topics; the monitor's own
sources (serial, replay) included. Engine-level: no broker, no server (tests/faults/test_ward.py
does the same through a real Mosquitto against a running station)."""

from __future__ import annotations

import asyncio
import json
import logging
import time

import numpy as np
import pytest
from test_sources import FakeSerial

from texsense import Layout, Recording
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import Linear, StageChain
from texsense.data.protocol import Frame, format_serial_line
from texsense.monitor import ExposureTracker, Monitor, ReplaySource, SerialSource
from texsense.station.ward import MatConfig, Station

LAY = Layout.grid(2, 3)
#: pF -> N/cm², unchanged values (a mat calibration without a spacer model)


def linear_chain() -> StageChain:
    """pF read as N/cm² one to one: a calibration that keeps the glitch tests simple."""
    return StageChain(
        [Linear("capacitance", "pF", "pressure", "N/cm2").fit(np.zeros(6), np.ones(6))]
    )


def pressure_monitor(reposition_min: float = 5.0) -> Monitor:
    rec = Recording(np.ones((2, 6)), [0.0, 1.0], LAY, "pressure", "N/cm2")
    tracker = ExposureTracker(LAY, reposition_min=reposition_min)
    return Monitor(ReplaySource(rec, speed=0), tracker=tracker)


def frame(seq: int, t: float, p: float = 1.0, n: int = 6) -> Frame:
    return Frame(seq, np.full(n, t), np.full(n, p), "N/cm2")


def test_the_clock_skips_a_glitch_and_resynchronises_a_jump():
    from texsense.monitor.clock import FrameClock

    clock = FrameClock()
    assert [clock.place(float(t), wall=float(t))[0] for t in range(5)] == ["ok"] * 5
    assert clock.place(1e12, wall=5.0)[0] == "ahead"  # from the future: skipped
    assert clock.place(5.0, wall=5.1) == ("ok", 5.0, 0.0)  # the next frame passes as it is
    assert clock.place(-3.0, wall=6.0)[0] == "backwards"  # from the past: skipped
    assert clock.place(6.0, wall=6.1)[0] == "ok"
    # the device restarts its clock at 0: one frame skipped, then re-synchronised so that
    # the time line goes on by the wall time that passed
    assert clock.place(0.0, wall=7.0)[0] == "backwards"
    verdict, t, jump = clock.place(1.0, wall=8.0)
    assert verdict == "resync" and t == pytest.approx(8.0, abs=0.2)
    assert jump == pytest.approx(-7.0, abs=0.2)
    assert clock.place(2.0, wall=9.0) == ("ok", pytest.approx(t + 1.0), 0.0)
    assert (clock.skipped, clock.resyncs) == (3, 1)


def test_the_clock_follows_sped_up_and_slow_sources():
    from texsense.monitor.clock import FrameClock

    fast = FrameClock()  # a virtual seat at 60x: a frame every 1.6 s simulated, 27 ms wall
    assert all(fast.place(k * 1.6, wall=k * 1.6 / 60)[0] == "ok" for k in range(200))
    slow = FrameClock()  # a recording of a frame every 10 s, replayed as fast as possible
    verdicts = [slow.place(k * 10.0, wall=k * 1e-3)[0] for k in range(50)]
    assert verdicts[1] == "ahead" and verdicts[2:] == ["ok"] * 48  # learnt from two frames
    burst = FrameClock()  # frames processed late, back to back (a busy event loop)
    assert all(burst.place(k * 1.0, wall=100.0)[0] == "ok" for k in range(100))


def test_a_source_that_knows_its_speed_loses_no_frame_at_the_start():
    """A night of a frame every 10 s replayed at 100x (0.1 s apart on the wall clock): the
    clock starts from the replay's rate, so its second frame is not taken for one from the
    future (it was, and was lost with a warning); a frame far ahead is still refused."""
    from texsense.monitor.clock import FrameClock

    night = Recording(np.full((30, 6), 0.5), np.arange(30) * 10.0, LAY, "pressure", "N/cm2")
    source = ReplaySource(night, speed=100.0)
    assert source.rate == 100.0
    m = Monitor(source, tracker=ExposureTracker(LAY, reposition_min=5))
    assert m.clock.rate_hint == 100.0
    for k in range(30):
        assert m.process(frame(k, k * 10.0), wall=1000.0 + k * 0.1) is not None
    assert m.clock.skipped == 0 and m.missed == 0 and m.frames == 30
    hinted = FrameClock(rate=100.0)
    assert hinted.place(0.0, wall=0.0)[0] == "ok"
    assert hinted.place(1e9, wall=0.1)[0] == "ahead"  # a glitch is still one
    assert hinted.place(10.0, wall=0.1)[0] == "ok"
    unhinted = FrameClock()  # (a live mat's: the second frame, 10 s ahead in 0.1 s, refused)
    assert unhinted.place(0.0, wall=0.0)[0] == "ok" and unhinted.place(10.0, wall=0.1)[0] == "ahead"


def test_a_frame_from_the_future_keeps_the_alert_and_the_mat_live():
    m = pressure_monitor()
    for k in range(320):  # 5 min 20 s under load: the reposition alert opens
        assert m.process(frame(k, float(k))) is not None
    alert = m.tracker.open_alert
    assert alert is not None and alert.active
    # one frame of an unloaded mat, stamped far in the future: skipped, the alert stays
    assert m.process(frame(320, 1e9, p=0.0)) is None
    assert m.tracker.open_alert is alert and alert.cleared_t is None
    # the real frames that follow are processed at once (no "frame times must not decrease")
    for k in range(321, 325):
        assert m.process(frame(k, float(k - 1))) is not None
    assert m.frames == 324 and m.clock.skipped == 1 and m.source.errors == 1
    assert m.tracker.open_alert is alert


def test_a_capacitance_mat_survives_times_that_go_backwards():
    rec = Recording(np.ones((2, 6)), [0.0, 1.0], LAY, "capacitance", "pF")
    m = Monitor(ReplaySource(rec, speed=0), pipeline=Pipeline(linear_chain(), LAY))
    cap = [Frame(k, np.full(6, t), np.full(6, 2.0)) for k, t in enumerate([0, 1, 2, -50, 3, 4])]
    snaps = [m.process(f) for f in cap]  # the pipeline would refuse -50 ("must not decrease")
    assert [s is None for s in snaps] == [False, False, False, True, False, False]
    assert m.frames == 5


def test_a_restarted_clock_is_resynchronised_with_an_event():
    m = pressure_monitor()
    for k in range(10):
        m.process(frame(k, 1000.0 + k), wall=float(k))
    got = [m.process(frame(k, float(k - 10)), wall=float(k)) for k in range(10, 14)]
    assert [g is None for g in got] == [True, False, False, False]  # live again at once
    times = [g["t"] for g in got[1:]]
    assert times[0] > 1009.0 and np.all(np.diff(times) > 0)  # the time line goes on
    (event,) = m.store.events(kind="clock")
    assert event["detail"]["jump_s"] == pytest.approx(-1010.0, abs=1.5)


def test_a_serial_frame_with_a_bad_time_does_not_blind_the_monitor():
    lines = [format_serial_line(k, k * 1_000_000, 0, [1.0] * 6).encode() for k in range(10)]
    lines.append(format_serial_line(10, 9 * 10**15, 0, [0.0] * 6).encode())  # a glitch
    lines += [format_serial_line(k, k * 1_000_000, 0, [1.0] * 6).encode() for k in range(11, 21)]
    src = SerialSource("fake", LAY, opener=lambda *a, **k: FakeSerial(lines))
    m = Monitor(src, pipeline=Pipeline(linear_chain(), LAY))
    with pytest.raises(EOFError):  # the fake line ends; the monitor never stopped before
        asyncio.run(m.run())
    assert m.frames == 20 and m.clock.skipped == 1


def test_a_replayed_recording_whose_time_goes_back_is_played_around_it():
    rec = Recording(np.ones((6, 6)), [0, 1, 2, 1.5, 3, 4], LAY, "pressure", "N/cm2")
    m = Monitor(ReplaySource(rec, speed=0))
    asyncio.run(m.run())
    assert m.frames == 5 and m.clock.skipped == 1


# ------------------------------------------------------------------------------ station
def station(*ids: str, n: int = 96) -> Station:
    """A station of pressure mats (refusing after 10 s of wrong element counts)."""
    mats = [MatConfig(i, Layout.grid(8, n // 8), quantity="pressure") for i in ids]
    return Station(None, mats)


def payload(seq: int, n: int = 96, t: float | None = None) -> bytes:
    t = seq * 1.0 if t is None else t
    return json.dumps({"seq": seq, "t": t, "values": [0.5] * n, "unit": "N/cm2"}).encode()


class Clock:
    """The wall clock the station sees (``texsense.station.ward``'s ``time.time``)."""

    def __init__(self, monkeypatch) -> None:
        import texsense.station.ward as ward

        self.now = 0.0
        monkeypatch.setattr(ward.time, "time", lambda: self.now)


def test_a_wrong_element_count_is_skipped_and_only_a_sustained_one_refuses(caplog, monkeypatch):
    clock = Clock(monkeypatch)
    st = station("bed1", "bed2")
    bed1 = st.mats["bed1"]
    for k in range(3):
        clock.now = float(k)
        st.handle("texsense/bed1/frames", payload(k))
    clock.now = 3.0
    st.handle("texsense/bed1/frames", payload(3, n=95))  # 95 of 96 values
    assert bed1.refused is None  # (it used to be refused for good, at once)
    clock.now = 4.0
    st.handle("texsense/bed1/frames", payload(4))
    assert bed1.monitor.frames == 4 and bed1.malformed == 1 and bed1.state == "live"
    # 10 s of frames of 95 values: refused, with an event; the other mat goes on
    for k in range(5, 16):
        clock.now = float(k)
        st.handle("texsense/bed1/frames", payload(k, n=95))
        st.handle("texsense/bed2/frames", payload(k))
        assert (bed1.refused is None) == (k < 15)
    assert "95 values" in bed1.refused and "96 elements" in bed1.refused
    assert bed1.view_state()[0] == "refused" and st.mats["bed2"].monitor.frames == 11
    clock.now = 17.0
    st.handle("texsense/bed1/frames", payload(17))
    assert bed1.ignored == 1 and bed1.monitor.frames == 4
    assert [e["kind"] for e in st.store.events(kind="refused")] == ["refused"]
    bed1.admit()  # the ward page's button
    clock.now = 18.0
    st.handle("texsense/bed1/frames", payload(18))
    assert bed1.monitor.frames == 5 and bed1.state == "live"
    assert st.store.events(kind="admitted")
    lines = [r for r in caplog.records if "bed1" in r.getMessage() and "95" in r.getMessage()]
    assert 1 <= len(lines) <= 2 and not any(r.exc_info for r in caplog.records)


def test_an_oversized_payload_is_refused_before_it_is_parsed(monkeypatch):
    st = station("bed1")
    st.handle("texsense/bed1/frames", payload(0, t=time.time()))
    parsed = []
    real = json.loads
    monkeypatch.setattr(json, "loads", lambda s, *a, **k: parsed.append(len(s)) or real(s))
    big = b'{"seq":1,"t":1,"values":[' + b"1.5," * 3_000_000 + b'1],"unit":"N/cm2"}'
    st.handle("texsense/bed1/frames", big)
    assert parsed == []  # 12 MB refused by its length
    entry = st.mats["bed1"]
    assert entry.malformed == 1 and "bytes" in entry.last_error and entry.refused is None
    st.handle("texsense/bed1/frames", payload(2, t=time.time()))
    assert entry.monitor.frames == 2 and entry.state == "live"


def test_unknown_topics_are_bounded_and_expire(caplog):
    st = station("bed1")
    for k in range(20_000):
        st.handle(f"texsense/intruder-{k}/frames", b"{}")
    assert len(json.dumps(st.ward())) < 20_000  # was 4.5 MB
    assert len(st.unknown) == 100 and st.unknown_forgotten == 20_000 - 100
    assert sum("unknown mat" in r.getMessage() for r in caplog.records) == 1
    from texsense.station.ward import UNKNOWN_TTL_S

    st.forget_unknown(now=time.time() + UNKNOWN_TTL_S)
    assert not st.unknown and st.header()["unknown_forgotten"] == 20_000


def test_one_mat_failing_is_one_line_and_the_ward_goes_on(caplog, monkeypatch):
    st = station("bed1", "bed2")

    def broken(*_a, **_k):
        raise RuntimeError("boom")

    monkeypatch.setattr(st.mats["bed1"].monitor, "process", broken)
    with caplog.at_level(logging.WARNING):
        for k in range(5):
            st.handle("texsense/bed1/frames", payload(k))
            st.handle("texsense/bed2/frames", payload(k))
    lines = [r for r in caplog.records if "boom" in r.getMessage()]
    assert len(lines) == 1 and lines[0].exc_info is None and "bed1" in lines[0].getMessage()
    assert st.mats["bed1"].failed == 5 and st.mats["bed2"].monitor.frames == 5


def test_a_busy_station_stays_current_and_calls_no_sending_mat_silent(monkeypatch):
    """Issue 33: under 20 virtual mats at 10x the station read its inbox ever further behind
    (50 s after two minutes) and called every mat silent ("no data") while its frames waited
    in the inbox. Two mats send 100 frames a second each to a station that reads 50: it
    skips the older frames of a mat whose newer ones wait, counts them, shows the newest,
    and judges silence on what it has read. Judged in frames, not seconds (the machine is
    shared: a stall of the process stops the sender too): the frames waiting in the inbox
    and how far the frame each mat shows is behind the newest one sent stay bounded, where a
    station that reads every frame in order (``max_wait_s`` infinite) falls ever further
    behind (here ~110 of a mat's 150 frames and ~220 waiting when the sending stops)."""
    import threading

    st = station("bed1", "bed2")
    for entry in st.mats.values():
        entry.min_stale_s = 0.3  # a floor above the sender thread's own hiccups
        real = entry.monitor.process

        def busy(frame, wall=None, real=real):
            time.sleep(0.02)  # a busy machine: 20 ms a frame
            return real(frame, wall=wall)

        monkeypatch.setattr(entry.monitor, "process", busy)
    sent = {"bed1": 0, "bed2": 0}
    waiting: list[int] = []  # frames waiting in the inbox, polled
    behind: list[int] = []  # frames between the newest sent and the one a mat shows

    async def run() -> None:
        inbox = st.open_inbox()
        inbox.max_wait_s = 0.2
        watch = asyncio.create_task(st.watch())

        def mats() -> None:
            for k in range(150):  # 1.5 s
                for m in sent:
                    inbox.put(f"texsense/{m}/frames", payload(k, t=k * 0.01))
                    sent[m] += 1
                time.sleep(0.01)

        sender = threading.Thread(target=mats)
        sender.start()
        while sender.is_alive() or inbox.waiting:
            waiting.append(inbox.waiting)
            for m, e in st.mats.items():
                shown = e.monitor.latest["seq"] if e.monitor.latest else -1
                behind.append(sent[m] - 1 - shown)
            await asyncio.sleep(0.01)
        watch.cancel()

    asyncio.run(run())
    # the old station: ~220 frames waiting, a mat showing a frame ~110 behind the newest
    assert max(waiting) <= 100, f"{max(waiting)} frames waited in the inbox"
    assert max(behind) <= 50, f"a mat showed a frame {max(behind)} behind the newest sent"
    assert not st.store.events(kind="stale"), "a mat that kept sending was called silent"
    for m, entry in st.mats.items():
        assert entry.state == "live" and entry.messages == sent[m] == 150
        assert entry.behind > 0 and entry.monitor.frames + entry.behind == 150
        assert entry.monitor.latest["seq"] == 149  # the newest frame is what the ward shows
    assert st.header()["skipped"] == sum(e.behind for e in st.mats.values())


def test_a_busy_station_keeps_a_skipped_burst_on_the_clock_and_every_recorded_frame():
    """Frames a busy station skips still keep the mat's clock in step: a burst of buffered
    frames (1 s apart, arriving at once) skipped in the middle is no clock jump, and the
    exposure covers their time. A recording keeps every frame even so."""
    st = station("bed1", "bed2")

    class Recorder:  # what the monitor's recorder is handed
        def __init__(self) -> None:
            self.seqs: list[int] = []
            self.pending: list[dict] = []  # the events raised while it records

        def append(self, frame, *_a) -> None:
            self.seqs.append(frame.seq)

    recorder = Recorder()
    st.mats["bed2"].monitor.recorder = recorder  # type: ignore[assignment]

    async def run() -> None:
        inbox = st.open_inbox()
        inbox.max_wait_s = 0.05
        for m in ("bed1", "bed2"):
            inbox.put(f"texsense/{m}/frames", payload(0, t=0.0))
        while inbox.waiting:
            await asyncio.sleep(0.01)
        for k in range(1, 21):  # all waiting while the loop is held below
            for m in ("bed1", "bed2"):
                inbox.put(f"texsense/{m}/frames", payload(k, t=float(k)))
        time.sleep(0.1)  # the station busy elsewhere: every message now waited too long
        while inbox.waiting:
            await asyncio.sleep(0.01)

    asyncio.run(run())
    bed1, bed2 = st.mats["bed1"], st.mats["bed2"]
    assert (bed1.behind, bed1.monitor.frames, bed1.monitor.latest["seq"]) == (19, 2, 20)
    assert bed1.monitor.clock.skipped == 0 and bed1.state == "live"
    assert bed1.monitor.tracker.exposure_s.max() == pytest.approx(20.0)  # 0.5 N/cm² is above
    assert (bed2.behind, bed2.monitor.frames, recorder.seqs) == (0, 21, list(range(21)))
    assert bed1.messages == bed2.messages == 21


def test_the_inbox_lets_pages_go_first_for_a_while():
    """While a page is being served the inbox waits (each step of a request would otherwise
    wait behind a slice of frames), but never more than max_defer_s at a time."""
    from texsense.monitor.clock import Quiet
    from texsense.station.inbox import Inbox

    handled: list[float] = []
    serving = [True]

    async def run() -> None:
        inbox = Inbox(asyncio.get_running_loop(), lambda *_a: handled.append(time.monotonic()),
                      Quiet(logging.getLogger("test")), defer=lambda: serving[0],
                      max_defer_s=0.3)  # fmt: skip
        inbox.put("texsense/bed1/frames", b"{}")
        await asyncio.sleep(0.1)
        assert not handled  # a page is being served: the frame waits
        serving[0] = False
        await asyncio.sleep(0.05)
        assert len(handled) == 1  # ... and is read once it is out
        serving[0] = True
        put = time.monotonic()
        inbox.put("texsense/bed1/frames", b"{}")
        while len(handled) < 2:
            await asyncio.sleep(0.01)
        assert 0.3 <= handled[1] - put < 1.0  # a page that takes long: read after 0.3 s
        put = time.monotonic()
        inbox.put("texsense/bed1/frames", b"{}")
        while len(handled) < 3:
            await asyncio.sleep(0.01)
        assert handled[2] - put < 0.25  # ... and then read as long without waiting again

    asyncio.run(run())


def test_a_slice_ends_when_the_loop_has_a_request_to_read():
    """A connection that becomes readable while the inbox handles a frame is served after
    that frame, not after the slice (a request's every step waited for a slice: issue 33),
    and one readable before the inbox starts is served before any frame; with the check off
    (``busy`` never true) the whole slice goes first."""
    import socket

    from texsense.monitor.clock import Quiet
    from texsense.station.inbox import Inbox

    def run(check: bool, early: bool = False) -> tuple[int, int]:
        async def main() -> tuple[int, int]:
            loop = asyncio.get_running_loop()
            here, there = socket.socketpair()
            served: list[int] = []
            handled: list[int] = []

            def handle(*_a: object) -> None:
                handled.append(1)
                if len(handled) == 1 and not early:
                    there.send(b"GET")  # a request comes while the first frame is handled
                time.sleep(0.01)  # a frame's work

            def read() -> None:
                here.recv(16)
                served.append(len(handled))

            loop.add_reader(here.fileno(), read)
            kw = {} if check else {"busy": lambda: False}
            inbox = Inbox(loop, handle, Quiet(logging.getLogger("test")), slice_s=5.0, **kw)
            if early:
                there.send(b"GET")  # a request is there before the frames
            for _ in range(8):
                inbox.put("texsense/bed1/frames", b"{}")
            while len(handled) < 8:
                await asyncio.sleep(0.005)
            loop.remove_reader(here.fileno())
            here.close()
            there.close()
            return served[0], inbox.yielded

        return asyncio.run(main())

    served, yielded = run(check=True)
    assert served == 1 and yielded >= 1  # served after the frame at hand ...
    assert run(check=False) == (8, 0)  # ... not after the whole slice
    assert run(check=True, early=True)[0] == 0  # a request already there: before any frame


def test_the_station_counts_the_pages_it_is_serving(monkeypatch):
    """What the inbox waits for: a request while it is served, a viewer until its first
    message (then it waits like the frames)."""
    from fastapi.testclient import TestClient

    from texsense.station.server import create_ward_app

    st = station("bed1")
    during: list[int] = []
    real = st.ward
    monkeypatch.setattr(st, "ward", lambda: during.append(st.serving) or real())
    with TestClient(create_ward_app(st), base_url="http://127.0.0.1:8766") as client:
        assert client.get("/api/ward").status_code == 200
        with client.websocket_connect("ws://127.0.0.1:8766/ws/ward") as ws:
            assert json.loads(ws.receive_text())["type"] == "ward"
            assert st.serving == 0  # the viewer has its first message
    assert during == [1] and st.serving == 0 and st.served_at > 0  # pages first a while after


def test_a_dashboard_opened_before_its_mats_first_frame_does_not_hold_the_inbox():
    """A viewer of a mat that has sent nothing yet waits for the mat's frames, which are in
    the inbox: it is no page being served (issue 38: viewers opened as 1,000 mats started
    kept the inbox waiting 0.5 s at a time until their mats' first frames were read). With a
    frame, its first message is sent at once and it counted until then."""
    from fastapi.testclient import TestClient

    from texsense.station.server import create_ward_app

    st = station("bed1", "bed2")
    with TestClient(create_ward_app(st), base_url="http://127.0.0.1:8766") as client:
        with client.websocket_connect("ws://127.0.0.1:8766/mats/bed1/ws"):
            assert st.serving == 0  # (before its accept: the handshake is one step)
            deadline = time.monotonic() + 5.0
            while st.pages_first() and time.monotonic() < deadline:
                time.sleep(0.05)  # (the grace after the handshake)
            assert not st.pages_first()  # the inbox reads while the viewer waits
        st.handle("texsense/bed2/frames", payload(0))
        with client.websocket_connect("ws://127.0.0.1:8766/mats/bed2/ws") as ws:
            assert json.loads(ws.receive_text())["seq"] == 0
            assert st.serving == 0


def test_the_inbox_waits_a_while_after_a_page_not_after_an_api_answer():
    """After a page (the ward's, its files) the inbox waits :data:`PAGE_GRACE_S` for the
    requests that follow it; after an API call's answer (a script polling ``/api/mats``) it
    reads at once (issue 38)."""
    from fastapi.testclient import TestClient

    from texsense.station.server import create_ward_app

    st = station("bed1")
    with TestClient(create_ward_app(st), base_url="http://127.0.0.1:8766") as client:
        assert client.get("/api/mats").status_code == 200
        assert client.get("/mats/bed1/api/status").status_code == 200
        assert st.serving == 0 and not st.pages_first() and st.served_at < 0
        assert client.get("/").status_code == 200
        assert st.pages_first() and st.served_at > 0


def test_the_mat_list_is_built_in_chunks_with_the_loop_between(monkeypatch):
    """``GET /api/mats`` builds its answer :data:`LIST_CHUNK` mats at a time and lets the
    event loop run between (issue 38: 1,000 mats held the loop 51-60 ms in one piece, every
    frame waiting); the inbox is not held for it; the answer is the same list, most urgent
    first."""
    import asyncio

    from fastapi.testclient import TestClient

    import texsense.station.server as server

    monkeypatch.setattr(server, "LIST_CHUNK", 2)
    st = station("bed1", "bed2", "bed3", "bed4", "bed5")
    st.handle("texsense/bed3/frames", payload(0))
    order: list[str] = []
    for mat_id, entry in st.mats.items():
        real = entry.status

        def status(real=real, mat_id=mat_id) -> dict:
            if not order:  # the first: some other work for the loop, now
                asyncio.get_running_loop().call_soon(order.append, "loop")
            order.append(f"{mat_id} serving={st.serving}")
            return real()

        monkeypatch.setattr(entry, "status", status)
    with TestClient(server.create_ward_app(st), base_url="http://127.0.0.1:8766") as client:
        got = client.get("/api/mats")
    assert got.status_code == 200 and got.headers["content-type"] == "application/json"
    assert order == ["bed1 serving=0", "bed2 serving=0", "loop", "bed3 serving=0",
                     "bed4 serving=0", "bed5 serving=0"]  # fmt: skip
    rows = got.json()
    assert rows == sorted(
        rows, key=lambda r: (-r["urgency"], -r["minutes_since_reposition"], r["id"])
    )
    assert {r["id"] for r in rows} == set(st.mats)
    assert [r["frames"] for r in rows if r["id"] == "bed3"] == [1]
