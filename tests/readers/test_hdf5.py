"""texsense HDF5: the conformance battery, and what the reader checks of what a file
declares against what it holds."""

import h5py
import numpy as np
import pytest

import texsense
from texsense import Layout, Recording
from texsense.exceptions import FormatError
from texsense.io import RecordingWriter, read_hdf5, write_hdf5


def _rec(t=30, seed=0):
    rng = np.random.default_rng(seed)
    lay = Layout.grid(3, 3, pitch_cm=1.0)
    return Recording(
        rng.random((t, 9)), np.arange(t) * 0.1, lay, valid=rng.random((t, 9)) > 0.1,
        element_times=np.arange(t)[:, None] * 0.1 + np.zeros(9),
        labels={"posture": rng.integers(0, 3, t), "who": np.array(["a", "b"] * (t // 2))},
        meta={"x": 1},
    )  # fmt: skip


def test_datasets_of_different_length(tmp_path, caplog):
    path = write_hdf5(_rec(), tmp_path / "r.h5")
    with h5py.File(path, "a") as f:
        f["times"].resize((3,))
    with pytest.raises(FormatError, match=r"r\.h5: the datasets differ in length \(frames 30, "):
        read_hdf5(path)
    assert read_hdf5(path, accept_truncated=True).n_frames == 3
    assert "differ in length" in caplog.text


def test_declared_length_beyond_the_data(tmp_path):
    path = tmp_path / "r.h5"
    with RecordingWriter(path, Layout.grid(2, 2), "pressure", "N/cm2", live=False) as w:
        w.append(np.ones((5, 4)), np.arange(5.0))
    with h5py.File(path, "a") as f:
        for name in ("frames", "valid", "times"):
            f[name].resize(10**9, axis=0)
    with pytest.raises(FormatError, match="declares 1000000000 frames but holds data for"):
        read_hdf5(path)


def test_unfinished_one_go_write_is_refused_live_recording_is_read(tmp_path, caplog):
    path = tmp_path / "one-go.h5"
    w = RecordingWriter(path, Layout.grid(2, 2), "pressure", "N/cm2", live=False)
    w.append(np.ones((5, 4)), np.arange(5.0))
    w.flush()  # killed here: never closed
    with pytest.raises(FormatError, match="not finished by its writer"):
        texsense.load(path)
    w.close()
    live = tmp_path / "live.h5"
    w = RecordingWriter(live, Layout.grid(2, 2), "pressure", "N/cm2")
    w.append(np.ones((5, 4)), np.arange(5.0))
    w.flush()
    assert texsense.load(live).n_frames == 5
    w.close()


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda f: f.attrs.__setitem__("meta", "{broken"), "attribute 'meta' is not JSON"),
        (lambda f: f.attrs.__setitem__("meta", "[1, 2]"), "'meta' is not a JSON object"),
        (lambda f: f.attrs.__setitem__("unit", "furlong"), "unknown unit"),
        (lambda f: f.attrs.__setitem__("quantity", "heat"), "quantity"),
        (lambda f: f.__delitem__("valid"), "missing dataset or group '/valid'"),
        (lambda f: f.__delitem__("layout/xy_cm"), "/layout is damaged"),
        (lambda f: f["times"].__setitem__(4, -1.0), "frame 5: the time -1 s goes back"),
    ],
)
def test_damaged_header_fields(tmp_path, edit, message):
    path = write_hdf5(_rec(), tmp_path / "r.h5")
    with h5py.File(path, "a") as f:
        edit(f)
    with pytest.raises(FormatError, match=message):
        read_hdf5(path)
