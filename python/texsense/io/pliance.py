"""novel pliance ASCII exports (``.asc``).

The file holds a short header (``file name``, ``mat type``, ``time per frame``, ``pressure
values in <unit>``), a table ``time[secs]`` + one column per sensor number with one frame per
line, the rows ``MPP`` and ``MVP`` (per-sensor peak and mean over the recording, skipped), a
table ``time[secs] force[N] x[cm] y[cm]`` (the vendor's total force and centre of pressure
per time step, ``-`` when unloaded), and the sensor geometry: ``sensor`` numbers, the corner
coordinates ``x[0..3]``/``y[0..3]``, the centres ``x[c]``/``y[c]`` and ``area`` (cm²).

Sensors become a points layout named by their sensor numbers, with the exported centres
(pliance's coordinates, as exported), sizes from the corners and the exported areas. The
vendor's force and centre of pressure at each frame time become the labels
``vendor_force_N``, ``vendor_cop_x_cm`` and ``vendor_cop_y_cm`` (NaN where the export has
``-``).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from texsense import units
from texsense.exceptions import FormatError, UnitError
from texsense.io._text import parse_float, parse_floats, read_lines
from texsense.layout import Layout
from texsense.recording import Recording

__all__ = ["read_pliance"]

_UNIT = re.compile(r"pressure values in\s+(\S+)", re.IGNORECASE)
_PERIOD = re.compile(r"time per frame \[secs\]:\s*([0-9.eE+-]+)")


def _find(lines: list[str], start: int, predicate: object, what: str, path: Path) -> int:
    for k in range(start, len(lines)):
        if predicate(lines[k]):  # type: ignore[operator]
            return k
    raise FormatError(path, f"{what} not found (truncated or not a pliance export?)")


def read_pliance(path: str | Path) -> Recording:
    """Read a novel pliance ASCII export.

    Returns
    -------
    Recording
        Pressure in N/cm² on a points layout (one element per pliance sensor).
    """
    path = Path(path)
    lines = read_lines(path)
    head = "\n".join(lines[:10])
    m = _UNIT.search(head)
    if not m:
        raise FormatError(path, "no 'pressure values in <unit>' line in the header")
    try:
        unit = units.canonical(m.group(1))
    except UnitError:
        raise FormatError(path, f"unknown pressure unit {m.group(1)!r} (never guessed)") from None
    if units.quantity_of(unit) != "pressure":
        raise FormatError(path, f"'pressure values in {m.group(1)}' is not a pressure unit")
    hdr = _find(
        lines,
        0,
        lambda s: s.strip().startswith("time[secs]") and "force" not in s,
        "the 'time[secs] <sensor numbers>' table header",
        path,
    )
    sensor_tokens = lines[hdr].split()[1:]
    n = len(sensor_tokens)
    if n == 0:
        raise FormatError(path, "the frame table names no sensors", hdr + 1)
    frames: list[np.ndarray] = []
    times: list[float] = []
    k = hdr + 1
    while k < len(lines):
        tokens = lines[k].split()
        if not tokens:
            k += 1
            continue
        try:
            t = float(tokens[0])
        except ValueError:
            break  # MPP / MVP rows end the frame table
        values = parse_floats(path, k + 1, tokens[1:], n, "a frame (one value per sensor)")
        frames.append(values)
        times.append(t)
        k += 1
    if not frames:
        raise FormatError(path, "the frame table holds no frames", hdr + 2)

    # Vendor force and centre of pressure per time step.
    force_hdr = _find(lines, k, lambda s: "force[N]" in s, "the 'time[secs] force[N]' table", path)
    vendor: dict[float, tuple[float, float, float]] = {}
    j = force_hdr + 1
    while j < len(lines):
        tokens = lines[j].split()
        if not tokens:
            j += 1
            continue
        if tokens[0] == "sensor" or len(tokens) != 4:
            break
        t = parse_float(path, j + 1, tokens[0], "time")
        f, x, y = (
            float("nan") if tok == "-" else parse_float(path, j + 1, tok, "force table")
            for tok in tokens[1:]
        )
        vendor[round(t, 4)] = (f, x, y)
        j += 1

    # Sensor geometry.
    sensor_row = _find(
        lines, j, lambda s: s.split()[:1] == ["sensor"], "the 'sensor' geometry table", path
    )
    if lines[sensor_row].split()[1:] != sensor_tokens:
        raise FormatError(
            path, "the geometry table lists other sensors than the frame table", sensor_row + 1
        )
    rows: dict[str, tuple[int, np.ndarray]] = {}
    for r in range(sensor_row + 1, len(lines)):
        tokens = lines[r].split()
        if len(tokens) == n + 1:
            rows[tokens[0]] = (r + 1, parse_floats(path, r + 1, tokens[1:], n, tokens[0]))
    for needed in ("x[c]", "y[c]", "area", "x[0]", "y[0]", "x[2]", "y[2]"):
        if needed not in rows:
            raise FormatError(path, f"geometry row {needed!r} is missing")
    xy = np.column_stack([rows["x[c]"][1], rows["y[c]"][1]])
    corners_x = np.array([rows[f"x[{c}]"][1] for c in range(4) if f"x[{c}]" in rows])
    corners_y = np.array([rows[f"y[{c}]"][1] for c in range(4) if f"y[{c}]" in rows])
    size = np.column_stack([np.ptp(corners_x, axis=0), np.ptp(corners_y, axis=0)])
    area = rows["area"][1]
    if np.any(area <= 0) or np.any(size <= 0):
        raise FormatError(path, "sensor areas and corner extents must be positive", rows["area"][0])
    layout = Layout.points(xy, size_cm=size, area_cm2=area, names=sensor_tokens)
    times_arr = np.asarray(times)
    looked_up = [vendor.get(round(t, 4), (np.nan, np.nan, np.nan)) for t in times]
    v = np.asarray(looked_up, dtype=np.float64).reshape(-1, 3)
    period_match = _PERIOD.search(head)
    header = {"header_lines": [s for s in lines[:hdr] if s.strip()]}
    if period_match:
        header["time_per_frame_s"] = float(period_match.group(1))
    return Recording(
        (np.asarray(frames) * units.factor(unit, "N/cm2")).astype(np.float32),
        times_arr,
        layout,
        quantity="pressure",
        unit="N/cm2",
        labels={"vendor_force_N": v[:, 0], "vendor_cop_x_cm": v[:, 1], "vendor_cop_y_cm": v[:, 2]},
        meta={"format": "pliance-asc", "source": str(path), "source_unit": unit, **header},
    )
