"""A real PostgreSQL server for the tests (Debian's postgresql: initdb and pg_ctl in a
temporary folder, as the postgres user when the tests run as root), which a test may stop and
start again on the same port."""

from __future__ import annotations

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


class PostgresServer:
    """A PostgreSQL server on loopback on a free port, database ``texsense``; ``url`` to
    connect. Its folder is outside pytest's (which only root may enter) so that the postgres
    user can own it."""

    def __init__(self) -> None:
        self.root = Path(tempfile.mkdtemp(prefix="texsense-pg-"))
        self.root.chmod(0o755)
        self.data, sock = self.root / "data", self.root / "sock"
        sock.mkdir()
        self.as_user: list[str] = []
        if os.geteuid() == 0:  # PostgreSQL refuses to run as root
            shutil.chown(self.root, "postgres")
            shutil.chown(sock, "postgres")
            self.as_user = ["runuser", "-u", "postgres", "--"]
        self.port = free_port()
        self.options = f"-p {self.port} -k {sock} -c listen_addresses=127.0.0.1"
        self._run(pg_bin("initdb"), "-D", str(self.data), "-U", "texsense", "--auth=trust",
                  "-E", "UTF8")  # fmt: skip
        self.start()
        self._run(pg_bin("createdb"), "-h", "127.0.0.1", "-p", str(self.port), "-U", "texsense",
                  "texsense")  # fmt: skip
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
