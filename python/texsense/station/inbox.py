"""The station's inbox (docs/station.md, "Faults"): messages that arrive on MQTT's network
thread wait here and are handled on the event loop in slices of at most :data:`SLICE_S`, so
that a page request or a WebSocket message is never queued behind a second's worth of frames
(issue 33: the ward page waited for 20 mats at 10x); a full inbox drops its oldest messages,
counted and logged.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections import deque
from collections.abc import Callable

from texsense.monitor.clock import Quiet

__all__ = ["INBOX_MAX", "SLICE_S", "Inbox"]

#: The longest the station handles messages before the event loop serves pages again, s.
SLICE_S = 0.02
#: Messages waiting at most (beyond: the oldest are dropped, counted and logged).
INBOX_MAX = 20_000


class Inbox:
    """Messages (topic, payload, arrival wall time) from another thread to ``handle`` on
    ``loop``, in slices of at most ``slice_s``."""

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        handle: Callable[[str, bytes, float], None],
        quiet: Quiet,
        *,
        slice_s: float = SLICE_S,
        size: int = INBOX_MAX,
    ) -> None:
        self.loop, self.handle, self.quiet = loop, handle, quiet
        self.slice_s, self.size = slice_s, size
        self.waiting: deque[tuple[str, bytes, float]] = deque()
        self.dropped = 0
        self._lock = threading.Lock()
        self._draining = False

    def put(self, topic: str, payload: bytes) -> None:
        """(Any thread.) Keep a message, and tell the loop once to drain."""
        with self._lock:
            if len(self.waiting) >= self.size:
                self.waiting.popleft()
                self.dropped += 1
                why = "the machine does not keep up with the mats: the oldest messages are dropped"
                self.quiet.warn("station", "behind", why)
            self.waiting.append((topic, payload, time.time()))
            if self._draining:
                return
            self._draining = True
        with contextlib.suppress(RuntimeError):  # the loop has closed: the station stops
            self.loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        """(The loop.) Handle waiting messages for at most ``slice_s``, then let the loop
        serve the pages before the next slice."""
        deadline = time.monotonic() + self.slice_s
        while time.monotonic() < deadline:
            with self._lock:
                if not self.waiting:
                    self._draining = False
                    return
                topic, payload, arrived = self.waiting.popleft()
            self.handle(topic, payload, arrived)
        self.loop.call_soon(self._drain)
