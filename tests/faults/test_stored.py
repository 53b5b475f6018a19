"""Family "state stored by another process": a mat's checkpoint, read by the member that
takes the mat over, was written by another process, maybe another version, and lies in a
database row that can be damaged. Every value of it is read as the type it must have
(:mod:`texsense.data.stored`, the restores of the clock, the exposure, the alert, the bed's
schedule and the posture vote); a part that does not fit is refused **whole** and starts
afresh (:class:`texsense.station.checkpoint.Part`'s ``fresh``: never half a part), the other
parts are kept, a damaged container starts the mat afresh, and no part unpacks beyond
``MAX_PART_BYTES``. Before, a value of another type was taken and failed a frame later (a
period of ``[1, 2]``: a ``TypeError`` in the next frame's arrival), a missing key stopped
the takeover with a ``KeyError``, and a refused part was left half restored.
"""

from __future__ import annotations

import json
import random

import numpy as np
import pytest

from texsense.apps.alerts import Alert
from texsense.exceptions import ParameterError
from texsense.monitor.store import EventStore
from texsense.station import checkpoint
from texsense.station.ward import MatEntry

AREA = "stored state"
#: values no checkpoint of this version holds at any place (and the place deleted)
ODD = [None, "x", -1, 2**70, 1e308, float("nan"), [], {}, [1, 2], True, 0.5]


def _places(obj: object, prefix: tuple = ()) -> list[tuple]:
    """Every place in a JSON value (the first three items of a list)."""
    out = [prefix]
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _places(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj[:3]):
            out += _places(v, (*prefix, i))
    return out


def _changed(obj: object, place: tuple, value: object, delete: bool) -> object:
    """A copy of ``obj`` with ``place`` set to ``value`` (or deleted)."""
    obj = json.loads(json.dumps(obj))
    cur = obj
    for k in place[:-1]:
        cur = cur[k]
    if delete and isinstance(cur, dict):
        del cur[place[-1]]
    else:
        cur[place[-1]] = value
    return obj


@pytest.fixture(scope="module")
def taken(seat_mat, tmp_path_factory):
    """A seat after 40 frames, an alert open: its checkpoint's head and parts (unpacked)."""
    config, payloads = seat_mat
    a = MatEntry(config, EventStore(":memory:"), tmp_path_factory.mktemp("a"), 1.0)
    for p, now in payloads[:40]:
        a.handle(p, now)
    head, parts = checkpoint.unpack(checkpoint.take(a, often=True).pack())
    _, rarely = checkpoint.unpack(checkpoint.take(a, often=False).pack())
    state = json.loads(parts["monitor"])  # (an open alert: its fields are damaged too)
    alert = Alert(3, 30.0, [5, 6], 400.0, None, None, ["left"], ["row 1"], 1010.0)
    state["tracker"] = {**state["tracker"], "alert": alert.to_dict(), "next_id": 4}
    return head, {**parts, **rarely, "monitor": json.dumps(state).encode()}


def _goes_on(seat_mat, tmp_path, blob: bytes) -> dict:
    """Restore a new mat from ``blob`` as a taking member does (group._restored), then feed
    it frames: no exception anywhere, every time and exposure finite, a refused monitor part
    the fresh one's."""
    config, payloads = seat_mat
    b = MatEntry(config, EventStore(":memory:"), tmp_path, 1.0)
    try:
        info = checkpoint.restore(b, [blob])
    except ParameterError:  # a damaged container: the member starts the mat afresh
        checkpoint.fresh(b)
        info = {"parts": [], "refused": {"checkpoint": "damaged"}}
    if "monitor" not in info["parts"]:
        assert b.monitor.frames == 0 and b.monitor.tracker.exposure_s.max() == 0
        assert b.monitor.clock.last_t is None and b.state == "waiting"
        assert b.monitor.tracker.open_alert is None
    for p, now in payloads[40:43]:
        b.handle(p, now + 1.0)
    assert b.monitor.frames >= 1 and b.state in ("live", "alert", "acknowledged")
    assert np.isfinite(b.monitor.tracker.exposure_s).all()
    assert np.isfinite(b.monitor.clock.last_t) and np.isfinite(b.period_s or 0.0)
    return info


def test_the_checkpoint_the_cases_spoil_restores_whole(seat_mat, taken, tmp_path):
    head, parts = taken
    b = MatEntry(seat_mat[0], EventStore(":memory:"), tmp_path, 1.0)
    info = checkpoint.restore(b, [checkpoint.pack(parts, **head)])
    assert sorted(info["parts"]) == ["monitor", "pipeline"] and not info["refused"]
    assert b.monitor.tracker.open_alert.elements == [5, 6] and b.monitor.frames == 40


def test_every_place_of_the_monitor_part_of_another_kind_refuses_that_part_whole(
    seat_mat, taken, tmp_path, fault_row
):
    """Every place of the monitor part's JSON x every odd value, and deleted: the mat goes on;
    the part is either taken (the value is one it may hold) or refused whole, the sensor's
    state (the pipeline part) kept either way."""
    head, parts = taken
    state = json.loads(parts["monitor"])
    cases, refused = 0, 0
    for place in _places(state)[1:]:
        for value, delete in [*((v, False) for v in ODD), (None, True)]:
            bad = json.dumps(_changed(state, place, value, delete)).encode()
            blob = checkpoint.pack({**parts, "monitor": bad}, **head)
            info = _goes_on(seat_mat, tmp_path / str(cases), blob)
            assert "pipeline" in info["parts"], (place, value)
            cases += 1
            refused += "monitor" in info["refused"]
    assert cases > 500 and refused > cases // 2
    fault_row(AREA, "monitor part: every place x 11 values and deleted", "refused",
              f"{refused} refused whole, {cases - refused} taken", cases)  # fmt: skip


def test_damaged_bytes_of_the_container_or_a_part_never_stop_a_takeover(
    seat_mat, taken, tmp_path, fault_row
):
    """The container and each part cut, a byte flipped, bytes added, at 40 places each:
    restored, the part refused, or the mat started afresh, and the mat goes on."""
    head, parts = taken
    rng = random.Random(7)
    cases = 0
    for name in (None, "monitor", "pipeline"):
        base = checkpoint.pack(parts, **head) if name is None else parts[name]
        for how in ("cut", "flip", "add"):
            for at in sorted(rng.sample(range(len(base)), 40)):
                raw = bytearray(base)
                if how == "cut":
                    del raw[at:]
                elif how == "flip":
                    raw[at] ^= rng.randrange(1, 256)
                else:
                    raw[at:at] = rng.randbytes(rng.randrange(1, 17))
                blob = raw if name is None else checkpoint.pack({**parts, name: bytes(raw)}, **head)
                _goes_on(seat_mat, tmp_path / str(cases), bytes(blob))
                cases += 1
    fault_row(AREA, "container and parts: cut, flipped, added to", "mat live", "", cases)


def test_a_part_that_unpacks_beyond_its_budget_is_refused_before_it_is_unpacked(
    taken, monkeypatch, fault_row
):
    """A part inflating past checkpoint.MAX_PART_BYTES (a zip bomb in the database row) is a
    damaged checkpoint; one of exactly the budget is read."""
    head, parts = taken
    monkeypatch.setattr(checkpoint, "MAX_PART_BYTES", 1 << 20)
    blob = checkpoint.pack({**parts, "monitor": b" " * ((1 << 20) + 1)}, **head)
    assert len(blob) < 100_000
    with pytest.raises(ParameterError, match="unpacks to more than 1 MB"):
        checkpoint.unpack(blob)
    checkpoint.unpack(checkpoint.pack({**parts, "monitor": b" " * (1 << 20)}, **head))
    fault_row(AREA, "a part that unpacks beyond MAX_PART_BYTES", "clear error")


def test_events_stored_after_the_checkpoint_of_other_kinds_are_skipped(
    seat_mat, taken, tmp_path, fault_row
):
    """The events replayed after a checkpoint (rows of the event store another member
    wrote): every field of a reposition and an acknowledgement x every odd value, and
    deleted: applied or skipped with a warning, never an exception or an alert naming a
    place the mat does not have."""
    head, parts = taken
    config, payloads = seat_mat
    blob = checkpoint.pack({k: v for k, v in parts.items() if k != "monitor"}, **head)
    good = [
        {"kind": "reposition", "t": 70.0, "alert": 7,
         "detail": {"elements": [1, 2], "where": ["left"]}},
        {"kind": "acknowledged", "t": 71.0, "alert": 7, "detail": {}},
    ]  # fmt: skip
    b = MatEntry(config, EventStore(":memory:"), tmp_path / "good", 1.0)
    checkpoint.restore(b, [blob])
    assert checkpoint.replay(b, good) == ["reposition", "acknowledged"]
    assert b.monitor.tracker.open_alert.acknowledged_t == 71.0
    cases, skipped = 0, 0
    for k, event in enumerate(good):
        for place in _places(event)[1:]:
            for value, delete in [*((v, False) for v in ODD), (None, True)]:
                bad = _changed(good, (k, *place), value, delete)
                b = MatEntry(config, EventStore(":memory:"), tmp_path / str(cases), 1.0)
                checkpoint.restore(b, [blob])
                applied = checkpoint.replay(b, bad)
                alert = b.monitor.tracker.open_alert
                assert alert is None or all(0 <= i < 96 for i in alert.elements)
                for p, now in payloads[40:42]:
                    b.handle(p, now + 1.0)
                cases += 1
                skipped += len(applied) < 2
    assert cases > 100 and skipped > cases // 3
    fault_row(AREA, "events after the checkpoint: every field x 11 values and deleted",
              "skipped, warned", f"{skipped} not applied", cases)  # fmt: skip
