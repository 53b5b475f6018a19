"""A mat's state as one small versioned container of named parts: what a station of a group
writes where every member can read it, and what the member that takes the mat over goes on
from (docs/station.md, "A group of stations").

The container::

    b"TXSCKPT\\0"  u32 version  u32 header length  header (JSON)  part bytes ...

The header names the mat, the frame time and wall clock of the state, and each part with its
length; every part is zlib-compressed. A part is registered with :func:`register_part`: a name,
how to save it from a :class:`~texsense.station.ward.MatEntry` (bytes, or None when the mat
has no such state) and how to restore it, and how often it is written:

- ``monitor`` (every checkpoint, a few kB): the exposure of every exposed element and the
  open alert (:meth:`~texsense.apps.alerts.ExposureTracker.state_packed`: arrays' bytes,
  exact; version 1 of the part held rows, still read), the bed's side, time on
  it and turning schedule (:meth:`~texsense.apps.bed.TurningSchedule.state`), the posture
  vote, the mat's clock (:meth:`~texsense.monitor.clock.FrameClock.state`) and its counters;
- ``pipeline`` (every ``sensor_every``-th checkpoint: 100-300 kB for 1024 elements): the
  compiled chain's state (:meth:`~texsense.compensation.pipeline.Pipeline.snapshot`:
  Preisach memory, drift history, detector, repair).

A part this version does not know is skipped with one line; a part that does not fit (another
calibration, another layout) is refused with one line naming the mat and the part, and that
part of the mat starts afresh: the others are restored all the same.

:func:`replay` applies the alert events a holder stored after its last checkpoint (a
reposition alert raised, acknowledged or cleared, a turn) to the restored state, so that an
alert raised just before a station died is not raised again, and an acknowledgement is kept.

Examples
--------
>>> blob = pack({"monitor": b'{"a": 1}'}, mat="bed7", t=12.5)
>>> head, parts = unpack(blob)
>>> head["mat"], head["t"], parts
('bed7', 12.5, {'monitor': b'{"a": 1}'})
"""

from __future__ import annotations

import json
import logging
import struct
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from texsense.apps.alerts import Alert
from texsense.data import stored
from texsense.exceptions import ParameterError, shown

if TYPE_CHECKING:
    from texsense.station.ward import MatEntry

__all__ = [
    "PARTS",
    "Part",
    "Taken",
    "fresh",
    "pack",
    "register_part",
    "replay",
    "restore",
    "save",
    "take",
    "unpack",
]

log = logging.getLogger("texsense.station")

#: The first bytes of a checkpoint.
MAGIC = b"TXSCKPT\x00"
#: The container's version (the parts carry their own).
VERSION = 1
#: The monitor part's own version.
MONITOR_VERSION = 2
#: The most bytes a part may unpack to (a 4096-element mat's sensor state is ~2 MB): a part
#: that inflates further is a damaged checkpoint, refused before it fills the memory.
MAX_PART_BYTES = 64 << 20
#: What a part's restore raises on data that does not fit it (a checkpoint of another
#: version, a damaged row): the part starts afresh (:class:`Part`).
NOT_FITTING = (ValueError, TypeError, KeyError, AttributeError, IndexError, OverflowError)


@dataclass(frozen=True)
class Part:
    """A named part of a mat's checkpoint: ``save(entry)`` gives its bytes, or a function
    of copies taken now that makes a JSON-ready dict later, off the event loop (None: nothing
    to save), ``restore(entry, data)`` goes on from the bytes (raising ``ValueError`` when
    they do not fit), ``fresh(entry)`` starts the part as if nothing were stored (also after
    a restore that did not fit: never half of one); ``often``: written with every
    checkpoint, else with every ``sensor_every``-th."""

    name: str
    save: Callable[[MatEntry], bytes | Callable[[], dict[str, Any]] | None]
    restore: Callable[[MatEntry, bytes], None]
    fresh: Callable[[MatEntry], None]
    often: bool = True


#: The parts, by name, in the order they are restored.
PARTS: dict[str, Part] = {}


def register_part(part: Part) -> Part:
    """Add a part (e.g. an in-use drift estimator's state) to every checkpoint."""
    PARTS[part.name] = part
    return part


def pack(parts: dict[str, bytes], **head: Any) -> bytes:
    """The container of ``parts`` (name -> bytes) with ``head`` (JSON-ready) in its header."""
    packed = {name: zlib.compress(data, 1) for name, data in parts.items()}
    header = json.dumps(
        {**head, "parts": [[name, len(data)] for name, data in packed.items()]},
        separators=(",", ":"),
    ).encode()
    return b"".join([MAGIC, struct.pack("<II", VERSION, len(header)), header, *packed.values()])


def unpack(blob: bytes) -> tuple[dict[str, Any], dict[str, bytes]]:
    """The header and the parts of a container; anything else is one ParameterError."""
    k = len(MAGIC)
    if blob[:k] != MAGIC or len(blob) < k + 8:
        raise ParameterError("not a texsense checkpoint")
    version, size = struct.unpack_from("<II", blob, k)
    if version != VERSION:
        raise ParameterError(f"a checkpoint of version {version}; this version reads {VERSION}")
    start = k + 8
    try:
        head = json.loads(blob[start : start + size])
        at = start + size
        parts: dict[str, bytes] = {}
        for name, length in head.pop("parts"):
            parts[str(name)] = _inflated(blob[at : at + int(length)], str(name))
            at += int(length)
    except (*NOT_FITTING, zlib.error) as e:
        raise ParameterError(f"a damaged checkpoint: {e}") from None
    if at != len(blob):
        raise ParameterError("a damaged checkpoint: bytes left over after its parts")
    return head, parts


def _inflated(data: bytes, name: str) -> bytes:
    """A part's bytes unpacked, at most :data:`MAX_PART_BYTES` of them."""
    z = zlib.decompressobj()
    out = z.decompress(data, MAX_PART_BYTES)
    if z.unconsumed_tail:
        raise ParameterError(f"a damaged checkpoint: its part {name!r} unpacks to more than "
                             f"{MAX_PART_BYTES >> 20} MB")  # fmt: skip
    if not z.eof:
        raise ParameterError(f"a damaged checkpoint: its part {name!r} is cut short")
    return out


@dataclass(frozen=True)
class Taken:
    """A mat's state as the parts' bytes or functions that make them, taken at once (on the
    event loop that changes it) and packed later, elsewhere (:meth:`pack`: the JSON text
    and the compression, in the journal's thread)."""

    parts: dict[str, bytes | Callable[[], dict[str, Any]]]
    head: dict[str, Any]

    def pack(self) -> bytes:
        """The container (:func:`pack`)."""
        return pack({name: data if isinstance(data, bytes) else
                     json.dumps(data(), separators=(",", ":")).encode()
                     for name, data in self.parts.items()}, **self.head)  # fmt: skip


def take(entry: MatEntry, often: bool = True) -> Taken:
    """The parts written every time (``often``), or the others, of the mat's state now."""
    parts: dict[str, bytes | Callable[[], dict[str, Any]]] = {}
    for part in PARTS.values():
        if part.often != often:
            continue
        data = part.save(entry)
        if data is not None:
            parts[part.name] = data
    return Taken(parts, {"mat": entry.id, "t": entry.monitor.clock.last_t, "wall": time.time()})


def save(entry: MatEntry, often: bool = True) -> bytes:
    """The mat's checkpoint of the parts written every time (``often``), or of the others."""
    return take(entry, often).pack()


def restore(entry: MatEntry, blobs: list[bytes]) -> dict[str, Any]:
    """Go on from checkpoints of the mat (later blobs' parts win): every part this version
    knows is restored, each on its own. Returns what was restored and what refused."""
    parts: dict[str, bytes] = {}
    head: dict[str, Any] = {}
    for blob in blobs:
        h, p = unpack(blob)
        if h.get("mat") != entry.id:
            raise ParameterError(f"a checkpoint of mat {h.get('mat')!r}, not of {entry.id!r}")
        head = h
        parts.update(p)
    restored, refused = [], {}
    for name, data in parts.items():
        part = PARTS.get(name)
        if part is None:
            log.warning("mat %s: the checkpoint's part %r is unknown here; skipped", entry.id, name)
            refused[name] = "unknown"
            continue
        try:
            part.restore(entry, data)
            restored.append(name)
        except NOT_FITTING as e:  # ParameterError too: that part starts afresh, whole
            log.warning("mat %s: the checkpoint's %s does not fit (%s); it starts afresh",
                        entry.id, name, e)  # fmt: skip
            refused[name] = str(e)
            part.fresh(entry)
    return {"t": head.get("t"), "wall": head.get("wall"), "parts": restored, "refused": refused}


# ------------------------------------------------------------------------ the monitor part
def _save_monitor(entry: MatEntry) -> Callable[[], dict[str, Any]]:
    """The monitor's state, taken now (copies; the exposure as arrays' bytes,
    :meth:`~texsense.apps.alerts.ExposureTracker.state_packed`), its JSON text made when
    called: in the journal's thread, not on the event loop."""
    state = {
        "version": MONITOR_VERSION,
        **entry.monitor.resume_state(),
        "mat": {
            "messages": entry.messages,
            "malformed": entry.malformed,
            "ignored": entry.ignored,
            "failed": entry.failed,
            "period_s": entry.period_s,
            "last_wall": entry.last_wall,
            "refused": entry.refused,
            "state": entry.state,
        },
    }

    return lambda: state


#: The states of a mat a checkpoint holds (the ward's ``alert`` and ``acknowledged`` are
#: those of a live mat with an open alert).
MAT_STATES = ("waiting", "live", "stale", "refused")


def _restore_monitor(entry: MatEntry, data: bytes) -> None:
    state = json.loads(data)
    version = state.get("version") if isinstance(state, dict) else None
    if isinstance(version, bool) or version not in (1, MONITOR_VERSION):  # 1: exposure as rows
        raise ParameterError(f"monitor state of version {shown(version)}")
    mat, what = state.get("mat"), "mat"
    counts = [stored.whole(mat, k, what) for k in ("messages", "malformed", "ignored", "failed")]
    period_s = stored.optional_number(mat, "period_s", what, lo=0)
    last_wall = stored.optional_number(mat, "last_wall", what)
    refused = stored.optional_text(mat, "refused", what)
    mat_state = stored.optional_text(mat, "state", what, choices=MAT_STATES) or "waiting"
    entry.monitor.resume(state)
    entry.messages, entry.malformed, entry.ignored, entry.failed = counts
    entry.period_s, entry.last_wall, entry.last_seen = period_s, last_wall, last_wall
    entry.refused, entry.state = refused, mat_state
    if entry.state == "live":  # stale once two of its periods pass without a frame here
        entry.last_wall = entry.last_seen = time.time()
    entry.version += 1


def _fresh_monitor(entry: MatEntry) -> None:
    entry.monitor.start_afresh()
    entry.state, entry.last_wall, entry.period_s, entry.refused = "waiting", None, None, None
    entry.last_seen = None
    entry.version += 1


def _save_pipeline(entry: MatEntry) -> bytes | None:
    pipeline = entry.monitor.pipeline
    return None if pipeline is None else bytes(pipeline.snapshot())


def _fresh_pipeline(entry: MatEntry) -> None:
    if entry.monitor.pipeline is not None:
        entry.monitor.pipeline.reset()


def _restore_pipeline(entry: MatEntry, data: bytes) -> None:
    pipeline = entry.monitor.pipeline
    if pipeline is None:
        raise ParameterError("the mat has no calibration here")
    pipeline.restore(data)


register_part(Part("monitor", _save_monitor, _restore_monitor, _fresh_monitor, often=True))
register_part(Part("pipeline", _save_pipeline, _restore_pipeline, _fresh_pipeline, often=False))


def fresh(entry: MatEntry) -> None:
    """Start the mat afresh (no checkpoint of it anywhere): every part as if nothing were
    stored (unloaded spacer states, no exposure, no alert, a new clock)."""
    for part in PARTS.values():
        part.fresh(entry)


# ------------------------------------------------------------------------ the events after
def replay(entry: MatEntry, events: list[dict[str, Any]]) -> list[str]:
    """Apply the alert events stored after the checkpoint (oldest first; rows of the event
    store: kind, t, alert, detail) to the restored state; returns the kinds applied. An
    event whose values are not of their kinds is skipped, with a warning."""
    tracker = entry.monitor.tracker
    schedule = entry.monitor.bed.schedule if entry.monitor.bed is not None else None
    applied = []
    for e in events:
        try:
            kind, t, alert_id, detail = _event_row(e, len(tracker.names))
        except ParameterError as err:
            log.warning("mat %s: an event stored after the checkpoint is skipped: %s",
                        entry.id, err)  # fmt: skip
            continue
        known = {a.id: a for a in tracker.alerts}
        if kind == "reposition" and alert_id is not None and alert_id not in known:
            if tracker.open_alert is None:  # raised after the checkpoint: it stays raised
                alert = Alert(alert_id, t, detail["elements"], tracker.reposition_s,
                              where=detail["where"])  # fmt: skip
                tracker.adopt(alert)
        elif kind in ("acknowledged", "cleared") and alert_id in known:
            alert = known[alert_id]
            if kind == "acknowledged" and alert.acknowledged_t is None:
                alert.acknowledged_t = t
            if kind == "cleared":
                alert.cleared_t = t
                tracker.alerts = [a for a in tracker.alerts if a.cleared_t is None]
        elif schedule is not None and kind == "turn-due" and schedule.due_since is None:
            schedule.due_since = t
        elif schedule is not None and kind == "turn-done":
            schedule.due_since = None
        elif schedule is not None and kind in ("turn", "in-bed"):
            schedule.side = detail.get("to") or detail.get("side") or schedule.side
            schedule.since_t = t
            schedule.turns += kind == "turn"
        elif schedule is not None and kind == "out-of-bed":
            schedule.side, schedule.since_t = None, None
        elif kind in ("seated", "left", "in-bed", "out-of-bed", "loaded", "unloaded"):
            tracker.seated = kind in ("seated", "in-bed", "loaded")
        else:
            continue
        applied.append(kind)
    if applied:
        entry.version += 1
    return applied


def _event_row(e: Any, places: int) -> tuple[str, float, int | None, dict[str, Any]]:
    """An event row's kind, time, alert id and the detail :func:`replay` reads, each of its
    kind (``elements`` within ``places``), or a :class:`ParameterError` naming it."""
    what = "event"
    kind = stored.optional_text(e, "kind", what) or ""
    t = stored.number(e, "t", what)
    alert_id = stored.optional_whole(e, "alert", what, lo=1)
    raw = e.get("detail") or {}
    if not isinstance(raw, dict):
        raise ParameterError(f"the stored event's detail is {shown(raw)}, not an object")
    detail = {
        "elements": stored.wholes(raw, "elements", what, hi=places) if "elements" in raw else [],
        "where": stored.texts(raw, "where", what, default=[]),
        "to": stored.optional_text(raw, "to", what),
        "side": stored.optional_text(raw, "side", what),
    }
    return kind, t, alert_id, detail
