"""One timing helper for the benchmarks: the best of a few runs (the machine is shared)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any


def best_of(fn: Callable[..., Any], *args: Any, repeat: int = 3) -> tuple[float, Any]:
    """Run ``fn(*args)`` ``repeat`` times; return the shortest time (s) and the last result."""
    best, result = float("inf"), None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn(*args)
        best = min(best, time.perf_counter() - start)
    return best, result
