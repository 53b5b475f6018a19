"""Wide CSV: one line per frame, ``time_s,e0,e1,...`` — reader and writer.

A texsense-written file starts with comment lines that make the round trip exact::

    # texsense wide-csv 1
    # quantity: pressure
    # unit: N/cm2
    # layout: {"kind": "grid", ...}        (JSON of Layout.to_dict, one line)
    time_s,e0,e1,e2
    0.0,0.5,0.25,nan

Files from elsewhere need only the ``time_s,...`` header; pass ``quantity`` and ``unit`` when
the file does not name them (units are never guessed). Without a layout line the elements are
placed in one row at 1 cm pitch and the column names become element names.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from texsense import units
from texsense.exceptions import FormatError, ParameterError, UnitError
from texsense.io._text import format_float, parse_csv_rows, read_lines
from texsense.layout import Layout
from texsense.recording import QUANTITIES, Recording

__all__ = ["MAGIC", "read_wide_csv", "write_wide_csv"]

MAGIC = "# texsense wide-csv 1"


def read_wide_csv(
    path: str | Path, *, quantity: str | None = None, unit: str | None = None
) -> Recording:
    """Read a wide CSV (``time_s,<element>,...``).

    Parameters
    ----------
    path : str or Path
        The file.
    quantity, unit : str, optional
        Needed when the file has no ``# quantity:`` / ``# unit:`` lines; if both are given
        they must agree.
    """
    path = Path(path)
    lines = read_lines(path)
    info: dict[str, str] = {}
    where: dict[str, int] = {}
    i = 0
    while i < len(lines) and lines[i].startswith("#"):
        text = lines[i][1:].strip()
        if ":" in text:
            key, value = text.split(":", 1)
            info[key.strip()] = value.strip()
            where[key.strip()] = i + 1
        i += 1
    if i >= len(lines):
        raise FormatError(path, "no header line 'time_s,<element>,...'")
    header = [s.strip() for s in lines[i].split(",")]
    if header[0] != "time_s":
        raise FormatError(
            path, f"expected the header to start with 'time_s', found {header[0]!r}", i + 1
        )
    names = header[1:]
    if not names:
        raise FormatError(path, "the header names no element columns", i + 1)
    if len(set(names)) != len(names):
        raise FormatError(path, "duplicate element column names in the header", i + 1)
    q = info.get("quantity")
    u = info.get("unit")
    for key, given, found in (("quantity", quantity, q), ("unit", unit, u)):
        if given is not None and found is not None and given != found:
            raise FormatError(
                path, f"file says {key} {found!r} but {given!r} was passed", where[key]
            )
    q = q or quantity
    u = u or unit
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
        u = units.canonical(u)
    except UnitError as e:
        raise FormatError(path, str(e), where.get("unit")) from None
    n = len(names)
    body = lines[i + 1 :]
    while body and not body[-1].strip():
        body.pop()
    data = parse_csv_rows(path, body, i + 2, n + 1, f"{n + 1} comma-separated values")
    if "layout" in info:
        try:
            layout = Layout.from_dict(json.loads(info["layout"]))
        except (json.JSONDecodeError, ParameterError, TypeError, ValueError) as e:
            raise FormatError(path, f"bad layout line: {e}", where["layout"]) from None
        if layout.n_elements != n:
            raise FormatError(
                path, f"layout has {layout.n_elements} elements, header {n}", where["layout"]
            )
    else:
        default = [f"e{k}" for k in range(n)]
        layout = Layout.grid(1, n, pitch_cm=1.0)
        if names != default:
            layout = Layout(
                layout.xy_cm,
                layout.size_cm,
                shape=layout.shape,
                cells=layout.cells,
                pitch_cm=layout.pitch_cm,
                neighbours=layout.neighbours,
                names=names,
            )
    meta = {"format": "wide-csv", "source": str(path)}
    if "meta" in info:
        try:
            meta = json.loads(info["meta"])
        except json.JSONDecodeError as e:
            raise FormatError(path, f"bad meta line: {e}", where["meta"]) from None
    return Recording(data[:, 1:].astype(np.float32), data[:, 0], layout, q, u, meta=meta)


def write_wide_csv(rec: Recording, path: str | Path) -> Path:
    """Write ``rec`` as a wide CSV that :func:`read_wide_csv` reads back exactly.

    Written exactly: frames (shortest float32 text), times (shortest float64 text), quantity,
    unit, layout and meta. Not written: the validity mask, labels, per-element times.
    """
    path = Path(path)
    names = [f"e{k}" for k in range(rec.n_elements)]
    out = [
        MAGIC,
        f"# quantity: {rec.quantity}",
        f"# unit: {rec.unit}",
        f"# layout: {json.dumps(rec.layout.to_dict(), separators=(',', ':'))}",
        f"# meta: {json.dumps(rec.meta, separators=(',', ':'))}",
        "time_s," + ",".join(names),
    ]
    for t, frame in zip(rec.times.tolist(), rec.frames, strict=True):
        out.append(repr(t) + "," + ",".join(format_float(v) for v in frame))
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
    return path
