"""One timing helper for the benchmarks: the best of a few runs (the machine is shared)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any


def best_of(
    fn: Callable[..., Any],
    *args: Any,
    repeat: int = 3,
    clock: Callable[[], float] = time.perf_counter,
) -> tuple[float, Any]:
    """Run ``fn(*args)`` ``repeat`` times; return the shortest time (s, by ``clock``: wall
    time, or ``time.process_time`` for CPU time) and the last result."""
    best, result = float("inf"), None
    for _ in range(repeat):
        start = clock()
        result = fn(*args)
        best = min(best, clock() - start)
    return best, result
