import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import h5py
import numpy as np
import pytest

import texsense
from texsense import Layout, Recording
from texsense.exceptions import FormatError, ParameterError, UnitError
from texsense.io import RecordingWriter, read_hdf5


def make_recording(t=5, rows=3, cols=4, seed=0) -> Recording:
    rng = np.random.default_rng(seed)
    lay = Layout.grid(rows, cols, pitch_cm=1.5).with_regions({"top": np.arange(cols)})
    valid = rng.random((t, rows * cols)) > 0.1
    return Recording(
        rng.random((t, rows * cols)) * 10,
        np.arange(t) * 0.25,
        lay,
        "pressure",
        "N/cm2",
        valid=valid,
        element_times=np.arange(t)[:, None] * 0.25 + np.arange(rows * cols) * 0.01,
        labels={"posture": rng.integers(1, 4, t), "subject": np.array(["S1"] * t)},
        meta={"device": "test", "nested": {"a": [1, 2]}},
    )


def test_basic_properties():
    rec = make_recording()
    assert (rec.n_frames, rec.n_elements) == (5, 12)
    assert rec.frame_period_s == pytest.approx(0.25)
    assert rec.duration_s == pytest.approx(1.25)
    assert rec.maps().shape == (5, 3, 4)
    assert "5 frames x 12 elements" in repr(rec)


def test_hdf5_round_trip_is_exact(tmp_path):
    rec = make_recording()
    rec.frames[0, 0] = np.nan
    path = rec.save(tmp_path / "r.h5")
    back = texsense.load(path)
    # exact, but a NaN is no reading: every reader marks it invalid, whatever the file says
    assert back.frames.tobytes() == rec.frames.tobytes()
    assert not back.valid[0, 0] and back._with(valid=rec.valid).equals(rec)
    assert back.labels["subject"].dtype.kind == "U"


def test_hdf5_schema_is_readable_with_h5py_alone(tmp_path):
    rec = make_recording()
    with h5py.File(rec.save(tmp_path / "r.h5"), "r") as f:
        assert f.attrs["format"] == "texsense.recording"
        assert f.attrs["version"] == 1
        assert f["frames"].dtype == np.float32 and f["frames"].shape == (5, 12)
        assert f["frames"].compression == "gzip" and f["frames"].chunks is not None
        assert f["frames"].maxshape == (None, 12)
        np.testing.assert_array_equal(f["times"][()], rec.times)
        assert json.loads(f.attrs["meta"])["device"] == "test"
        assert f["layout"].attrs["rows"] == 3
        assert list(f["layout/regions"]) == ["top"]


def test_empty_recording_round_trip(tmp_path):
    lay = Layout.grid(2, 2)
    rec = Recording(np.zeros((0, 4)), [], lay, labels={"posture": np.zeros(0, int)})
    back = texsense.load(rec.save(tmp_path / "e.h5"))
    assert back.equals(rec)


def test_writer_appends_blocks_and_single_frames(tmp_path):
    lay = Layout.grid(2, 2)
    path = tmp_path / "live.h5"
    with RecordingWriter(path, lay, "capacitance", "pF", element_times=True) as w:
        w.append(
            np.ones((2, 4)),
            [0.0, 0.1],
            element_times=np.zeros((2, 4)),
            labels={"posture": ["a", "b"]},
        )
        w.append(np.full(4, 2.0), 0.2, element_times=np.zeros(4), labels={"posture": ["c"]})
        assert w.n_frames == 3
    rec = read_hdf5(path)
    assert rec.n_frames == 3 and rec.unit == "pF"
    assert rec.labels["posture"].tolist() == ["a", "b", "c"]
    np.testing.assert_array_equal(rec.frames[2], 2.0)


def test_writer_rejects_inconsistent_appends(tmp_path):
    with RecordingWriter(tmp_path / "w.h5", Layout.grid(2, 2), "pressure", "kPa") as w:
        with pytest.raises(ParameterError, match="4 elements"):
            w.append(np.ones(5), 0.0)
        w.append(np.ones(4), 0.0, labels={"posture": [1]})
        with pytest.raises(ParameterError, match="labels"):
            w.append(np.ones(4), 0.1)
        with pytest.raises(ParameterError, match="element_times"):
            w.append(np.ones(4), 0.1, element_times=np.ones(4), labels={"posture": [1]})


def test_killed_writer_leaves_a_readable_file(tmp_path):
    """A recorder killed with SIGKILL keeps every flushed frame."""
    path = tmp_path / "killed.h5"
    script = textwrap.dedent(
        f"""
        import sys, time, numpy as np
        from texsense import Layout
        from texsense.io import RecordingWriter
        w = RecordingWriter({str(path)!r}, Layout.grid(8, 8), "pressure", "N/cm2")
        k = 0
        while True:
            w.append(np.full((5, 64), k, np.float32), np.arange(k, k + 5) * 0.1)
            k += 5
            if k == 50:
                print("ready", flush=True)
            time.sleep(0.002)
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.3)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
    rec = read_hdf5(path)
    assert rec.n_frames >= 50
    # frames are intact and in order: frame k holds the value k // 5 * 5
    np.testing.assert_array_equal(rec.frames[:, 0], np.arange(rec.n_frames) // 5 * 5)
    np.testing.assert_allclose(rec.times, np.arange(rec.n_frames) * 0.1)


def test_select_concatenate_and_units():
    rec = make_recording()
    part = rec.select(slice(1, 3))
    assert part.n_frames == 2 and part.labels["posture"].shape == (2,)
    both = Recording.concatenate([rec.select([0, 1]), rec.select(slice(2, None))])
    assert both.equals(rec)
    kpa = rec.to_unit("kPa")
    assert kpa.unit == "kPa"
    np.testing.assert_allclose(kpa.frames, rec.frames * 10, rtol=1e-6)
    with pytest.raises(UnitError):
        rec.to_unit("mm")


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"frames": np.zeros(3)}, "frames"),
        ({"times": np.zeros(2)}, "times"),
        ({"quantity": "temperature"}, "quantity"),
        ({"unit": "pF"}, "does not measure pressure"),
        ({"unit": "furlong"}, "unknown unit"),
        ({"valid": np.ones((2, 2), bool)}, "valid"),
        ({"labels": {"posture": [1, 2]}}, "label 'posture'"),
        ({"meta": {"x": object()}}, "JSON"),
    ],
)
def test_bad_recording_parameters(change, message):
    args = {"frames": np.zeros((3, 4)), "times": np.zeros(3), "layout": Layout.grid(2, 2)}
    args.update(change)
    with pytest.raises((ParameterError, UnitError), match=message):
        Recording(**args)


def test_not_a_texsense_hdf5(tmp_path):
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as f:
        f["x"] = [1, 2]
    with pytest.raises(FormatError, match="not a texsense recording"):
        read_hdf5(path)
    rec_path = make_recording().save(tmp_path / "v.h5")
    with h5py.File(rec_path, "a") as f:
        f.attrs["version"] = 99
    with pytest.raises(FormatError, match="unknown texsense recording version 99"):
        read_hdf5(rec_path)
    broken = tmp_path / "broken.h5"
    broken.write_bytes(b"\x89HDF\r\n\x1a\n" + b"garbage" * 10)
    with pytest.raises(FormatError, match="not a readable HDF5"):
        texsense.load(broken)


def test_save_writes_the_format_of_the_extension(tmp_path):
    """Recording.save goes through texsense.io by extension: .csv is a wide CSV, .asf Tekscan
    ASCII, .h5 HDF5; an unknown extension is refused, naming it."""
    from texsense import load
    from texsense.exceptions import ParameterError
    from texsense.io import sniff_format

    rec = Recording(np.arange(12.0).reshape(3, 4), [0.0, 0.1, 0.2], Layout.grid(2, 2))
    for name, fmt in (("x.csv", "wide-csv"), ("x.asf", "tekscan"), ("x.h5", "hdf5")):
        path = rec.save(tmp_path / name)
        assert sniff_format(path) == fmt
        np.testing.assert_allclose(load(path).frames, rec.frames)
    with pytest.raises(ParameterError, match=r"x\.bin"):
        rec.save(tmp_path / "x.bin")
