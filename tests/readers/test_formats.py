"""Every format of the registry (texsense.io.READER_CLASSES, WRITERS) through one battery:
the conformance checks of ``_conformance.check_reader`` on each reader's cases, a round trip
through each writer, and the table of docs/formats.md made from the registry. A format
added to texsense.io without a case here fails ``test_every_reader_has_conformance_cases``."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from _conformance import check_reader

import texsense
from texsense import Layout, Recording
from texsense.io import READER_CLASSES, WRITERS, formats_table, sniff_format
from texsense.io.columns_csv import write_columns_csv
from texsense.io.hdf5 import write_hdf5
from texsense.io.tekscan import write_tekscan
from texsense.io.wide_csv import write_wide_csv

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data"
VENDOR = SHARED / "vendor-formats"


def _generated(t: int = 30, seed: int = 0) -> Recording:
    rng = np.random.default_rng(seed)
    return Recording(
        rng.random((t, 9)), np.arange(t) * 0.1, Layout.grid(3, 3, pitch_cm=1.0),
        valid=rng.random((t, 9)) > 0.1,
        element_times=np.arange(t)[:, None] * 0.1 + np.zeros(9),
        labels={"posture": rng.integers(0, 3, t), "who": np.array(["a", "b"] * (t // 2))},
        meta={"x": 1},
    )  # fmt: skip


def _wide(tmp: Path) -> Path:
    rng = np.random.default_rng(5)
    valid = rng.random((40, 12)) > 0.2
    rec = Recording(rng.random((40, 12)) * 5, np.arange(40) * 0.05,
                    Layout.grid(3, 4, pitch_cm=1.5), valid=valid)  # fmt: skip
    return write_wide_csv(rec, tmp / "w.csv")


def _written_tekscan(tmp: Path) -> Path:
    return write_tekscan(texsense.load(VENDOR / "iscan_test.csv"), tmp / "w.asf", unit="raw")


def _table(tmp: Path) -> Path:
    t = np.arange(50) * 0.1
    return write_columns_csv(
        tmp / "table.csv",
        {"time_s": t, "compression_mm": np.sin(t), "pressure_ncm2": 1 + np.cos(t)},
    )


#: (case name, make the file in a folder, options of check_reader) by format.
Case = tuple[str, Callable[[Path], Path], dict]
CASES: dict[str, list[Case]] = {
    "hdf5": [("generated", lambda tmp: write_hdf5(_generated(), tmp / "r.h5"), {})],
    "tekscan": [
        ("iscan_test.csv", lambda tmp: VENDOR / "iscan_test.csv", {}),
        ("fscan_testL.asf", lambda tmp: VENDOR / "fscan_testL.asf", {}),
        ("written", _written_tekscan, {}),
    ],
    "xsensor": [("xsensor_data.csv", lambda tmp: VENDOR / "xsensor_data.csv", {})],
    "pliance": [
        ("pliance_test.asc", lambda tmp: VENDOR / "pliance_test.asc", {"tail_cut_seen": False})
    ],
    "columns-csv": [("generated", _table, {})],
    "wide-csv": [("generated", _wide, {})],
    "pmd": [
        ("posture file", lambda tmp: SHARED / "pmd" / "experiment-i" / "S2" / "7.txt", {}),
        ("subject folder", lambda tmp: SHARED / "pmd" / "experiment-i" / "S5", {}),
    ],
}


def test_every_reader_has_conformance_cases():
    missing = sorted(set(READER_CLASSES) - set(CASES))
    assert not missing, f"readers without a conformance case here: {missing}"
    assert set(CASES) == set(READER_CLASSES)


@pytest.mark.parametrize(("fmt", "case"), [(f, c[0]) for f, cases in CASES.items() for c in cases])
def test_conformance(fmt, case, tmp_path, caplog):
    _, make, options = next(c for c in CASES[fmt] if c[0] == case)
    path = make(tmp_path)
    assert sniff_format(path) == fmt
    check_reader(path, tmp_path / "battery", caplog, **options)


@pytest.mark.parametrize("fmt", list(WRITERS))
def test_every_writer_is_read_back_as_its_format(fmt, tmp_path):
    w = WRITERS[fmt]
    rec = _generated() if fmt != "tekscan" else texsense.load(VENDOR / "iscan_test.csv")
    path = texsense.io.save(rec, tmp_path / f"out{w.suffixes[0]}")
    assert sniff_format(path) == fmt
    back = texsense.load(path)
    assert back.n_frames == rec.n_frames and back.n_elements == rec.n_elements
    assert np.allclose(back.frames, rec.frames, equal_nan=True, rtol=1e-6)


def test_the_docs_table_is_the_registry():
    assert formats_table() in (ROOT / "docs" / "formats.md").read_text(encoding="utf-8")


def test_a_reader_must_say_what_it_reads_and_names_are_unique():
    from texsense.io._base import RecordingReader

    with pytest.raises(TypeError, match="must say what it reads"):
        type("Nameless", (RecordingReader,), {"format": "nameless-test"})
    with pytest.raises(TypeError, match="already"):
        type("Another", (RecordingReader,), {"format": "hdf5", "what": "x"})
    assert "nameless-test" not in READER_CLASSES


def test_read_functions_come_from_the_registry():
    from texsense.io import read_pmd, read_tekscan, read_xsensor

    assert read_tekscan.__name__ == "read_tekscan" and "Tekscan" in (read_tekscan.__doc__ or "")
    assert read_xsensor(VENDOR / "xsensor_data.csv").n_frames == 101
    assert read_pmd(SHARED / "pmd" / "experiment-i" / "S2" / "7.txt").layout.shape == (64, 32)
    with pytest.raises(AttributeError):
        texsense.io.read_nothing  # noqa: B018
