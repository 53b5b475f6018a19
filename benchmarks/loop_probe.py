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
import time
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


def _windows() -> list[tuple[float, float]]:
    """LOOP_PROBE_PROFILE: ``a-b,c-d`` seconds after the first frame."""
    text = os.environ.get("LOOP_PROBE_PROFILE", "")
    return [(float(a), float(b)) for a, b in (w.split("-") for w in text.split(",") if w)]


def run_module(module: str, path: str) -> None:
    """Install the probe, then run ``module`` as ``python -m`` would (its arguments are
    ``sys.argv[1:]``)."""
    install(path)
    runpy.run_module(module, run_name="__main__", alter_sys=True)
