"""Wire formats of live sources: the serial line protocol and the MQTT payload (docs/monitor.md).

Serial (one ASCII line per frame, ``\\n`` terminated)::

    F,<seq>,<t0_us>,<dt_us>,<v_1>,...,<v_N>[*<XX>]

``seq`` counts frames (wraps at 2**32), ``t0_us`` is the microcontroller's clock when element 1
was read, ``dt_us`` the time between two elements (element i was read at
``t0_us + (i - 1) * dt_us``), ``v_i`` the capacitance in pF (decimal; empty or ``nan`` for a
reading that failed), ``*XX`` an optional checksum: the XOR of all bytes between the start of
the line and ``*``, two hex digits (as in NMEA). Lines starting with ``#`` are comments.

A device may announce its layout in a comment line (first, and again now and then for a
reader that opens the port later), so that no ``--grid`` is needed::

    #layout {"grid": [15, 16], "pitch_cm": [2.07, 2.07], "element_cm": [2.0, 2.0],
             "active": "<hex>", "elements": 96, "spacer": "textile-3mm", ...}

(one line; ``active`` is the hex bitmask of the active cells, row by row, omitted when every
cell is active; ``orientation``, optional, what lies beyond each edge of the map, row 0 at the
top: a preset of :data:`texsense.data.layout.ORIENTATIONS` such as ``"seat"``, one turned
toward an edge such as ``"bed:bottom"``, or ``{"top": "head", ...}``; further keys describe
the device). A grid layout is all the announcement
carries (4-neighbours linked across one empty cell, as :meth:`Layout.grid` does).

MQTT (topic ``texsense/<mat>/frames``), a JSON object per message::

    {"seq": 17, "t": 12.25, "dt": 0.0005, "values": [0.0, 12.3, ...], "unit": "pF"}

``t`` is the time (s) of element 1, ``dt`` (s, optional, default 0) the time between elements
or ``element_times`` (s, one per element) instead; ``unit`` any capacitance or pressure unit
(default pF); ``null`` for a failed reading.

Both parsers raise :class:`ProtocolError` naming what is wrong; the sources count, log and skip
such lines (the monitor keeps running). A payload longer than :func:`payload_limit` allows
for the mat's element count is refused by its length, before any parsing
(:class:`PayloadSizeError`); a payload with another number of values than the mat has elements
raises :class:`CountError`, which says how many it had.

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
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from texsense._core import parse_json_frame, parse_json_numbers
from texsense.data import units
from texsense.data.files import json_loads
from texsense.data.layout import Layout, parse_orientation, whole_numbers
from texsense.exceptions import ParameterError, shown

if TYPE_CHECKING:
    from texsense.data.layout import Layout

__all__ = [
    "CountError",
    "Frame",
    "PayloadSizeError",
    "ProtocolError",
    "format_serial_line",
    "layout_announcement",
    "parse_announcement",
    "parse_mqtt_payload",
    "parse_serial_line",
    "payload_limit",
    "peek_mqtt_payload",
]

MAX_LINE = 65536  # characters; longer lines are rejected before parsing
#: Largest integer the protocol's counters and time stamps may hold (int64).
MAX_INT = 2**63 - 1


class ProtocolError(ValueError):
    """A line or payload that does not follow the protocol."""


class CountError(ProtocolError):
    """A payload with another number of values than the mat has elements (``got`` values)."""

    def __init__(self, message: str, got: int) -> None:
        super().__init__(message)
        self.got = got


class PayloadSizeError(ProtocolError):
    """A payload longer than :func:`payload_limit` (``size`` bytes): refused unparsed."""

    def __init__(self, size: int, limit: int) -> None:
        super().__init__(f"a payload of {size} bytes, more than the {limit} a frame can need")
        self.size, self.limit = size, limit


def payload_limit(n_elements: int) -> int:
    """The longest MQTT payload a frame of ``n_elements`` can need, bytes: room for every value
    and every element time written with 17 significant digits, spaces, and the keys (4 kB +
    64 bytes per element: 10 kB for 96 elements, 135 kB for 2048)."""
    return 4096 + 64 * int(n_elements)


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
        value = int(text)
    except ValueError:
        raise ProtocolError(f"{what} is not an integer: {shown(text, 20)}") from None
    if abs(value) > MAX_INT:
        raise ProtocolError(f"{what} is out of range: {shown(text, 20)}")
    return value


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
            raise ProtocolError(
                f"checksum mismatch ({shown(check, 4)}, expected {_checksum(body)})"
            )
    parts = body.split(",")
    if parts[0] != "F":
        raise ProtocolError(f"unknown record type {shown(parts[0], 8)} (expected 'F')")
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
            raise ProtocolError(f"value {i + 1} is not a number: {shown(text, 20)}") from None
        if not math.isfinite(values[i]):
            raise ProtocolError(f"value {i + 1} is not finite: {shown(text, 20)}")
    times = (float(t0) + float(dt) * np.arange(n_elements)) * 1e-6
    return Frame(seq, times, values, "pF")


def _values(vals: list[Any], n: int) -> np.ndarray:
    """The values of a payload: numbers, ``null`` for a failed reading (NaN). One numpy
    conversion for the common case of plain numbers; the element-wise check names the first
    bad value otherwise."""
    if set(map(type, vals)) <= {float, int}:  # not bool, str, None (one pass in C)
        try:
            values = np.array(vals, dtype=np.float64)
        except OverflowError:  # an integer beyond any float: named below
            values = np.empty(0)
        if values.shape == (n,) and np.all(np.isfinite(values)):
            return values
    values = np.empty(n)
    for i, v in enumerate(vals):
        if v is None:
            values[i] = np.nan
        elif isinstance(v, (int, float)) and not isinstance(v, bool) and _finite(v):
            values[i] = v
        else:
            raise ProtocolError(f"value {i + 1} is not a finite number or null")
    return values


def _finite(v: float) -> bool:
    try:
        return math.isfinite(v) and math.isfinite(float(v))
    except OverflowError:  # an integer beyond any float
        return False


def _splice(b: bytes) -> tuple[dict[str, Any], bytes] | None:
    """A payload's own ``values`` list cut out: the rest parsed as JSON (``values`` 0 in its
    place) and the bytes inside the list; None unless the payload is of the plain form where
    that is certain (one key ``values``, holding a flat list, no escapes outside it, UTF-8):
    then parse it whole."""
    i = b.find(b'"values"')
    j = b.find(b"[", i)
    k = b.find(b"]", j)
    if i < 0 or j < 0 or k < 0 or b[i + 8 : j].strip(b" \t\r\n") != b":":
        return None
    inner = b[j + 1 : k]
    if any(c in inner for c in (b"[", b"{", b'"')):
        return None
    rest = b[:i] + b'"values":0' + b[k + 1 :]
    if b"\\" in rest or rest.find(b'"values"', i + 1) >= 0:  # another key may be "values"
        return None
    try:
        d = json_loads(rest.decode("utf-8"))
    except (ValueError, UnicodeDecodeError):
        return None
    if not isinstance(d, dict) or d.get("values") != 0:  # not the payload's own key
        return None
    return d, inner


def peek_mqtt_payload(
    payload: bytes | str, n_elements: int, max_bytes: int | None = None
) -> tuple[int, float] | None:
    """A payload's ``seq`` and ``t`` without parsing its values, for a frame that will not be
    processed (a station that is behind skips it, taking only its time): the ``values`` list
    is counted and left out of the JSON that is parsed. None when the payload is not of that
    plain form (numbers or nulls in one list) or has another count: then parse it whole (which
    says whether the list is JSON and how many values it has). The size is checked first."""
    limit = payload_limit(n_elements) if max_bytes is None else max_bytes
    if len(payload) > limit:
        raise PayloadSizeError(len(payload), limit)
    got = _splice(payload.encode() if isinstance(payload, str) else payload)
    if got is None:
        return None
    d, inner = got
    try:
        seq, t = _seq_and_t(d)
    except ProtocolError:
        return None  # (parsed whole: the error named there)
    count = inner.count(b",") + 1 if inner.strip() else 0
    return (seq, float(t)) if count == n_elements else None


def parse_mqtt_payload(
    payload: bytes | str, n_elements: int, max_bytes: int | None = None
) -> Frame:
    """Parse one MQTT message (JSON, see the module docstring); ``max_bytes`` (default
    :func:`payload_limit`) is checked first, before anything is parsed. A payload of the
    plain form is read whole by the compiled core in one call (:func:`_parse_plain`: the keys
    ``seq``, ``t``, ``values``, ``unit`` and ``dt`` only); one with other keys has its values
    list read by the core (:func:`texsense._core.parse_json_numbers`, JSON's number grammar)
    and the rest by :mod:`json`; anything else, and anything the core does not read, is
    parsed whole, which names what is wrong. All give the same frame (tested on generated
    payloads)."""
    limit = payload_limit(n_elements) if max_bytes is None else max_bytes
    if len(payload) > limit:
        raise PayloadSizeError(len(payload), limit)
    plain = _parse_plain(payload, n_elements) if isinstance(payload, bytes) else None
    if plain is not None:
        return plain
    got = _splice(payload) if isinstance(payload, bytes) else None
    values = None if got is None else parse_json_numbers(got[1], n_elements)
    if got is not None and values is not None:
        return _frame_of(got[0], values, n_elements)
    return _parse_whole(payload, n_elements)


#: The canonical units of the unit texts plain payloads have carried (None: not a frame's).
_PLAIN_UNITS: dict[str | None, str | None] = {}


def _plain_unit(text: str | None) -> str | None:
    """A plain payload's unit (``None``: not given, pF) as :func:`_frame_of` reads it, or None
    when that would refuse it (then the full parse says why); remembered per text."""
    if text in _PLAIN_UNITS:
        return _PLAIN_UNITS[text]
    try:
        unit: str | None = _frame_unit("pF" if text is None else text)
    except ProtocolError:
        unit = None
    if len(_PLAIN_UNITS) < 64:  # (a mat sends one or two)
        _PLAIN_UNITS[text] = unit
    return unit


def _parse_plain(payload: bytes, n_elements: int) -> Frame | None:
    """A payload of the plain form (the keys ``seq``, ``t``, ``values``, ``unit``, ``dt``,
    each once, no escapes; what mats send) read in one compiled call
    (:func:`texsense._core.parse_json_frame`, without the interpreter lock), the frame being
    the one :func:`_frame_of` makes of it; None for anything else or anything it would
    refuse (the caller's parse then reads it or names the error)."""
    got = parse_json_frame(payload, n_elements)
    if got is None:
        return None
    seq, t, text, dt, values = got
    unit = _plain_unit(text)
    if unit is None:
        return None
    try:
        times = _element_times(t, 0.0 if dt is None else dt, n_elements)
    except ProtocolError:
        return None
    return Frame(seq, times, values, unit)


def _parse_whole(payload: bytes | str, n_elements: int) -> Frame:
    """:func:`parse_mqtt_payload` by :mod:`json` alone (the size already checked)."""
    try:
        text = payload.decode("utf-8") if isinstance(payload, bytes) else payload
    except UnicodeDecodeError:
        raise ProtocolError("payload is not JSON: not UTF-8 text") from None
    try:
        d: Any = json_loads(text)
    except ValueError as e:
        raise ProtocolError(f"payload is not JSON: {e}") from None
    if not isinstance(d, dict):
        raise ProtocolError("payload must be a JSON object")
    for key in ("seq", "t", "values"):
        if key not in d:
            raise ProtocolError(f"payload lacks {key!r}")
    _seq_and_t(d)
    vals = d["values"]
    if not isinstance(vals, list):
        raise ProtocolError(f"'values' must be a list of {n_elements} numbers")
    if len(vals) != n_elements:
        raise CountError(
            f"'values' must be a list of {n_elements} numbers, got {len(vals)}", len(vals)
        )
    return _frame_of(d, _values(vals, n_elements), n_elements)


def _seq_and_t(d: dict[str, Any]) -> tuple[int, float]:
    """A payload's ``seq`` and ``t``, checked (after its keys were)."""
    for key in ("seq", "t"):
        if key not in d:
            raise ProtocolError(f"payload lacks {key!r}")
    seq, t = d["seq"], d["t"]
    if not isinstance(seq, int) or isinstance(seq, bool) or not 0 <= seq <= MAX_INT:
        raise ProtocolError(f"'seq' must be an integer in 0..2**63-1, got {shown(seq, 20)}")
    if not isinstance(t, (int, float)) or isinstance(t, bool) or not _finite(t):
        raise ProtocolError(f"'t' must be a finite number, got {shown(t, 20)}")
    return seq, t


def _frame_unit(unit: Any) -> str:
    """A frame's unit, canonical, checked: a text naming a capacitance or a pressure."""
    if not isinstance(unit, str):
        raise ProtocolError("'unit' must be a string")
    try:
        unit = units.canonical(unit)
    except ValueError as e:
        raise ProtocolError(str(e)) from None
    if units.quantity_of(unit) not in ("capacitance", "pressure"):
        raise ProtocolError(f"unit {unit!r} is neither capacitance nor pressure")
    return str(unit)


def _frame_of(d: dict[str, Any], values: np.ndarray, n_elements: int) -> Frame:
    """The frame of a payload's object ``d`` whose values were read: its seq, time, unit
    and element times, checked."""
    seq, t = _seq_and_t(d)
    unit = _frame_unit(d.get("unit", "pF"))
    if "element_times" in d:
        et = d["element_times"]
        ok = isinstance(et, list) and len(et) == n_elements
        if not ok or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and _finite(x) for x in et
        ):
            raise ProtocolError(f"'element_times' must be {n_elements} finite numbers")
        times = np.asarray(et, dtype=np.float64)
    else:
        times = _element_times(t, d.get("dt", 0.0), n_elements)
    return Frame(seq, times, values, unit)


def _element_times(t: float, dt: Any, n_elements: int) -> np.ndarray:
    """The element times of a frame at ``t`` whose elements are ``dt`` apart, checked."""
    if not isinstance(dt, (int, float)) or isinstance(dt, bool) or not dt >= 0:
        raise ProtocolError("'dt' must be a number >= 0")
    if not _finite(dt):
        raise ProtocolError("'t' + 'dt' x elements is not a finite time")
    if dt == 0:  # every element at t (the same bits as the sum below, one array)
        times = np.full(n_elements, float(t) + 0.0)
    else:
        times = np.asarray(float(t) + float(dt) * np.arange(n_elements), dtype=np.float64)
    if not np.isfinite(times[-1]):
        raise ProtocolError("'t' + 'dt' x elements is not a finite time")
    return times


ANNOUNCE = "#layout "


def layout_announcement(layout: Layout, **info: Any) -> str:
    """The ``#layout`` comment line of a grid ``layout`` (without newline), with ``info``
    (JSON-able: the device, its spacer, frame time, ...) added to it.

    >>> from texsense.data.layout import Layout
    >>> line = layout_announcement(Layout.grid(2, 3, pitch_cm=1.5), spacer="textile-3mm")
    >>> line[:61]
    '#layout {"grid": [2, 3], "pitch_cm": [1.5, 1.5], "element_cm"'
    >>> parse_announcement(line)[0] == Layout.grid(2, 3, pitch_cm=1.5)
    True
    """
    if layout.shape is None or layout.pitch_cm is None:
        raise ProtocolError("only a grid layout can be announced on the serial line")
    rows, cols = layout.shape
    size = np.unique(layout.size_cm, axis=0)
    if size.shape[0] != 1:
        raise ProtocolError("only a grid of equal elements can be announced")
    d: dict[str, Any] = {
        "grid": [int(rows), int(cols)],
        "pitch_cm": [float(v) for v in layout.pitch_cm],
        "element_cm": [float(size[0, 1]), float(size[0, 0])],  # (height, width)
    }
    active = layout.active
    if active is not None and not bool(np.all(active)):
        bits = np.packbits(np.asarray(active, dtype=bool).ravel())
        d["active"] = bits.tobytes().hex()
    d["elements"] = layout.n_elements
    if layout.orientation:
        d["orientation"] = layout.orientation
    d.update(info)
    line = ANNOUNCE + json.dumps(d)
    if len(line) > MAX_LINE:
        raise ProtocolError(f"the announcement is longer than {MAX_LINE} characters")
    return line


def parse_announcement(line: str | bytes) -> tuple[Layout, dict[str, Any]] | None:
    """(layout, the other keys) of a ``#layout`` line; None for any other line;
    :class:`ProtocolError` naming the field for a malformed announcement."""

    if isinstance(line, bytes):
        line = line.decode("ascii", errors="replace")
    line = line.strip()
    if not line.startswith(ANNOUNCE.strip()):
        return None
    if len(line) > MAX_LINE:
        raise ProtocolError(f"announcement longer than {MAX_LINE} characters")
    try:
        d = json_loads(line[len(ANNOUNCE) - 1 :])
    except ValueError as e:
        raise ProtocolError(f"layout announcement is not JSON: {e}") from None
    if not isinstance(d, dict):
        raise ProtocolError("layout announcement must be a JSON object")
    try:
        rows, cols = (int(v) for v in whole_numbers(d["grid"], "grid"))
        pitch = tuple(float(v) for v in d["pitch_cm"])
        element = tuple(float(v) for v in d.get("element_cm", pitch))
        if not (0 < rows <= 4096 and 0 < cols <= 4096) or len(pitch) != 2 or len(element) != 2:
            raise ValueError("grid, pitch_cm and element_cm need two positive numbers each")
        active = None
        if "active" in d:
            bits = np.unpackbits(np.frombuffer(bytes.fromhex(str(d["active"])), np.uint8))
            if bits.size < rows * cols:
                raise ValueError("'active' has fewer bits than the grid has cells")
            active = bits[: rows * cols].reshape(rows, cols).astype(bool)
        layout = Layout.grid(
            rows, cols, pitch_cm=(pitch[0], pitch[1]), active=active,
            element_size_cm=(element[0], element[1]),
        )  # fmt: skip
        if d.get("orientation") is not None:
            layout = layout.with_orientation(parse_orientation(d["orientation"]))
    except ParameterError as e:
        raise ProtocolError(f"layout announcement: {e}") from None
    except (KeyError, TypeError, ValueError, OverflowError) as e:
        what = f"lacks {e}" if isinstance(e, KeyError) else str(e)
        raise ProtocolError(f"layout announcement {what}") from None
    if "elements" in d and d["elements"] != layout.n_elements:
        raise ProtocolError(
            f"layout announcement says {d['elements']} elements, its grid has {layout.n_elements}"
        )
    layout_keys = ("grid", "pitch_cm", "element_cm", "active", "orientation")
    info = {k: v for k, v in d.items() if k not in layout_keys}
    return layout, info
