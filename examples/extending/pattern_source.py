"""A new live source in one module: a test pattern (a load that moves across the mat).

``texsense monitor --source pattern`` shows it once the module is imported (saved inside
``texsense/monitor/`` and named in ``SOURCE_MODULES``, or imported by a plugin); the test
``tests/test_extending.py`` runs it through the contract every source keeps.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

import numpy as np

from texsense.data.layout import Layout
from texsense.data.protocol import Frame
from texsense.monitor.sources import Source, SourceOptions


class PatternSource(Source):
    """A 2 N/cm² square that moves one column a frame over a mat (``--grid``, default 8x8),
    ``--speed`` frames per second (0: as fast as possible)."""

    name = "test pattern"
    scheme = "pattern"  # --source pattern
    summary = "a load that moves across the mat (a test pattern)"
    reads = frozenset({"--grid", "--speed"})  # the source options it uses (others: refused)
    quantity, unit = "pressure", "N/cm2"

    @classmethod
    def from_option(cls, argument: str, options: SourceOptions) -> Source:
        """``pattern``, with ``--grid`` and ``--speed``."""
        return cls(options.grid or Layout.grid(8, 8), options.speed)

    def __init__(self, layout: Layout, rate_hz: float = 1.0) -> None:
        super().__init__()
        self.layout, self.rate_hz = layout, float(rate_hz)

    async def frames(self) -> AsyncIterator[Frame]:
        """Frames of the pattern, for ever."""
        rows, cols = self.layout.shape or (1, self.layout.n_elements)
        seq = 0
        while True:
            grid = np.zeros((rows, cols))
            grid[:, seq % cols] = 2.0
            t = seq / self.rate_hz if self.rate_hz > 0 else float(seq)
            values = self.layout.from_grid(grid)
            yield Frame(seq, np.full(self.layout.n_elements, t), values, self.unit)
            seq += 1
            await asyncio.sleep(1 / self.rate_hz if self.rate_hz > 0 else 0)
