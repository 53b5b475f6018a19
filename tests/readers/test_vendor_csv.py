"""XSENSOR CSV and novel pliance .asc: real exports, cross-checked against the vendors' own
per-frame statistics."""

import numpy as np
import pytest

import texsense
from conftest import check_recording
from texsense.apps import stats
from texsense.exceptions import FormatError
from texsense.io import read_pliance, read_xsensor


@pytest.fixture(scope="module")
def xsensor_path(shared_data):
    return shared_data / "vendor-formats" / "xsensor_data.csv"


@pytest.fixture(scope="module")
def pliance_path(shared_data):
    return shared_data / "vendor-formats" / "pliance_test.asc"


def test_xsensor_frames_sensors_and_units(xsensor_path, tmp_path):
    rec = texsense.load(xsensor_path)
    assert rec.meta["format"] == "xsensor-csv"
    assert rec.n_frames == 101
    assert len(rec.meta["sensors"]) == 2
    assert rec.n_elements == 2 * 31 * 11
    assert rec.meta["source_unit"] == "mmHg" and rec.unit == "N/cm2"
    assert rec.labels["frame_number"][[0, -1]].tolist() == [1464, 1564]
    assert rec.times[-1] == pytest.approx(19.313 - 17.982)
    # first SENSELS row with a load: "0,0,0,0,0,107.87,0,0,174.74,89.9,0"
    left = rec.layout.regions[rec.meta["sensors"][0]]
    np.testing.assert_allclose(
        rec.frames[0, left[11:22]] * 75.00615,
        [0, 0, 0, 0, 0, 107.87, 0, 0, 174.74, 89.9, 0],
        rtol=1e-5,
    )
    check_recording(rec, tmp_path)


def test_xsensor_vendor_statistics_agree_with_ours(xsensor_path):
    rec = texsense.load(xsensor_path)
    per_region = stats.region_stats(rec)
    for i, name in enumerate(rec.meta["sensors"], start=1):
        ours = per_region[name]
        # the vendor's sensel area is 0.2 % larger than 0.86 cm squared (rounding of the width)
        np.testing.assert_allclose(
            ours["load_N"], rec.labels[f"vendor_load_N_s{i}"], rtol=5e-3, atol=0.2
        )
        np.testing.assert_allclose(
            ours["contact_area_cm2"],
            rec.labels[f"vendor_contact_area_cm2_s{i}"],
            rtol=5e-3,
            atol=0.05,
        )
        np.testing.assert_allclose(ours["peak"], rec.labels[f"vendor_peak_ncm2_s{i}"], rtol=1e-5)


def test_pliance_layout_and_vendor_force(pliance_path, tmp_path):
    rec = texsense.load(pliance_path)
    assert rec.meta["format"] == "pliance-asc"
    assert rec.layout.kind == "points"
    assert rec.n_elements == 812 and rec.n_frames == 281
    assert rec.layout.names[:2] == ("4", "5")
    np.testing.assert_allclose(rec.layout.area_cm2[:2], 0.5428)
    np.testing.assert_allclose(rec.layout.xy_cm[0], [0.264, 29.298])
    assert rec.frame_period_s == pytest.approx(0.04167, abs=1e-4)
    load = stats.total_load(rec)
    np.testing.assert_allclose(load, rec.labels["vendor_force_N"], atol=0.02)
    check_recording(rec, tmp_path)


def test_pliance_centre_of_pressure_is_the_vendors_rotated_by_180_degrees(pliance_path):
    # pliance reports its centre of pressure with the origin at the opposite corner of the
    # sensor geometry it exports: x' = W - x, y' = H - y.
    rec = texsense.load(pliance_path)
    _, x1, _, y1 = rec.layout.extent_cm
    cof = stats.centre_of_force(rec)
    loaded = stats.total_load(rec) > 5
    np.testing.assert_allclose(
        x1 - cof[loaded, 0], rec.labels["vendor_cop_x_cm"][loaded], atol=0.02
    )
    np.testing.assert_allclose(
        y1 - cof[loaded, 1], rec.labels["vendor_cop_y_cm"][loaded], atol=0.02
    )


def test_xsensor_bad_input(xsensor_path, tmp_path):
    lines = xsensor_path.read_text(encoding="utf-8-sig").splitlines()
    bad = tmp_path / "x.csv"
    bad.write_text("\n".join(lines[:80]) + "\n", encoding="utf-8")
    with pytest.raises(FormatError, match="truncated"):
        read_xsensor(bad)
    edited = list(lines)
    edited[2] = "Units:,stone,,,"
    bad.write_text("\n".join(edited) + "\n")
    with pytest.raises(FormatError, match="line 3: Units: unknown unit 'stone'"):
        read_xsensor(bad)
    edited = list(lines)
    row = next(i for i, s in enumerate(lines) if s.startswith("0,0,0,0,0,107.87"))
    edited[row] = edited[row].replace("107.87", "1o7.87")
    bad.write_text("\n".join(edited) + "\n")
    with pytest.raises(
        FormatError, match=f"line {row + 1}: expected a number for SENSELS row 2, found '1o7.87'"
    ):
        read_xsensor(bad)


def test_pliance_bad_input(pliance_path, tmp_path):
    lines = pliance_path.read_text().splitlines()
    bad = tmp_path / "p.asc"
    edited = list(lines)
    edited[20] = edited[20].rsplit(None, 1)[0]
    bad.write_text("\n".join(edited) + "\n")
    with pytest.raises(FormatError, match="line 21: expected 812 values"):
        read_pliance(bad)
    bad.write_text("\n".join(lines[:200]) + "\n")
    with pytest.raises(FormatError, match="force"):
        read_pliance(bad)
    edited = [s.replace("pressure values in kPa", "pressure values in bananas") for s in lines]
    bad.write_text("\n".join(edited) + "\n")
    with pytest.raises(FormatError, match="unknown pressure unit 'bananas'"):
        read_pliance(bad)


def test_xsensor_cut_in_half(xsensor_path, tmp_path, caplog):
    data = xsensor_path.read_bytes()
    half = tmp_path / "half.csv"
    half.write_bytes(data[: len(data) // 2])
    with pytest.raises(FormatError, match=r"half\.csv: truncated: .*inside frame 1514"):
        read_xsensor(half)
    rec = read_xsensor(half, accept_truncated=True)
    whole = read_xsensor(xsensor_path)
    assert rec.n_frames == 50
    np.testing.assert_array_equal(rec.frames, whole.frames[:50])
    assert "half.csv" in caplog.text and "50 complete frame" in caplog.text
