"""The event store on a real PostgreSQL server started by the test (Debian's postgresql: initdb
and pg_ctl in a temporary folder, as the postgres user when the tests run as root), and the
station writing its events there."""

from __future__ import annotations

import glob
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import pytest

from conftest import free_port
from texsense.apps.alerts import Event
from texsense.monitor.store import PostgresEventStore, open_store


def _pg_bin(name: str) -> str:
    """A server program of the newest PostgreSQL installed (Debian's layout first)."""
    for path in [*sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"), reverse=True),
                 shutil.which(name)]:  # fmt: skip
        if path and os.access(path, os.X_OK):
            return path
    pytest.fail(f"no PostgreSQL {name}: install Debian's postgresql (scripts/test.sh does)")


@pytest.fixture(scope="module")
def postgres():
    """A PostgreSQL server on loopback on a free port; yields its URL (database texsense).
    Its folder is outside pytest's (which only root may enter) so that the postgres user can
    own it."""
    root = Path(tempfile.mkdtemp(prefix="texsense-pg-"))
    root.chmod(0o755)
    data, sock = root / "data", root / "sock"
    sock.mkdir()
    as_user: list[str] = []
    if os.geteuid() == 0:  # PostgreSQL refuses to run as root
        shutil.chown(root, "postgres")
        shutil.chown(sock, "postgres")
        as_user = ["runuser", "-u", "postgres", "--"]
    port = free_port()
    run = lambda *cmd: subprocess.run([*as_user, *cmd], check=True, capture_output=True)  # noqa: E731
    run(_pg_bin("initdb"), "-D", str(data), "-U", "texsense", "--auth=trust", "-E", "UTF8")
    run(_pg_bin("pg_ctl"), "-D", str(data), "-l", str(root / "pg.log"), "-w", "-o",
        f"-p {port} -k {sock} -c listen_addresses=127.0.0.1", "start")  # fmt: skip
    try:
        run(_pg_bin("createdb"), "-h", "127.0.0.1", "-p", str(port), "-U", "texsense", "texsense")
        yield f"postgresql://texsense@127.0.0.1:{port}/texsense"
    finally:
        run(_pg_bin("pg_ctl"), "-D", str(data), "-m", "fast", "-w", "stop")
        shutil.rmtree(root, ignore_errors=True)


def test_the_store_round_trips_sessions_and_events(postgres):
    store = open_store(postgres)
    assert isinstance(store, PostgresEventStore)
    sid = store.start_session("mat bed1 (mqtt)")
    first = store.add_event(sid, Event("reposition", 1200.0, 1, {"where": ["17"]}))
    second = store.add_event(sid, Event("stale", 1300.5, None, {"mat": "bed1"}))
    assert second > first > 0
    store.set_recording(sid, ["a.h5"])
    store.set_recording(sid, ["b.h5"])
    store.end_session(sid)
    again = open_store(postgres)  # another connection sees the committed rows
    events = again.events(session=sid)
    assert [(e["kind"], e["detail"]) for e in events] == [
        ("stale", {"mat": "bed1"}), ("reposition", {"where": ["17"]}),
    ]  # fmt: skip
    assert again.events(kind="reposition")[0]["alert"] == 1
    session = next(s for s in again.sessions() if s["id"] == sid)
    assert session["recordings"] == ["a.h5", "b.h5"] and session["ended"] is not None
    store.close()
    again.close()


def test_a_wrong_server_is_a_clear_error():
    port = free_port()
    with pytest.raises(ValueError, match=f"cannot connect to PostgreSQL at 127.0.0.1:{port}"):
        open_store(f"postgresql://someone:secret@127.0.0.1:{port}/none")


def test_the_station_stores_its_events_in_postgresql(postgres, tmp_path):
    from test_station import Publisher, StationProcess, ward_file

    from texsense.station.broker import Broker

    with Broker() as broker:
        url = f"mqtt://127.0.0.1:{broker.port}"
        st = StationProcess(tmp_path, "--config", str(ward_file(tmp_path, "bed7")),
                            "--broker", url, "--db", postgres)  # fmt: skip
        try:
            st.until(lambda: st.get("api/ward")["connected"], bool)
            pub = Publisher(broker)
            for k in range(6):
                pub.frame("bed7", k, [0.3] * 16)
                time.sleep(0.1)
            pub.close()
            st.until(st.mats, lambda m: m["bed7"]["state"] == "stale", 10)
        finally:
            st.stop()
    store = open_store(postgres)
    kinds = [e["kind"] for e in store.events()]
    assert "stale" in kinds
    assert any(s["source"].startswith("mat bed7") for s in store.sessions())
    store.close()
    assert not (tmp_path / "station.sqlite").exists()  # nothing went to SQLite (the default)
