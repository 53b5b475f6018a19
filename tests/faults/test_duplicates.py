"""Family "a JSON object with a key twice" (harden9 item 6): ``json`` keeps the last of two
equal keys without a word, so ``{"gain": 1, "gain": 1e9}`` meant to one reader what another
(a hash, a viewer, a parser that keeps the first) did not see. Every JSON texsense reads from
outside goes through :func:`texsense.data.files.json_loads`, which refuses it, so that it is
one line naming the file (every place a file's JSON is read, the model files), a
``ProtocolError`` (MQTT payloads, a device's ``#layout`` line) or a 400 (every route of both
servers that takes a body: :class:`texsense.monitor.web.Guard` checks every body with it).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient

from faults._families import batch, one_line
from faults.test_nesting import PLACES
from faults.test_requests import UNSAFE, _fill, _routes
from faults.test_web import BASE
from texsense import Layout, Recording
from texsense.data.files import json_loads
from texsense.data.protocol import ProtocolError, parse_announcement, parse_mqtt_payload
from texsense.io import save

#: JSON texts with a key twice: at the top, deep inside, and spelt once with an escape
DUPLICATES = {
    "at the top": '{"a": 1, "a": 2}',
    "nested": '[1, {"b": {"c": 1, "c": 1}}]',
    "spelt with an escape": '{"k": 1, "\\u006b": 2}',
}


def test_json_loads_refuses_a_key_twice():
    for text in DUPLICATES.values():
        for given in (text, text.encode()):
            with pytest.raises(json.JSONDecodeError, match="twice"):
                json_loads(given)
    assert json_loads('{"a": {"a": 1}, "b": [{"a": 2}, {"a": 3}]}')["b"][1] == {"a": 3}


def test_a_key_twice_in_a_file_is_one_line(tmp_path, fault_row):
    argvs, names = [], []
    for kind, text in DUPLICATES.items():
        for place, make in PLACES.items():
            folder = tmp_path / f"f{len(argvs)}"
            folder.mkdir()
            argv, name = make(folder, text)
            argvs.append(argv)
            names.append((kind, place, name))
    # a model file (the calibration of process): its format key twice
    cap = Recording(np.full((4, 12), 10.0), np.arange(4.0), Layout.grid(3, 4), "capacitance", "pF")
    save(cap, tmp_path / "cap.h5")
    from texsense.cli import main

    lin = tmp_path / "lin.json"
    assert main(["calibrate", "linear", "--like", str(tmp_path / "cap.h5"), "--gain", "2",
                 "--to", "pressure:N/cm2", "-o", str(lin)]) == 0  # fmt: skip
    text = lin.read_text(encoding="utf-8")
    for k, key in enumerate(("format", "content")):
        doc = json.loads(text)
        twice = "{" + json.dumps(key) + ": " + json.dumps(doc[key]) + ", " + text.strip()[1:]
        path = tmp_path / f"model-{k}.json"
        path.write_text(twice, encoding="utf-8")
        argvs.append(["process", str(tmp_path / "cap.h5"), "--calibration", str(path), "-o",
                      str(tmp_path / f"out-{k}.h5")])  # fmt: skip
        names.append((f"{key} twice", "a model file (process --calibration)", path.name))
    results, _, _ = batch(argvs, tmp_path)
    wrong = []
    for (kind, place, name), (rc, _out, err) in zip(names, results, strict=True):
        try:
            line = one_line(rc, err, name)
            assert "twice in one object" in line, line  # (the folder says twice too)
        except AssertionError as e:
            wrong.append(f"{kind} / {place}: {str(e)[:300]}")
    assert wrong == [], f"{len(wrong)} of {len(argvs)}:\n" + "\n".join(wrong)
    fault_row("duplicate keys", f"a key twice ({', '.join(DUPLICATES)}) at {len(PLACES)} places "
              "a file's JSON is read (info, report), and in a model file", "clear error",
              cases=len(argvs))  # fmt: skip


def test_a_key_twice_in_a_message_is_a_protocol_error(fault_row):
    tried, wrong = 0, []
    payloads = [
        '{"seq": 1, "seq": 2, "t": 0, "values": [1, 2]}',
        '{"seq": 1, "t": 0, "t": 5, "values": [1, 2]}',
        '{"seq": 1, "t": 0, "values": [1, 2], "values": [3, 4]}',
        '{"seq": 1, "t": 0, "unit": "pF", "values": [1, 2], "unit": "kPa"}',
        '{"seq": 1, "t": 0, "values": [1, 2], "x": {"a": 1, "a": 2}}',
    ]
    for payload in payloads:
        for given in (payload, payload.encode()):
            tried += 1
            try:
                parse_mqtt_payload(given, 2, max_bytes=1 << 20)
                wrong.append(f"taken: {payload}")
            except ProtocolError as e:
                if "twice" not in str(e):
                    wrong.append(f"{payload}: {e}")
    for line in ('#layout {"grid": [1, 2], "grid": [2, 1], "pitch_cm": [1, 1]}',
                 '#layout {"grid": [1, 2], "pitch_cm": [1, 1], "pitch_cm": [2, 2]}'):  # fmt: skip
        tried += 1
        try:
            parse_announcement(line)
            wrong.append(f"taken: {line}")
        except ProtocolError as e:
            if "twice" not in str(e):
                wrong.append(f"{line}: {e}")
    assert wrong == [], f"{len(wrong)} of {tried}:\n" + "\n".join(wrong)
    fault_row("duplicate keys", "a key twice in an MQTT payload (seq, t, values, unit, another) "
              "or a device's #layout line", "refused", "ProtocolError naming the key",
              cases=tried)  # fmt: skip


@pytest.mark.parametrize("kind", ["monitor", "station"])
def test_a_key_twice_in_a_request_body_is_a_400(kind, tmp_path, fault_row):
    from faults.test_web import loaded_monitor, loaded_station
    from texsense.monitor.server import create_app
    from texsense.station.server import create_ward_app

    if kind == "monitor":
        m = loaded_monitor(tmp_path)
        application, alert = create_app(m, run_source=False), m.tracker.open_alert.id
    else:
        st = loaded_station(tmp_path)
        application = create_ward_app(st)
        alert = st.mats["bed1"].monitor.tracker.open_alert.id
    unsafe = [(m, p) for m, p in _routes(application) if m in UNSAFE]
    bodies = [b'{"frames": 5, "frames": 100000}', b'{"kind": "bed", "kind": "seat"}',
              b'{"regions": [], "regions": [{"a": 1, "a": 2}]}']  # fmt: skip
    tried, wrong = 0, []
    with TestClient(application, base_url=BASE) as client:
        for method, path in unsafe:
            for body in bodies:
                for headers in ({"Content-Type": "application/json"}, {}):
                    r = client.request(method, _fill(path, alert), content=body, headers=headers)
                    tried += 1
                    if r.status_code != 400 or "twice" not in r.text:
                        wrong.append(f"{method} {path} {body!r}: {r.status_code} {r.text[:120]}")
    assert wrong == [], f"{len(wrong)} of {tried}:\n" + "\n".join(wrong)
    fault_row("duplicate keys", f"{kind}: {len(unsafe)} routes that take a body x a key twice",
              "refused", f"{tried} requests: 400 naming the key", cases=tried)  # fmt: skip
