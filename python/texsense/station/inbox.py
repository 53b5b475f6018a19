"""The station's inbox (docs/station.md, "Faults"): messages that arrive on MQTT's network
thread wait here and are handled on the event loop in slices of at most :data:`SLICE_S`, so
that a page request or a WebSocket message is never queued behind a second's worth of frames
(issue 33: the ward page waited for 20 mats at 10x).

A station that cannot keep up stays current instead of falling ever further behind: a message
that has waited longer than :data:`MAX_WAIT_S` is skipped when a newer one of the same topic
waits behind it (only its time is read, which keeps the mat's clock in step; counted per mat
as ``behind``), so what the ward shows is never much older than that. (Without it, 20 virtual
mats at 10x on a shared 2-core machine put the station 50 s behind after two minutes, growing
by 0.6 s every second, and every mat was called silent while its frames waited.) The exposure
is integrated over the frames' own times, so a skipped frame costs resolution, not minutes
above the threshold; a mat being recorded keeps every frame (``skip`` says no). A full inbox
(:data:`INBOX_MAX`) drops its oldest messages, counted and logged.

The station judges a mat's silence on the time line of what it has read
(:meth:`Inbox.read_until`): frames waiting in the inbox are not silence.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections import deque
from collections.abc import Callable

from texsense.monitor.clock import Quiet

__all__ = ["INBOX_MAX", "MAX_WAIT_S", "SLICE_S", "Inbox"]

#: The longest the station handles messages before the event loop serves pages again, s.
SLICE_S = 0.02
#: A message that waited longer than this is skipped when a newer one of its topic waits, s.
MAX_WAIT_S = 1.0
#: Messages waiting at most (beyond: the oldest are dropped, counted and logged).
INBOX_MAX = 20_000


class Inbox:
    """Messages (topic, payload, arrival wall time) from another thread to ``handle`` on
    ``loop``, in slices of at most ``slice_s``; a message older than ``max_wait_s`` with a
    newer one of its topic waiting goes to ``skip`` (topic, payload, arrival) instead, which
    says whether it skipped it (False: it is handled after all)."""

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        handle: Callable[[str, bytes, float], None],
        quiet: Quiet,
        *,
        skip: Callable[[str, bytes, float], bool] | None = None,
        slice_s: float = SLICE_S,
        max_wait_s: float = MAX_WAIT_S,
        size: int = INBOX_MAX,
    ) -> None:
        self.loop, self.handle, self.skip, self.quiet = loop, handle, skip, quiet
        self.slice_s, self.max_wait_s, self.size = slice_s, max_wait_s, size
        self.waiting: deque[tuple[str, bytes, float]] = deque()
        self.per_topic: dict[str, int] = {}  # topic -> messages of it waiting
        self.dropped = 0
        self.skipped = 0
        self._lock = threading.Lock()
        self._draining = False

    def put(self, topic: str, payload: bytes) -> None:
        """(Any thread.) Keep a message, and tell the loop once to drain."""
        with self._lock:
            if len(self.waiting) >= self.size:
                self._forget(self.waiting.popleft()[0])
                self.dropped += 1
                why = "the machine does not keep up with the mats: the oldest messages are dropped"
                self.quiet.warn("station", "behind", why)
            self.waiting.append((topic, payload, time.time()))
            self.per_topic[topic] = self.per_topic.get(topic, 0) + 1
            if self._draining:
                return
            self._draining = True
        with contextlib.suppress(RuntimeError):  # the loop has closed: the station stops
            self.loop.call_soon_threadsafe(self._drain)

    def _forget(self, topic: str) -> int:
        """(Under the lock.) One message of ``topic`` left the inbox: how many still wait."""
        left = self.per_topic[topic] - 1
        if left:
            self.per_topic[topic] = left
        else:
            del self.per_topic[topic]
        return left

    def read_until(self, now: float) -> float:
        """The wall time up to which every message that arrived has been read (handled or
        skipped): ``now`` when nothing waits, else the arrival of the oldest waiting one."""
        with self._lock:
            return self.waiting[0][2] if self.waiting else now

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
                newer = self._forget(topic)
            late = newer and time.time() - arrived > self.max_wait_s
            if late and self.skip is not None and self.skip(topic, payload, arrived):
                self.skipped += 1
                continue
            self.handle(topic, payload, arrived)
        self.loop.call_soon(self._drain)
