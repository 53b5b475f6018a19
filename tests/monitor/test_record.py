"""texsense record (raw frames from any source) and a monitor with no calibration, through
the virtual device on a real pseudo-terminal."""

import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import MonitorProcess
from faults.conftest import run_cli
from texsense import load


@pytest.fixture
def device(tmp_path):
    """``texsense simulate device`` as a child process; yields a starter."""
    procs = []

    def start(*args, link="ttyTEX0"):
        path = tmp_path / link
        cmd = [sys.executable, "-m", "texsense.cli", "simulate", "device", "--link", link, *args]
        proc = subprocess.Popen(
            cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        procs.append(proc)
        deadline = time.monotonic() + 30
        while not path.is_symlink():
            assert proc.poll() is None, proc.stdout.read()
            assert time.monotonic() < deadline, "the device did not come up"
            time.sleep(0.05)
        return path, proc

    yield start
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
        p.communicate(timeout=10)


def test_record_through_the_serial_line_needs_no_grid(device, tmp_path):
    link, proc = device("--load", "uniform:1.5", "--speed", "20")
    rc, out, err = run_cli("record", "--source", f"serial:{link}", "-o", "u.h5", "--frames", "8",
                           cwd=tmp_path)  # fmt: skip
    assert rc == 0, err
    assert "8 frames" in out and "0 dropped" in out
    rec = load(tmp_path / "u.h5")
    assert rec.n_frames == 8 and rec.layout.n_elements == 96 and rec.unit == "pF"
    assert rec.meta["spacer"] == "textile-3mm"  # what the device announced
    assert rec.element_times is not None and np.all(np.diff(rec.times) > 0)
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=10)
    assert "stopped after" in out and not (tmp_path / "ttyTEX0").exists()


def test_record_virtual_seat_for_a_duration(tmp_path):
    rc, _, err = run_cli("record", "--source", "virtual", "--speed", "50", "-o", "v.h5",
                           "--duration", "10", cwd=tmp_path)  # fmt: skip
    assert rc == 0, err
    rec = load(tmp_path / "v.h5")
    assert rec.quantity == "capacitance" and rec.duration_s >= 10 - 1.6


def test_record_ctrl_c_keeps_what_was_recorded(tmp_path):
    proc = subprocess.Popen(
        [sys.executable, "-m", "texsense.cli", "record", "--source", "virtual", "--speed", "20",
         "-o", "c.h5"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    time.sleep(6)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=15)
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    n = load(tmp_path / "c.h5").n_frames
    assert n >= 2 and f"{n} frames" in out


def test_monitor_without_calibration_shows_and_records_raw_pf(device, tmp_path):
    link, _ = device("--load", "uniform:1", "--speed", "20")
    mon = MonitorProcess(tmp_path, "--source", f"serial:{link}", "--record",
                         "--record-dir", str(tmp_path / "rec"))  # fmt: skip
    try:
        mon.wait_for_frames(3)
        snap = mon.get("api/frame/latest")
        assert snap["calibrated"] is False and snap["raw_unit"] == "pF"
        assert all(v is None for v in snap["pressure"]) and snap["alert"] is None
        assert sum(v is not None for v in snap["raw"]) >= 90
        assert "no calibration" in mon.log()
    finally:
        mon.proc.send_signal(signal.SIGINT)
        mon.proc.wait(timeout=20)
    files = sorted(p.name for p in (tmp_path / "rec").iterdir())
    assert len(files) == 1 and files[0].endswith("-raw.h5"), files  # no pressure file
    rec = load(tmp_path / "rec" / files[0])
    assert rec.unit == "pF" and rec.n_frames >= 3
