"""A group of `texsense station` members as real processes, with a real PostgreSQL and a real
Mosquitto and `texsense simulate mats` publishing the virtual mats (docs/station.md, "A group
of stations"); shared by tests/faults/test_group.py and benchmarks/station_failover.py."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from typing import Any

import psycopg

from conftest import free_port
from postgres_server import PostgresServer
from texsense.station.broker import Broker


class NotReachedError(AssertionError):
    """A condition was not reached (with the members' logs)."""


class Cluster:
    """``members`` members of the group ``ward`` over ``mats`` virtual mats at ``speed``
    simulated seconds per second, in ``folder``. The members share one folder of the virtual
    mats' calibrations (``--virtual-calibrations``: the first member calibrates, ~5 s of a
    core, the others read its file). No beds by default (their side model is one more thing
    to train or read at the start). A mat is stale after 2 s without a frame at the least
    (``--stale-after 2``: at 4x two frame periods are 0.8 s, less than a loaded machine's
    hiccups). ``ready_s``: the members' READY_S (default: texsense's, 10 s), set in their
    processes by tests/group_ready/sitecustomize.py."""

    def __init__(self, folder: Path, members: list[str], mats: int, *, speed: float = 1.0,
                 reposition_min: float = 20.0, beds: int = 0,
                 extra: tuple[str, ...] = (), publish: bool = True,
                 ready_s: float | None = None) -> None:  # fmt: skip
        self.folder, self.mats, self.speed = folder, mats, speed
        self.env = {**os.environ, "TMPDIR": str(folder)}
        if ready_s is not None:
            here = str(Path(__file__).with_name("group_ready"))
            path = os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH")) if p)
            self.env.update(PYTHONPATH=path, TEXSENSE_TEST_READY_S=str(ready_s))
        self.extra = ("--reposition-min", str(reposition_min), "--virtual-beds", str(beds),
                      "--virtual-calibrations", str(folder / "calibrations"),
                      "--stale-after", "2", *extra)  # fmt: skip
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.ports: dict[str, int] = {}
        self.groups: dict[str, str] = {}
        self.pg = PostgresServer()
        self.broker = Broker()
        self.broker.start()
        self.broker_url = f"mqtt://127.0.0.1:{self.broker.port}"
        self.beds = beds
        self.publisher: subprocess.Popen[bytes] | None = None
        if publish:
            self.publish()
        for m in members:
            self.start(m)

    def publish(self, replay: bool = False, every: int = 1) -> None:
        """Start `texsense simulate mats` (``publish=False``: the stations can be started
        first, so that all of them read the mats from their first frame); ``replay``: the
        virtual seats' frames made once and replayed (tests/replay_mats.py, no beds), each
        mat's ``every``-th frame only."""
        if replay:
            with (self.folder / "simulate.log").open("ab") as out:
                self.publisher = subprocess.Popen(
                    [sys.executable, str(Path(__file__).with_name("replay_mats.py")),
                     str(self.broker.port), str(self.mats), str(self.speed), str(every)],
                    stdout=out, stderr=subprocess.STDOUT, cwd=self.folder)  # fmt: skip
            return
        self.publisher = self._spawn("simulate", ["simulate", "mats", "--count", str(self.mats),
                                                  "--broker", self.broker_url,
                                                  "--speed", str(self.speed),
                                                  "--beds", str(self.beds)])  # fmt: skip

    def _spawn(self, name: str, args: list[str]) -> subprocess.Popen[bytes]:
        with (self.folder / f"{name}.log").open("ab") as out:
            return subprocess.Popen([sys.executable, "-m", "texsense.cli", *args], stdout=out,
                                    stderr=subprocess.STDOUT, cwd=self.folder,
                                    env=self.env)  # fmt: skip

    # ---------------------------------------------------------------- members
    def database(self, name: str) -> str:
        """A database ``name`` of its own on the server (for a second group)."""
        with psycopg.connect(self.pg.url, autocommit=True) as c:
            c.execute(f"CREATE DATABASE {name}")
        return self.pg.url.rsplit("/", 1)[0] + "/" + name

    def start(self, member: str, group: str = "ward", db: str | None = None) -> None:
        """Start ``member`` of ``group`` (again, on its port: its page stays where it was)."""
        port = self.ports.setdefault(member, free_port())
        self.groups[member] = group
        self.procs[member] = self._spawn(member, [
            "station", "--group", group, "--member", member, "--broker", self.broker_url,
            "--db", db or self.pg.url, "--virtual-mats", str(self.mats), "--speed", str(self.speed),
            "--port", str(port), "--record-dir", f"rec-{member}", *self.extra])  # fmt: skip

    def cpu(self, name: str, proc: subprocess.Popen[bytes]) -> None:
        """Note the CPU time a process has used so far (user + system, s) in ``cpu.txt`` of
        the folder (what each part of a run costs)."""
        with contextlib.suppress(OSError, IndexError, ValueError):
            fields = Path(f"/proc/{proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
            used = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
            with (self.folder / "cpu.txt").open("a") as out:
                out.write(f"{name} {used:.2f}\n")

    def kill(self, member: str) -> None:
        """SIGKILL ``member`` (no last word)."""
        proc = self.procs.pop(member)
        self.cpu(member, proc)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)

    def url(self, member: str) -> str:
        return f"http://127.0.0.1:{self.ports[member]}/"

    def get(self, member: str, path: str) -> Any:
        with urllib.request.urlopen(self.url(member) + path, timeout=5) as r:
            return json.load(r)

    def mats_of(self, member: str) -> dict[str, dict[str, Any]]:
        """``GET /api/mats`` of ``member``: every mat of the group by id."""
        return {m["id"]: m for m in self.get(member, "api/mats")}

    def until(self, what: Any, cond: Any, timeout: float, step: float = 0.25) -> Any:
        """Poll ``what()`` until ``cond(value)``; :class:`NotReachedError` with the logs
        otherwise."""
        deadline = time.monotonic() + timeout
        value = None
        while True:
            for name, proc in self.procs.items():
                if proc.poll() is not None:
                    raise NotReachedError(f"member {name} exited:\n{self.log(name)[-3000:]}")
            with contextlib.suppress(OSError, KeyError, ValueError):
                value = what()
                if cond(value):
                    return value
            if time.monotonic() > deadline:
                logs = "\n".join(f"--- {n}\n{self.log(n)[-1500:]}" for n in self.procs)
                raise NotReachedError(
                    f"not reached in {timeout} s (last: {str(value)[:800]}):\n{logs}"
                )
            time.sleep(step)

    def all_held(
        self, member: str, alive: set[str] | None = None, timeout: float = 60.0
    ) -> dict[str, dict[str, Any]]:
        """Until every mat is held (by a member of ``alive``, default: the running members of
        ``member``'s group) and live, as ``member`` sees it."""
        alive = alive or {m for m in self.procs if self.groups[m] == self.groups[member]}

        def ok(mats: dict[str, dict[str, Any]]) -> bool:
            return len(mats) == self.mats and all(
                m.get("holder") in alive and m["state"] not in ("stale", "unwatched", "waiting")
                for m in mats.values())  # fmt: skip

        return dict(self.until(lambda: self.mats_of(member), ok, timeout))

    def log(self, name: str) -> str:
        path = self.folder / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def close(self) -> None:
        procs = [*self.procs.values(), *([self.publisher] if self.publisher else [])]
        for name, proc in [*self.procs.items(), ("publisher", self.publisher)]:
            if proc is not None:
                self.cpu(name, proc)
        for proc in procs:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(signal.SIGTERM)
        for proc in procs:
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
        self.broker.stop()
        self.pg.close()
