"""What the ward WebSocket sends (docs/station.md, "The ward page's feed"): each mat as a tile
with its pressure map downsampled and quantised, and to each viewer only the tiles that
changed since it last heard, at most :data:`TICK_S` apart and within a byte budget.

A 600-mat ward at one frame a second would otherwise send every mat's full map five times a
second to every viewer: tens of megabytes a second each.

- :class:`BlockMap` turns a mat's pressure map into a grid of at most :data:`MAX_SIDE` x
  :data:`MAX_SIDE` blocks (the highest reading of each block: peaks matter for pressure
  injuries), one byte each: the pressure in mmHg, 0-250 (the ward draws 0-100 mmHg), base64:
  344 characters for a 32 x 32 mat, 324 for a 64 x 32 bed.
- :class:`WardFeed` is one viewer's feed. The first message has ``reset: true``; every
  message carries the broker's state and the tiles of the mats whose ``revision`` changed since
  this viewer got them, the most urgent first, as many as the viewer's byte budget allows
  (the rest follow in the next messages; a slow viewer just gets fewer, fresher messages).
  Nothing changed: one small message a second, so the page knows the station is there.

Examples
--------
>>> import numpy as np
>>> from texsense.data.layout import Layout
>>> blocks = BlockMap(Layout.grid(64, 32))
>>> (blocks.rows, blocks.cols)
(22, 11)
>>> tile = blocks.encode(np.full(2048, 1.0))          # N/cm²: 75 mmHg
>>> tile["rows"], tile["cols"], tile["unit"], len(tile["b64"])
(22, 11, 'mmHg', 324)
>>> base64.b64decode(tile["b64"])[0]
75
"""

from __future__ import annotations

import asyncio
import base64
import json
import math
import time
from typing import Any

import numpy as np

from texsense.data.layout import Layout

__all__ = ["MAX_BYTES_PER_S", "MAX_SIDE", "TICK_S", "BlockMap", "WardFeed"]

#: A tile's map has at most this many blocks along each side.
MAX_SIDE = 24
#: Shortest time between two messages to one viewer, s.
TICK_S = 0.2
#: A viewer's byte budget, bytes per second (averaged over a second).
MAX_BYTES_PER_S = 600_000
#: A message at least this often, even when nothing changed, s.
HEARTBEAT_S = 1.0
#: Byte values of the map: 0..250 the block's highest reading in mmHg (250: 250 or more);
#: these two mean no reading (a failed element) and no element.
NO_READING, NO_ELEMENT = 254, 255
#: mmHg per N/cm² (texsense.data.units).
MMHG_PER_NCM2 = 75.00615


class BlockMap:
    """The downsampled, quantised map of a grid layout (None for a layout of points)."""

    def __init__(self, layout: Layout, max_side: int = MAX_SIDE) -> None:
        self.ok = layout.shape is not None and layout.cells is not None
        self.rows = self.cols = 0
        if not self.ok:
            return
        n_rows, n_cols = layout.shape  # type: ignore[misc]
        b = max(1, math.ceil(max(n_rows, n_cols) / max_side))
        self.rows, self.cols = math.ceil(n_rows / b), math.ceil(n_cols / b)
        r, c = np.divmod(np.asarray(layout.cells), n_cols)
        self.block = (r // b) * self.cols + c // b
        self.has = np.zeros(self.rows * self.cols, bool)
        self.has[self.block] = True
        # the elements sorted by block, where each block starts: one reduceat per map
        self._order = np.argsort(self.block, kind="stable")
        ordered = self.block[self._order]
        self._starts = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]])
        self._blocks = ordered[self._starts]

    def encode(self, pressure: np.ndarray) -> dict[str, Any] | None:
        """The map of ``pressure`` (N/cm², NaN where unknown): rows, cols, unit (mmHg) and
        the bytes in base64, row by row."""
        if not self.ok:
            return None
        v = np.asarray(pressure, dtype=np.float64)
        out = np.full(self.rows * self.cols, np.nan)
        with np.errstate(invalid="ignore"):
            out[self._blocks] = np.fmax.reduceat(v[self._order], self._starts)  # NaN: no reading
        read = np.isfinite(out)
        q = np.full(out.shape, NO_READING, np.uint8)
        q[read] = np.clip(np.round(out[read] * MMHG_PER_NCM2), 0, 250).astype(np.uint8)
        q[~self.has] = NO_ELEMENT
        b64 = base64.b64encode(q.tobytes()).decode()
        return {"rows": self.rows, "cols": self.cols, "unit": "mmHg", "b64": b64}


class WardFeed:
    """One ward viewer's messages (see the module docstring).

    Parameters
    ----------
    station : Station
        The ward.
    tick_s : float
        Shortest time between two messages.
    max_bytes_per_s : float
        The viewer's byte budget.
    """

    def __init__(
        self,
        station: Any,
        tick_s: float = TICK_S,
        max_bytes_per_s: float = MAX_BYTES_PER_S,
        heartbeat_s: float = HEARTBEAT_S,
    ) -> None:
        self.station = station
        self.tick_s, self.rate, self.heartbeat_s = tick_s, float(max_bytes_per_s), heartbeat_s
        self.sent: dict[str, int] = {}  # mat id -> revision this viewer has
        self.sent_at: dict[str, float] = {}
        self.reset = True
        self.credit = self.rate  # the first message may fill a second's budget
        self.last: float | None = None  # when the last message went out (monotonic s)
        self.last_header: str | None = None
        self.bytes = 0
        self.messages = 0

    def message(self, now: float | None = None) -> str | None:
        """The next message, or None when there is nothing to say yet."""
        now = time.monotonic() if now is None else now
        elapsed = self.tick_s if self.last is None else max(now - self.last, 0.0)
        self.credit = min(self.rate, self.credit + self.rate * elapsed)
        header = json.dumps(self.station.header(), separators=(",", ":"))
        changed = [e for e in self.station.mats.values() if self.sent.get(e.id) != e.revision]
        quiet = not changed and header == self.last_header
        if quiet and elapsed < self.heartbeat_s:
            return None
        changed.sort(key=lambda e: (-e.view_state()[1], self.sent_at.get(e.id, 0.0)))
        tiles: list[str] = []
        size = len(header) + 64
        for e in changed:
            text = e.tile()
            if size + len(text) > self.credit and (tiles or self.credit <= 0):
                break  # the rest in the next messages
            tiles.append(text)
            size += len(text) + 1
            self.sent[e.id], self.sent_at[e.id] = e.revision, now
        reset = "true" if self.reset else "false"
        body = (f'{{"type":"ward","reset":{reset},"wall":{time.time():.3f},'
                f'"header":{header},"mats":[{",".join(tiles)}]}}')  # fmt: skip
        self.reset, self.last, self.last_header = False, now, header
        self.credit -= len(body)
        self.bytes += len(body)
        self.messages += 1
        return body

    async def next(self) -> str:
        """Wait for the next message (at most one per ``tick_s``)."""
        while True:
            wait = 0.0 if self.last is None else self.last + self.tick_s - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
            text = self.message()
            if text is not None:
                return text
            await asyncio.sleep(self.tick_s)
