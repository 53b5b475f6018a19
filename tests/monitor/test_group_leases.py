"""Who holds which mat, decided by a real PostgreSQL server (started by the test): the leases
of texsense.station.lease driven beat by beat, with a member that stops beating, one killed
(its connection gone), one that comes back, and the journal's fenced checkpoints."""

from __future__ import annotations

import time
from typing import ClassVar

import psycopg
import pytest

from postgres_server import PostgresServer
from texsense.apps.alerts import Event
from texsense.station import lease
from texsense.station.journal import Journal
from texsense.station.lease import Membership, plan, preferred

MATS = [f"bed{k:02d}" for k in range(12)]


@pytest.fixture(scope="module")
def server():
    s = PostgresServer()
    try:
        yield s
    finally:
        s.close()


@pytest.fixture
def db(server):
    """A fresh database per test (the tables of the group and of the event store)."""
    name = f"t{time.monotonic_ns()}"
    with psycopg.connect(server.url, autocommit=True) as c:
        c.execute(f"CREATE DATABASE {name}")
    url = server.url.rsplit("/", 1)[0] + "/" + name
    from texsense.monitor.store import PostgresEventStore

    PostgresEventStore(url).close()  # sessions and events
    return url


class Member:
    """A Membership driven by hand: what it hands the station is kept here."""

    made: ClassVar[list[Member]] = []

    def __init__(self, db: str, name: str, mats=MATS, alive=lambda: True) -> None:
        Member.made.append(self)
        self.held: dict[str, int] = {}
        self.granted: list = []
        self.m = Membership(
            db, "ward", name, page=f"http://{name}/", ward="w1",
            mats={m: f"mat {m}" for m in mats}, on_grant=self._grant,
            on_release=self._release, on_lost=self._lost, on_view=lambda v: None,
            loop_alive=alive,
        )  # fmt: skip
        self.m.join_group()

    def _grant(self, grants) -> None:
        self.granted += grants
        self.held.update({g.mat: g.epoch for g in grants})

    def _release(self, items) -> None:  # as the station does: gone at once (lease via journal)
        for mat, epoch in items:
            self.held.pop(mat)
            self.m.conn.execute(
                "UPDATE group_leases SET member = NULL, expires = now() WHERE mat = %s AND "
                "member = %s AND epoch = %s", (mat, self.m.member, epoch))  # fmt: skip

    def _lost(self, mats) -> None:
        for mat in mats:
            self.held.pop(mat)

    def tick(self) -> None:
        self.m.tick()


@pytest.fixture
def quick(monkeypatch):
    """Short times: a lease of 1.5 s, settling 0.2 s, ready 0.5 s, a grace of 0.6 s; the members'
    connections closed at the end."""
    monkeypatch.setattr(lease, "LEASE_S", 1.5)
    monkeypatch.setattr(lease, "SETTLE_S", 0.2)
    monkeypatch.setattr(lease, "READY_S", 0.5)
    monkeypatch.setattr(lease, "GRACE_S", 0.6)
    yield
    for m in Member.made:
        if m.m.conn is not None:
            m.m.conn.close()
    Member.made.clear()


def beats(members, n: int = 1, pause: float = 0.25) -> None:
    for _ in range(n):
        for m in members:
            m.tick()
        time.sleep(pause)


def test_the_mats_spread_as_rendezvous_hashing_says_and_move_back(db, quick):
    a, b = Member(db, "a"), Member(db, "b")
    beats([a, b], 6)
    assert set(a.held) | set(b.held) == set(MATS) and not set(a.held) & set(b.held)
    assert all(preferred(m, ["a", "b"]) == "a" for m in a.held)
    assert all(preferred(m, ["a", "b"]) == "b" for m in b.held)
    # a third member joins: exactly the mats that prefer it move to it
    c = Member(db, "c")
    beats([a, b, c], 6)
    for who in (a, b, c):
        assert all(preferred(m, ["a", "b", "c"]) == who.m.member for m in who.held)
    assert sorted([*a.held, *b.held, *c.held]) == MATS


def test_a_member_killed_loses_its_mats_within_a_beat(db, quick):
    a, b = Member(db, "a"), Member(db, "b")
    beats([a, b], 6)
    of_b, epochs = set(b.held), dict(b.held)
    assert of_b
    b.m.conn.close()  # as SIGKILL: the server's process of its connection ends
    start = time.monotonic()
    while not of_b <= set(a.held):
        assert time.monotonic() - start < 1.0, "not taken over at the next beat"
        beats([a], 1, 0.05)
    assert time.monotonic() - start < lease.LEASE_S  # before its lease would have expired
    taken = {g.mat: g.epoch for g in a.granted if g.mat in of_b}  # the latest grant of each
    assert taken == {m: e + 1 for m, e in epochs.items()}


def test_a_member_that_stops_beating_loses_its_mats_and_hears_it(db, quick):
    stuck = {"b": False}
    a, b = Member(db, "a"), Member(db, "b", alive=lambda: not stuck["b"])
    beats([a, b], 6)
    of_b = set(b.held)
    stuck["b"] = True  # its event loop does not answer: no heartbeat, no renewal
    start = time.monotonic()
    while not of_b <= set(a.held):
        assert time.monotonic() - start < lease.LEASE_S + 2.0
        beats([a, b], 1, 0.1)
    assert time.monotonic() - start >= lease.LEASE_S - 0.3  # not before its lease lapsed
    beats([b], 1)
    assert not b.held  # b was told (on_lost) and holds nothing
    stuck["b"] = False  # back: after settling, the mats that prefer b go back to it
    beats([a, b], 8)
    assert set(b.held) == of_b


def test_a_member_restarted_under_its_name_takes_its_leases_again(db, quick):
    a = Member(db, "a")
    beats([a], 6)
    assert set(a.held) == set(MATS)
    epochs = dict(a.held)
    again = Member(db, "a")  # a new process, the same name: the old leases are in its name
    beats([again], 4)
    assert again.held == {m: e + 1 for m, e in epochs.items()}


def test_the_plan_takes_free_mats_that_prefer_it_first():
    leases = {m: lease.Lease(m, None, 0, False) for m in MATS}
    since: dict[str, float] = {}
    take, release = plan("a", leases, {"a", "b"}, {"a", "b"}, set(), set(), since, 0.0, True)
    assert take == [m for m in MATS if preferred(m, ["a", "b"]) == "a"] and not release
    take, _ = plan("a", leases, {"a", "b"}, {"a", "b"}, set(), set(), since, 10.0, True)
    assert take == MATS  # after the grace, any free mat
    take, _ = plan("a", leases, {"a"}, {"a"}, set(), set(), {}, 0.0, False)
    assert take == []  # not settled yet: nothing


def test_the_journal_fences_checkpoints_and_keeps_events_in_order(db, quick):
    a = Member(db, "a")
    beats([a], 4)
    lost: list[str] = []
    j = Journal(db, "ward", "a", lost.extend)
    j.start()
    mat = MATS[0]
    session = next(g.session for g in a.granted if g.mat == mat)
    j.event(session, Event("reposition", 300.0, 1, {"elements": [3]}))
    j.checkpoint(mat, a.held[mat], session, 300.0, b"often-1", b"rarely-1")
    j.checkpoint(mat, a.held[mat], session, 301.0, b"often-2")  # replaces it, keeps rarely
    j.checkpoint(MATS[1], a.held[MATS[1]] + 7, session, 1.0, b"x")  # another epoch: refused
    assert j.flush(10)
    with psycopg.connect(db) as c:
        ((often, rarely, last),) = c.execute(
            "SELECT often, rarely, last_event FROM group_checkpoints WHERE mat = %s", (mat,)
        ).fetchall()
        (eid,) = c.execute("SELECT max(id) FROM events").fetchone()
        assert c.execute("SELECT count(*) FROM group_checkpoints WHERE mat = %s",
                         (MATS[1],)).fetchone() == (0,)  # fmt: skip
    assert (bytes(often), bytes(rarely), last) == (b"often-2", b"rarely-1", eid)
    assert lost == [MATS[1]]
    j.stop()


def test_the_journal_waits_while_the_server_is_away():
    """A server that refuses connections (down, restarting) is a wait, not the journal's end:
    the writes stay in memory and the thread tries again (found by the fault test's
    PostgreSQL restart: 'the database system is shutting down' ended the thread)."""
    from conftest import free_port

    j = Journal(f"postgresql://nobody@127.0.0.1:{free_port()}/none", "ward", "a", print)
    j.start()
    try:
        j.event(1, Event("reposition", 300.0, 1, {}))
        deadline = time.monotonic() + 10
        while j.down is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert j.down and "cannot connect to PostgreSQL" in j.down
        time.sleep(0.2)
        assert j.is_alive() and len(j.ops) == 1  # kept, to be written when it is back
    finally:
        with j.cond:
            j._halt = True
            j.cond.notify_all()
        j.join(5)


def test_a_member_checkpoints_what_changed_and_less_often_with_many_mats(db, monkeypatch):
    """Checkpoints cost what changed: a mat without a frame since its last checkpoint is not
    written again, and the interval grows with the mats held (group.CHECKPOINTS_PER_S)."""
    from texsense.data.layout import Layout
    from texsense.station import group
    from texsense.station.broker import BrokerURL
    from texsense.station.ward import MatConfig

    mats = [MatConfig(f"m{k}", Layout.grid(2, 2), quantity="pressure") for k in range(4)]
    st = group.GroupStation(BrokerURL("127.0.0.1", 9), mats, group="g", member="a", db=db,
                            page="http://a/", record_dir=".", checkpoint_s=2.0)  # fmt: skip
    written: list[tuple[str, bool]] = []
    monkeypatch.setattr(st.journal, "checkpoint",
                        lambda mat, *a, **k: written.append((mat, a[4] is not None)))  # fmt: skip
    st.grant([lease.Grant(m.id, 1, 0) for m in mats])  # no loop: held at once
    t0 = time.monotonic() + 1.0  # (the first full checkpoints come at most 20 a second)
    assert st.checkpoints(t0) == 4  # the first checkpoint of each at once
    assert sum(full for _, full in written) == 0  # fresh: the sensor's state is the reset one
    frame = b'{"seq":%d,"t":%.1f,"values":[1,2,0,0],"unit":"N/cm2"}'
    written.clear()
    st.mats["m0"].handle(frame % (1, 1.0), 1.0)
    assert st.checkpoints(t0 + 2.1) == 1, written
    assert written == [("m0", False)]  # m1-m3: no frame since their last one
    assert st.skipped == 3
    monkeypatch.setattr(group, "CHECKPOINTS_PER_S", 1.0)  # 4 mats held: every 4 s
    assert st.interval() == 4.0
    st.share = 0.5  # a worker of two (--workers 2): half its member's checkpoints a second
    assert st.interval() == 8.0
    st.share = 1.0
    written.clear()
    for k in range(2, 14):  # every mat reads a frame every second
        for m in mats:
            st.mats[m.id].handle(frame % (k, float(k)), float(k))
        st.checkpoints(t0 + 2.1 + k - 1)
    per_mat = {m.id: sum(w == m.id for w, _ in written) for m in mats}
    # 12 s: at 4.1 s (the old 2 s), then every 4 s (at 2 s: 6 each); one more for a mat
    # whose alert event (loaded) came between two
    assert all(3 <= n <= 4 for n in per_mat.values()), written
    assert sum(per_mat.values()) <= 14
    st.store.close()


def test_checkpoints_that_come_due_together_are_spread_over_turns_in_order(db, monkeypatch):
    """Mats taken together come due spread over one interval (group.due_phase), and a turn of
    the watch writes the due ones for at most group.DUE_S (at least one), the rest in the
    next turns, in their order, none lost."""
    from texsense.data.layout import Layout
    from texsense.station import group
    from texsense.station.broker import BrokerURL
    from texsense.station.ward import MatConfig

    mats = [MatConfig(f"m{k}", Layout.grid(2, 2), quantity="pressure") for k in range(6)]
    st = group.GroupStation(BrokerURL("127.0.0.1", 9), mats, group="g", member="a", db=db,
                            page="http://a/", record_dir=".", checkpoint_s=2.0)  # fmt: skip
    written: list[str] = []
    monkeypatch.setattr(st.journal, "checkpoint", lambda mat, *a, **k: written.append(mat))
    st.grant([lease.Grant(m.id, 1, 0) for m in mats])
    t0 = time.monotonic() + 1.0
    assert st.checkpoints(t0) == 6  # (a budget of 5 ms: six small mats in one turn)
    due = sorted(when - t0 for when, _ in st._due)  # their first due ones: at their phases
    assert due == pytest.approx(sorted(2.0 * group.due_phase(m.id) for m in mats))
    assert len(set(due)) == 6
    frame = b'{"seq":%d,"t":%.1f,"values":[1,2,0,0],"unit":"N/cm2"}'
    for m in mats:
        st.mats[m.id].handle(frame % (1, 1.0), 1.0)
    st._soon_mats.clear()  # (their first frames' events: not what is looked at here)
    order = [m for _, m in sorted(st._due)]
    written.clear()
    monkeypatch.setattr(group, "DUE_S", 0.0)  # a turn's budget spent by one checkpoint
    assert [st.checkpoints(t0 + 2.1) for _ in range(6)] == [1] * 6
    assert written == order and len(set(written)) == 6
    assert st.checkpoints(t0 + 2.1) == 0  # none due any more: each in an interval again
    st.store.close()


def test_a_member_sends_at_most_its_tiles_budget_changed_states_first(db, monkeypatch):
    """Tiles for the other members cost the event loop: at most group.TILES_PER_S a second,
    a mat whose shown state changed first, then the longest unsent; an unchanged mat never."""
    from texsense.data.layout import Layout
    from texsense.station import group
    from texsense.station.broker import BrokerURL
    from texsense.station.ward import MatConfig

    mats = [MatConfig(f"m{k}", Layout.grid(2, 2), quantity="pressure") for k in range(5)]
    st = group.GroupStation(BrokerURL("127.0.0.1", 9), mats, group="g", member="a", db=db,
                            page="http://a/", record_dir=".")  # fmt: skip
    st.grant([lease.Grant(m.id, 1, 0) for m in mats])  # no loop: held at once
    sent: list[bytes] = []

    class Client:
        def publish(self, topic: str, payload: bytes) -> None:
            sent.append(payload)

    st._client, st.connected = Client(), True
    st.view = lease.View(members={"a": {"alive": True}, "b": {"alive": True}}, holders={})
    monkeypatch.setattr(group, "TILES_PER_S", 3.0)
    now = st.mats["m0"].revision
    # m0 was last sent as "live" (now "waiting": its state changed); m1-m3 only changed,
    # sent last at 3, 1, 2 s; m4 has not changed since its last tile
    st._sent = {"m0": (now - 1, "live", 9.0), "m1": (now - 1, "waiting", 3.0),
                "m2": (now - 1, "waiting", 1.0), "m3": (now - 1, "waiting", 2.0),
                "m4": (st.mats["m4"].revision, "waiting", 0.0)}  # fmt: skip
    assert [m for m, _ in st._due_tiles(3)] == ["m0", "m2", "m3"]
    assert st.publish_tiles(10.0) == 3
    assert [line.count(b'"id"') for line in sent[-1].split(b"\n")] == [0, 1, 1, 1]
    assert st.publish_tiles(11.0) == 1  # m1, the one left
    assert st.publish_tiles(12.0) == 0
    st.store.close()


def test_a_turns_budget_gives_one_turn_at_least_and_more_until_it_is_spent(monkeypatch):
    """group.at_least_once_for: the loops of the watch's checkpoints (DUE_S, SOON_S)."""
    from texsense.station import group

    ticks = iter([0.0, 0.5, 0.9, 1.0, 1.5])
    monkeypatch.setattr(group.time, "monotonic", lambda: next(ticks))
    assert sum(1 for _ in group.at_least_once_for(1.0)) == 3  # at 0 (the first), 0.5, 0.9
    ticks = iter([5.0, 5.0])
    assert sum(1 for _ in group.at_least_once_for(0.0)) == 1


def test_a_calibrated_mat_s_sensor_state_is_written_once_it_has_read_frames(db, seat_mat):
    """Round 15's flake of the group fault test: a member took its mats before any frame came
    (the full checkpoint, the sensor's state, written then), was killed four frames later,
    and its survivor went on from the monitor's state after those frames with a pipeline that
    had read none: an alert 12.8 s before the reference's. The first checkpoint after a mat
    reads frames here queues a full one (at most FULL_PER_S a second), not SENSOR_EVERY
    intervals later."""
    from texsense.station import group
    from texsense.station.broker import BrokerURL

    config, payloads = seat_mat
    st = group.GroupStation(BrokerURL("127.0.0.1", 9), [config], group="g", member="a", db=db,
                            page="http://a/", record_dir=".", checkpoint_s=2.0)  # fmt: skip
    written: list[bool] = []  # with the sensor's state
    st.journal.checkpoint = lambda mat, *a, **k: written.append(a[4] is not None)  # type: ignore
    st.grant([lease.Grant(config.id, 1, 0)])  # fresh (no blobs), before any frame
    t0 = time.monotonic() + 1.0
    assert st.checkpoints(t0) == 1 and written == [False]  # the reset state: nothing to write
    for k in range(1, 4):  # three frames, a checkpoint after each (none full before)
        st.mats[config.id].handle(*payloads[k - 1])
        st.checkpoints(t0 + 2.1 * k)
    assert True in written[:3], written  # the sensor's state of the frames read here
    assert written.count(True) == 1, written  # once: then every SENSOR_EVERY-th again
    st.store.close()
