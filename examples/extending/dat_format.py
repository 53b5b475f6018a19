"""A new file format in one module: the reader of a made-up ``.dat`` export.

A ``.dat`` file is a line ``# example-dat ROWS COLS UNIT``, then one frame per line: the time
in seconds and ROWS x COLS pressures, separated by spaces. Saved as
``python/texsense/io/dat.py`` it is found by ``texsense.io`` (the package imports every public
module of its folder); here it is imported by the test that checks it
(``tests/test_extending.py``).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from texsense.data.layout import Layout
from texsense.exceptions import FormatError
from texsense.io._base import FrameRow, Header, RecordingReader
from texsense.io._registry import Probe
from texsense.io._text import TextLines

MAGIC = "# example-dat"


class DatReader(RecordingReader):
    """Read a ``.dat`` export (see the module docstring)."""

    format = "example-dat"  # its name: load(path, format="example-dat"), read_example_dat
    what = "example .dat export"  # in the table of formats, the help and the errors
    sniff_order = 45  # asked before the looser CSV rules

    @classmethod
    def sniff(cls, probe: Probe) -> bool:
        """The first line names the format."""
        return probe.first.startswith(MAGIC)

    def _read_header(self) -> Header:
        self._lines = TextLines(self.path)
        line = self.lines.next_nonblank()
        fields = line.text.split() if line is not None else []
        if len(fields) != 5 or not fields[2].isdigit() or not fields[3].isdigit():
            raise FormatError(self.path, f"expected '{MAGIC} ROWS COLS UNIT'", 1)
        rows, cols, unit = int(fields[2]), int(fields[3]), fields[4]
        return Header(Layout.grid(rows, cols), "pressure", "N/cm2", {"format": self.format},
                      source_unit=unit)  # fmt: skip

    def _frames(self) -> Iterator[FrameRow]:
        n = self.header.layout.n_elements
        for line in self.lines.data_lines():
            fields = line.text.split()
            if not line.ended or len(fields) != n + 1:  # a last line without its newline: cut
                self._cut(f"line {line.number}: expected a time and {n} values")
                return
            try:
                values = np.array([float(v) for v in fields], dtype=np.float64)
            except ValueError:
                raise FormatError(self.path, "expected numbers", line.number) from None
            yield FrameRow(values[1:], float(values[0]), line.number, {})
