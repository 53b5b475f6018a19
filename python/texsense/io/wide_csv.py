"""Wide CSV: one line per frame, ``time_s,e0,e1,...`` — reader and writer.

A texsense-written file starts with comment lines that make the round trip exact::

    # texsense wide-csv 2
    # quantity: pressure
    # unit: N/cm2
    # frames: 2
    # layout: {"kind": "grid", ...}        (JSON of Layout.to_dict, one line)
    # meta: {...}
    time_s,e0,e1,e2,invalid
    0.0,0.5,0.25,nan,
    0.1,0.5,0.25,0.75,0 2

The last column lists the elements whose reading is invalid in that frame (space-separated
indices; empty when all are valid): the file carries the recording's validity mask.
``# frames:`` declares the frame count, so a file cut short is noticed.

Files from elsewhere (and version 1 files) need only the ``time_s,...`` header; pass
``quantity`` and ``unit`` when the file does not name them (units are never guessed). Without
a layout line the elements are placed in one row at 1 cm pitch and the column names become
element names. Without an ``invalid`` column, readings that are not a number, infinite or
impossible for the quantity (a negative pressure) are invalid.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from texsense.data import units
from texsense.data.files import atomic_open, json_loads
from texsense.data.layout import Layout
from texsense.data.recording import QUANTITIES, Recording
from texsense.exceptions import FormatError, ParameterError, UnitError
from texsense.io._base import FrameRow, Header, RecordingReader, plausible
from texsense.io._registry import Probe, writer
from texsense.io._text import Line, TextLines, format_float, is_number
from texsense.io.policy import check_json

__all__ = ["MAGIC", "WideCSVReader", "write_wide_csv"]

#: The first line of a texsense-written wide CSV (followed by the version).
MAGIC = "# texsense wide-csv"
VERSION = 2
_MASK = "invalid"


def _comments(path: Path, lines: TextLines) -> tuple[dict[str, str], dict[str, int], int]:
    """``# key: value`` lines, where each is, and the file's version (0: not texsense)."""
    info: dict[str, str] = {}
    where: dict[str, int] = {}
    version = 0
    while (line := lines.peek()) is not None and line.text.startswith("#"):
        next(lines)
        if line.number == 1 and line.text.startswith(MAGIC):
            try:
                version = int(line.text[len(MAGIC) :].strip())
            except ValueError:
                raise FormatError(path, "expected '# texsense wide-csv <version>'", 1) from None
            if version > VERSION:
                raise FormatError(
                    path,
                    f"wide-csv version {version} is newer than this texsense reads ({VERSION})",
                    1,
                )
            continue
        text = line.text[1:].strip()
        if ":" in text:
            key, value = text.split(":", 1)
            info[key.strip()] = value.strip()
            where[key.strip()] = line.number
    return info, where, version


def _quantity_unit(
    path: Path, info: dict[str, str], where: dict[str, int], quantity: str | None, unit: str | None
) -> tuple[str, str]:
    q, u = info.get("quantity"), info.get("unit")
    for key, given, found in (("quantity", quantity, q), ("unit", unit, u)):
        if given is not None and found is not None and given != found:
            raise FormatError(
                path, f"file says {key} {found!r} but {given!r} was passed", where[key]
            )
    q, u = q or quantity, u or unit
    if q is None or u is None:
        raise FormatError(
            path,
            "the file names no quantity/unit ('# quantity:' and '# unit:' lines); "
            "pass quantity=... and unit=... (units are never guessed)",
        )
    if q not in QUANTITIES:
        raise FormatError(
            path,
            f"unknown quantity {q!r}; expected one of {', '.join(QUANTITIES)}",
            where.get("quantity"),
        )
    try:
        return q, units.canonical(u)
    except UnitError as e:
        raise FormatError(path, str(e), where.get("unit")) from None


def _layout(path: Path, info: dict[str, str], where: dict[str, int], names: list[str]) -> Layout:
    n = len(names)
    if "layout" in info:
        try:
            layout = Layout.from_dict(json_loads(info["layout"]))
        except (json.JSONDecodeError, ParameterError, TypeError, ValueError, KeyError) as e:
            raise FormatError(path, f"bad layout line: {e}", where["layout"]) from None
        if layout.n_elements != n:
            raise FormatError(
                path, f"layout has {layout.n_elements} elements, header {n}", where["layout"]
            )
        return layout
    layout = Layout.grid(1, n, pitch_cm=1.0)
    if names == [f"e{k}" for k in range(n)]:
        return layout
    return Layout(
        layout.xy_cm,
        layout.size_cm,
        shape=layout.shape,
        cells=layout.cells,
        pitch_cm=layout.pitch_cm,
        neighbours=layout.neighbours,
        names=names,
    )


class WideCSVReader(RecordingReader):
    """Read a wide CSV (``time_s,<element>,...``).

    Parameters
    ----------
    path : str or Path
        The file.
    quantity, unit : str, optional
        Needed when the file has no ``# quantity:`` / ``# unit:`` lines; if both are given
        they must agree.
    accept_truncated : bool
        Read a file that holds fewer frames than its ``# frames:`` line declares, or whose
        last line was cut, up to its last complete frame (with a warning).
    """

    format = "wide-csv"
    what = "wide CSV (time_s,e0,e1,...)"
    sniff_order = 50

    @classmethod
    def sniff(cls, probe: Probe) -> bool:
        """texsense's first line, or a ``time_s,`` header, or comment lines first."""
        return probe.first.startswith((MAGIC, "time_s,", "# "))

    def __init__(
        self,
        path: str | Path,
        *,
        quantity: str | None = None,
        unit: str | None = None,
        accept_truncated: bool = False,
    ) -> None:
        self._given = (quantity, unit)
        super().__init__(path, accept_truncated=accept_truncated)

    def _read_header(self) -> Header:
        path = self.path
        self._lines = TextLines(path)
        info, where, self.version = _comments(path, self.lines)
        head = self.lines.next_nonblank()
        if head is None:
            raise FormatError(path, "no header line 'time_s,<element>,...'")
        header = [s.strip() for s in head.text.split(",")]
        if header[0] != "time_s":
            raise FormatError(
                path,
                f"expected the header to start with 'time_s', found {header[0]!r}",
                head.number,
            )
        names = header[1:]
        self.has_mask = self.version >= 2 and names[-1:] == [_MASK]
        names = names[:-1] if self.has_mask else names
        if not names:
            raise FormatError(path, "the header names no element columns", head.number)
        if len(set(names)) != len(names):
            raise FormatError(path, "duplicate element column names in the header", head.number)
        q, u = _quantity_unit(path, info, where, *self._given)
        layout = _layout(path, info, where, names)
        meta: dict[str, Any] = {"format": "wide-csv", "source": str(path)}
        if "meta" in info:
            try:
                meta = json_loads(info["meta"])
            except json.JSONDecodeError as e:
                raise FormatError(path, f"bad meta line: {e}", where["meta"]) from None
            if not isinstance(meta, dict):
                raise FormatError(path, "bad meta line: expected a JSON object", where["meta"])
        declared = None
        if "frames" in info:
            try:
                declared = int(info["frames"])
            except ValueError:
                raise FormatError(
                    path, f"frames: expected a count, found {info['frames']!r}", where["frames"]
                ) from None
        return Header(layout, q, u, meta, declared_frames=declared)

    def _row(self, line: Line, n: int) -> FrameRow | None:
        tokens = line.text.split(",")
        width = n + 1 + self.has_mask
        if len(tokens) != width:
            self._bad_line(line, f"expected {width} comma-separated values, found {len(tokens)}")
            return None
        numbers = tokens[: n + 1]
        try:
            data = np.array([float(t) for t in numbers])
        except ValueError:
            bad = next(t for t in numbers if not is_number(t))
            self._bad_line(line, f"expected a number, found {bad.strip()!r}")
            return None
        valid = None
        if self.has_mask:
            valid = np.ones(n, dtype=bool)
            try:
                invalid = [int(k) for k in tokens[-1].split()]
                valid[invalid] = False
            except (ValueError, IndexError):
                self._bad_line(
                    line,
                    f"the invalid column must list element indices 0..{n - 1}, "
                    f"found {tokens[-1].strip()!r}",
                )
                return None
        return FrameRow(data[1:], float(data[0]), line.number, {}, valid)

    def _frames(self) -> Iterator[FrameRow]:
        n = self.header.layout.n_elements
        count = 0
        for line in self.lines.data_lines():
            if self.version >= 2 and not line.ended:
                self._cut(f"truncated: the file ends in the middle of line {line.number}")
                return
            row = self._row(line, n)
            if row is None:
                return
            yield row
            count += 1
        declared = self.header.declared_frames
        if declared is not None and count < declared:
            self._cut(
                f"truncated: '# frames: {declared}' but the file holds {count} "
                f"({declared - count} missing)"
            )
        elif declared is not None and count > declared:
            raise FormatError(
                self.path, f"the file holds {count} frames, '# frames:' declares {declared}"
            )


@writer("wide-csv", what="wide CSV (exact round trip)", suffixes=(".csv",))
def write_wide_csv(rec: Recording, path: str | Path) -> Path:
    """Write ``rec`` as a wide CSV that :func:`read_wide_csv` reads back exactly.

    Written exactly: frames (shortest float32 text), times (shortest float64 text), the
    validity mask (with the readings no reader accepts marked invalid: not a number, infinite,
    negative pressure, beyond any sensor), quantity, unit, layout and meta. Not written:
    labels, per-element times. The file is written to a temporary name and renamed
    (:mod:`texsense.data.files`).
    """
    path = Path(path)
    names = [f"e{k}" for k in range(rec.n_elements)]
    head = [
        f"{MAGIC} {VERSION}",
        f"# quantity: {rec.quantity}",
        f"# unit: {rec.unit}",
        f"# frames: {rec.n_frames}",
        f"# layout: {check_json(rec.layout.to_dict(), 'the layout')}",
        f"# meta: {check_json(rec.meta)}",
        "time_s," + ",".join(names) + "," + _MASK,
    ]
    with atomic_open(path, "w", encoding="utf-8") as out:
        out.write("\n".join(head) + "\n")
        # what every reader finds impossible is written as invalid (see texsense.io._base)
        marked = rec.valid & plausible(rec.frames, rec.quantity)
        for t, frame, valid in zip(rec.times.tolist(), rec.frames, marked, strict=True):
            invalid = " ".join(map(str, np.flatnonzero(~valid).tolist()))
            out.write(repr(t) + "," + ",".join(format_float(v) for v in frame) + f",{invalid}\n")
    return path
