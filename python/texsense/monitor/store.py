"""Sessions and events of the monitor in SQLite (the embedded default; one file, no server).

Examples
--------
>>> from texsense.monitor.alerts import Event
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

from texsense.monitor.alerts import Event

__all__ = ["EventStore"]

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


class EventStore:
    """SQLite store of sessions (a monitor run) and their events. Every write commits at once
    (a killed monitor keeps every event written before)."""

    def __init__(self, path: str | Path = "texsense-monitor.sqlite") -> None:
        self.path = str(path)
        self._db = sqlite3.connect(self.path, check_same_thread=False)
        self._db.row_factory = sqlite3.Row
        self._lock = threading.Lock()
        with self._lock, self._db:
            self._db.executescript(_SCHEMA)

    def start_session(self, source: str) -> int:
        """A new session; returns its id."""
        with self._lock, self._db:
            cur = self._db.execute(
                "INSERT INTO sessions (source, started) VALUES (?, ?)", (source, time.time())
            )
        return int(cur.lastrowid or 0)

    def end_session(self, session: int) -> None:
        """Mark a session ended."""
        with self._lock, self._db:
            self._db.execute("UPDATE sessions SET ended = ? WHERE id = ?", (time.time(), session))

    def set_recording(self, session: int, paths: list[str]) -> None:
        """Add recording files to a session."""
        with self._lock, self._db:
            row = self._db.execute(
                "SELECT recordings FROM sessions WHERE id = ?", (session,)
            ).fetchone()
            files = [*json.loads(row["recordings"]), *paths] if row else paths
            self._db.execute(
                "UPDATE sessions SET recordings = ? WHERE id = ?", (json.dumps(files), session)
            )

    def add_event(self, session: int, event: Event) -> int:
        """Store an event; returns its id."""
        with self._lock, self._db:
            cur = self._db.execute(
                "INSERT INTO events (session, wall, t, kind, alert, detail) VALUES (?,?,?,?,?,?)",
                (
                    session,
                    time.time(),
                    event.t,
                    event.kind,
                    event.alert_id,
                    json.dumps(event.detail),
                ),
            )
        return int(cur.lastrowid or 0)

    def sessions(self) -> list[dict[str, Any]]:
        """All sessions, newest first."""
        with self._lock:
            rows = self._db.execute("SELECT * FROM sessions ORDER BY id DESC").fetchall()
        return [{**dict(r), "recordings": json.loads(r["recordings"])} for r in rows]

    def events(
        self, session: int | None = None, kind: str | None = None, limit: int = 1000
    ) -> list[dict[str, Any]]:
        """Events, newest first, optionally of one session or kind."""
        sql, args = "SELECT * FROM events WHERE 1=1", []
        if session is not None:
            sql += " AND session = ?"
            args.append(session)
        if kind is not None:
            sql += " AND kind = ?"
            args.append(kind)
        sql += " ORDER BY id DESC LIMIT ?"
        args.append(int(limit))
        with self._lock:
            rows = self._db.execute(sql, args).fetchall()
        return [{**dict(r), "detail": json.loads(r["detail"])} for r in rows]

    def close(self) -> None:
        """Close the database."""
        self._db.close()
