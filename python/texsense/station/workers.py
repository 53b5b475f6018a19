"""One member of a group in worker processes (``texsense station --group G --workers N``,
issue 38; docs/station.md, "A member on more than one core").

Every thread of a station shares one interpreter lock: a member gets at most one core,
however many the machine has (at 1,000 mats of 1024 elements at 1 Hz it needed ~0.9 of one
on a 2-core machine beside the publisher, and fell behind at the first stall). With
``--workers N`` the command is a supervisor of N processes, each a member of the group in
its own right (:class:`~texsense.station.group.GroupStation`), named ``MEMBER.wK`` and
serving its pages on ``PORT + K``: PostgreSQL's leases split the mats over them as over any
members (rendezvous hashing), each worker subscribes to the frames of the mats it holds (the
broker routes: a mat's frames reach one worker, in order), checkpoints them, and its ward
page shows every mat of the group. What the workers do not share they need not: no frames,
no state, no events pass between them but through the broker and PostgreSQL, as between
members; the checkpoints' budget (:data:`~texsense.station.group.CHECKPOINTS_PER_S`) is
split between them, so N workers write as many checkpoints a second as one member.

A worker that dies is never silent: the supervisor says so on stderr and starts it again
(:data:`RESTART_S` later); meanwhile its mats are taken over by the other members of the
group — its sibling workers first of all — from their checkpoints, as when any member dies,
and the restarted worker gets its share back once it has beaten for
:data:`~texsense.station.lease.READY_S`. A worker that fails at its start (an error, not a
signal) stops the whole member with its exit code, as does one that dies
:data:`QUICK_DEATHS` times in a row within :data:`QUICK_S` of its start. A worker whose
supervisor is gone (SIGKILL) stops by itself (SIGTERM to itself within
:data:`PARENT_CHECK_S`: its mats are handed on, not left).
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

__all__ = [
    "PARENT_CHECK_S",
    "QUICK_DEATHS",
    "QUICK_S",
    "RESTART_S",
    "WORKER_ENV",
    "Supervisor",
    "Worker",
    "watch_parent",
    "worker_env",
    "worker_name",
]

log = logging.getLogger("texsense.station")

#: The environment variable that makes a ``texsense station`` a worker: ``K:N:PARENT_PID``.
WORKER_ENV = "TEXSENSE_STATION_WORKER"
#: A dead worker is started again this long after, s.
RESTART_S = 1.0
#: A worker that ends within this long of its start ...
QUICK_S = 30.0
#: ... this many times in a row stops the member (it would only die again).
QUICK_DEATHS = 3
#: A worker looks whether its supervisor is still there this often, s.
PARENT_CHECK_S = 0.5
#: The supervisor waits this long for its workers to hand their mats on at a stop, s.
STOP_WAIT_S = 30.0


@dataclass(frozen=True)
class Worker:
    """Which worker a station process is: ``index`` of ``count``, under ``parent``."""

    index: int
    count: int
    parent: int


def worker_env(environ: dict[str, str] | None = None) -> Worker | None:
    """The worker this process is (from :data:`WORKER_ENV`), or None: not a worker."""
    text = (os.environ if environ is None else environ).get(WORKER_ENV)
    if not text:
        return None
    try:
        k, n, parent = (int(v) for v in text.split(":"))
    except ValueError:
        raise ValueError(f"${WORKER_ENV} must be K:N:PARENT_PID, got {text!r}") from None
    if not 0 <= k < n:
        raise ValueError(f"${WORKER_ENV}: worker {k} of {n} does not exist")
    return Worker(k, n, parent)


def worker_name(member: str, index: int) -> str:
    """The group member name of a member's worker ``index``."""
    return f"{member}.w{index}"


def watch_parent(parent: int, every_s: float = PARENT_CHECK_S) -> threading.Thread:
    """Stop this process (SIGTERM to itself: the clean stop, mats handed on) once its
    supervisor ``parent`` is gone (it is then a child of another process)."""

    def look() -> None:
        while os.getppid() == parent:
            time.sleep(every_s)
        log.error("the station's supervisor (pid %d) is gone: this worker stops", parent)
        os.kill(os.getpid(), signal.SIGTERM)

    thread = threading.Thread(target=look, name="texsense-worker-parent", daemon=True)
    thread.start()
    return thread


class Supervisor:
    """Run ``count`` workers of ``command`` (the station's own command line, each started
    with :data:`WORKER_ENV` set) until SIGTERM or Ctrl-C; restart a worker that dies (see
    the module). ``say``: where its lines go (stderr)."""

    def __init__(
        self,
        command: Sequence[str],
        count: int,
        *,
        restart_s: float = RESTART_S,
        say: Callable[[str], None] | None = None,
    ) -> None:
        if count < 1:
            raise ValueError(f"a member needs at least one worker, got {count}")
        self.command, self.count, self.restart_s = list(command), count, restart_s
        self.say = say or (lambda text: print(text, file=sys.stderr, flush=True))
        self.procs: list[subprocess.Popen[bytes] | None] = [None] * count
        self.started = [0.0] * count
        self.quick = [0] * count  # deaths in a row soon after the start
        self.restarts = 0
        self._stop: int | None = None

    def _start(self, k: int) -> None:
        env = {**os.environ, WORKER_ENV: f"{k}:{self.count}:{os.getpid()}"}
        self.procs[k] = subprocess.Popen(self.command, env=env)
        self.started[k] = time.monotonic()

    def _signal(self, sig: int, _frame: object) -> None:
        self._stop = sig

    def run(self) -> int:
        """Supervise until stopped; the exit code (0 after a stop, or a failed worker's)."""
        previous = {s: signal.signal(s, self._signal) for s in (signal.SIGTERM, signal.SIGINT)}
        try:
            for k in range(self.count):
                self._start(k)
            code = self._watch()
        finally:
            self._stop_all()
            for s, h in previous.items():
                signal.signal(s, h)
        return code

    def _watch(self) -> int:
        """Look at the workers until a stop; the exit code."""
        while self._stop is None:
            for k, proc in enumerate(self.procs):
                code = None if proc is None else proc.poll()
                if code is None or self._stop is not None:
                    continue
                failed = self._ended(k, code)
                if failed is not None:
                    return failed
            time.sleep(0.1)
        return 0

    def _ended(self, k: int, code: int) -> int | None:
        """Worker ``k`` ended with ``code``: restart it, or the member's exit code."""
        proc = self.procs[k]
        pid = proc.pid if proc is not None else 0
        lived = time.monotonic() - self.started[k]
        how = f"signal {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
        quick = lived < QUICK_S
        self.quick[k] = self.quick[k] + 1 if quick else 0
        if (quick and code > 0) or self.quick[k] >= QUICK_DEATHS:
            self.say(f"texsense station: worker {k} (pid {pid}) ended with {how} "
                     f"{lived:.0f} s after its start: the member stops")  # fmt: skip
            return code if code > 0 else 1
        self.say(f"texsense station: worker {k} (pid {pid}) ended with {how} after "
                 f"{lived:.0f} s; its mats go on from their checkpoints at the group's other "
                 f"members, and it is started again")  # fmt: skip
        time.sleep(self.restart_s)
        if self._stop is None:
            self._start(k)
            self.restarts += 1
        return None

    def _stop_all(self) -> None:
        """SIGTERM to every worker (each hands its mats on), then SIGKILL after
        :data:`STOP_WAIT_S`."""
        live = [p for p in self.procs if p is not None and p.poll() is None]
        for p in live:
            p.terminate()
        deadline = time.monotonic() + STOP_WAIT_S
        for p in live:
            try:
                p.wait(max(deadline - time.monotonic(), 0.1))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
