"""Sessions and events of the monitor and the station: SQLite (the embedded default; one file,
no server) or PostgreSQL (``--db postgresql://...``).

Examples
--------
>>> from texsense.apps.alerts import Event
>>> store = EventStore(":memory:")
>>> sid = store.start_session("virtual seat")
>>> store.add_event(sid, Event("reposition", 1200.0, 1, {"where": ["17"]}))
1
>>> [(e["kind"], e["detail"]) for e in store.events()]
[('reposition', {'where': ['17']})]
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from pathlib import Path
from typing import Any

from texsense.apps.alerts import Event
from texsense.exceptions import ParameterError, WriteError, shown

__all__ = ["EventStore", "PostgresEventStore", "open_store"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS sessions (
    id INTEGER PRIMARY KEY, source TEXT NOT NULL, started REAL NOT NULL, ended REAL,
    recordings TEXT NOT NULL DEFAULT '[]'
);
CREATE TABLE IF NOT EXISTS events (
    id INTEGER PRIMARY KEY, session INTEGER NOT NULL REFERENCES sessions(id),
    wall REAL NOT NULL, t REAL NOT NULL, kind TEXT NOT NULL, alert INTEGER,
    detail TEXT NOT NULL DEFAULT '{}'
);
CREATE INDEX IF NOT EXISTS events_session ON events(session);
"""


def _held(args: tuple[Any, ...]) -> tuple[Any, ...]:
    """``args`` of a query if the database can hold every number among them (a whole number
    within 64 bits: ``?session=99999999999999999999999`` of a request was an ``OverflowError``
    out of SQLite), else a :class:`ParameterError` saying which."""
    for a in args:
        if isinstance(a, int) and not -(2**63) <= a < 2**63:
            raise ParameterError(f"{shown(a)} lies beyond the event store's whole numbers")
    return args


class EventStore:
    """SQLite store of sessions (a monitor run, or one mat of a station) and their events.
    Every write commits at once (a killed monitor keeps every event written before)."""

    #: The placeholder of query parameters.
    _mark = "?"

    def __init__(self, path: str | Path = "texsense-monitor.sqlite") -> None:
        self.path = str(path)
        self._lock = threading.Lock()
        self._db = self._connect()
        self._init_schema()

    # ---------------------------------------------------------------- the SQL dialect
    def _connect(self) -> Any:
        db = sqlite3.connect(self.path, check_same_thread=False)
        db.row_factory = sqlite3.Row
        if self.path != ":memory:":
            # write-ahead log: a commit appends to the log and syncs it once, where the
            # rollback journal synced the journal and the file (a station's 600 mats' first
            # events, one commit each: 2.6 -> ~1.6 ms a mat, issue 38); every commit is
            # still synced (synchronous FULL, SQLite's default) and other processes read the
            # file as before (SQLite's own -wal and -shm files beside it). A file system
            # without WAL keeps the journal it had (the pragma answers with it).
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA synchronous=FULL")
        return db

    def _init_schema(self) -> None:
        with self._lock, self._db:
            self._db.executescript(_SCHEMA)

    def _rows(self, sql: str, args: tuple[Any, ...] = ()) -> list[dict[str, Any]]:
        with self._lock:
            return [dict(r) for r in self._db.execute(self._sql(sql), _held(args)).fetchall()]

    def _write(self, sql: str, args: tuple[Any, ...]) -> int:
        """Run an INSERT or UPDATE and commit; returns the new row's id for an INSERT."""
        with self._lock, self._db:
            cur = self._db.execute(self._sql(sql), _held(args))
        return int(cur.lastrowid or 0)

    def _sql(self, sql: str) -> str:
        return sql.replace("?", self._mark)

    # ---------------------------------------------------------------- the store
    def start_session(self, source: str) -> int:
        """A new session; returns its id."""
        return self._write(
            "INSERT INTO sessions (source, started) VALUES (?, ?)", (source, time.time())
        )

    def end_session(self, session: int) -> None:
        """Mark a session ended."""
        self._write("UPDATE sessions SET ended = ? WHERE id = ?", (time.time(), session))

    def end_sessions(self, sessions: list[int]) -> None:
        """Mark many sessions ended in one write (a station of hundreds of mats stops within
        a second)."""
        for k in range(0, len(sessions), 500):
            ids = [int(s) for s in sessions[k : k + 500]]
            marks = ",".join("?" * len(ids))
            self._write(f"UPDATE sessions SET ended = ? WHERE id IN ({marks})", (time.time(), *ids))

    def set_recording(self, session: int, paths: list[str]) -> None:
        """Add recording files to a session."""
        rows = self._rows("SELECT recordings FROM sessions WHERE id = ?", (session,))
        files = [*json.loads(rows[0]["recordings"]), *paths] if rows else paths
        self._write("UPDATE sessions SET recordings = ? WHERE id = ?", (json.dumps(files), session))

    def add_event(self, session: int, event: Event) -> int:
        """Store an event; returns its id."""
        return self._write(
            "INSERT INTO events (session, wall, t, kind, alert, detail) VALUES (?,?,?,?,?,?)",
            (session, time.time(), event.t, event.kind, event.alert_id, json.dumps(event.detail)),
        )

    def sessions(self) -> list[dict[str, Any]]:
        """All sessions, newest first."""
        rows = self._rows("SELECT * FROM sessions ORDER BY id DESC")
        return [{**r, "recordings": json.loads(r["recordings"])} for r in rows]

    def events(
        self, session: int | None = None, kind: str | None = None, limit: int = 1000
    ) -> list[dict[str, Any]]:
        """Events, newest first, optionally of one session or kind."""
        sql, args = "SELECT * FROM events WHERE 1=1", list[Any]()
        if session is not None:
            sql += " AND session = ?"
            args.append(session)
        if kind is not None:
            sql += " AND kind = ?"
            args.append(kind)
        sql += " ORDER BY id DESC LIMIT ?"
        args.append(int(limit))
        return [{**r, "detail": json.loads(r["detail"])} for r in self._rows(sql, tuple(args))]

    def close(self) -> None:
        """Close the database."""
        self._db.close()


_PG_SCHEMA = """
CREATE TABLE IF NOT EXISTS sessions (
    id BIGSERIAL PRIMARY KEY, source TEXT NOT NULL, started DOUBLE PRECISION NOT NULL,
    ended DOUBLE PRECISION, recordings TEXT NOT NULL DEFAULT '[]'
);
CREATE TABLE IF NOT EXISTS events (
    id BIGSERIAL PRIMARY KEY, session BIGINT NOT NULL REFERENCES sessions(id),
    wall DOUBLE PRECISION NOT NULL, t DOUBLE PRECISION NOT NULL, kind TEXT NOT NULL,
    alert BIGINT, detail TEXT NOT NULL DEFAULT '{}'
);
CREATE INDEX IF NOT EXISTS events_session ON events(session);
"""


#: The lock (``pg_advisory_xact_lock``) under which the event store's tables are made.
PG_SCHEMA_LOCK = 0x74657875  # "texu"


class PostgresEventStore(EventStore):
    """The same store on a PostgreSQL server (``postgresql://user:password@host/db``), with
    psycopg 3; the tables are created when missing. For a ward whose events several systems
    read, or a site with several stations writing to one database."""

    _mark = "%s"

    def _connect(self) -> Any:
        import psycopg
        from psycopg.rows import dict_row

        try:
            return psycopg.connect(self.path, autocommit=True, row_factory=dict_row)
        except psycopg.OperationalError as e:
            where = self.path.split("@")[-1]  # never echo a password
            raise ParameterError(f"cannot connect to PostgreSQL at {where}: {e}") from None

    def _init_schema(self) -> None:
        """The tables, once however many stations start at the same time: ``IF NOT EXISTS``
        alone is not safe against a concurrent creation (two stations of a group started
        together: "duplicate key ... pg_class_relname_nsp_index"), so under a lock of the
        server held to the end of the transaction."""
        with self._lock, self._db.transaction():
            self._db.execute("SELECT pg_advisory_xact_lock(%s)", (PG_SCHEMA_LOCK,))
            for statement in filter(str.strip, _PG_SCHEMA.split(";")):
                self._db.execute(statement)

    def _rows(self, sql: str, args: tuple[Any, ...] = ()) -> list[dict[str, Any]]:
        with self._lock:
            return list(self._db.execute(self._sql(sql), _held(args)).fetchall())

    def _write(self, sql: str, args: tuple[Any, ...]) -> int:
        returning = sql.lstrip().upper().startswith("INSERT")
        with self._lock:
            cur = self._db.execute(
                self._sql(sql) + (" RETURNING id" if returning else ""), _held(args)
            )
            return int(cur.fetchone()["id"]) if returning else 0


def open_store(where: str | Path) -> EventStore:
    """An event store: PostgreSQL for a ``postgresql://`` URL, else a SQLite file."""
    text = str(where)
    if text.startswith(("postgresql://", "postgres://")):
        return PostgresEventStore(text)
    if text != ":memory:":
        path = Path(text)
        if path.is_dir():
            raise WriteError(path, "--db is a folder, expected a SQLite file")
        if path.exists() and not path.is_file():
            raise WriteError(path, "--db is not a regular file (a device, a FIFO, ...)")
        if not (path.parent if str(path.parent) else Path(".")).is_dir():
            raise WriteError(path, f"--db: the folder {path.parent} does not exist")
    try:
        return EventStore(text)
    except sqlite3.Error as e:
        raise WriteError(Path(text), f"cannot open the event store ({e})") from None
