"""texsense record (raw frames from any source) and a monitor with no calibration, through
the virtual device on a real pseudo-terminal."""

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import MonitorProcess
from faults.conftest import run_cli
from texsense import load
from texsense.monitor.live import raw_rise


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
    assert "Ctrl-C stops" in proc.stderr.readline()  # recording (however slow the start)
    time.sleep(3)
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
        assert set(snap["stats"].values()) == {None}  # no pressure statistics without pressure
        raw = snap["raw_stats"]
        assert raw["unit"] == "pF" and raw["working"] >= 90 and raw["peak_rise"] >= 0
        assert 0 <= raw["responding"] <= raw["working"] and raw["respond_above"] > 0
        assert mon.status()["raw_unit"] == "pF" and mon.status()["calibrated"] is False
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


def _type_load(proc, text):
    """Type a load on the device and wait until it says it serves it (however slow the
    machine), then for a few frames of it."""
    proc.stdin.write(text + "\n")
    proc.stdin.flush()
    said = f"texsense simulate device: load {text} from frame"
    for line in proc.stdout:
        if line.startswith(said):
            break
    else:
        raise AssertionError(f"the device ended before taking the load {text}")
    time.sleep(0.5)


def test_device_record_calibrate_process_through_the_serial_line(device, tmp_path):
    """The whole hardware path: device -> serial -> record -> calibrate (a preset) -> process."""
    link, proc = device("--speed", "20", "--seed", "2")
    port = f"serial:{link}"
    for name, load_text in (("zero", None), ("one", "uniform:1.0"), ("two", "uniform:2.0")):
        if load_text:
            _type_load(proc, load_text)
        rc, _, err = run_cli("record", "--source", port, "-o", f"{name}.h5", "--frames", "6",
                             cwd=tmp_path)  # fmt: skip
        assert rc == 0, err
    rc, out, err = run_cli("calibrate", "mat", "--material", "textile-3mm", "--baseline",
                           "zero.h5", "--uniform", "one.h5", "--pressure", "10kPa", "-o",
                           "mat.json", cwd=tmp_path)  # fmt: skip
    assert rc == 0, err
    assert "the preset textile-3mm (3 mm) at 1 N/cm²" in out and "drift" in out
    rc, _, err = run_cli("process", "two.h5", "--calibration", "mat.json", "-o", "p.h5",
                         cwd=tmp_path)  # fmt: skip
    assert rc == 0, err
    p = load(tmp_path / "p.h5")
    median = float(np.median(np.where(p.valid, p.frames, np.nan)))
    assert abs(median - 2.0) < 0.2, median
    # the same recordings against a spacer the device did not announce: refused, with why
    rc, _, err = run_cli("calibrate", "mat", "--material", "textile-6mm", "--baseline",
                         "zero.h5", "--uniform", "one.h5", "--pressure", "1", "-o", "x.json",
                         cwd=tmp_path)  # fmt: skip
    assert (
        rc == 1 and "declares the spacer textile-3mm" in err and not (tmp_path / "x.json").exists()
    )


def test_calibrate_wizard_with_yes_waits_for_each_load(device, tmp_path):
    link, proc = device("--speed", "20", "--seed", "4")
    wizard = subprocess.Popen(
        [sys.executable, "-m", "texsense.cli", "calibrate", "wizard", "--source", f"serial:{link}",
         "-o", "mat.json", "--yes", "--frames", "5", "--wait-s", "60"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    lines = []
    for line in wizard.stdout:
        lines.append(line)
        if line.startswith("step 2/4"):
            _type_load(proc, "uniform:1.0")
        elif line.startswith("step 4/4"):
            _type_load(proc, "uniform:2.0")
    wizard.stdout.close()
    assert wizard.wait(timeout=30) == 0, "".join(lines)
    text = "".join(lines)
    assert "material: textile-3mm (announced by the device)" in text
    assert "check at 2 N/cm²: median of 96 working elements" in text
    median = float(text.split("working elements ")[1].split(" N/cm²")[0])
    assert abs(median - 2.0) < 0.2, text
    for step in ("zero", "uniform", "check"):
        rec = load(tmp_path / f"mat-{step}.h5")
        assert rec.n_frames == 5 and rec.meta["spacer"] == "textile-3mm"
    assert (tmp_path / "mat.json").exists()


class _Output:
    """A child's output read in the background, prompts without a newline included."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.text = ""
        self._proc = proc
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while chunk := os.read(self._proc.stdout.fileno(), 4096):
            self.text += chunk.decode("utf-8", "replace")

    def close(self) -> None:
        """After the child has ended: the rest of its output, and the pipe closed."""
        self._thread.join(timeout=10)
        self._proc.stdout.close()

    def wait_for(self, needle: str, timeout: float = 90.0) -> None:
        deadline = time.monotonic() + timeout
        while needle not in self.text:
            assert self._proc.poll() is None or needle in self.text, self.text
            assert time.monotonic() < deadline, f"no {needle!r} in:\n{self.text}"
            time.sleep(0.05)


def _as_from_a_shell() -> None:
    """(In the child, before exec.) Ctrl-C and SIGTERM as a terminal gives them: default and
    not blocked, whatever the test process inherited or set (a wizard started by a test
    worker ignored Ctrl-C in three runs of the whole suite under two workers)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})


@pytest.fixture
def wizard(tmp_path):
    """``texsense calibrate wizard`` on a device's link as a child process, its output read in
    the background; stopped and its pipes closed at the end of the test."""
    started: list[tuple[subprocess.Popen, _Output]] = []

    def start(link, *extra: str) -> tuple[subprocess.Popen, _Output]:
        proc = subprocess.Popen(
            [sys.executable, "-m", "texsense.cli", "calibrate", "wizard", "--source",
             f"serial:{link}", "-o", "mat.json", "--frames", "5", "--wait-s", "60", *extra],
            cwd=tmp_path, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, env=dict(os.environ, PYTHONFAULTHANDLER="1"),
            preexec_fn=_as_from_a_shell,
        )  # fmt: skip
        started.append((proc, _Output(proc)))
        return started[-1]

    yield start
    for proc, out in started:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=30)
        proc.stdin.close()
        out.close()


def test_calibrate_wizard_asks_and_a_person_answers_with_enter(device, wizard, tmp_path):
    """The interactive path: every step waits for Enter, the person puts the load on first."""
    link, dev = device("--speed", "20", "--seed", "5")
    proc, out = wizard(link)
    out.wait_for("step 1/4: take everything off the mat, then press Enter")
    time.sleep(1.0)
    assert not (tmp_path / "mat-zero.h5").exists()  # nothing recorded before Enter
    proc.stdin.write(b"\n")
    proc.stdin.flush()
    out.wait_for("step 2/4")  # the zero frames were recorded after Enter
    _type_load(dev, "uniform:1.0")
    time.sleep(0.5)
    proc.stdin.write(b"\n")
    proc.stdin.flush()
    out.wait_for("step 4/4")
    _type_load(dev, "uniform:2.0")
    time.sleep(0.5)
    proc.stdin.write(b"\n")
    proc.stdin.flush()
    assert proc.wait(timeout=90) == 0, out.text
    assert "check at 2 N/cm²: median of 96 working elements" in out.text
    assert (tmp_path / "mat.json").exists() and (tmp_path / "mat-check.h5").exists()


@pytest.mark.parametrize("how", ["Ctrl-C", "SIGKILL"])
def test_a_wizard_stopped_mid_way_keeps_what_it_recorded_and_writes_no_calibration(
    device, wizard, tmp_path, how
):
    """Stopped while it waits for the uniform load: the zero recording already written stays
    whole and readable, no calibration and no half-written file is left; Ctrl-C says one
    line, no traceback."""
    link, _ = device("--speed", "20", "--seed", "6")
    proc, out = wizard(link, "--yes")
    out.wait_for("step 2/4")
    time.sleep(1.0)  # waiting for a load that does not come
    proc.send_signal(signal.SIGINT if how == "Ctrl-C" else signal.SIGKILL)
    try:
        rc = proc.wait(timeout=30)
    except subprocess.TimeoutExpired:  # where it hangs: Python's fault handler dumps its stacks
        status = Path(f"/proc/{proc.pid}/status").read_text()
        said = [line for line in status.splitlines() if line.startswith(("SigBlk", "SigIgn"))]
        out.text += "\n" + "\n".join(said) + "\n"
        proc.send_signal(signal.SIGABRT)
        proc.wait(timeout=30)
        out.close()
        raise AssertionError(f"the wizard did not stop:\n{out.text[-6000:]}") from None
    out.close()  # all of its output
    if how == "Ctrl-C":
        assert rc == 130, out.text
        assert "Traceback" not in out.text
        assert out.text.strip().splitlines()[-1] == "texsense calibrate wizard: stopped"
    else:
        assert rc == -signal.SIGKILL
    zero = load(tmp_path / "mat-zero.h5")
    assert zero.n_frames == 5 and zero.meta["spacer"] == "textile-3mm"
    assert not (tmp_path / "mat.json").exists()
    left = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("mat"))
    assert left == ["mat-zero.h5"], left


def test_the_raw_rise_of_a_mat_without_calibration():
    floor = np.array([3.0, 4.0, 3.5, np.nan, 3.5])
    raw = np.array([3.0, 4.5, 3.51, 3.8, np.nan])  # threshold: 0.5 % of 3.5 pF = 0.0175 pF
    r = raw_rise(raw, floor)
    assert r == {"peak_rise": 0.5, "responding": 1, "working": 3, "respond_above": 0.0175}
    assert raw_rise(np.full(5, np.nan), floor)["peak_rise"] is None


def test_a_live_recording_writes_the_pressure_shown_and_no_bound_below_zero(tmp_path):
    # the recorder writes the pressure it is given: the monitor's, an empty element's estimate
    # a hair below zero already shown as 0 (no_negative, tests/monitor/test_shown_pressure.py);
    # it does not clip it a second time (a value below zero it is given is the writer's
    # invalid), only the lower bounds, which nothing clipped before: never below zero
    from types import SimpleNamespace

    from texsense import Layout
    from texsense.data.protocol import Frame
    from texsense.io.hdf5 import read_bounds
    from texsense.monitor.record import Recorder

    source = SimpleNamespace(layout=Layout.grid(1, 4), quantity="capacitance", unit="pF")
    rec = Recorder(tmp_path, "r", source, {}, bounds=True)
    pressure = np.array([-0.001, 0.0, 0.5, -5.0])
    frame = Frame(0, np.zeros(4), np.full(4, 3.0))
    rec.append(frame, pressure, np.ones(4, bool), 0.0, bounds=(pressure - 0.08, pressure + 0.08))
    rec.close()
    out = load(tmp_path / "r.h5")
    lo, hi = read_bounds(tmp_path / "r.h5")
    assert out.frames[0].tolist() == pressure.astype(np.float32).tolist()
    assert out.valid[0].tolist() == [False, True, True, False]
    assert lo[0].tolist() == np.float32([0.0, 0.0, 0.42, 0.0]).tolist()
    assert hi[0].tolist() == (pressure + 0.08).astype(np.float32).tolist()
