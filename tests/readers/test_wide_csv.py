import numpy as np
import pytest

import texsense
from conftest import check_recording
from texsense import Layout, Recording
from texsense.exceptions import FormatError
from texsense.io import read_wide_csv, write_wide_csv
from texsense.io._base import plausible


def test_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(7)
    active = rng.random((4, 6)) > 0.25
    lay = Layout.grid(4, 6, pitch_cm=(2.0, 2.7), active=active).with_regions({"r": [0, 1]})
    frames = (rng.standard_normal((9, lay.n_elements)) * 1e3).astype(np.float32)
    frames[2, 3] = np.nan
    frames[4, 0] = 1e-30
    times = np.cumsum(rng.random(9)) / 3
    rec = Recording(frames, times, lay, "capacitance", "pF", meta={"device": "AD7746", "n": 1})
    back = read_wide_csv(write_wide_csv(rec, tmp_path / "w.csv"))
    # what is read is what was written, but a negative capacitance is no reading (every
    # reader marks it invalid, whatever the file says)
    assert back.equals(rec._with(valid=rec.valid & plausible(rec.frames, "capacitance")))
    check_recording(back, tmp_path)


def test_real_data_round_trip(shared_data, tmp_path):
    rec = texsense.load(shared_data / "vendor-formats" / "pliance_test.asc")
    rec = Recording(rec.frames, rec.times, rec.layout, rec.quantity, rec.unit, meta=rec.meta)
    back = texsense.load(write_wide_csv(rec, tmp_path / "p.csv"))
    assert back.equals(rec)


def test_foreign_file_needs_units(tmp_path):
    path = tmp_path / "f.csv"
    path.write_text("time_s,left,right\n0,1.5,2\n0.5,1,0\n")
    with pytest.raises(FormatError, match="never guessed"):
        read_wide_csv(path)
    rec = texsense.load(path, unit="kPa", quantity="pressure")
    assert rec.layout.names == ("left", "right")
    assert rec.frames.tolist() == [[1.5, 2.0], [1.0, 0.0]]
    with pytest.raises(FormatError, match="unknown unit"):
        read_wide_csv(path, unit="parsec", quantity="pressure")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("time,e0\n0,1\n", "start with 'time_s'"),
        ("# unit: pF\n# quantity: capacitance\ntime_s,e0,e1\n0,1\n", "line 4: expected 3"),
        (
            "# unit: pF\n# quantity: capacitance\ntime_s,e0\n0,abc\n",
            "line 4: expected a number, found 'abc'",
        ),
        ("# unit: pF\n# quantity: weight\ntime_s,e0\n", "line 2: unknown quantity"),
        ("# unit: pF\n# quantity: capacitance\n# layout: {bad\ntime_s,e0\n", "line 3: bad layout"),
        ("# unit: pF\n# quantity: capacitance\ntime_s,e0,e0\n", "duplicate"),
    ],
)
def test_bad_files(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(FormatError, match=message):
        read_wide_csv(path)


def test_foreign_file_impossible_values_are_invalid(tmp_path, caplog):
    path = tmp_path / "f.csv"
    path.write_text("time_s,a,b\n0,1.5,nan\n0.5,-2,inf\n1.0,1e308,3\n")
    rec = texsense.load(path, quantity="pressure", unit="kPa")
    assert rec.valid.tolist() == [[True, False], [False, False], [False, True]]
    assert "4 reading(s) marked invalid" in caplog.text


def test_cut_texsense_file(tmp_path):
    rec = Recording(np.ones((6, 2)), np.arange(6.0), Layout.grid(1, 2))
    path = write_wide_csv(rec, tmp_path / "w.csv")
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:-2]) + "\n")  # cut at a line end
    with pytest.raises(FormatError, match=r"'# frames: 6' but the file holds 4"):
        read_wide_csv(path)
    assert read_wide_csv(path, accept_truncated=True).n_frames == 4
