"""XSENSOR CSV exports (frame blocks).

Layout of the file: a header (``File:``, ``Units:``, ``Threshold:``), then per frame a block
``FRAME,<k>``, ``Date,<yyyy Mon dd>``, ``Time,<hh:mm:ss.fff>``, one ``SENSOR,<name>`` block per
sensor (``Rows``, ``Columns``, ``Sensel Width (cm)``, ``Sensel Height (cm)``, statistics,
``SENSELS`` and Rows lines of Columns values) and optional ``GROUP`` blocks (region
statistics). Lines of commas only are separators.

Several sensors (for example a left and a right insole) become one grid layout, side by side
with two empty columns between them, and one named region per sensor. The vendor's per-frame
statistics ``Est. Load (N)``, ``Contact Area (cm²)``, ``Peak Pressure`` and
``Average Pressure`` are kept as labels ``vendor_load_N_s<i>``, ``vendor_contact_area_cm2_s<i>``,
``vendor_peak_ncm2_s<i>`` and ``vendor_mean_ncm2_s<i>`` (i = sensor number from 1), useful
to cross-check :mod:`texsense.stats`. GROUP blocks are skipped (their cell membership is not
exported).
"""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import numpy as np

from texsense import units
from texsense.exceptions import FormatError, UnitError
from texsense.io._text import parse_float, read_lines
from texsense.layout import Layout
from texsense.recording import Recording

__all__ = ["read_xsensor"]

_GAP = 2  # empty columns between two sensors in the combined grid
# statistic -> (label prefix, is a pressure in the file's unit)
_VENDOR_STATS = {
    "Est. Load (N)": ("vendor_load_N", False),
    "Contact Area (cm²)": ("vendor_contact_area_cm2", False),
    "Peak Pressure": ("vendor_peak_ncm2", True),
    "Average Pressure": ("vendor_mean_ncm2", True),
}


def _fields(line: str) -> list[str]:
    parts = [p.strip() for p in line.split(",")]
    while parts and parts[-1] == "":
        parts.pop()
    return parts


class _Sensor:
    def __init__(self, name: str) -> None:
        self.name = name
        self.rows = 0
        self.cols = 0
        self.width_cm = 0.0
        self.height_cm = 0.0
        self.stats: dict[str, float] = {}
        self.values: np.ndarray | None = None


def read_xsensor(path: str | Path) -> Recording:
    """Read an XSENSOR CSV export.

    Returns
    -------
    Recording
        Pressure in N/cm² (converted from the file's ``Units:``), frames timed from each
        frame's ``Time`` field relative to the first frame.
    """
    path = Path(path)
    lines = read_lines(path)
    unit: str | None = None
    frames: list[list[_Sensor]] = []
    stamps: list[datetime] = []
    frame_ids: list[int] = []
    date_text = ""
    current: list[_Sensor] | None = None
    sensor: _Sensor | None = None
    in_group = False
    i = 0
    n = len(lines)
    while i < n:
        f = _fields(lines[i])
        i += 1
        if not f:
            continue
        key = f[0]
        value = f[1] if len(f) > 1 else ""
        if key == "Units:":
            try:
                unit = units.canonical(value)
            except UnitError:
                raise FormatError(
                    path, f"Units: unknown unit {value!r} (never guessed)", i
                ) from None
        elif key == "FRAME":
            try:
                frame_ids.append(int(value))
            except ValueError:
                raise FormatError(
                    path, f"FRAME: expected a frame number, found {value!r}", i
                ) from None
            current = []
            frames.append(current)
            sensor, in_group = None, False
        elif key == "Date":
            date_text = value
        elif key == "Time":
            if current is None:
                raise FormatError(path, "Time before the first FRAME line", i)
            try:
                stamps.append(datetime.strptime(f"{date_text} {value}", "%Y %b %d %H:%M:%S.%f"))
            except ValueError:
                raise FormatError(
                    path,
                    f"expected 'Date,yyyy Mon dd' and 'Time,hh:mm:ss.fff', found "
                    f"{date_text!r} {value!r}",
                    i,
                ) from None
        elif key == "SENSOR":
            if current is None:
                raise FormatError(path, "SENSOR block before the first FRAME line", i)
            sensor = _Sensor(value)
            current.append(sensor)
            in_group = False
        elif key == "GROUP":
            in_group, sensor = True, None
        elif in_group:
            continue
        elif sensor is not None and key in ("Rows", "Columns"):
            try:
                setattr(sensor, "rows" if key == "Rows" else "cols", int(value))
            except ValueError:
                raise FormatError(path, f"{key}: expected an integer, found {value!r}", i) from None
        elif sensor is not None and key.startswith("Sensel Width"):
            sensor.width_cm = parse_float(path, i, value, "Sensel Width (cm)")
        elif sensor is not None and key.startswith("Sensel Height"):
            sensor.height_cm = parse_float(path, i, value, "Sensel Height (cm)")
        elif sensor is not None and key == "SENSELS":
            if sensor.rows < 1 or sensor.cols < 1:
                raise FormatError(path, f"SENSELS of {sensor.name!r} before its Rows/Columns", i)
            values = np.empty((sensor.rows, sensor.cols))
            r = 0
            while r < sensor.rows:
                if i >= n:
                    raise FormatError(
                        path,
                        f"sensor {sensor.name!r}: file ends after {r} of {sensor.rows} "
                        "SENSELS rows (truncated)",
                        n,
                    )
                row = _fields(lines[i])
                i += 1
                if not row:
                    continue
                if len(row) != sensor.cols:
                    raise FormatError(
                        path,
                        f"sensor {sensor.name!r}: expected {sensor.cols} values per "
                        f"SENSELS row, found {len(row)}",
                        i,
                    )
                for c, tok in enumerate(row):
                    values[r, c] = parse_float(path, i, tok, f"SENSELS row {r + 1}")
                r += 1
            sensor.values = values
        elif sensor is not None:
            for prefix in _VENDOR_STATS:
                if key.startswith(prefix) and value:
                    sensor.stats[prefix] = parse_float(path, i, value, key)
    if unit is None:
        raise FormatError(path, "no 'Units:' line: not an XSENSOR CSV export?")
    if not frames:
        raise FormatError(path, "no FRAME blocks found")
    if len(stamps) != len(frames):
        raise FormatError(path, f"{len(frames)} FRAME blocks but {len(stamps)} Time lines")
    first = frames[0]
    if not first:
        raise FormatError(path, f"frame {frame_ids[0]} has no SENSOR block")
    signature = [(s.name, s.rows, s.cols, s.width_cm, s.height_cm) for s in first]
    for k, fr in enumerate(frames):
        sig = [(s.name, s.rows, s.cols, s.width_cm, s.height_cm) for s in fr]
        if sig != signature:
            raise FormatError(path, f"frame {frame_ids[k]}: sensors differ from the first frame")
        for s in fr:
            if s.values is None:
                raise FormatError(path, f"frame {frame_ids[k]}: sensor {s.name!r} has no SENSELS")
    widths = {(s.width_cm, s.height_cm) for s in first}
    if len(widths) != 1:
        raise FormatError(path, "sensors with different sensel sizes are not supported")
    width_cm, height_cm = widths.pop()
    rows = max(s.rows for s in first)
    cols = sum(s.cols for s in first) + _GAP * (len(first) - 1)
    active = np.zeros((rows, cols), dtype=bool)
    regions: dict[str, np.ndarray] = {}
    offsets = []
    c0 = 0
    for s in first:
        active[: s.rows, c0 : c0 + s.cols] = True
        offsets.append(c0)
        c0 += s.cols + _GAP
    layout = Layout.grid(rows, cols, pitch_cm=(height_cm, width_cm), active=active, neighbour_gap=0)
    cell_to_element = np.full(rows * cols, -1)
    cell_to_element[layout.cells] = np.arange(layout.n_elements)
    for s, off in zip(first, offsets, strict=True):
        cells = (np.arange(s.rows)[:, None] * cols + off + np.arange(s.cols)[None, :]).ravel()
        regions[s.name] = cell_to_element[cells]
    layout = layout.with_regions(regions)
    data = np.empty((len(frames), layout.n_elements))
    labels: dict[str, np.ndarray] = {"frame_number": np.asarray(frame_ids)}
    to_ncm2 = units.factor(unit, "N/cm2")
    for si, s in enumerate(first):
        members = regions[s.name]
        for k, fr in enumerate(frames):
            data[k, members] = fr[si].values.ravel()  # type: ignore[union-attr]
        for stat, (label, is_pressure) in _VENDOR_STATS.items():
            if all(stat in fr[si].stats for fr in frames):
                v = np.array([fr[si].stats[stat] for fr in frames])
                labels[f"{label}_s{si + 1}"] = v * to_ncm2 if is_pressure else v
    t0 = stamps[0]
    times = np.array([(t - t0).total_seconds() for t in stamps])
    return Recording(
        (data * to_ncm2).astype(np.float32),
        times,
        layout,
        quantity="pressure",
        unit="N/cm2",
        labels=labels,
        meta={
            "format": "xsensor-csv",
            "source": str(path),
            "source_unit": unit,
            "sensors": [s.name for s in first],
            "start_time": t0.isoformat(),
        },
    )
