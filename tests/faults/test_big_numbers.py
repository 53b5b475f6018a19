"""Family "a JSON integer beyond any real number" (harden9, further attack): ``json`` reads
``1`` and 400 zeros as an exact integer, and every reader that takes it as a real number
raised ``OverflowError``: a traceback from ``report`` for a recording whose alert settings or
regions held one, a 500 from the monitor for such regions. :func:`texsense.data.files.json_loads`
refuses an integer no float holds, so every JSON from outside (the places of the nesting and
duplicate-key families, the alert settings of a recording's ``meta``, MQTT payloads, a device's
``#layout`` line, request bodies) says it in one line, a ``ProtocolError`` or a 4xx.
"""

from __future__ import annotations

import json

import h5py
import pytest
from fastapi.testclient import TestClient

from faults._families import batch, one_line, small_recording
from faults.test_nesting import PLACES
from faults.test_web import BASE, loaded_monitor
from texsense.data.files import json_loads
from texsense.data.protocol import ProtocolError, parse_announcement, parse_mqtt_payload
from texsense.io import save
from texsense.monitor.server import create_app

BIG = "1" + "0" * 400
#: texts with an integer beyond any float where a reader takes a real number
TEXTS = {
    "a region's corner": '[{"name": "a", "kind": "box", "points": [[@, 0], [1, 1]]}]'.replace(
        "@", BIG
    ),
    "negative, in an object": '{"a": -@}'.replace("@", BIG),
    "in a list": "[@]".replace("@", BIG),
}


def test_json_loads_refuses_a_number_beyond_any_float():
    for text in TEXTS.values():
        with pytest.raises(json.JSONDecodeError, match="beyond any real number"):
            json_loads(text)
    assert json_loads(f"[{2**1000}, -{2**1000}, 1e308]")[0] == 2**1000  # floats hold it
    with pytest.raises(ValueError, match="beyond"):
        json_loads("[" + "9" * 5000 + "]")  # (past Python's own limit of digits too)


def _meta_alerts(folder, text):
    path = save(small_recording(), folder / "alerts.h5")
    with h5py.File(path, "a") as f:
        f.attrs["meta"] = '{"alerts": {"threshold_mmhg": @}}'.replace("@", BIG)
    return ["report", str(path), "-o", str(folder / "alerts.html")], "alerts.h5"


def test_a_number_beyond_any_float_in_a_file_is_one_line(tmp_path, fault_row):
    argvs, names = [], []
    places = {**PLACES, "a recording's alert settings (meta)": _meta_alerts}
    for kind, text in TEXTS.items():
        for place, make in places.items():
            folder = tmp_path / f"f{len(argvs)}"
            folder.mkdir()
            argv, name = make(folder, text)
            argvs.append(argv)
            names.append((kind, place, name))
    results, _, _ = batch(argvs, tmp_path)
    wrong = []
    for (kind, place, name), (rc, _out, err) in zip(names, results, strict=True):
        try:
            line = one_line(rc, err, name)
            assert "beyond any real number" in line, line
        except AssertionError as e:
            wrong.append(f"{kind} / {place}: {str(e)[:300]}")
    assert wrong == [], f"{len(wrong)} of {len(argvs)}:\n" + "\n".join(wrong)
    fault_row("nesting", f"an integer of 401 digits at {len(places)} places a file's JSON is "
              "read (info, report)", "clear error", cases=len(argvs))  # fmt: skip


def test_in_a_message_and_a_body(tmp_path, fault_row):
    tried = 0
    for payload in ('{"seq": 1, "t": @, "values": [1, 2]}'.replace("@", BIG),
                    '{"seq": 1, "t": 0, "values": [@, 2]}'.replace("@", BIG),
                    '{"seq": 1, "t": 0, "values": [1, 2], "x": -@}'.replace("@", BIG)):  # fmt: skip
        with pytest.raises(ProtocolError):
            parse_mqtt_payload(payload.encode(), 2, max_bytes=1 << 20)
        tried += 1
    with pytest.raises(ProtocolError):
        parse_announcement('#layout {"grid": [1, 2], "pitch_cm": [@, 1]}'.replace("@", BIG))
    m = loaded_monitor(tmp_path)
    m.record_dir.mkdir(parents=True, exist_ok=True)
    save(small_recording(), m.record_dir / "ok.h5")
    with TestClient(create_app(m, run_source=False), base_url=BASE) as client:
        for text in TEXTS.values():
            r = client.put("/api/playback/ok.h5/rois", content=text.encode())
            assert r.status_code == 400 and "beyond any real number" in r.text, r.text[:200]
            tried += 1
    fault_row("nesting", "an integer of 401 digits in an MQTT payload, a #layout line, a "
              "regions body", "refused", cases=tried + 1)  # fmt: skip
