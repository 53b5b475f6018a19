"""A group member's journal (docs/station.md, "A group of stations"): its events and its
mats' checkpoints, written to PostgreSQL in one ordered stream on a connection of its own,
so that an alert event is in the database before any checkpoint taken after it. While the
server is away the stream waits in memory (checkpoints of one mat replace each other) and is
written when it is back. A checkpoint is fenced by the writer's lease
(:mod:`texsense.station.lease`): the lease rows are locked and a checkpoint is written only
while its lease is still this member's, with the same epoch.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import psycopg

from texsense.apps.alerts import Event
from texsense.exceptions import ParameterError
from texsense.station.checkpoint import Taken
from texsense.station.lease import BEAT_S, connect

__all__ = ["Journal"]

log = logging.getLogger("texsense.station")


@dataclass
class _Checkpoint:
    mat: str
    epoch: int
    session: int
    t: float | None
    often: bytes | Taken
    rarely: bytes | Taken | None
    release: bool = False
    skip: bool = False


def _packed(blob: bytes | Taken | None) -> bytes | None:
    """A checkpoint's bytes: a :class:`~texsense.station.checkpoint.Taken` state is packed
    (compressed) here, in the journal's thread, not on the event loop that took it."""
    return blob.pack() if isinstance(blob, Taken) else blob


class Journal(threading.Thread):
    """A member's events and checkpoints, written in order on a connection of its own (see
    the module). ``on_lost(mats)``: checkpoints refused because the lease is no longer this
    member's (called in this thread)."""

    #: At most this many writes in one transaction.
    BATCH = 500

    def __init__(self, url: str, group: str, member: str,
                 on_lost: Callable[[list[str]], None]) -> None:  # fmt: skip
        super().__init__(name=f"texsense-journal-{member}", daemon=True)
        self.url, self.group, self.member, self.on_lost = url, group, member, on_lost
        self.conn: psycopg.Connection[Any] | None = None
        self.ops: deque[Any] = deque()
        self.cond = threading.Condition()
        self.last_event: dict[int, int] = {}  # session -> id of its last event written
        self.latest: dict[str, _Checkpoint] = {}  # mat -> its checkpoint waiting
        self.written = 0
        self.down: str | None = None
        self._busy = False
        self._halt = False

    def event(self, session: int, event: Event, wall: float | None = None) -> None:
        """Store an event (in order with everything else this member writes)."""
        with self.cond:
            self.ops.append(("event", session, event, time.time() if wall is None else wall))
            self.cond.notify()

    def adopt(self, session: int, last_event: int) -> None:
        """A session taken over: its events up to ``last_event`` are in the database."""
        with self.cond:
            self.last_event[session] = max(self.last_event.get(session, 0), last_event)

    def checkpoint(self, mat: str, epoch: int, session: int, t: float | None,
                   often: bytes | Taken, rarely: bytes | Taken | None = None,
                   release: bool = False) -> None:  # fmt: skip
        """Write a mat's checkpoint (``release``: then give up its lease): bytes, or a state
        taken and packed here in the journal's thread. A checkpoint of the mat still waiting
        is replaced (its sensor part kept when this one has none)."""
        op = _Checkpoint(mat, epoch, session, t, often, rarely, release)
        with self.cond:
            old = self.latest.get(mat)
            if old is not None and not old.skip and old.epoch == epoch:
                old.skip = True
                op.rarely = op.rarely if op.rarely is not None else old.rarely
            self.latest[mat] = op
            self.ops.append(op)
            self.cond.notify()

    def waiting(self) -> int:
        """Writes not yet in the database."""
        with self.cond:
            return len(self.ops) + (1 if self._busy else 0)

    def flush(self, timeout: float) -> bool:
        """Wait until everything is written (True) or ``timeout`` passed (False)."""
        deadline = time.monotonic() + timeout
        with self.cond:
            while self.ops or self._busy:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self.cond.wait(min(left, 0.05))
        return True

    def stop(self, timeout: float = 2.0) -> bool:
        """Write what waits (at most ``timeout``), then stop; False if some was left."""
        done = self.flush(timeout)
        with self.cond:
            self._halt = True
            self.cond.notify_all()
        self.join(1.0)
        if self.conn is not None:
            self.conn.close()
        return done

    def run(self) -> None:
        while True:
            with self.cond:
                while not self.ops and not self._halt:
                    self.cond.wait()
                if self._halt:
                    return
                batch = [self.ops.popleft() for _ in range(min(self.BATCH, len(self.ops)))]
                self._busy = True
            try:
                lost = self._write(batch)
                self.written += len(batch)
                if self.down is not None:
                    log.warning("the journal writes to PostgreSQL again")
                self.down = None
            except (psycopg.Error, ParameterError) as e:  # ParameterError: cannot connect
                self._failed(e, batch)
                continue
            finally:
                with self.cond:
                    self._busy = False
                    self.cond.notify_all()
            if lost:
                self.on_lost(lost)

    def _failed(self, e: Exception, batch: list[Any]) -> None:
        text = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        if self.down is None:
            log.warning("PostgreSQL does not take the journal (%s): events and checkpoints "
                        "wait in memory", text)  # fmt: skip
        self.down = text
        if self.conn is not None:
            self.conn.close()
        self.conn = None
        with self.cond:
            self.ops.extendleft(reversed(batch))
            if not self._halt:
                self.cond.wait(BEAT_S)

    def _write(self, batch: list[Any]) -> list[str]:
        """One transaction: the events and checkpoints of ``batch`` in order; returns the
        mats whose checkpoint was refused (the lease is another's now)."""
        if self.conn is None or self.conn.closed:
            self.conn = connect(self.url)
        conn = self.conn
        checkpoints = [op for op in batch if isinstance(op, _Checkpoint) and not op.skip]
        lost: list[str] = []
        with conn.transaction():
            valid: set[tuple[str, int]] = set()
            if checkpoints:  # the leases, locked: nobody takes them until this commits
                rows = conn.execute(
                    "SELECT mat, epoch FROM group_leases WHERE grp = %s AND member = %s "
                    "AND mat = ANY(%s::text[]) FOR SHARE",
                    (self.group, self.member, sorted({c.mat for c in checkpoints})),
                ).fetchall()
                valid = {(str(m), int(e)) for m, e in rows}
            written: list[dict[str, Any]] = []  # each with the last event written before it
            for op in batch:
                if isinstance(op, _Checkpoint):
                    if op.skip:
                        continue
                    if (op.mat, op.epoch) not in valid:
                        lost.append(op.mat)
                        continue
                    written.append(self._checkpoint_row(op))
                else:
                    _, session, event, wall = op
                    (eid,) = conn.execute(
                        "INSERT INTO events (session, wall, t, kind, alert, detail) "
                        "VALUES (%s, %s, %s, %s, %s, %s) RETURNING id",
                        (session, wall, event.t, event.kind, event.alert_id,
                         json.dumps(event.detail)),
                    ).fetchone() or (0,)  # fmt: skip
                    self.last_event[session] = int(eid)
            self._write_checkpoints(conn, written)
        with self.cond:
            for op in checkpoints:
                if self.latest.get(op.mat) is op:
                    del self.latest[op.mat]
        return lost

    def _checkpoint_row(self, op: _Checkpoint) -> dict[str, Any]:
        return {"grp": self.group, "mat": op.mat, "epoch": op.epoch, "me": self.member,
                "t": op.t, "session": op.session, "last": self.last_event.get(op.session, 0),
                "often": _packed(op.often), "rarely": _packed(op.rarely),
                "release": op.release}  # fmt: skip

    def _write_checkpoints(self, conn: psycopg.Connection[Any], rows: list[dict[str, Any]]) -> None:
        """The checkpoints of a batch in one statement (psycopg's ``executemany``: one round
        trip), then the leases given up with them."""
        if rows:
            conn.cursor().executemany(
                """INSERT INTO group_checkpoints AS c (grp, mat, epoch, member, saved, t,
                       session, last_event, often, rarely, rarely_saved)
                   VALUES (%(grp)s, %(mat)s, %(epoch)s, %(me)s, now(), %(t)s, %(session)s,
                       %(last)s, %(often)s, %(rarely)s::bytea,
                       CASE WHEN %(rarely)s::bytea IS NULL THEN NULL ELSE now() END)
                   ON CONFLICT (grp, mat) DO UPDATE SET epoch = EXCLUDED.epoch,
                       member = EXCLUDED.member, saved = EXCLUDED.saved, t = EXCLUDED.t,
                       session = EXCLUDED.session, last_event = EXCLUDED.last_event,
                       often = EXCLUDED.often, rarely = coalesce(EXCLUDED.rarely, c.rarely),
                       rarely_saved = coalesce(EXCLUDED.rarely_saved, c.rarely_saved)""",
                rows,
            )
        released = [(self.group, r["mat"], self.member, r["epoch"]) for r in rows if r["release"]]
        if released:
            conn.cursor().executemany(
                "UPDATE group_leases SET member = NULL, expires = now() WHERE grp = %s AND "
                "mat = %s AND member = %s AND epoch = %s",
                released,
            )
