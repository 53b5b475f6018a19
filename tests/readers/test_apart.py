"""Reading a recording in a child process (texsense.io.apart): the same recording, the same
refusal with the same message and facts, and a stop ends the child."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from texsense._progress import STOPPING, StoppingError
from texsense.data import budget
from texsense.data.layout import Layout
from texsense.data.recording import Recording
from texsense.exceptions import FormatError
from texsense.io import load, save
from texsense.io.apart import load_apart


def _recording() -> Recording:
    rng = np.random.default_rng(3)
    frames = rng.uniform(0, 4, (25, 6)).astype(np.float32)
    return Recording(frames, np.arange(25) * 0.1, Layout.grid(2, 3), quantity="raw", unit="count")


def test_the_same_recording_as_a_read_here(tmp_path):
    path = save(_recording(), tmp_path / "r.csv")
    here, apart = load(path), load_apart(path)
    np.testing.assert_array_equal(apart.frames, here.frames)
    np.testing.assert_array_equal(apart.times, here.times)
    facts = ("quantity", "unit", "labels")
    assert [getattr(apart, k) for k in facts] == [getattr(here, k) for k in facts]
    assert apart.layout.shape == here.layout.shape


def test_a_refusal_comes_back_as_itself(tmp_path):
    path = save(_recording(), tmp_path / "r.csv")
    lines = path.read_text().splitlines()
    lines[-3] = lines[-3].replace(",", ",x", 1)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(FormatError) as here:
        load(path)
    with pytest.raises(FormatError) as apart:
        load_apart(path)
    assert str(apart.value) == str(here.value)
    assert (apart.value.path, apart.value.line, apart.value.detail) == (
        here.value.path, here.value.line, here.value.detail)  # fmt: skip


def test_the_budget_goes_with_the_read(tmp_path):
    path = save(_recording(), tmp_path / "r.csv")
    with pytest.raises(FormatError, match="memory"):
        load_apart(path, memory=64)
    with budget.share(64), pytest.raises(FormatError, match="memory"):
        load_apart(path)


def test_a_stop_ends_the_child(tmp_path):
    path = tmp_path / "big.csv"
    row = "," + ",".join(["7"] * 300) + "\n"
    with path.open("w") as f:
        f.write("# quantity: raw\n# unit: count\ntime_s," + ",".join(f"e{k}" for k in range(300)))
        f.write("\n" + "".join(f"{t}{row}" for t in range(40_000)))
    threading.Timer(0.5, STOPPING.set).start()  # the read itself takes seconds
    try:
        with pytest.raises(StoppingError):  # raised only while waiting for the child
            load_apart(path)
    finally:
        STOPPING.clear()
