from pathlib import Path

import numpy as np
import pytest

import texsense
from conftest import check_recording
from texsense import Layout, Recording
from texsense.exceptions import FormatError
from texsense.io import read_tekscan, write_tekscan


@pytest.fixture(scope="module")
def iscan(shared_data) -> Path:
    return shared_data / "vendor-formats" / "iscan_test.csv"


@pytest.fixture(scope="module")
def fscan(shared_data) -> Path:
    return shared_data / "vendor-formats" / "fscan_testL.asf"


def test_iscan_raw(iscan, tmp_path):
    rec = texsense.load(iscan)
    assert rec.meta["format"] == "tekscan-ascii"
    assert rec.layout.shape == (28, 28)
    assert rec.n_frames == 309
    assert rec.frame_period_s == pytest.approx(0.1)
    assert (rec.quantity, rec.unit) == ("raw", "count")
    assert rec.layout.pitch_cm == (0.127, 0.127)
    # 'B' cells: two full rows and columns of B around and between four 11 x 11 pads
    assert rec.n_elements == 4 * 11 * 11
    assert not rec.layout.active[0].any() and not rec.layout.active[:, 13].any()
    header = rec.meta["header"]
    assert header["SENSOR_TYPE"] == "6900" and header["SENSEL_AREA"] == "0.016129 cm2"
    assert header["TIME"] == "12/2/2019 6:21:52.34PM"
    # every frame line ends with 'Raw Sum=,,<sum>': our cells add up to it in all 309 frames
    sums = [
        int(s.rsplit(",", 1)[1]) for s in iscan.read_text().splitlines() if s.startswith("Frame")
    ]
    np.testing.assert_array_equal(rec.frames.sum(axis=1), sums)
    check_recording(rec, tmp_path)


def test_fscan_calibrated_kpa_to_ncm2(fscan, tmp_path):
    rec = texsense.load(fscan)
    assert rec.layout.shape == (60, 21)
    assert rec.n_frames == 205
    assert rec.quantity == "pressure" and rec.unit == "N/cm2"
    assert rec.meta["source_unit"] == "kPa"
    assert rec.layout.pitch_cm == pytest.approx((0.508, 0.508))
    assert rec.frame_period_s == pytest.approx(0.032)
    assert "overground walk p10" in rec.meta["header"]["COMMENTS"]
    assert rec.meta["header"]["CALIBRATION_MODE_1"] == "Walk"
    # values in the file are kPa: the text of one loaded cell, divided by 10
    check_recording(rec, tmp_path)


def test_fscan_value_matches_text(fscan):
    lines = fscan.read_text().splitlines()
    start = lines.index("Frame 100")
    block = [r.split(",") for r in lines[start + 1 : start + 61]]
    rec = texsense.load(fscan)
    flat = [float(v) for row in block for v in row if v != "B"]
    np.testing.assert_allclose(rec.frames[99], np.array(flat) / 10, rtol=1e-6)


@pytest.mark.parametrize("name", ["iscan_test.csv", "fscan_testL.asf"])
def test_round_trip_real_files(shared_data, tmp_path, name):
    rec = texsense.load(shared_data / "vendor-formats" / name)
    back = read_tekscan(write_tekscan(rec, tmp_path / "out.asf"))
    np.testing.assert_array_equal(back.frames, rec.frames)
    np.testing.assert_array_equal(back.times, rec.times)
    assert back.layout == rec.layout
    assert (back.quantity, back.unit) == (rec.quantity, rec.unit)
    # header keys survive (those that describe the grid are rewritten)
    assert back.meta["header"]["SENSOR_TYPE"] == rec.meta["header"]["SENSOR_TYPE"]


def test_round_trip_random_pressure_is_bit_exact(tmp_path):
    rng = np.random.default_rng(3)
    active = rng.random((5, 7)) > 0.3
    lay = Layout.grid(5, 7, pitch_cm=(0.508, 0.3), active=active)
    frames = (rng.random((4, lay.n_elements)) * 12).astype(np.float32)
    rec = Recording(frames, [0.0, 0.033, 0.067, 0.1], lay, "pressure", "N/cm2")
    for unit in ("kPa", "mmHg", "psi", "N/cm2"):
        back = read_tekscan(
            write_tekscan(rec, tmp_path / f"{unit.replace('/', '')}.csv", unit=unit)
        )
        np.testing.assert_array_equal(back.frames, rec.frames)
        np.testing.assert_array_equal(back.times, rec.times)
        assert back.layout == rec.layout


def _corrupt(src: Path, dst: Path, edit) -> Path:
    lines = src.read_text().splitlines()
    dst.write_text("\n".join(edit(lines)) + "\n")
    return dst


def test_truncated_file_names_the_problem(iscan, tmp_path):
    bad = _corrupt(iscan, tmp_path / "t.csv", lambda ls: ls[:100])
    with pytest.raises(FormatError, match=r"t\.csv.*truncated"):
        read_tekscan(bad)


def test_corrupt_cell_names_line_and_column(iscan, tmp_path):
    def edit(ls):
        ls[40] = ls[40].replace("0", "x", 1)
        return ls

    bad = _corrupt(iscan, tmp_path / "c.csv", edit)
    with pytest.raises(
        FormatError, match=r"line 41: frame 1, column \d+: expected a number or 'B'"
    ):
        read_tekscan(bad)


def test_short_row(iscan, tmp_path):
    def edit(ls):
        ls[35] = ls[35].rsplit(",", 1)[0]
        return ls

    with pytest.raises(FormatError, match="line 36: frame 1: expected 28 comma-separated"):
        read_tekscan(_corrupt(iscan, tmp_path / "s.csv", edit))


def test_changing_b_pattern(iscan, tmp_path):
    def edit(ls):
        row = ls[60].split(",")  # frame 2, row 2
        row[5] = "B"
        ls[60] = ",".join(row)
        return ls

    with pytest.raises(FormatError, match=r"'B' .* pattern differs"):
        read_tekscan(_corrupt(iscan, tmp_path / "b.csv", edit))


def test_unknown_units_and_spacing(iscan, tmp_path):
    def units(ls):
        return [("UNITS furlongs" if s.startswith("UNITS") else s) for s in ls]

    with pytest.raises(FormatError, match="UNITS: unknown unit 'furlongs'"):
        read_tekscan(_corrupt(iscan, tmp_path / "u.csv", units))

    def spacing(ls):
        return [("ROW_SPACING 0.1 cubits" if s.startswith("ROW_SPACING") else s) for s in ls]

    with pytest.raises(FormatError, match="line 11: ROW_SPACING"):
        read_tekscan(_corrupt(iscan, tmp_path / "sp.csv", spacing))


def test_missing_rows_key_and_data_marker(iscan, tmp_path):
    with pytest.raises(FormatError, match="header lacks ROWS"):
        read_tekscan(
            _corrupt(
                iscan, tmp_path / "r.csv", lambda ls: [s for s in ls if not s.startswith("ROWS")]
            )
        )
    with pytest.raises(FormatError, match="ASCII_DATA"):
        read_tekscan(_corrupt(iscan, tmp_path / "d.csv", lambda ls: ls[:20]))


def test_closed_early_is_refused_or_read_with_a_warning(iscan, tmp_path, caplog):
    # 100 of the 309 frames (END_FRAME 309), then the end marker: a file closed early
    lines = iscan.read_text().splitlines()
    end = next(i for i, s in enumerate(lines) if s.startswith("Frame 101,"))
    bad = _corrupt(iscan, tmp_path / "early.csv", lambda ls: [*ls[:end], "@@"])
    with pytest.raises(
        FormatError,
        match=r"early\.csv: truncated: END_FRAME is 309, '@@' came after frame 100 \(209 missing",
    ):
        read_tekscan(bad)
    rec = read_tekscan(bad, accept_truncated=True)
    assert rec.n_frames == 100
    assert "209 missing" in caplog.text and "early.csv" in caplog.text
