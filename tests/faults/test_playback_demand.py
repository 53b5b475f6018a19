"""Family "a file that declares more than it holds" (issue 32, item 2), the playback's part: a
recording longer than the memory budget plays, frame by frame, read on demand
(:mod:`texsense.io.lazy`) with a cache bounded by the budget. A ~90 MB HDF5 recording,
written chunk by chunk, is played under a 16 MiB ``TEXSENSE_MAX_MEMORY`` in a child process
whose peak memory is measured; seeks anywhere give h5py's own slices.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from texsense import Layout, Recording
from texsense.io import save

BUDGET = "16M"
BUDGET_KIB = 16 * 1024
#: what the child may take beyond its warm-up peak besides the budget (HDF5's chunk caches,
#: allocator slack, the JSON of the summary), KiB; far less than the recording (~88,000 KiB)
CONSTANT_KIB = 24 * 1024
SIDE = 32  # a 32 x 32 mat
FRAMES = 9600  # float64 frames and a validity mask: 9 bytes a value, ~88 MiB
#: the recording the seeks are generated on: its frames as read (float32 and a mask, ~20 MiB)
#: are more than the budget too
SEEKABLE = 4000


def _long_recording(path: Path, frames: int) -> Path:
    """A texsense recording of ``frames`` float64 frames of a 32 x 32 mat (foot mode: the
    statistics, not the alert engine, are what opening it costs), written 1200 frames at a
    time (never whole in memory); element 3 is flagged invalid in every 7th frame."""
    lay = Layout.grid(SIDE, SIDE, pitch_cm=0.5)
    save(Recording(np.zeros((0, lay.n_elements)), [], lay, meta={"mode": "foot"}), path)
    n = lay.n_elements
    with h5py.File(path, "a") as f:
        for key in ("frames", "valid", "times"):
            del f[key]
        fr = f.create_dataset("frames", (frames, n), np.float64, chunks=(min(64, frames), n))
        va = f.create_dataset("valid", (frames, n), bool, chunks=(min(64, frames), n))
        ti = f.create_dataset("times", (frames,), np.float64, chunks=(min(4096, frames),))
        for a in range(0, frames, 1200):
            b = min(frames, a + 1200)
            k = np.arange(a, b, dtype=np.float64)[:, None]
            fr[a:b] = (k % 97) * 0.01 + np.arange(n) * 1e-4  # frame a and element e: unique
            valid = np.ones((b - a, n), bool)
            valid[:, 3] = np.arange(a, b) % 7 != 0
            va[a:b] = valid
            ti[a:b] = np.arange(a, b) * 0.01
    return path


@pytest.fixture(scope="module")
def long_h5(tmp_path_factory) -> Path:
    return _long_recording(tmp_path_factory.mktemp("long") / "long.h5", FRAMES)


_PLAYER = r"""
import json, sys
from pathlib import Path
from texsense.monitor.playback import _Reviews, _frame, _summary

def kib(key):
    for line in open("/proc/self/status"):
        if line.startswith(key + ":"):
            return int(line.split()[1])

reviews = _Reviews()
warm = Path(sys.argv[2])
review = reviews.get(warm)
_summary(review, warm), _frame(review, 0)
base = kib("VmHWM")
path = Path(sys.argv[1])
review = reviews.get(path)
summary = _summary(review, path)
seeks = {i: _frame(review, i) for i in json.loads(sys.argv[3])}
print(json.dumps({"frames": summary["frames"], "times": summary["times"][-1],
                  "events": len(summary["events"]), "base_kib": base,
                  "peak_kib": kib("VmHWM"), "seeks": seeks}))
"""


def test_a_recording_longer_than_the_budget_plays_on_demand(long_h5, tmp_path, fault_row):
    assert long_h5.stat().st_size > 5 * BUDGET_KIB * 1024  # the file is 5x the budget
    warm = _long_recording(tmp_path / "warm.h5", 200)
    seeks = [0, 1, 7, FRAMES // 2, FRAMES - 2, FRAMES - 1]
    env = dict(os.environ, TEXSENSE_MAX_MEMORY=BUDGET, TEXSENSE_NO_PROGRESS="1")
    proc = subprocess.run([sys.executable, "-c", _PLAYER, str(long_h5), str(warm),
                           json.dumps(seeks)], capture_output=True, text=True, env=env,
                          timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout)
    assert out["frames"] == FRAMES and out["times"] == pytest.approx((FRAMES - 1) * 0.01)
    with h5py.File(long_h5) as f:
        for i in seeks:
            got = out["seeks"][str(i)]
            want = f["frames"][i]  # a flagged reading of pressure is a repair: it counts
            values = np.array([np.nan if v is None else v for v in got["values"]])
            np.testing.assert_allclose(values, np.round(want, 4), atol=1e-4, equal_nan=True)
            assert got["repaired"] == ([3] if i % 7 == 0 else []), i
    grown = out["peak_kib"] - out["base_kib"]
    print(f"peak memory grew by {grown} KiB playing {long_h5.stat().st_size >> 10} KiB")
    assert grown <= BUDGET_KIB + CONSTANT_KIB, f"the child grew by {grown} KiB"
    size = long_h5.stat().st_size >> 20
    fault_row("declares more", f"playback of an {size} MiB recording under a 16 MiB budget "
              "(opened, seeks to start, middle, end)", "read",
              f"on demand; peak memory {grown >> 10} MiB over the warm-up",
              cases=len(seeks))  # fmt: skip


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    from texsense.apps.review import open_review

    path = _long_recording(tmp_path_factory.mktemp("seek") / "seek.h5", SEEKABLE)
    os.environ["TEXSENSE_MAX_MEMORY"] = BUDGET
    try:
        review = open_review(path, unit="N/cm2", on_demand=True)
    finally:
        del os.environ["TEXSENSE_MAX_MEMORY"]
    f = h5py.File(path)
    yield review, f
    f.close()


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(i=st.integers(0, SEEKABLE - 1), length=st.integers(1, 300))
def test_seeks_anywhere_read_the_files_own_frames(played, i, length, monkeypatch):
    """A frame, a slice across cache blocks, a selection: what h5py reads there."""
    monkeypatch.setenv("TEXSENSE_MAX_MEMORY", BUDGET)
    review, f = played
    # every reading is finite: flagged ones are repairs and count (as live)
    np.testing.assert_array_equal(review.frame(i), f["frames"][i].astype(np.float32))
    stop = min(SEEKABLE, i + length)
    got = review.rec.select(slice(i, stop))
    np.testing.assert_array_equal(got.frames, f["frames"][i:stop].astype(np.float32))
    np.testing.assert_array_equal(got.times, f["times"][i:stop])
    raw = review.raw
    assert raw is not None
    np.testing.assert_array_equal(raw.valid[i:stop], f["valid"][i:stop])
    picks = np.arange(i, stop, 37)
    np.testing.assert_array_equal(review.rec.frames[picks], f["frames"][picks].astype(np.float32))


def test_what_needs_every_frame_is_refused_in_one_line(played, monkeypatch):
    monkeypatch.setenv("TEXSENSE_MAX_MEMORY", BUDGET)
    from texsense.exceptions import FormatError

    review, _ = played
    with pytest.raises(FormatError, match=r"seek\.h5.*memory budget") as e:
        np.asarray(review.rec.frames)
    assert len(str(e.value).splitlines()) == 1
