"""The station's inbox (docs/station.md, "Faults"): messages that arrive on MQTT's network
thread wait here and are handled on the event loop in slices of at most :data:`SLICE_S`, so
that a page request or a WebSocket message is never queued behind a second's worth of frames
(issue 33: the ward page waited for 20 mats at 10x).

A station that cannot keep up stays current instead of falling ever further behind: the mats
are read in turn, and when a mat's next message has waited longer than :data:`MAX_WAIT_S`,
the messages behind it but the newest are skipped (the station follows them through the
pipeline and the exposure without a snapshot, or reads only their time when they waited
very long: :meth:`texsense.station.ward.Station.skip`; counted per mat as ``behind``) and the
newest is handled, so every mat's newest frame is read once a round. (Without it, 20 virtual
mats at 10x on a shared 2-core machine put the station 50 s behind after two minutes, growing
by 0.6 s every second, and every mat was called silent while its frames waited.) A mat being
recorded keeps every frame (``skip`` says no). A full inbox (:data:`INBOX_MAX`)
drops its oldest messages, counted and logged.

The loop's other work goes first too (a connection to accept, a request's bytes or its next
step, a viewer's message, a thread's result; :func:`io_waiting`): a slice ends after the
message at hand when there is some, and the next waits until the loop has done it (within
the same ``max_defer_s`` bounds). A request's first steps (accept, read, start), before it
counts as a page being served, waited for a slice each (issue 33: 0.25-0.52 s to the first
byte of the ward page under 20 mats at 10x, on a machine loaded by others as well).

Pages go first: while ``defer`` says a page request or a new viewer is being served, the
inbox waits (at most :data:`MAX_DEFER_S` at a time, and then it reads as long without waiting:
pages polled without a pause get at most half of the loop), since every step of a
request would otherwise wait behind a slice of at least one frame (issue 33: on a loaded
machine a bed frame takes 0.1-0.2 s, and opening the ward page takes a dozen such steps).

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

__all__ = ["INBOX_MAX", "MAX_DEFER_S", "MAX_WAIT_S", "SLICE_S", "Inbox", "io_waiting"]

#: The longest the station handles messages before the event loop serves pages again, s.
SLICE_S = 0.02
#: A message that waited longer than this is skipped when a newer one of its topic waits, s.
MAX_WAIT_S = 1.0
#: The longest the inbox waits for pages being served before it reads a slice anyway, s.
MAX_DEFER_S = 0.5
#: How often it looks again meanwhile, s.
DEFER_STEP_S = 0.005
#: Messages waiting at most (beyond: the oldest are dropped, counted and logged).
INBOX_MAX = 20_000


def io_waiting(loop: asyncio.AbstractEventLoop) -> Callable[[], bool]:
    """A check whether ``loop`` has other work waiting: callbacks ready to run (a request's
    next step, a viewer's message) or I/O ready (its selector polled without waiting; the
    selector is level-triggered, so the loop still sees it next). Both are asyncio's own
    selector loop's (``_ready``, ``_selector``); another loop says never: slices then end
    by time only."""
    ready = getattr(loop, "_ready", None)
    selector = getattr(loop, "_selector", None)
    if ready is None or selector is None or not callable(getattr(selector, "select", None)):
        return lambda: False
    return lambda: bool(ready) or bool(selector.select(0))


class Inbox:
    """Messages (topic, payload, arrival wall time) from another thread to ``handle`` on
    ``loop``, in slices of at most ``slice_s``: each topic's in order, the topics in turn (one
    message of each, round after round: a busy mat never holds the others back). When a
    topic's next message has waited longer than ``max_wait_s`` and newer ones wait behind it,
    all but the newest go to ``skip`` (topic, payload, arrival), which says whether it skipped
    it (False: it is handled after all), and the newest is handled: every mat's newest frame
    is read once a round, however far behind the station is. While ``defer()`` is true (pages
    are being served) or ``busy()`` (the loop has other work waiting: default
    :func:`io_waiting`) it waits, at most ``max_defer_s`` at a time; a slice ends early when
    ``busy()``, after at least one message."""

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        handle: Callable[[str, bytes, float], None],
        quiet: Quiet,
        *,
        skip: Callable[[str, bytes, float], bool] | None = None,
        defer: Callable[[], bool] | None = None,
        max_defer_s: float = MAX_DEFER_S,
        slice_s: float = SLICE_S,
        max_wait_s: float = MAX_WAIT_S,
        size: int = INBOX_MAX,
        busy: Callable[[], bool] | None = None,
    ) -> None:
        self.loop, self.handle, self.skip, self.quiet = loop, handle, skip, quiet
        self.busy = busy if busy is not None else io_waiting(loop)
        self.yielded = 0  # slices ended early for the loop's I/O
        self.slice_s, self.max_wait_s, self.size = slice_s, max_wait_s, size
        self.defer, self.max_defer_s = defer, max_defer_s
        self._deferred: float | None = None  # since when it has waited for pages
        self._reading_until = 0.0  # after a wait: no waiting again before this (monotonic s)
        self.pending: dict[str, deque[tuple[bytes, float]]] = {}  # topic -> (payload, arrival)
        self.turns: deque[str] = deque()  # the topics with messages, in turn
        self.waiting = 0  # messages waiting
        self.dropped = 0
        self.skipped = 0
        self._lock = threading.Lock()
        self._draining = False

    def put(self, topic: str, payload: bytes) -> None:
        """(Any thread.) Keep a message, and tell the loop once to drain."""
        with self._lock:
            if self.waiting >= self.size:
                self._drop_oldest()
            queue = self.pending.get(topic)
            if queue is None:
                queue = self.pending[topic] = deque()
                self.turns.append(topic)
            queue.append((payload, time.time()))
            self.waiting += 1
            if self._draining:
                return
            self._draining = True
        with contextlib.suppress(RuntimeError):  # the loop has closed: the station stops
            self.loop.call_soon_threadsafe(self._drain)

    def _drop_oldest(self) -> None:
        """(Under the lock.) The inbox is full: drop the next topic's oldest message."""
        topic = self.turns[0]
        queue = self.pending[topic]
        queue.popleft()
        if not queue:
            del self.pending[topic]
            self.turns.popleft()
        self.waiting -= 1
        self.dropped += 1
        why = "the machine does not keep up with the mats: the oldest messages are dropped"
        self.quiet.warn("station", "behind", why)

    def read_until(self, now: float) -> float:
        """The wall time up to which every message that arrived has been read (handled or
        skipped): ``now`` when nothing waits, else the arrival of the oldest waiting one."""
        with self._lock:
            return min((q[0][1] for q in self.pending.values()), default=now)

    def _take(self) -> tuple[str, list[tuple[bytes, float]]] | None:
        """(The loop.) The next topic's next message, or all of its messages when that one
        is late (then the topic's turn is over: nothing of it waits)."""
        with self._lock:
            if not self.turns:
                return None
            topic = self.turns.popleft()
            queue = self.pending[topic]
            if len(queue) > 1 and time.time() - queue[0][1] > self.max_wait_s:
                taken = list(queue)
                queue.clear()
            else:
                taken = [queue.popleft()]
            self.waiting -= len(taken)
            if queue:
                self.turns.append(topic)  # its next message in the next round
            else:
                del self.pending[topic]
            return topic, taken

    def _drain(self) -> None:
        """(The loop.) Handle waiting messages for at most ``slice_s``, then let the loop
        serve the pages before the next slice."""
        start = time.monotonic()
        if start >= self._reading_until:
            pages = self.defer is not None and self.defer()
            if pages or self.busy():  # pages being served, or the loop has other work
                self._deferred = self._deferred or start
                if start - self._deferred < self.max_defer_s:
                    # pages: look again shortly; other work: right after it
                    self.loop.call_later(DEFER_STEP_S if pages else 0.0, self._drain)
                    return
                self._reading_until = start + self.max_defer_s  # as long as it waited
        self._deferred = None
        deadline = start + self.slice_s
        first = True
        while first or time.monotonic() < deadline:
            if not first and self.busy():  # a request or a viewer: the loop first
                self.yielded += 1
                self.loop.call_later(0.0, self._drain)  # after the I/O and what waits
                return
            first = False
            took = self._take()
            if took is None:
                with self._lock:
                    if not self.turns:  # (a message may have come meanwhile)
                        self._draining = False
                        return
                continue
            topic, messages = took
            for k, (payload, arrived) in enumerate(messages[:-1]):  # late, newer ones behind
                if self.skip is None or not self.skip(topic, payload, arrived):
                    self.handle(topic, payload, arrived)  # kept (a recording): one a turn
                    self._put_back(topic, messages[k + 1 :])
                    break
                self.skipped += 1
            else:
                self.handle(topic, *messages[-1])
        self.loop.call_soon(self._drain)

    def _put_back(self, topic: str, messages: list[tuple[bytes, float]]) -> None:
        """(The loop.) Messages taken but not read: first in their topic's queue again."""
        with self._lock:
            queue = self.pending.get(topic)
            if queue is None:
                queue = self.pending[topic] = deque()
                self.turns.append(topic)
            queue.extendleft(reversed(messages))
            self.waiting += len(messages)
