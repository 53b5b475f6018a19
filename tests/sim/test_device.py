"""The virtual device behind a real pseudo-terminal (texsense.sim.device)."""

import threading
import time

import numpy as np
import pytest
import serial

from texsense import load
from texsense.data.protocol import (
    ProtocolError,
    layout_announcement,
    parse_announcement,
    parse_serial_line,
)
from texsense.exceptions import ParameterError
from texsense.sim.device import VirtualDevice, parse_load
from texsense.sim.mat import VirtualMat


def _read_frames(link, n, timeout=30.0):
    """The announcement and n frames read through the serial port at ``link``."""
    port = serial.Serial(str(link), timeout=0.5)
    layout, info, frames = None, None, []
    deadline = time.monotonic() + timeout
    try:
        while len(frames) < n and time.monotonic() < deadline:
            line = port.readline()
            got = parse_announcement(line)
            if got is not None:
                layout, info = got
            elif layout is not None and line.startswith(b"F,"):
                frames.append(parse_serial_line(line, layout.n_elements))
    finally:
        port.close()
    return layout, info, frames


@pytest.fixture
def serve(tmp_path):
    running = []

    def start(device, **kwargs):
        stop = threading.Event()
        link = tmp_path / "ttyTEX0"
        th = threading.Thread(target=device.serve, args=(link,), kwargs={"stop": stop, **kwargs})
        th.start()
        deadline = time.monotonic() + 10
        while not link.is_symlink() and time.monotonic() < deadline:
            time.sleep(0.01)
        running.append((stop, th))
        return link

    yield start
    for stop, th in running:
        stop.set()
        th.join(timeout=5)


def test_seat_announces_its_layout_and_serves_frames(serve, tmp_path):
    dev = VirtualDevice("seat", load="uniform:2", speed=50)
    link = serve(dev, truth=tmp_path / "truth.h5")
    layout, info, frames = _read_frames(link, 5)
    assert layout == VirtualMat.seat().layout
    assert info["spacer"] == "textile-3mm" and info["load"] == "uniform:2"
    assert len(frames) == 5
    seqs = [f.seq for f in frames]
    assert seqs == sorted(seqs)
    assert np.all(np.diff([f.t for f in frames]) > 0)
    # a loaded element reads more than it does unloaded (eq. 2.1: the gap closes)
    empty = next(VirtualDevice("seat", load="empty").frames())[2]
    empty_values = parse_serial_line(empty, 96).values
    assert np.nanmedian(frames[-1].values) > np.nanmedian(empty_values) + 0.1


def test_truth_is_recorded_and_the_link_removed(serve, tmp_path):
    dev = VirtualDevice("seat", load="uniform:1.5", speed=100)
    link = serve(dev, truth=tmp_path / "truth.h5", max_frames=12)
    deadline = time.monotonic() + 20
    while link.is_symlink() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not link.exists() and not link.is_symlink()
    truth = load(tmp_path / "truth.h5")
    assert truth.n_frames == 12
    assert np.allclose(truth.frames, 1.5)


def test_bed_device_announces_64_by_32():
    dev = VirtualDevice("bed", load="person", seed=1)
    layout, info = parse_announcement(dev.announcement())
    assert layout.shape == (64, 32) and info["elements"] == 2048
    _t, _p, line = next(dev.frames())
    assert parse_serial_line(line, 2048).values.shape == (2048,)


@pytest.mark.parametrize(
    ("text", "why"),
    [("full", "must be one of"), ("uniform:", "uniform:P"), ("uniform:-1", "0-100"),
     ("uniform:nan", "0-100"), ("uniform:1e9", "0-100")],
)  # fmt: skip
def test_bad_load_is_one_clear_error(text, why):
    with pytest.raises(ParameterError, match=why):
        parse_load(text)


def test_link_that_exists_is_refused(tmp_path):
    (tmp_path / "taken").write_text("")
    with pytest.raises(ParameterError, match="exists"):
        VirtualDevice("seat").serve(tmp_path / "taken")
    with pytest.raises(ParameterError, match="--mat"):
        VirtualDevice("sofa")


@pytest.mark.parametrize(
    "line",
    ['#layout {"grid": [2]}', "#layout [1, 2]", "#layout {not json",
     '#layout {"grid": [2, 2], "pitch_cm": [1, 1], "elements": 5}',
     '#layout {"grid": [2, 2], "pitch_cm": [1, 1], "active": "zz"}',
     '#layout {"grid": [100000, 2], "pitch_cm": [1, 1]}', '#layout {"pitch_cm": [1, 1]}'],
)  # fmt: skip
def test_malformed_announcement_names_the_problem(line):
    with pytest.raises(ProtocolError, match="layout announcement"):
        parse_announcement(line)


def test_announcement_round_trips_a_checkerboard():
    lay = VirtualMat.seat().layout
    back, info = parse_announcement(layout_announcement(lay, spacer="x"))
    assert back == lay and info == {"elements": 96, "spacer": "x"}


def test_the_layout_is_announced_again_at_least_four_times_a_second(serve):
    """A reader that opens the port while the device runs (`texsense record`, a monitor)
    waits for the next announcement: at most a quarter of a second (ANNOUNCE_EVERY_S; 1 s
    before, half a second on average of every such start). Counted in frames between two
    announcements: at 100x a seat frame is 16 ms, a quarter second 15.6 of them (a busy
    machine paces fewer frames into it, never more)."""
    dev = VirtualDevice("seat", load="empty", speed=100)
    port = serial.Serial(str(serve(dev)), timeout=0.5)
    runs, run, frames = [], 0, 0
    try:
        while frames < 120:
            line = port.readline()
            assert line, "the device went quiet"
            if parse_announcement(line) is not None:
                runs.append(run)
                run = 0
            elif line.startswith(b"F,"):
                run, frames = run + 1, frames + 1
    finally:
        port.close()
    assert len(runs) >= 5 and max(runs[1:]) <= 17, runs
