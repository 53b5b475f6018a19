"""A probe of a process's event loop (issue 38, docs/station.md, "Round 11"): every callback
of the loop that runs longer than a threshold, and every full collection of the garbage
collector, written as a line to a file with its wall time, wall and CPU duration and what
it was. Started in a member by ``station_group_capacity.py --probe DIR``:

    python -c "import loop_probe; loop_probe.run_module('texsense.cli', PATH)" station ...

Diagnosis only: the station itself knows nothing of it.
"""

from __future__ import annotations

import asyncio.events
import cProfile
import gc
import os
import runpy
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

#: Callbacks at least this long are written, s.
THRESHOLD_S = 0.02


def _name(handle: Any) -> str:
    cb = getattr(handle, "_callback", None)
    text = repr(cb)
    task = getattr(cb, "__self__", None)
    coro = getattr(task, "get_coro", None)
    if callable(coro):  # a task's step: the coroutine's name and where it waits
        c = coro()
        frame = getattr(c, "cr_frame", None)
        where = f"{frame.f_code.co_filename}:{frame.f_lineno}" if frame is not None else ""
        text = f"task {getattr(c, '__qualname__', c)} at {where}"
    return text[:200]


def install(path: str, threshold_s: float = THRESHOLD_S) -> None:
    """Time every callback of every asyncio loop of this process; write the long ones and
    the full collections to ``path`` (one line each, tab-separated: wall start, kind, wall
    ms, CPU ms of the thread, what)."""
    out = open(path, "a", buffering=1)  # noqa: SIM115 - open for the process's life
    run = asyncio.events.Handle._run
    windows = _windows()
    first: list[float] = []  # when the first frame was handled (the inbox's first drain)
    profiles: dict[int, cProfile.Profile] = {}

    def profiled(self: Any, w0: float) -> None:
        """Profile the loop's callbacks in each window of LOOP_PROBE_PROFILE (seconds after
        the first frame), each written to ``path.<k>.prof``."""
        if not first:
            if "Inbox._drain" not in repr(getattr(self, "_callback", None)):
                return
            first.append(w0)
        since = w0 - first[0]
        for k, (a, b) in enumerate(windows):
            p = profiles.get(k)
            if p is None and a <= since < b:
                p = profiles[k] = cProfile.Profile()
                p.enable()
            elif p is not None and since >= b and p is not False:
                p.disable()
                p.dump_stats(f"{path}.{k}.prof")
                profiles[k] = False  # type: ignore[assignment]

    def timed(self: Any) -> None:
        w0, c0 = time.perf_counter(), time.thread_time()
        if not _inbox and "Inbox._drain" in repr(getattr(self, "_callback", None)):
            _inbox.append(self._callback.__self__)
        if windows:
            profiled(self, w0)
        try:
            run(self)
        finally:
            wall = time.perf_counter() - w0
            if wall >= threshold_s:
                cpu = time.thread_time() - c0
                out.write(f"{time.time() - wall:.3f}\tcallback\t{1e3 * wall:.1f}\t"
                          f"{1e3 * cpu:.1f}\t{_name(self)}\n")  # fmt: skip

    asyncio.events.Handle._run = timed  # type: ignore[method-assign]
    started: dict[str, float] = {}

    def collected(phase: str, info: dict[str, Any]) -> None:
        if info.get("generation") != 2:
            return
        if phase == "start":
            started["t"] = time.perf_counter()
            return
        wall = time.perf_counter() - started.get("t", time.perf_counter())
        out.write(
            f"{time.time() - wall:.3f}\tgc2\t{1e3 * wall:.1f}\t\t"
            f"{info.get('collected')} collected\n"
        )

    gc.callbacks.append(collected)
    if os.environ.get("LOOP_PROBE_WATCH", "1") != "0":
        threading.Thread(target=_watch, args=(out,), name="loop-probe-watch", daemon=True).start()


#: The member's inbox, once its first drain has run (the watcher reads its waiting messages).
_inbox: list[Any] = []
#: A stall: the inbox's oldest waiting message this old, s (the watcher writes a line).
STALL_S = 0.15
#: The watcher's period, s, and the window its lines sum the threads' CPU over, s.
WATCH_S, WINDOW_S = 0.02, 0.5
#: Every this many s the watcher writes each thread's CPU since its last such line (``threads``).
EVERY_S = 5.0


def _threads_cpu() -> dict[str, float]:
    """CPU seconds of each thread of this process (from /proc), by thread name."""
    names = {t.native_id: t.name for t in threading.enumerate()}
    out: dict[str, float] = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            stat = Path(f"/proc/self/task/{tid}/stat").read_text()
        except OSError:
            continue
        f = stat.rsplit(")", 1)[1].split()
        name = names.get(int(tid), tid)
        out[name] = out.get(name, 0.0) + (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")
    return out


def _machine_busy() -> tuple[float, float]:
    """The machine's (busy, all) CPU seconds since boot, every core's."""
    f = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    tick = os.sysconf("SC_CLK_TCK")
    return (sum(f) - f[3] - f[4]) / tick, sum(f) / tick


def _shares(before: dict[str, float], after: dict[str, float], span: float) -> str:
    """Each thread's CPU between two readings ``span`` s apart, % of a core."""
    return " ".join(f"{k}={100 * (after[k] - before.get(k, 0.0)) / span:.0f}%"
                    for k in sorted(after) if after[k] - before.get(k, 0.0) > 0)  # fmt: skip


def _oldest(inbox: Any, now: float) -> tuple[float, int]:
    with inbox._lock:
        age = max((now - q[0][1] for q in inbox.pending.values() if q), default=0.0)
        return age, inbox.waiting


def _stack(ident: int | None, depth: int = 4) -> str:
    frame = sys._current_frames().get(ident) if ident is not None else None
    parts = []
    while frame is not None and len(parts) < depth:
        parts.append(f"{os.path.basename(frame.f_code.co_filename)}:{frame.f_lineno}"
                     f":{frame.f_code.co_name}")  # fmt: skip
        frame = frame.f_back
    return "<".join(parts)


def _watch(out: Any) -> None:
    """Every WATCH_S: the inbox's oldest message's age; while it is over STALL_S, a line
    (kind ``stall``): its age, messages waiting, the watcher's own lateness (the GIL or the
    machine), pages being served, the CPU of each thread and of the machine (both cores) over
    the last WINDOW_S, and where the loop's thread is; every EVERY_S a line (kind
    ``threads``) of each thread's CPU since the last."""
    main = threading.main_thread().ident
    ring: deque[tuple[float, dict[str, float], tuple[float, float]]] = deque()
    late_max: deque[tuple[float, float]] = deque()
    every: list[Any] = [time.monotonic(), _threads_cpu(), _machine_busy()]
    while True:
        t0 = time.monotonic()
        time.sleep(WATCH_S)
        now_m = time.monotonic()
        late = now_m - t0 - WATCH_S
        late_max.append((now_m, late))
        ring.append((now_m, _threads_cpu(), _machine_busy()))
        while ring and now_m - ring[0][0] > WINDOW_S:
            ring.popleft()
        while late_max and now_m - late_max[0][0] > WINDOW_S:
            late_max.popleft()
        if not _inbox:
            continue
        inbox = _inbox[0]
        age, waiting = _oldest(inbox, time.time())
        if now_m - every[0] >= EVERY_S:  # the threads' CPU since the last such line
            cpu, machine = ring[-1][1], ring[-1][2]
            span = max(now_m - every[0], 1e-3)
            out.write(f"{time.time():.3f}\tthreads\t{1e3 * age:.0f}\t{waiting}\t"
                      f"machine={100 * (machine[0] - every[2][0]) / span:.0f}% "
                      f"{_shares(every[1], cpu, span)}\n")  # fmt: skip
            every[:] = [now_m, cpu, machine]
        if age < STALL_S or len(ring) < 2:
            continue
        (ta, ca, ma), (tb, cb, mb) = ring[0], ring[-1]
        span = max(tb - ta, 1e-3)
        threads = _shares(ca, cb, span)
        station = getattr(getattr(inbox, "defer", None), "__self__", None)
        serving = getattr(station, "serving", "?")
        grace = time.monotonic() - getattr(station, "served_at", -1e9)
        deferred = inbox._deferred is not None
        out.write(f"{time.time():.3f}\tstall\t{1e3 * age:.0f}\t{waiting}\t"
                  f"late={1e3 * late:.0f}ms max={1e3 * max(v for _, v in late_max):.0f}ms "
                  f"serving={serving} since_served={grace:.2f}s deferred={deferred} "
                  f"machine={100 * (mb[0] - ma[0]) / span:.0f}% threads: {threads} "
                  f"loop at {_stack(main)}\n")  # fmt: skip


def _windows() -> list[tuple[float, float]]:
    """LOOP_PROBE_PROFILE: ``a-b,c-d`` seconds after the first frame."""
    text = os.environ.get("LOOP_PROBE_PROFILE", "")
    return [(float(a), float(b)) for a, b in (w.split("-") for w in text.split(",") if w)]


def run_module(module: str, path: str) -> None:
    """Install the probe, then run ``module`` as ``python -m`` would (its arguments are
    ``sys.argv[1:]``)."""
    install(path)
    runpy.run_module(module, run_name="__main__", alter_sys=True)
