"""Wire formats of live sources: the serial line protocol and the MQTT payload (docs/monitor.md).

Serial (one ASCII line per frame, ``\\n`` terminated)::

    F,<seq>,<t0_us>,<dt_us>,<v_1>,...,<v_N>[*<XX>]

``seq`` counts frames (wraps at 2**32), ``t0_us`` is the microcontroller's clock when element 1
was read, ``dt_us`` the time between two elements (element i was read at
``t0_us + (i - 1) * dt_us``), ``v_i`` the capacitance in pF (decimal; empty or ``nan`` for a
reading that failed), ``*XX`` an optional checksum: the XOR of all bytes between the start of
the line and ``*``, two hex digits (as in NMEA). Lines starting with ``#`` are comments.

MQTT (topic ``texsense/<mat>/frames``), a JSON object per message::

    {"seq": 17, "t": 12.25, "dt": 0.0005, "values": [0.0, 12.3, ...], "unit": "pF"}

``t`` is the time (s) of element 1, ``dt`` (s, optional, default 0) the time between elements
or ``element_times`` (s, one per element) instead; ``unit`` any capacitance or pressure unit
(default pF); ``null`` for a failed reading.

Both parsers raise :class:`ProtocolError` naming what is wrong; the sources count, log and skip
such lines (the monitor keeps running).

Examples
--------
>>> line = format_serial_line(3, 1_000_000, 500, [12.5, 13.0])
>>> line
'F,3,1000000,500,12.5,13*47'
>>> f = parse_serial_line(line, 2)
>>> f.seq, f.element_times.tolist(), f.values.tolist()
(3, [1.0, 1.0005], [12.5, 13.0])
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense import units

__all__ = [
    "Frame",
    "ProtocolError",
    "format_serial_line",
    "parse_mqtt_payload",
    "parse_serial_line",
]

MAX_LINE = 65536  # characters; longer lines are rejected before parsing


class ProtocolError(ValueError):
    """A line or payload that does not follow the protocol."""


@dataclass
class Frame:
    """One frame from a source: per-element time stamps (s) and values in ``unit``."""

    seq: int
    element_times: np.ndarray  # (N,)
    values: np.ndarray  # (N,), NaN for a failed reading
    unit: str = "pF"

    @property
    def t(self) -> float:
        """Time of the first element, s."""
        return float(self.element_times[0])


def _checksum(body: str) -> str:
    x = 0
    for b in body.encode("ascii", errors="replace"):
        x ^= b
    return f"{x:02X}"


def format_serial_line(
    seq: int, t0_us: int, dt_us: int, values: npt.ArrayLike, checksum: bool = True
) -> str:
    """One frame as a serial line (without the newline); what a sender writes."""
    vals = ",".join("" if not math.isfinite(v) else f"{v:.6g}" for v in np.asarray(values, float))
    body = f"F,{int(seq)},{int(t0_us)},{int(dt_us)},{vals}"
    return f"{body}*{_checksum(body)}" if checksum else body


def _int(text: str, what: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ProtocolError(f"{what} is not an integer: {text[:20]!r}") from None


def parse_serial_line(line: str | bytes, n_elements: int) -> Frame | None:
    """Parse one serial line; None for a blank line or a comment."""
    if isinstance(line, bytes):
        try:
            line = line.decode("ascii")
        except UnicodeDecodeError:
            raise ProtocolError("line is not ASCII") from None
    if len(line) > MAX_LINE:
        raise ProtocolError(f"line longer than {MAX_LINE} characters")
    line = line.strip()
    if not line or line.startswith("#"):
        return None
    body = line
    if "*" in line:
        body, _, check = line.rpartition("*")
        if len(check) != 2 or check.upper() != _checksum(body):
            raise ProtocolError(f"checksum mismatch ({check[:4]!r}, expected {_checksum(body)})")
    parts = body.split(",")
    if parts[0] != "F":
        raise ProtocolError(f"unknown record type {parts[0][:8]!r} (expected 'F')")
    if len(parts) != 4 + n_elements:
        raise ProtocolError(f"expected {n_elements} values, got {max(len(parts) - 4, 0)}")
    seq = _int(parts[1], "frame counter")
    t0 = _int(parts[2], "time stamp")
    dt = _int(parts[3], "element period")
    if seq < 0 or t0 < 0 or dt < 0:
        raise ProtocolError("frame counter, time stamp and element period must be >= 0")
    values = np.empty(n_elements)
    for i, text in enumerate(parts[4:]):
        if text == "" or text.lower() == "nan":
            values[i] = np.nan
            continue
        try:
            values[i] = float(text)
        except ValueError:
            raise ProtocolError(f"value {i + 1} is not a number: {text[:20]!r}") from None
        if not math.isfinite(values[i]):
            raise ProtocolError(f"value {i + 1} is not finite: {text[:20]!r}")
    times = (t0 + dt * np.arange(n_elements)) * 1e-6
    return Frame(seq, times, values, "pF")


def _values(vals: list[Any], n: int) -> np.ndarray:
    """The values of a payload: numbers, ``null`` for a failed reading (NaN). One numpy
    conversion for the common case of plain numbers; the element-wise check names the first
    bad value otherwise."""
    if all(type(v) is float or type(v) is int for v in vals):  # not bool, str, None
        values = np.array(vals, dtype=np.float64)
        if values.shape == (n,) and np.all(np.isfinite(values)):
            return values
    values = np.empty(n)
    for i, v in enumerate(vals):
        if v is None:
            values[i] = np.nan
        elif isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
            values[i] = v
        else:
            raise ProtocolError(f"value {i + 1} is not a finite number or null")
    return values


def parse_mqtt_payload(payload: bytes | str, n_elements: int) -> Frame:
    """Parse one MQTT message (JSON, see the module docstring)."""
    if len(payload) > 16 * MAX_LINE:
        raise ProtocolError("payload too large")
    try:
        d: Any = json.loads(payload)
    except (ValueError, UnicodeDecodeError) as e:
        raise ProtocolError(f"payload is not JSON: {e}") from None
    if not isinstance(d, dict):
        raise ProtocolError("payload must be a JSON object")
    for key in ("seq", "t", "values"):
        if key not in d:
            raise ProtocolError(f"payload lacks {key!r}")
    seq, t, vals = d["seq"], d["t"], d["values"]
    if not isinstance(seq, int) or isinstance(seq, bool) or seq < 0:
        raise ProtocolError(f"'seq' must be an integer >= 0, got {str(seq)[:20]!r}")
    if not isinstance(t, (int, float)) or isinstance(t, bool) or not math.isfinite(t):
        raise ProtocolError(f"'t' must be a finite number, got {str(t)[:20]!r}")
    if not isinstance(vals, list) or len(vals) != n_elements:
        got = len(vals) if isinstance(vals, list) else type(vals).__name__
        raise ProtocolError(f"'values' must be a list of {n_elements} numbers, got {got}")
    values = _values(vals, n_elements)
    unit = d.get("unit", "pF")
    if not isinstance(unit, str):
        raise ProtocolError("'unit' must be a string")
    try:
        unit = units.canonical(unit)
    except ValueError as e:
        raise ProtocolError(str(e)) from None
    if units.quantity_of(unit) not in ("capacitance", "pressure"):
        raise ProtocolError(f"unit {unit!r} is neither capacitance nor pressure")
    if "element_times" in d:
        et = d["element_times"]
        ok = isinstance(et, list) and len(et) == n_elements
        if not ok or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in et
        ):
            raise ProtocolError(f"'element_times' must be {n_elements} finite numbers")
        times = np.asarray(et, dtype=np.float64)
    else:
        dt = d.get("dt", 0.0)
        if not isinstance(dt, (int, float)) or isinstance(dt, bool) or not dt >= 0:
            raise ProtocolError("'dt' must be a number >= 0")
        times = np.asarray(float(t) + float(dt) * np.arange(n_elements), dtype=np.float64)
    return Frame(seq, times, values, unit)
