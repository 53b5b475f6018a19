"""A group of stations that share a site's mats (docs/station.md, "A group of stations").

``texsense station --group NAME`` makes the station a member of a group: every member has the
same ward, the mats publish to the site's broker, and PostgreSQL decides which member holds
which mat (:mod:`texsense.station.lease`). A member subscribes to the frames of the mats it
holds, and only those; it checkpoints every mat it holds (:mod:`texsense.station.checkpoint`)
every ``checkpoint_s`` and after every alert event, and when it takes a mat over it goes on
from the mat's last checkpoint and the alert events stored after it.

The ward page of any member shows every mat of the group: the member publishes the tiles of
its mats that changed, once a second (at most :data:`TILES_PER_S` of them), in one message
per 200 kB to ``<prefix>/_group/<group>/<member>`` (a mat id never starts with ``_``), and
reads the others'. A mat is shown with the member that holds it; a mat that no alive member
holds is shown as *unwatched* (red, on top of the ward), and one whose holder has sent no
word for :data:`~texsense.station.group_view.SILENT_S` as stale.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import hashlib
import heapq
import json
import logging
import time
import urllib.error
import urllib.request
import zlib
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from texsense.apps.alerts import Event
from texsense.data.files import json_loads
from texsense.exceptions import ParameterError
from texsense.monitor.store import PostgresEventStore
from texsense.station import checkpoint
from texsense.station.broker import BrokerURL, mat_topic
from texsense.station.group_view import Elsewhere, GroupMatEntry
from texsense.station.journal import Journal
from texsense.station.lease import BEAT_S, LEASE_S, Grant, Membership, View
from texsense.station.ward import CHECK_S, MIN_STALE_S, MatConfig, MatEntry, Station, mat_id_of

__all__ = ["GroupMatEntry", "GroupStation", "GroupStore", "ward_digest"]

log = logging.getLogger("texsense.station")

#: Tiles of the mats that changed go to the others this often, s.
TILE_S = 1.0
#: A member sends at most this many tiles a second; with more of its mats changing, each
#: changed mat in turn (the longest unsent first), a mat whose state changed (an alert, stale)
#: before all: 500 mats at 1 Hz each every 2 s (a tile costs ~0.12 ms of the event loop;
#: issue 38, a member of two workers of 500 mats spent 8 % of its samples on tiles).
TILES_PER_S = 250.0
#: A message of tiles holds at most this many bytes (a site broker's packet limit is 256 kB).
TILE_BATCH_BYTES = 200_000
#: The sensor's state (the ``rarely`` parts) goes with every this many checkpoints.
SENSOR_EVERY = 15
#: A member writes at most about this many checkpoints a second: with more mats than
#: ``checkpoint_s`` x this, each mat's interval grows with the mats held (1,000 mats: 10 s).
#: The exposure timers run on the frames' clock, so a takeover from an older checkpoint
#: still continues them (the first frame after it carries the time between).
CHECKPOINTS_PER_S = 100.0
#: First full checkpoints (the sensor's state) of mats just taken, at most this many a second
#: (a member that takes 300 mats does not copy 300 pipelines in one turn of its loop).
FULL_PER_S = 20.0
#: The checkpoints after events (an alert, a mat loaded) take at most about this long of a turn
#: of the watch, s; the rest wait for the next turn (1,000 mats loaded at once each raise an
#: event: their checkpoints in one turn held the loop for ~0.5 s, issue 38).
SOON_S = 0.005
#: The checkpoints that came due take at most about this long of a turn of the watch, s; the
#: rest wait for the next turns, in order. (Mats taken together came due together: 1,000 mats
#: granted at the start, every 10 s a burst of 100-170 checkpoints of ~0.25 ms held the loop
#: 30-35 ms of CPU, 60-120 ms of wall time on a loaded machine; now they are spread over the
#: interval, :func:`due_phase`, and this bounds what is left of a burst, issue 38.)
DUE_S = 0.005


def at_least_once_for(seconds: float) -> Iterator[None]:
    """Turns of a loop with a budget of time: the first always, more while ``seconds`` (on
    the monotonic clock) have not passed since the first."""
    end = time.monotonic() + seconds
    yield
    while time.monotonic() < end:
        yield


def due_phase(mat: str) -> float:
    """A mat's share of the checkpoint interval, in (0, 1], the same on every member: when its
    first checkpoint after it was taken comes due (mats taken at once come due spread over one
    interval, issue 38: 1,000 mats due in the same turn held a member's loop for 30-35 ms of
    CPU every 10 s)."""
    return (zlib.crc32(mat.encode()) % 1000 + 1) / 1000


def ward_digest(mats: list[MatConfig]) -> str:
    """What every member of a group must share: the mats, their layouts and calibrations."""
    text = json.dumps(sorted([m.id, m.layout.n_elements, m.quantity, m.bed,
                              None if m.calibration is None else m.calibration.id]
                             for m in mats))  # fmt: skip
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class GroupStore(PostgresEventStore):
    """The event store of a member: reads on a connection of its own, writes through the
    member's journal (in order with its checkpoints; kept while the server is away). A mat's
    session comes with its lease (one session per mat across members), so
    :meth:`start_session` gives 0 until the mat is held, and sessions are not ended when a
    member stops (the next holder goes on with them)."""

    def __init__(self, url: str, journal: Journal) -> None:
        super().__init__(url)
        self.journal = journal
        self.on_event: list[Any] = []  # called with the session of every event

    def start_session(self, source: str) -> int:
        return 0

    def end_session(self, session: int) -> None:
        return None

    def end_sessions(self, sessions: list[int]) -> None:
        return None

    def add_event(self, session: int, event: Event) -> int:
        self.journal.event(session, event)
        for call in self.on_event:
            call(session)
        return 0


def _restored(entry: MatEntry, g: Grant) -> dict[str, Any]:
    """Restore a mat from its checkpoint and the events stored after it; what was done."""
    try:
        info = checkpoint.restore(entry, g.blobs)
    except ParameterError as e:  # a damaged container: the mat starts afresh
        log.warning("mat %s: %s; it starts afresh", g.mat, e)
        checkpoint.fresh(entry)
        info = {"parts": [], "refused": {"checkpoint": str(e)}}
    replayed = checkpoint.replay(entry, g.events)
    return {"checkpoint_from": g.source, "checkpoint_age_s": round(g.age_s or 0, 2),
            "parts": info["parts"], "refused": info["refused"],
            "events_after": replayed}  # fmt: skip


class GroupStation(Station):
    """A :class:`~texsense.station.ward.Station` that is a member of a group (see the
    module). ``db``: the PostgreSQL URL; ``page``: this member's ward page (for the others'
    links); ``share``: this process's share of its member's checkpoint budget (a worker of
    ``--workers N``: 1/N, :mod:`texsense.station.workers`)."""

    entry_class = GroupMatEntry

    def __init__(
        self,
        broker: BrokerURL,
        mats: list[MatConfig],
        *,
        group: str,
        member: str,
        db: str,
        page: str,
        topic: str = "texsense/+/frames",
        record_dir: Path | str = "recordings",
        checkpoint_s: float = 2.0,
        min_stale_s: float = MIN_STALE_S,
        refuse_after_s: float = 10.0,
        token: str | None = None,
        share: float = 1.0,
    ) -> None:
        for m in mats:
            mat_topic(topic, m.id)  # a group subscribes to each mat's own topic
        if checkpoint_s <= 0:
            raise ParameterError(f"--checkpoint-every must be > 0 s, got {checkpoint_s}")
        self.name, self.member, self.page, self.token = group, member, page, token
        self.prefix = topic.split("/+/")[0]
        self.checkpoint_s = float(checkpoint_s)
        if not 0 < share <= 1:
            raise ParameterError(f"a member's share of its checkpoints is in (0, 1], got {share}")
        self.share = float(share)
        self.journal = Journal(db, group, member, self._from_thread(self.lost))
        store = GroupStore(db, self.journal)
        super().__init__(broker, mats, topic=topic, store=store, record_dir=record_dir,
                         min_stale_s=min_stale_s, refuse_after_s=refuse_after_s)  # fmt: skip
        store.on_event.append(self._soon)
        for e in self.mats.values():
            assert isinstance(e, GroupMatEntry)
            e.group = self
        self.membership = Membership(
            db, group, member, page=page, ward=ward_digest(mats),
            mats={m.id: self.mats[m.id].source.name for m in mats},
            on_grant=self._from_thread(self.grant), on_release=self._from_thread(self.release),
            on_lost=self._from_thread(self.lost), on_view=self._from_thread(self._set_view),
            loop_alive=lambda: time.monotonic() - self.loop_beat < LEASE_S - BEAT_S,
        )  # fmt: skip
        self.held: dict[str, int] = {}  # mat -> epoch of its lease
        self.view: View | None = None
        self.not_held = 0  # frames of a mat held elsewhere (in flight while it moved)
        self.loop_beat = time.monotonic()
        self.moves = {"taken": 0, "released": 0, "lost": 0}
        self._session_mat: dict[int, str] = {}
        self._due: list[tuple[float, str]] = []  # (when, mat): a heap of due checkpoints
        self._phase: set[str] = set()  # mats just taken: their first due one at their phase
        self._count: dict[str, int] = {}  # checkpoints of each held mat so far
        self._revision: dict[str, int] = {}  # each held mat's revision at its last checkpoint
        self._scheduled: set[str] = set()  # mats in the queue of due checkpoints
        self.skipped = 0  # checkpoints not written: the mat had not changed since its last
        self._soon_mats: set[str] = set()
        self._tiles: dict[str, tuple[dict[str, Any] | None, str, float]] = {}
        self._sent: dict[str, tuple[int, str, float]] = {}  # mat -> revision, state, when
        self._next_tiles = 0.0
        self._next_check = 0.0
        self._unwatched: dict[str, float] = {}
        self._main: asyncio.AbstractEventLoop | None = None
        self._restoring: dict[str, int] = {}  # mat -> epoch: restored in the worker thread
        self._release_later: dict[str, int] = {}  # released while still being restored
        self._worker = ThreadPoolExecutor(1, thread_name_prefix=f"texsense-restore-{member}")
        self._full: collections.deque[str] = collections.deque()  # first full checkpoints
        #: held mats whose sensor state has not been written since they read a frame here:
        #: their clock's time when taken (:meth:`_checkpoint`)
        self._unread: dict[str, float | None] = {}
        self._allowance, self._full_t = 0.0, time.monotonic()

    # ---------------------------------------------------------------- threads -> loop
    def _from_thread(self, fn: Any) -> Any:
        def call(*args: Any) -> None:
            loop = self._main
            if loop is not None:
                with contextlib.suppress(RuntimeError):  # the loop closed: the station stops
                    loop.call_soon_threadsafe(fn, *args)

        return call

    def _set_view(self, view: View) -> None:
        now = time.time()
        for mat, holder in view.holders.items():
            if holder is None:
                self._unwatched.setdefault(mat, now)
            else:
                self._unwatched.pop(mat, None)
        if self.view is None or view.holders != self.view.holders:
            for e in self.mats.values():
                e.version += 1
        self.view = view

    def unwatched_since(self, mat: str) -> float:
        """Since when no alive member holds ``mat`` (wall clock)."""
        return self._unwatched.get(mat, time.time())

    def member_url(self, member: str | None) -> str | None:
        """A member's ward page."""
        if member is None or self.view is None:
            return None
        return self.view.members.get(member, {}).get("url")

    # ---------------------------------------------------------------- holding
    def grant(self, grants: list[Grant]) -> None:
        """Mats this member now holds: each is restored (its checkpoint, the events after
        it) in the worker thread while the event loop goes on with the others, then held
        (:meth:`_hold`)."""
        if self._stopping:  # the station stops: the leases lapse, the others take them
            return
        for g in grants:
            self._restoring[g.mat] = g.epoch
            self.journal.adopt(g.session, g.last_event)
        if self._main is None:  # no loop (a test driving the station by hand): here
            self._hold(grants, self._restore_all(grants))
            return
        done = self._main.run_in_executor(self._worker, self._restore_all, grants)
        done.add_done_callback(lambda f: self._hold(grants, f.result()))

    def _restore_all(self, grants: list[Grant]) -> dict[str, dict[str, Any]]:
        """(The worker thread.) Restore the granted mats that are still being taken (the
        loop does not touch a mat that is not held); returns each one's event detail."""
        out = {}
        for g in grants:
            if self._restoring.get(g.mat) != g.epoch:
                continue  # lost again meanwhile
            entry = self.mats[g.mat]
            entry.monitor.session_id = g.session
            detail: dict[str, Any] = {"member": self.member, "epoch": g.epoch}
            try:
                if g.blobs:
                    detail.update(_restored(entry, g))
                else:
                    checkpoint.fresh(entry)
            except Exception as e:  # never a mat left unwatched: it starts afresh, said
                log.warning("mat %s: its state could not be restored (%s: %s); it starts "
                            "afresh", g.mat, type(e).__name__, e)  # fmt: skip
                checkpoint.fresh(entry)
                detail["refused"] = {"checkpoint": f"{type(e).__name__}: {e}"}
            out[g.mat] = detail
        return out

    def _hold(self, grants: list[Grant], details: dict[str, dict[str, Any]]) -> None:
        """(The loop.) The restored mats are held: their frames subscribed, a first small
        checkpoint at once (the new epoch and session in the database), the first full one
        of a mat taken over (the sensor's state) spread over the next beats
        (:data:`FULL_PER_S`)."""
        topics, held = [], []
        for g in grants:
            if g.mat not in details or self._restoring.get(g.mat) != g.epoch:
                continue
            del self._restoring[g.mat]
            entry = self.mats[g.mat]
            assert isinstance(entry, GroupMatEntry)
            entry.held = True
            entry.version += 1
            self.held[g.mat] = g.epoch
            self._session_mat[g.session] = g.mat
            self._count[g.mat] = 1  # the sensor's state: by the queue of first full ones
            self._phase.add(g.mat)
            self._revision.pop(g.mat, None)  # its first checkpoint is written whatever it holds
            if g.blobs:  # a fresh mat's sensor state is the reset one: nothing to write yet
                self._full.append(g.mat)
            if entry.monitor.pipeline is not None:
                self._unread[g.mat] = entry.monitor.clock.last_t
            self._soon_mats.add(g.mat)
            topics.append(mat_topic(self.topic, g.mat))
            kind = "taken-over" if g.blobs else "watched"
            entry.monitor.record_events(
                [Event(kind, entry.monitor.clock.last_t or 0.0, None, details[g.mat])]
            )
            held.append(g.mat)
        self.moves["taken"] += len(held)
        if topics and self._client is not None:
            self._client.subscribe([(t, 0) for t in topics])
        if held:
            log.info("group %s: %s holds %d more mat(s): %s", self.name, self.member,
                     len(held), ", ".join(held[:8]))  # fmt: skip
        later = [(m, e) for m, e in self._release_later.items() if self.held.get(m) == e]
        self._release_later = {m: e for m, e in self._release_later.items()
                               if m in self._restoring}  # fmt: skip
        if later:
            self.release(later)

    def _unhold(self, mats: list[str]) -> list[str]:
        gone = [m for m in mats if m in self.held]
        for m in gone:
            del self.held[m]
            self._unread.pop(m, None)
            entry = self.mats[m]
            assert isinstance(entry, GroupMatEntry)
            entry.held = False
            entry.version += 1
        if gone and self._client is not None:
            self._client.unsubscribe([mat_topic(self.topic, m) for m in gone])
        return gone

    def release(self, items: list[tuple[str, int]]) -> None:
        """Hand mats to the members they belong to: stop reading them, write their last
        checkpoint and give up their leases (in one transaction); a mat still being
        restored is handed on once it is."""
        self._release_later.update((m, e) for m, e in items if self._restoring.get(m) == e)
        mats = [m for m, e in items if self.held.get(m) == e]
        for m in self._unhold(mats):
            self._write(m, dict(items)[m], rarely=True, release=True)
        self.moves["released"] += len(mats)

    def lost(self, mats: list[str]) -> None:
        """Mats another member took (this member's lease lapsed): stop at once."""
        for m in mats:
            self._restoring.pop(m, None)
            self._release_later.pop(m, None)
        gone = self._unhold(mats)
        if gone:
            self.moves["lost"] += len(gone)
            log.warning("group %s: %d mat(s) are held by another member now: %s", self.name,
                        len(gone), ", ".join(gone[:8]))  # fmt: skip

    def _write(self, mat: str, epoch: int, rarely: bool = False, release: bool = False) -> None:
        """Checkpoint a mat: its state taken here (a copy), packed in the journal's thread."""
        entry = self.mats[mat]
        self._revision[mat] = entry.revision
        often = checkpoint.take(entry, often=True)
        sensor = checkpoint.take(entry, often=False) if rarely else None
        self.journal.checkpoint(mat, epoch, entry.monitor.session_id, entry.monitor.clock.last_t,
                                often, sensor, release)  # fmt: skip

    def _soon(self, session: int) -> None:
        mat = self._session_mat.get(session)
        if mat is not None:
            self._soon_mats.add(mat)

    def interval(self) -> float:
        """Seconds between two checkpoints of a held mat: ``checkpoint_s``, or longer when
        this member holds more than ``checkpoint_s`` x :data:`CHECKPOINTS_PER_S` (its share of
        them) mats."""
        return max(self.checkpoint_s, len(self.held) / (CHECKPOINTS_PER_S * self.share))

    def checkpoints(self, now: float) -> int:
        """Checkpoint the held mats that are due (every :meth:`interval`, the sensor's state
        every :data:`SENSOR_EVERY`-th time; a mat that has not changed since its last one is
        not written again; for at most :data:`DUE_S`, the rest in the next turns), those with a
        new event (for at most :data:`SOON_S`, the rest in the next turns), and the first full
        checkpoints of mats just taken (at most :data:`FULL_PER_S` a second); returns how
        many."""
        soon: set[str] = set()  # (at most :data:`SOON_S` of them in one turn)
        n = 0
        for _ in at_least_once_for(SOON_S):
            if not self._soon_mats:
                break
            m = self._soon_mats.pop()
            soon.add(m)
            if m in self.held:
                n += self._checkpoint(m, now)
        per_s = FULL_PER_S * self.share
        self._allowance = min(self._allowance + (now - self._full_t) * per_s, per_s)
        self._full_t = now
        while self._full and self._allowance >= 1:
            m = self._full.popleft()
            if m in self.held:
                self._write(m, self.held[m], rarely=True)
                self._allowance -= 1
                n += 1
        for _ in at_least_once_for(DUE_S):
            if not self._due or self._due[0][0] > now:
                break
            _, m = heapq.heappop(self._due)
            self._scheduled.discard(m)
            if m in soon and m in self.held:  # written just now: the next one in an interval
                self._schedule(m, now)
            elif m in self.held:
                n += self._checkpoint(m, now)
        return n

    def _schedule(self, mat: str, now: float) -> None:
        """The mat's next checkpoint due an interval from ``now``; for a mat just taken, at
        its own phase of that interval (:func:`due_phase`), so that mats taken together do
        not come due together, then and every interval after."""
        if mat not in self._scheduled:  # one place in the queue per mat
            self._scheduled.add(mat)
            wait = self.interval()
            if mat in self._phase:
                self._phase.discard(mat)
                wait *= due_phase(mat)
            heapq.heappush(self._due, (now + wait, mat))

    def _checkpoint(self, mat: str, now: float) -> bool:
        self._schedule(mat, now)
        if self._revision.get(mat) == self.mats[mat].revision:
            self.skipped += 1  # nothing changed (no frame, no event): the last one holds
            return False
        k = self._count.get(mat, 0)
        self._count[mat] = k + 1
        if mat in self._unread and self.mats[mat].monitor.clock.last_t != self._unread[mat]:
            # its first frames here: the sensor's state goes with the next full checkpoints
            # (a takeover from a state taken before any frame, with the monitor's after them,
            # read the rest through a pipeline without their memory: round 15's fault test,
            # an alert 12.8 s early), not only in SENSOR_EVERY intervals
            del self._unread[mat]
            self._full.append(mat)
        self._write(mat, self.held[mat], rarely=k % SENSOR_EVERY == 0)
        return True

    # ---------------------------------------------------------------- MQTT
    @property
    def tiles_topic(self) -> str:
        return f"{self.prefix}/_group/{self.name}"

    def _on_connect(self, client: Any, _u: Any, _f: Any, reason: Any, _p: Any = None) -> None:
        if getattr(reason, "is_failure", False):
            super()._on_connect(client, _u, _f, reason, _p)
            return
        self.refusal = None
        self.connects += 1
        topics = [self.tiles_topic + "/+"] + [mat_topic(self.topic, m) for m in list(self.held)]
        client.subscribe([(t, 0) for t in topics])

    def handle(self, topic: str, payload: bytes, now: float | None = None) -> None:
        if topic.startswith(self.tiles_topic + "/"):
            self._tiles_from(topic, payload)
            return
        mat = mat_id_of(topic)
        if mat is not None and mat in self.mats and mat not in self.held:
            self.not_held += 1
            return
        super().handle(topic, payload, now)

    def _tiles_from(self, topic: str, payload: bytes) -> None:
        """A message of tiles from another member: one JSON per line, the first the header
        (member, wall, and every mat it holds)."""
        member = topic.rsplit("/", 1)[-1]
        if member == self.member:
            return
        lines = payload.split(b"\n")
        try:
            head = json_loads(lines[0])
            arrived = time.time()
            for mat in head.get("held", []):
                old = self._tiles.get(mat)
                if old is not None and old[0] is not None and old[0].get("holder") == member:
                    self._tiles[mat] = (old[0], old[1], arrived)
            for line in lines[1:]:
                text = line.decode()
                mat = json_loads(text)["id"]
                if mat in self.mats and mat not in self.held:
                    self._tiles[mat] = (None, text, arrived)
                    self.mats[mat].version += 1
        except (ValueError, KeyError, TypeError, UnicodeDecodeError) as e:
            self.quiet.warn("group", "tiles", f"a message of tiles from {member!r} is not "
                            f"readable ({e}); skipped")  # fmt: skip

    def remote_tile(self, mat: str) -> tuple[dict[str, Any] | None, str | None, float]:
        """The latest tile of ``mat`` from its holder, parsed (once), its text and arrival."""
        got = self._tiles.get(mat)
        if got is None:
            return None, None, 0.0
        tile, text, wall = got
        if tile is None:
            tile = json_loads(text)
            self._tiles[mat] = (tile, text, wall)
        return tile, text, wall

    def publish_tiles(self, now: float) -> int:
        """Send the tiles of the held mats that changed (at most :data:`TILES_PER_S` x
        :data:`TILE_S`, :meth:`_due_tiles`; in messages of at most
        :data:`TILE_BATCH_BYTES`); returns how many."""
        client = self._client
        if client is None or not self.connected:
            return 0
        view = self.view
        if view is not None and {m for m, v in view.members.items() if v.get("alive")} <= {
            self.member
        }:
            self._sent.clear()  # alone: nobody reads them (a member that joins gets them all)
            return 0
        head = json.dumps({"member": self.member, "url": self.page, "wall": time.time(),
                           "held": sorted(self.held)}, separators=(",", ":"))  # fmt: skip
        lines: list[str] = []
        size, sent = 0, 0
        topic = f"{self.tiles_topic}/{self.member}"
        for m, state in self._due_tiles(max(1, round(TILES_PER_S * TILE_S))):
            e = self.mats[m]
            text = e.tile()
            if lines and size + len(text) > TILE_BATCH_BYTES:
                client.publish(topic, "\n".join([head, *lines]).encode())
                lines, size = [], 0
            lines.append(text)
            size += len(text) + 1
            self._sent[m] = (e.revision, state, now)
            sent += 1
        client.publish(topic, "\n".join([head, *lines]).encode())
        return sent

    def _due_tiles(self, budget: int) -> list[tuple[str, str]]:
        """The held mats whose tiles are sent now, with the state each shows: those that
        changed since their last tile, a changed state (an alert, stale) first, then the
        longest unsent; at most ``budget``."""
        due = []
        for m in self.held:
            e = self.mats[m]
            last = self._sent.get(m)
            if last is not None and last[0] == e.revision:
                continue
            state = e.view_state()[0]
            due.append((last is not None and last[1] == state, last[2] if last else 0.0, m, state))
        due.sort(key=lambda d: (d[0], d[1]))
        return [(m, state) for _, _, m, state in due[:budget]]

    # ---------------------------------------------------------------- running
    def start(self) -> None:
        self._main = asyncio.get_running_loop()
        self.loop_beat = time.monotonic()
        self.journal.start()
        self.membership.join_group()  # here: a refusal (another ward) stops the start
        self.membership.start()
        super().start()

    async def watch(self, every_s: float = 0.02) -> None:
        """Mark mats stale, checkpoint them, send their tiles (runs until cancelled)."""
        k = 0
        while True:
            now = time.time()
            self.loop_beat = time.monotonic()
            try:
                self._beat(now)
            except Exception as e:  # never the end of the watch: one line, counted
                self.quiet.warn("group", "beat", f"the group's beat failed ({type(e).__name__}: "
                                f"{e})")  # fmt: skip
            k += 1
            if k % 50 == 0:
                self.forget_unknown(now)
            await asyncio.sleep(every_s)

    def _beat(self, now: float) -> None:
        if now >= self._next_check:  # silence judged at what the inbox has read (behind)
            self._next_check = now + CHECK_S
            self.check_all(now, list(self.held))
        self.checkpoints(time.monotonic())
        if time.monotonic() >= self._next_tiles:
            self._next_tiles = time.monotonic() + TILE_S
            self.publish_tiles(now)

    def stop(self) -> None:
        """Hand every held mat over (a last checkpoint each, the leases released), say that
        this member left, then stop as a station does (the sessions go on elsewhere)."""
        self._stopping = True  # no more grants
        held = dict(self.held)
        for m in self._unhold(list(held)):
            self._write(m, held[m], rarely=True, release=True)
        if not self.journal.stop(3.0):
            log.warning("group %s: %d write(s) could not be made before the stop", self.name,
                        self.journal.waiting())  # fmt: skip
        self.membership.stop()
        self._worker.shutdown(wait=False, cancel_futures=True)
        super().stop()

    # ---------------------------------------------------------------- elsewhere
    def holder_of(self, mat: str) -> tuple[str | None, str | None]:
        """The alive member that holds ``mat`` and its page (None, None: nobody)."""
        holder = self.view.holders.get(mat) if self.view is not None else None
        return holder, self.member_url(holder)

    async def _forward(self, mat: str, path: str) -> dict[str, Any]:
        """POST ``path`` to the member that holds ``mat`` (with this member's token: every
        member of a group has the same) and return its answer."""
        holder, url = self.holder_of(mat)
        if holder is None or url is None:
            raise ParameterError(f"no station watches mat {mat} at the moment; try again")
        request = urllib.request.Request(url.rstrip("/") + path, method="POST")
        if self.token:
            request.add_header("Authorization", f"Bearer {self.token}")

        def post() -> dict[str, Any]:
            with urllib.request.urlopen(request, timeout=5) as r:
                return dict(json_loads(r.read()))

        try:
            return await asyncio.to_thread(post)
        except urllib.error.HTTPError as e:
            body = e.read().decode(errors="replace")[:300]
            e.close()
            raise ParameterError(f"member {holder} answered {e.code}: {body}") from None
        except (OSError, ValueError) as e:
            raise ParameterError(f"member {holder} ({url}) did not answer: {e}") from None

    async def acknowledge(self, mat_id: str, alert_id: int) -> dict[str, Any]:
        if mat_id in self.held:
            return await super().acknowledge(mat_id, alert_id)
        return await self._forward(mat_id, f"/api/mats/{mat_id}/alerts/{alert_id}/ack")

    async def admit(self, mat_id: str) -> dict[str, Any]:
        if mat_id in self.held:
            return await super().admit(mat_id)
        return await self._forward(mat_id, f"/api/mats/{mat_id}/admit")

    def layers(self) -> list[tuple[Any, dict[str, Any]]]:
        return [(Elsewhere, {"station": self})]

    def header(self) -> dict[str, Any]:
        view = self.view
        return {
            **super().header(),
            "group": self.name,
            "member": self.member,
            "members": view.members if view else {},
            "held": len(self.held),
            "unwatched": sum(1 for h in (view.holders.values() if view else []) if h is None),
            "database": self.membership.down or self.journal.down,
        }
