"""A real PostgreSQL server for the tests (Debian's postgresql: initdb and pg_ctl in a
temporary folder, as the postgres user when the tests run as root), which a test may stop and
start again on the same port. One cluster is made per test process (initdb, the database
``texsense``) and copied for each server: initdb took 5.2 s of wall time, a copy takes
~0.1 s. The servers run without fsync (``-N``, ``fsync=off``): a stop, even ``immediate``,
keeps what was written; only a crash of the machine would lose it, which no test makes."""

from __future__ import annotations

import atexit
import glob
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

from conftest import free_port


def pg_bin(name: str) -> str:
    """A server program of the newest PostgreSQL installed (Debian's layout first)."""
    for path in [*sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"), reverse=True),
                 shutil.which(name)]:  # fmt: skip
        if path and os.access(path, os.X_OK):
            return path
    pytest.fail(f"no PostgreSQL {name}: install Debian's postgresql (scripts/test.sh does)")


_TEMPLATE: list[Path] = []  # the cluster copied by every server of this process


def _as_postgres(path: Path) -> list[str]:
    """``runuser -u postgres --`` when the tests run as root (PostgreSQL refuses root), and
    ``path`` given to that user."""
    if os.geteuid() != 0:
        return []
    shutil.chown(path, "postgres")
    return ["runuser", "-u", "postgres", "--"]


def template() -> Path:
    """The data folder of a stopped cluster with the database ``texsense``, made once."""
    if _TEMPLATE:
        return _TEMPLATE[0]
    root = Path(tempfile.mkdtemp(prefix="texsense-pgtemplate-"))
    root.chmod(0o755)
    atexit.register(shutil.rmtree, root, True)
    sock = root / "sock"
    sock.mkdir()
    as_user = _as_postgres(root)
    _as_postgres(sock)
    data, port = root / "data", free_port()

    def run(*cmd: str) -> None:
        subprocess.run([*as_user, *cmd], check=True, capture_output=True)

    run(pg_bin("initdb"), "-D", str(data), "-U", "texsense", "--auth=trust", "-E", "UTF8", "-N")
    run(pg_bin("pg_ctl"), "-D", str(data), "-l", str(root / "pg.log"), "-w", "-o",
        f"-p {port} -k {sock} -c listen_addresses=127.0.0.1 -c fsync=off", "start")  # fmt: skip
    try:
        run(pg_bin("createdb"), "-h", "127.0.0.1", "-p", str(port), "-U", "texsense", "texsense")
    finally:
        run(pg_bin("pg_ctl"), "-D", str(data), "-m", "fast", "-w", "stop")
    _TEMPLATE.append(data)
    return data


class PostgresServer:
    """A PostgreSQL server on loopback on a free port, database ``texsense``; ``url`` to
    connect. Its folder is outside pytest's (which only root may enter) so that the postgres
    user can own it."""

    def __init__(self) -> None:
        self.root = Path(tempfile.mkdtemp(prefix="texsense-pg-"))
        self.root.chmod(0o755)
        self.data, sock = self.root / "data", self.root / "sock"
        sock.mkdir()
        self.as_user = _as_postgres(self.root)
        _as_postgres(sock)
        self.port = free_port()
        self.options = f"-p {self.port} -k {sock} -c listen_addresses=127.0.0.1 -c fsync=off"
        self._run("cp", "-a", str(template()), str(self.data))
        self.start()
        self.url = f"postgresql://texsense@127.0.0.1:{self.port}/texsense"

    def _run(self, *cmd: str) -> None:
        subprocess.run([*self.as_user, *cmd], check=True, capture_output=True)

    def start(self) -> None:
        """Start (again, on the same port)."""
        self._run(pg_bin("pg_ctl"), "-D", str(self.data), "-l", str(self.root / "pg.log"), "-w",
                  "-o", self.options, "start")  # fmt: skip

    def stop(self, mode: str = "fast") -> None:
        """Stop (``fast``: the clients' connections are closed; ``immediate``: as a crash)."""
        self._run(pg_bin("pg_ctl"), "-D", str(self.data), "-m", mode, "-w", "stop")

    def close(self) -> None:
        """Stop and remove its folder."""
        try:
            self.stop()
        finally:
            shutil.rmtree(self.root, ignore_errors=True)
