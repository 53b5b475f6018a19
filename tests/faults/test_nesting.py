"""Family "JSON nested too deeply": every place texsense parses JSON that came from outside (a
file's line or attribute, a sidecar, an option file, a label, a device's message) goes through
:func:`texsense.data.files.json_loads`, which turns text nested deeper than the parser's
recursion into the same ``ValueError`` as any other text that is not JSON. Without it a few
kB of ``[`` were a traceback in ``info`` and ``report``, a 500 from the monitor (the request
bodies: ``test_requests.py``) and, in a device's message, an exception that is no
``ProtocolError``, which ends the reading of a serial device.
"""

from __future__ import annotations

import json
import re

import h5py
import numpy as np
import pytest

from faults._families import batch, one_line, small_recording
from texsense.apps.clinical import EVENTS_LABEL
from texsense.data.files import json_loads
from texsense.data.protocol import ProtocolError, parse_announcement, parse_mqtt_payload
from texsense.io import save

#: JSON texts nested deeper than Python's parser recurses (its limit is about 1000 levels)
DEPTH = 3000
NESTINGS = {
    "arrays": "[" * DEPTH + "]" * DEPTH,
    "objects": '{"a":' * DEPTH + "1" + "}" * DEPTH,
    "mixed": '[{"a":' * (DEPTH // 2) + "1" + "}]" * (DEPTH // 2),
}


def _wide_csv(folder, key, text):
    path = folder / f"{key}.csv"
    save(small_recording(), path)
    src = path.read_text(encoding="utf-8")
    path.write_text(re.sub(rf"(?m)^# {key}: .*$", lambda m: f"# {key}: {text}", src), "utf-8")
    return ["info", str(path)], path.name


def _h5_attr(folder, where, text):
    path = folder / f"attr-{where.strip('/') or 'root'}.h5"
    save(small_recording(), path)
    with h5py.File(path, "a") as f:
        f[where].attrs["meta" if where == "/" else "orientation"] = text
    return ["info", str(path)], path.name


def _events_label(folder, text):
    rec = small_recording()
    events = np.array([text] + [""] * (rec.n_frames - 1))
    path = folder / "events.h5"
    save(rec.with_labels({EVENTS_LABEL: events}), path)
    return ["report", str(path), "-o", str(folder / "events.html")], "events.h5"


def _sidecar(folder, text):
    path = folder / "sidecar.h5"
    save(small_recording(), path)
    (folder / "sidecar.h5.rois.json").write_text(text, encoding="utf-8")
    return ["report", str(path), "-o", str(folder / "sidecar.html")], "sidecar.h5.rois.json"


def _rois_option(folder, text):
    path = folder / "option.h5"
    save(small_recording(), path)
    (folder / "regions.json").write_text(text, encoding="utf-8")
    out = str(folder / "option.html")
    return ["report", str(path), "--rois", str(folder / "regions.json"), "-o", out], "regions.json"


#: every place a file's JSON is parsed: (name, make(folder, text) -> (argv, the name the
#: error line must hold))
PLACES = {
    "wide CSV layout line": lambda d, t: _wide_csv(d, "layout", t),
    "wide CSV meta line": lambda d, t: _wide_csv(d, "meta", t),
    "HDF5 meta attribute": lambda d, t: _h5_attr(d, "/", t),
    "HDF5 layout orientation attribute": lambda d, t: _h5_attr(d, "/layout", t),
    "HDF5 events label of a live recording": _events_label,
    "a recording's regions sidecar": _sidecar,
    "report --rois": _rois_option,
}


def test_json_loads_says_nested_too_deeply_as_not_json():
    for text in NESTINGS.values():
        with pytest.raises(json.JSONDecodeError, match="nested too deeply"):
            json_loads(text)
        with pytest.raises(ValueError, match="nested too deeply"):
            json_loads(text.encode())
    assert json_loads('{"a": [1, 2]}') == {"a": [1, 2]}


def test_json_nested_too_deeply_in_a_file_is_one_line(tmp_path, fault_row):
    argvs, names = [], []
    for kind, text in NESTINGS.items():
        for place, make in PLACES.items():
            folder = tmp_path / f"{kind}-{len(argvs)}"
            folder.mkdir()
            argv, name = make(folder, text)
            argvs.append(argv)
            names.append((kind, place, name))
    results, _, _ = batch(argvs, tmp_path)
    for (kind, place, name), (rc, _out, err) in zip(names, results, strict=True):
        line = one_line(rc, err, name)
        assert "nested too deeply" in line, (kind, place, line)
    fault_row("nesting", f"JSON nested {DEPTH} deep ({', '.join(NESTINGS)}) at "
              f"{len(PLACES)} places a file's JSON is read (info, report)", "clear error",
              cases=len(argvs))  # fmt: skip


def test_json_nested_too_deeply_in_a_message_is_a_protocol_error(fault_row):
    tried = 0
    depth = 1500  # deeper than the parser recurses, within a payload's size
    for text in ("[" * depth + "]" * depth, '{"a":' * depth + "1" + "}" * depth):
        for payload in (text, '{"seq": 1, "t": 0, "values": ' + text + "}",
                        '{"seq": 1, "t": 0, "x": ' + text + ', "values": [1, 2]}'):  # fmt: skip
            with pytest.raises(ProtocolError):
                parse_mqtt_payload(payload.encode(), 2, max_bytes=1 << 20)
            tried += 1
        with pytest.raises(ProtocolError):
            parse_announcement("#layout " + text)
        with pytest.raises(ProtocolError):
            parse_announcement('#layout {"grid": [1, 2], "pitch_cm": [1, 1], "x": ' + text + "}")
        tried += 2
    fault_row("nesting", "JSON nested 1500 deep in an MQTT payload or a device's #layout line",
              "refused", "ProtocolError: counted and skipped like any malformed message",
              cases=tried)  # fmt: skip
