"""Who holds which mat in a group of stations, decided by PostgreSQL (docs/station.md, "A
group of stations"); :mod:`texsense.station.journal` writes a member's events and
checkpoints there.

No coordinator of our own: the assignment is rows of a table on the PostgreSQL server that
every member already uses for its events.

- **members** (``group_members``): each member's row with its heartbeat and the server
  process of its connection (``pg_backend_pid()`` and that process's start). A member is
  *alive* while its heartbeat is younger than :data:`LEASE_S` and, when it registered since
  the server started, its connection's server process still runs: a member killed with
  SIGKILL loses its connection at once (the kernel closes the socket), so the others see it
  gone at their next look (:data:`BEAT_S`); a member whose machine vanished stops beating
  and is gone :data:`LEASE_S` later. After a restart of the server every member gets
  :data:`LEASE_S` from the server's start to come back (``pg_postmaster_start_time()``).
- **leases** (``group_leases``): per mat its holder, an epoch that grows with every change
  of holder, and an expiry that the holder renews with every heartbeat (one UPDATE for all
  its mats). A mat is free when nobody holds it, its lease expired or its holder is not
  alive. Taking is one UPDATE whose WHERE says "free": two members can never both win it
  (the row lock serialises them and the loser's condition no longer holds).
- **who should hold what**: rendezvous hashing over the alive members (each mat goes to the
  member with the highest hash of (mat, member)): every member computes the same answer,
  the mats spread evenly, only the mats of a member that leaves move, and a member that
  comes back gets the same mats back. A member takes the free mats that prefer it at once,
  any free mat after :data:`GRACE_S`, and releases (with a last checkpoint) the mats that
  prefer another member who has been beating for :data:`READY_S` without a break.
- **checkpoints** (``group_checkpoints``): per mat the latest state (``often``: the clinical
  state, every ``--checkpoint-every`` s and after every alert event; ``rarely``: the
  sensor's state). A write is fenced by the writer's lease: it locks the lease row and
  writes only while the lease is still its own, with the same epoch.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import psycopg

from texsense.exceptions import ParameterError

__all__ = [
    "BEAT_S",
    "GRACE_S",
    "LEASE_S",
    "READY_S",
    "SETTLE_S",
    "Grant",
    "Lease",
    "Membership",
    "View",
    "connect",
    "plan",
    "preferred",
]

log = logging.getLogger("texsense.station")

#: A lease (and a member's heartbeat) lasts this long without renewal, s.
LEASE_S = 5.0
#: Members beat, renew and look at the group this often, s.
BEAT_S = 1.0
#: A free mat that prefers another member is taken by anyone after this, s.
GRACE_S = 3.0
#: A member takes nothing in its first seconds (who else is starting?), s.
SETTLE_S = 2.0
#: Others give a member its mats once it has been beating this long without a break (a
#: member that came back, or whose event loop was stuck and whose leases lapsed, does not
#: get its mats back at once), s.
READY_S = 10.0
#: At most this many mats change hands per member and beat (the event loop restores them).
MOVES_PER_BEAT = 200
#: A lock number (``pg_advisory_xact_lock``) for creating the tables.
SCHEMA_LOCK = 0x74657873  # "texs"

_SCHEMA = [
    """CREATE TABLE IF NOT EXISTS group_members (
        grp TEXT NOT NULL, member TEXT NOT NULL, url TEXT, ward TEXT,
        pid INTEGER, backend_start TIMESTAMPTZ, joined TIMESTAMPTZ NOT NULL,
        heartbeat TIMESTAMPTZ NOT NULL, beating_since TIMESTAMPTZ NOT NULL,
        left_at TIMESTAMPTZ, PRIMARY KEY (grp, member))""",
    """CREATE TABLE IF NOT EXISTS group_leases (
        grp TEXT NOT NULL, mat TEXT NOT NULL, member TEXT, epoch BIGINT NOT NULL DEFAULT 0,
        expires TIMESTAMPTZ, PRIMARY KEY (grp, mat))""",
    """CREATE TABLE IF NOT EXISTS group_checkpoints (
        grp TEXT NOT NULL, mat TEXT NOT NULL, epoch BIGINT NOT NULL, member TEXT NOT NULL,
        saved TIMESTAMPTZ NOT NULL, t DOUBLE PRECISION, session BIGINT NOT NULL,
        last_event BIGINT NOT NULL DEFAULT 0, often BYTEA NOT NULL, rarely BYTEA,
        rarely_saved TIMESTAMPTZ, PRIMARY KEY (grp, mat))""",
]

_ALIVE = """m.left_at IS NULL
    AND greatest(m.heartbeat, pg_postmaster_start_time()) > now() - make_interval(secs => %(lease)s)
    AND (m.backend_start IS NULL OR m.backend_start < pg_postmaster_start_time()
         OR EXISTS (SELECT 1 FROM pg_stat_activity a
                    WHERE a.pid = m.pid AND a.backend_start = m.backend_start))"""


def connect(url: str) -> psycopg.Connection[Any]:
    """A connection for the group's threads: autocommit, short timeouts, and keepalives both
    ways (a vanished peer is noticed in seconds, not hours). Errors name the host, never the
    password."""
    try:
        conn = psycopg.connect(
            url, autocommit=True, connect_timeout=3, keepalives=1, keepalives_idle=3,
            keepalives_interval=1, keepalives_count=3, tcp_user_timeout=6000,
            options="-c statement_timeout=10000 -c tcp_keepalives_idle=3 "
            "-c tcp_keepalives_interval=1 -c tcp_keepalives_count=3",
        )  # fmt: skip
    except psycopg.OperationalError as e:
        where = url.split("@")[-1]
        raise ParameterError(f"cannot connect to PostgreSQL at {where}: {e}") from None
    return conn


def create_schema(conn: psycopg.Connection[Any]) -> None:
    """The group's tables (once, however many members start at the same time)."""
    with conn.transaction():
        conn.execute("SELECT pg_advisory_xact_lock(%s)", (SCHEMA_LOCK,))
        for statement in _SCHEMA:
            conn.execute(statement)


@lru_cache(maxsize=1 << 16)
def _score(mat: str, member: str) -> int:
    digest = hashlib.blake2b(f"{mat}\0{member}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big")


def preferred(mat: str, members: list[str] | set[str]) -> str | None:
    """The member that should hold ``mat`` (rendezvous hashing), None without members.

    >>> preferred("bed7", ["a", "b", "c"]) == preferred("bed7", ["c", "a", "b"])
    True
    """
    return max(members, key=lambda m: (_score(mat, m), m)) if members else None


@dataclass
class Lease:
    """A mat's lease as the group reads it."""

    mat: str
    member: str | None
    epoch: int
    valid: bool  # not expired


def plan(
    me: str,
    leases: dict[str, Lease],
    alive: set[str],
    ready: set[str],
    mine: set[str],
    releasing: set[str],
    free_since: dict[str, float],
    now: float,
    settled: bool,
) -> tuple[list[str], list[str]]:
    """Which mats to take and which to release (see the module): ``alive`` members, of which
    ``ready`` (beating for :data:`READY_S`), the mats whose lease is ``mine``, the mats being
    released, and since when each free mat has been free (updated here)."""
    candidates = sorted(ready | ({me} if settled else set()))
    take, release = [], []
    for mat, lease in leases.items():
        pref = preferred(mat, candidates)
        if mat in mine:
            free_since.pop(mat, None)
            if mat not in releasing and pref is not None and pref != me and pref in ready:
                release.append(mat)
            continue
        held = lease.member is not None and lease.valid and lease.member in alive
        if held or not settled:
            free_since.pop(mat, None)
            continue
        since = free_since.setdefault(mat, now)
        if pref == me or pref is None or now - since >= GRACE_S:
            take.append(mat)
    return take[:MOVES_PER_BEAT], release[:MOVES_PER_BEAT]


@dataclass
class Grant:
    """A mat this member now holds: its epoch, the session its events go to, the latest
    checkpoints (``often`` and ``rarely`` containers, when there are), the events stored
    after them, and where they came from."""

    mat: str
    epoch: int
    session: int
    blobs: list[bytes] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    last_event: int = 0
    source: str | None = None  # the member that wrote the checkpoint
    age_s: float | None = None  # how old the checkpoint was


@dataclass
class View:
    """The group as the last look saw it: members (url, alive, how many mats) and each mat's
    holder (None: nobody alive holds it)."""

    members: dict[str, dict[str, Any]]
    holders: dict[str, str | None]
    db: str | None = None  # why the database is not answering, when it is not
    wall: float = 0.0


class Membership(threading.Thread):
    """This member's side of the group: beats, renews its leases, looks at the group and
    takes or releases mats (see the module). ``on_*`` are called with lists, in this thread
    (the station hands them to its event loop)."""

    def __init__(
        self,
        url: str,
        group: str,
        member: str,
        *,
        page: str,
        ward: str,
        mats: dict[str, str],
        on_grant: Callable[[list[Grant]], None],
        on_release: Callable[[list[tuple[str, int]]], None],
        on_lost: Callable[[list[str]], None],
        on_view: Callable[[View], None],
        loop_alive: Callable[[], bool] = lambda: True,
    ) -> None:
        super().__init__(name=f"texsense-group-{member}", daemon=True)
        self.url, self.group, self.member, self.page, self.ward = url, group, member, page, ward
        self.mats = mats  # mat id -> the name of its session's source
        self.on_grant, self.on_release, self.on_lost, self.on_view = (
            on_grant, on_release, on_lost, on_view)  # fmt: skip
        self.loop_alive = loop_alive
        self.conn: psycopg.Connection[Any] | None = None
        self.assigned: dict[str, int] = {}  # what the station holds (or is being handed)
        self.releasing: dict[str, int] = {}
        self.free_since: dict[str, float] = {}
        self.joined = time.monotonic()
        self.down: str | None = None  # why the database does not answer
        self._first = True
        self._halt = threading.Event()
        self._said_loop = False

    # ---------------------------------------------------------------- joining
    def join_group(self) -> None:
        """Connect, make the tables, register (refusing a member of another ward) and add
        a lease row per mat. Raises :class:`ParameterError` (one line) when it cannot."""
        conn = connect(self.url)
        try:
            create_schema(conn)
            if self._first:
                self._check_ward(conn)
            conn.execute(
                """INSERT INTO group_members AS m (grp, member, url, ward, pid, backend_start,
                       joined, heartbeat, beating_since, left_at)
                   SELECT %(grp)s, %(me)s, %(url)s, %(ward)s, pid, backend_start, now(), now(),
                       now(), NULL FROM pg_stat_activity WHERE pid = pg_backend_pid()
                   ON CONFLICT (grp, member) DO UPDATE SET url = EXCLUDED.url,
                       ward = EXCLUDED.ward, pid = EXCLUDED.pid,
                       backend_start = EXCLUDED.backend_start, heartbeat = now(), left_at = NULL,
                       joined = CASE WHEN %(first)s THEN now() ELSE m.joined END,
                       beating_since = CASE WHEN %(first)s OR m.heartbeat
                           < now() - make_interval(secs => %(lease)s) THEN now()
                           ELSE m.beating_since END""",
                {"grp": self.group, "me": self.member, "url": self.page, "ward": self.ward,
                 "first": self._first, "lease": LEASE_S},
            )  # fmt: skip
            conn.execute(
                "INSERT INTO group_leases (grp, mat) SELECT %s, unnest(%s::text[]) "
                "ON CONFLICT DO NOTHING",
                (self.group, sorted(self.mats)),
            )
        except BaseException:
            conn.close()
            raise
        if self._first:
            self.joined = time.monotonic()
        self._first = False
        self.conn = conn

    def _check_ward(self, conn: psycopg.Connection[Any]) -> None:
        rows = conn.execute(
            f"SELECT m.member, m.ward FROM group_members m WHERE m.grp = %(grp)s "
            f"AND m.member <> %(me)s AND m.ward IS DISTINCT FROM %(ward)s AND {_ALIVE}",
            {"grp": self.group, "me": self.member, "ward": self.ward, "lease": LEASE_S},
        ).fetchall()
        if rows:
            raise ParameterError(
                f"the member {rows[0][0]!r} of the group {self.group!r} watches another ward "
                "(other mats or calibrations): every member of a group needs the same ward file "
                "and the same --virtual-mats"
            )

    # ---------------------------------------------------------------- the beat
    def run(self) -> None:
        while not self._halt.is_set():
            began = time.monotonic()
            try:
                if self.conn is None or self.conn.closed:
                    self.join_group()
                self.tick()
                if self.down is not None:
                    log.warning("PostgreSQL answers again: group %s caught up", self.group)
                self.down = None
            except (psycopg.Error, ParameterError) as e:
                self._lost_db(e)
            self._halt.wait(max(0.05, BEAT_S - (time.monotonic() - began)))

    def _lost_db(self, e: Exception) -> None:
        text = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        if self.down is None:
            log.warning("PostgreSQL does not answer (%s): the group's mats stay where they "
                        "are and are watched from memory; trying again every %g s", text,
                        BEAT_S)  # fmt: skip
        self.down = text
        if self.conn is not None:
            self.conn.close()
        self.conn = None

    def tick(self) -> None:
        """One beat: heartbeat and renewal, a look at the group, takes and releases."""
        conn = self.conn
        assert conn is not None
        args = {"grp": self.group, "me": self.member, "lease": LEASE_S}
        if self.loop_alive():
            self._said_loop = False
            conn.execute(
                "UPDATE group_members SET heartbeat = now(), beating_since = CASE WHEN heartbeat "
                "< now() - make_interval(secs => %(lease)s) THEN now() ELSE beating_since END "
                "WHERE grp = %(grp)s AND member = %(me)s",
                args,
            )
            mine_rows = conn.execute(
                "UPDATE group_leases SET expires = now() + make_interval(secs => %(lease)s) "
                "WHERE grp = %(grp)s AND member = %(me)s RETURNING mat, epoch",
                args,
            ).fetchall()
        else:  # a stuck event loop: let the leases lapse, so that others take the mats
            if not self._said_loop:
                log.warning("the station's event loop does not answer: its leases lapse")
            self._said_loop = True
            mine_rows = conn.execute("SELECT mat, epoch FROM group_leases WHERE grp = %(grp)s "
                                     "AND member = %(me)s", args).fetchall()  # fmt: skip
        mine = {str(m): int(e) for m, e in mine_rows}
        members = conn.execute(
            f"SELECT m.member, m.url, {_ALIVE} AS alive, "
            "extract(epoch FROM now() - m.beating_since)::float8 FROM group_members m "
            "WHERE m.grp = %(grp)s", args,
        ).fetchall()  # fmt: skip
        alive = {str(m) for m, _u, ok, _a in members if ok}
        ready = {str(m) for m, _u, ok, age in members if ok and age >= READY_S}
        leases = {
            str(mat): Lease(str(mat), member, int(epoch), bool(valid))
            for mat, member, epoch, valid in conn.execute(
                "SELECT mat, member, epoch, coalesce(expires > now(), false) FROM group_leases "
                "WHERE grp = %(grp)s",
                args,
            ).fetchall()
            if str(mat) in self.mats
        }
        self._settle(mine)
        settled = time.monotonic() - self.joined >= SETTLE_S
        # leases in my name that this process does not hold (a previous run of this member)
        orphans = [m for m in mine if m not in self.assigned and m not in self.releasing]
        take, release = plan(self.member, leases, alive, ready, set(mine) - set(orphans),
                             set(self.releasing), self.free_since, time.monotonic(),
                             settled)  # fmt: skip
        if settled:
            take = sorted(set(take) | set(orphans))
        if take:
            self._take(conn, take, alive)
        if release:
            items = [(m, mine[m]) for m in release]
            self.releasing.update(items)
            self.on_release(items)
        self._view(members, leases, alive)

    def _settle(self, mine: dict[str, int]) -> None:
        """Compare what the database says is mine with what the station holds: mats taken
        from under it (its lease lapsed and another took it) are lost."""
        lost = [m for m, e in self.assigned.items() if mine.get(m) != e and m not in self.releasing]
        for m in [m for m in self.releasing if m not in mine]:
            self.releasing.pop(m)
            self.assigned.pop(m, None)
        for m in lost:
            self.assigned.pop(m)
        if lost:
            self.on_lost(lost)

    def _take(self, conn: psycopg.Connection[Any], mats: list[str], alive: set[str]) -> None:
        rows = conn.execute(
            """UPDATE group_leases SET member = %(me)s, epoch = epoch + 1,
                   expires = now() + make_interval(secs => %(lease)s)
               WHERE grp = %(grp)s AND mat = ANY(%(mats)s::text[]) AND (member IS NULL
                   OR member = %(me)s OR expires IS NULL OR expires <= now()
                   OR NOT (member = ANY(%(alive)s::text[])))
               RETURNING mat, epoch""",
            {"grp": self.group, "me": self.member, "lease": LEASE_S, "mats": mats,
             "alive": sorted(alive - {self.member})},
        ).fetchall()  # fmt: skip
        if not rows:
            return
        got = {str(m): int(e) for m, e in rows}
        grants = self._grants(conn, got)
        for g in grants:
            self.assigned[g.mat] = g.epoch
            self.free_since.pop(g.mat, None)
        self.on_grant(grants)

    def _grants(self, conn: psycopg.Connection[Any], got: dict[str, int]) -> list[Grant]:
        """The checkpoints of the mats just taken, the events after them, and a session for
        a mat that has none yet."""
        rows = conn.execute(
            "SELECT mat, member, extract(epoch FROM now() - saved)::float8, session, "
            "last_event, often, rarely FROM group_checkpoints WHERE grp = %s "
            "AND mat = ANY(%s::text[])",
            (self.group, sorted(got)),
        ).fetchall()
        found = {str(r[0]): r for r in rows}
        sessions = [int(r[3]) for r in rows]
        lasts = [int(r[4]) for r in rows]
        after: dict[int, list[dict[str, Any]]] = {}
        if sessions:
            for session, eid, t, kind, alert, detail in conn.execute(
                "SELECT e.session, e.id, e.t, e.kind, e.alert, e.detail FROM events e "
                "JOIN unnest(%s::bigint[], %s::bigint[]) AS c(session, last) "
                "ON e.session = c.session AND e.id > c.last ORDER BY e.id",
                (sessions, lasts),
            ).fetchall():  # fmt: skip
                after.setdefault(int(session), []).append(
                    {"id": eid, "t": t, "kind": kind, "alert": alert, "detail": json.loads(detail)}
                )
        grants = []
        for mat, epoch in sorted(got.items()):
            row = found.get(mat)
            if row is None:
                (session,) = conn.execute(
                    "INSERT INTO sessions (source, started) VALUES (%s, %s) RETURNING id",
                    (self.mats[mat], time.time()),
                ).fetchone() or (0,)
                grants.append(Grant(mat, epoch, int(session)))
                continue
            _m, source, age, session, last, often, rarely = row
            blobs = [bytes(b) for b in (rarely, often) if b is not None]
            events = after.get(int(session), [])
            last = max([int(last), *(int(e["id"]) for e in events)])
            grants.append(Grant(mat, epoch, int(session), blobs, events, last, source, age))
        return grants

    def _view(self, members: list[Any], leases: dict[str, Lease], alive: set[str]) -> None:
        holders = {
            mat: lease.member if lease.member in alive and lease.valid else None
            for mat, lease in leases.items()
        }
        counts: dict[str, int] = {}
        for h in holders.values():
            if h is not None:
                counts[h] = counts.get(h, 0) + 1
        info = {
            str(m): {"url": url, "alive": bool(ok), "mats": counts.get(str(m), 0)}
            for m, url, ok, _age in members
            if ok or counts.get(str(m))
        }
        self.on_view(View(info, holders, None, time.time()))

    # ---------------------------------------------------------------- leaving
    def stop(self, timeout: float = 2.0) -> None:
        """Stop beating and say that this member left (the others take its mats at once)."""
        self._halt.set()
        self.join(timeout)
        conn = self.conn
        if conn is None:
            return
        with contextlib.suppress(psycopg.Error):  # gone: the others see the heartbeat stop
            conn.execute("UPDATE group_members SET left_at = now() WHERE grp = %s AND member = %s",
                         (self.group, self.member))  # fmt: skip
        conn.close()
        self.conn = None
