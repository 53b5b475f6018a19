"""Family "text that is not Unicode" (harden12): a lone surrogate, which no UTF-8 file, report,
figure or page can hold, reaches texsense three ways: a file name of bytes that are not UTF-8
on the command line (Python keeps them as lone surrogates), a ``\\udcff`` escape in JSON (a
wide CSV's layout and meta lines, a sidecar, a message) and an HDF5 attribute of bytes that are
not UTF-8 (h5py gives them as lone surrogates). Each is stopped at its one entry:
``_options.nonempty`` (every path and text argument), ``data.outside.json_loads`` (every JSON
from outside) and ``io.policy.text_of`` (every text of an HDF5 file). Before, ``report`` and
``plot`` of any of them were a ``UnicodeEncodeError`` or a matplotlib traceback.

The table: every entry x every command that shows or writes its texts; never a traceback, and
what is written holds no lone surrogate.
"""

from __future__ import annotations

import json
import os
import re

import h5py
import pytest

from faults._families import batch, small_recording
from texsense.io import save

#: the sinks: commands that print, write or draw the texts of a recording
SINKS = {
    "info": lambda p, out: ["info", p],
    "info --json": lambda p, out: ["info", "--json", p],
    "convert h5": lambda p, out: ["convert", p, f"{out}.h5"],
    "convert csv": lambda p, out: ["convert", p, f"{out}.csv"],
    "convert asf": lambda p, out: ["convert", p, f"{out}.asf"],
    "report html": lambda p, out: ["report", p, "-o", f"{out}.html"],
    "report pdf": lambda p, out: ["report", p, "-o", f"{out}.pdf"],
    "plot": lambda p, out: ["plot", p, "-o", f"{out}.png"],
}

#: where a JSON escape goes in a wide CSV: (line, the text's place in it)
CSV_PLACES = {
    "region name": ("layout", r'"regions":\{"r"', r'"regions":{"\udcff"'),
    "element name": ("layout", r'"names":\["s0"', r'"names":["s\udcff"'),
    "orientation": ("layout", r'"orientation":\{\}', r'"orientation":{"top":"\ud800"}'),
    "meta key": ("meta", r"^\{\}$", r'{"\udcffkey": 1}'),
    "meta value": ("meta", r"^\{\}$", r'{"source": "a\udfffb"}'),
}

#: HDF5 attributes given bytes that are not UTF-8: (object, attribute)
H5_PLACES = {
    "region name": ("layout/regions/r", "name"),
    "label name": ("labels/posture", "name"),
    "unit": ("/", "unit"),
    "meta": ("/", "meta"),
    "orientation": ("layout", "orientation"),
}
_H5_VALUES = {"unit": b"N/cm\xb2", "meta": b'{"source": "\xff\xfe"}',
              "orientation": b'{"top": "\xe9"}'}  # fmt: skip


def _csv(folder, name, line, pattern, text):
    path = folder / f"csv-{name.replace(' ', '-')}.csv"
    save(small_recording(), path)
    lines = path.read_text("utf-8").splitlines(keepends=True)
    k = next(i for i, s in enumerate(lines) if s.startswith(f"# {line}: "))
    head, body = f"# {line}: ", lines[k][len(f"# {line}: ") :].rstrip("\n")
    changed = re.sub(pattern, lambda m: text, body, count=1, flags=re.M)
    assert changed != body, (name, body[:200])
    lines[k] = head + changed + "\n"
    path.write_text("".join(lines), "utf-8")
    return path


def _h5(folder, name, obj, attr):
    path = folder / f"h5-{name.replace(' ', '-')}.h5"
    rec = small_recording()
    save(rec, path)
    with h5py.File(path, "a") as f:
        f[obj].attrs[attr] = _H5_VALUES.get(name, b"\xff\xfe")
    return path


def _entries(folder):
    """(entry, path as given on the command line)"""
    out = {}
    raw = os.fsdecode(b"name-\xff\xfe.csv")  # as Python gives such a name in sys.argv
    save(small_recording(), folder / raw)
    out["argv: a file name not UTF-8"] = raw
    for name, (line, pattern, text) in CSV_PLACES.items():
        out[f"JSON escape: {name}"] = str(_csv(folder, name, line, pattern, text))
    for name, (obj, attr) in H5_PLACES.items():
        out[f"HDF5 bytes: {name}"] = str(_h5(folder, name, obj, attr))
    return out


def _lone(data: bytes) -> bool:
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        return True  # a surrogate written with surrogateescape or surrogatepass
    return re.search("[\ud800-\udfff]", text) is not None


@pytest.mark.slow
def test_no_lone_surrogate_reaches_an_output(tmp_path, fault_row):
    entries = _entries(tmp_path)
    cases = [(e, s) for e in entries for s in SINKS]
    argvs = [SINKS[s](entries[e], str(tmp_path / f"out{k}")) for k, (e, s) in enumerate(cases)]
    results, _, _ = batch(argvs, tmp_path, timeout=900)
    bad = []
    for k, ((entry, sink), (rc, out, err)) in enumerate(zip(cases, results, strict=True)):
        lines = [s for s in err.strip().splitlines() if s.strip()]
        what = f"{entry} -> {sink}: exit {rc}, {lines[-1][:160] if lines else ''}"
        if "Traceback" in err or rc not in (0, 1, 2):
            bad.append(what)
        elif rc == 1 and len(lines) != 1:
            bad.append(what + " (not one line)")
        elif rc == 2 and "not UTF-8 text" not in err:
            bad.append(what + " (refused, not said why)")
        elif rc == 0:
            written = [p for p in tmp_path.glob(f"out{k}.*")]
            if _lone(out.encode("utf-8", "surrogateescape")) or any(
                _lone(p.read_bytes()) for p in written if p.suffix in (".csv", ".asf", ".html")
            ):
                bad.append(what + " (a lone surrogate written)")
    print(f"{len(cases) - len(bad)} of {len(cases)} cases held")
    assert not bad, "\n".join(bad)
    fault_row("not Unicode", f"a lone surrogate from {len(entries)} entries (a file name, JSON "
              f"escapes, HDF5 bytes) x {len(SINKS)} commands that show or write it",
              "clear error or read", cases=len(cases))  # fmt: skip


def test_json_refuses_lone_surrogates_only(fault_row):
    from texsense.data.files import json_loads

    for text in ('"\udcff"', '{"\ud800": 1}', '[["a\\uDFFFb"]]', '"\udcff"'):
        with pytest.raises(ValueError, match="lone surrogate"):
            json_loads(text)
    assert json_loads('["\\ud83d\\ude00", "\\u00e9"]') == ["\U0001f600", "é"]
    assert json.loads(json.dumps(json_loads(b'{"a": "\\u20ac"}'))) == {"a": "€"}
    fault_row("not Unicode", "a lone surrogate escaped in JSON from outside", "refused", cases=4)


@pytest.mark.slow
def test_a_folder_entry_named_in_bytes_that_are_not_utf8(tmp_path, fault_row):
    """A file whose name is not UTF-8 inside a folder texsense lists (``data.files.
    regular_files``: a folder read as one recording, an archive, the monitor's recordings):
    passed over and said, as a FIFO is (the monitor's listing was a 500)."""
    from conftest import ChildServer

    folder = tmp_path / "recordings"
    folder.mkdir()
    save(small_recording(), folder / "ok.h5")
    save(small_recording(), folder / os.fsdecode(b"\xff\xfe.h5"))
    (rc, _out, err), *_ = batch([["info", str(folder)]], tmp_path)[0]
    assert rc == 0 and "not UTF-8" in err and "Traceback" not in err, err
    m = ChildServer(tmp_path, "monitor", "--source", "virtual", "--record-dir", str(folder))
    try:
        m.until(lambda: m.get("api/status")["frames"], lambda n: n > 0, 60)
        assert [r["name"] for r in m.get("api/playback")] == ["ok.h5"]
    finally:
        m.stop()
    fault_row("not Unicode", "a file named in bytes that are not UTF-8 in a folder read as one "
              "recording and in the monitor's recordings", "read, warned", cases=2)  # fmt: skip
