"""Family "a path inside a file" (harden9 items 1 and 2): every path a ward file names
(``layout``, ``calibration``, ``model``, and the file, folder or device of its ``source``:
``replay:``, ``iio:``, ``serial:``) is found by one rule, relative to the ward file's folder
(:func:`texsense.io.named.named_path`), never to the folder the station runs in, and is of
the kind its key reads: a file, a recording (a file or a format's folder, not any folder tree:
``layout = "/tmp"`` read the whole tree as recordings), a folder, a device. Anything else is
one error naming the ward file, the ``[[mat]]`` and the key.

Generated: every path-valued key x (relative from another working folder, absolute, ``..``)
and x every wrong kind (a folder, a folder tree, a file where a folder or device is, a FIFO,
missing), read by ``read_config`` and, for a sample, by ``texsense station --config``.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from faults._families import batch, one_line, small_recording
from texsense import Layout, Recording
from texsense.commands.station import PATH_KEYS, read_config
from texsense.exceptions import FormatError
from texsense.io import save


@pytest.fixture
def place(tmp_path):
    """A ward folder ``ward/`` beside files of every kind, and a working folder elsewhere."""
    from texsense.apps.posture.features import FeatureSet
    from texsense.apps.posture.model import PostureModel
    from texsense.cli import main

    ward = tmp_path / "site" / "ward"
    ward.mkdir(parents=True)
    save(small_recording(), ward / "rec.h5")
    cap = Recording(np.full((4, 12), 10.0), np.arange(4.0), Layout.grid(3, 4), "capacitance", "pF")
    save(cap, ward / "cap.h5")
    assert main(["calibrate", "linear", "--like", str(ward / "cap.h5"), "--gain", "2", "--to",
                 "pressure:N/cm2", "-o", str(ward / "cal.json")]) == 0  # fmt: skip
    lay = Layout.grid(3, 4)
    y = np.array(["left", "right"] * 10)
    frames = np.random.default_rng(0).random((20, 12))
    PostureModel(FeatureSet(("elements",)), lay, "logistic").fit(frames, y).save(
        ward / "sides.joblib"
    )
    (ward / "tree" / "a").mkdir(parents=True)
    save(small_recording(), ward / "tree" / "a" / "x.h5")
    (ward / "iio").mkdir()
    os.mkfifo(ward / "fifo")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    return ward, elsewhere


#: key -> (a line of a [[mat]] naming PATH, the path that works) for every path-valued key
VALID = {
    "layout": ('layout = "PATH"', "rec.h5"),
    "calibration": ('layout = "cap.h5"\ncalibration = "PATH"', "cal.json"),
    "model": ('layout = "grid:3x4"\nbed = true\nmodel = "PATH"', "sides.joblib"),
    "source": ('layout = "grid:3x4"\nsource = "replay:PATH"', "rec.h5"),
}
#: key -> the kinds of wrong path tried, each (the [[mat]] line, the value's path)
WRONG = {
    "layout": ["tree", "iio", "fifo", "missing.h5", "/", "rec.h5/x"],
    "calibration": ["tree", "fifo", "missing.json", "rec.h5/x"],
    "model": ["tree", "fifo", "missing.joblib", "rec.h5/x"],
    "source": ["tree", "fifo", "missing.h5", "rec.h5/x"],
    "source iio": ["rec.h5", "fifo", "missing", "rec.h5/x"],
    "source serial": ["rec.h5", "tree", "rec.h5/x"],
}


def _mat(key: str, value: str) -> str:
    if key == "source iio":
        return f'layout = "grid:3x4"\nsource = "iio:{value}"'
    if key == "source serial":
        return f'layout = "grid:3x4"\nsource = "serial:{value}"'
    return VALID[key][0].replace("PATH", value)


def _ward(ward, body: str, name: str = "ward.toml"):
    path = ward / name
    path.write_text(f'[[mat]]\nid = "a"\n{body}\n', encoding="utf-8")
    return path


def test_every_path_key_is_known():
    assert set(PATH_KEYS) == set(VALID)


def test_paths_are_relative_to_the_ward_file(place, monkeypatch, fault_row):
    ward, elsewhere = place
    monkeypatch.chdir(elsewhere)
    tried, wrong = 0, []
    for key, (_line, good) in VALID.items():
        for spelt in (good, f"./{good}", f"../ward/{good}", str(ward / good)):
            path = _ward(ward, _mat(key, spelt))
            tried += 1
            try:
                _mats, local = read_config(path, 20.0)
            except (FormatError, OSError) as e:
                wrong.append(f"{key} = {spelt!r}: {e}")
                continue
            if key == "source":
                assert local["a"].rec.n_frames == small_recording().n_frames
    # the ward file named by a relative path too (--config site/ward/ward.toml)
    monkeypatch.chdir(ward.parent.parent)
    for key, (_line, good) in VALID.items():
        _ward(ward, _mat(key, good))
        tried += 1
        try:
            read_config(ward.relative_to(ward.parent.parent) / "ward.toml", 20.0)
        except (FormatError, OSError) as e:
            wrong.append(f"{key} = {good!r} (--config relative): {e}")
    assert wrong == [], f"{len(wrong)} of {tried}:\n" + "\n".join(wrong)
    fault_row("paths in files", f"every path a ward file names ({', '.join(VALID)}): relative to "
              "the ward file's folder", "read", f"{tried} spellings from another working "
              "folder", cases=tried)  # fmt: skip


def test_a_path_of_the_wrong_kind_is_one_error(place, monkeypatch, fault_row):
    ward, elsewhere = place
    monkeypatch.chdir(elsewhere)
    tried, wrong = 0, []
    for key, values in WRONG.items():
        for value in values:
            path = _ward(ward, _mat(key, value))
            tried += 1
            try:
                read_config(path, 20.0)
            except FormatError as e:
                text = str(e)
                short = key.split()[0]
                if not ("ward.toml" in text and "[[mat]] #1" in text and short in text):
                    wrong.append(f"{key} = {value!r}: does not say where: {text}")
                elif "write" in text:  # (a path to read: "could not write" was said once)
                    wrong.append(f"{key} = {value!r}: speaks of writing: {text}")
                continue
            except Exception as e:  # anything else is the failure
                wrong.append(f"{key} = {value!r}: {type(e).__name__}: {str(e)[:200]}")
                continue
            wrong.append(f"{key} = {value!r}: taken")
    assert wrong == [], f"{len(wrong)} of {tried}:\n" + "\n".join(wrong)
    fault_row("paths in files", "every path a ward file names x a folder tree, a file for a folder "
              "or device, a FIFO, missing", "clear error", "the ward file, the [[mat]] and the "
              "key named", cases=tried)  # fmt: skip


def test_the_station_says_it_in_one_line(place):
    ward, elsewhere = place
    argvs = []
    for key, value in (("layout", "tree"), ("layout", "/"), ("calibration", "tree"),
                       ("source", "tree")):  # fmt: skip
        path = _ward(ward, _mat(key, value), f"w{len(argvs)}.toml")
        argvs.append(["station", "--config", str(path), "--port", "1",
                      "--db", str(elsewhere / "s.sqlite"),
                      "--record-dir", str(elsewhere / "r")])  # fmt: skip
    results, _, _ = batch(argvs, elsewhere, timeout=300)
    for argv, (rc, _out, err) in zip(argvs, results, strict=True):
        one_line(rc, err, argv[2], "[[mat]] #1")
