"""Fault battery, stopping and saying so (issue 28): Ctrl-C and SIGTERM stop `texsense
monitor` and `texsense station` within 2 s in every state (a browser tab that has closed, no
data flowing), the station's own Mosquitto and its temporary folder included (we run as root
here: Mosquitto drops its privileges); a serial device that is missing or refuses, or stays
silent, is one line on the console and a state on the page."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from conftest import ChildServer, free_port
from texsense.compensation.stages import Linear, StageChain


@contextlib.contextmanager
def silent_device():
    """A TCP device (pyserial ``socket://``) that accepts a connection and never sends."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()
    held: list[socket.socket] = []

    def accept() -> None:
        with contextlib.suppress(OSError):
            while True:
                held.append(srv.accept()[0])

    threading.Thread(target=accept, daemon=True).start()
    try:
        yield f"socket://127.0.0.1:{srv.getsockname()[1]}"
    finally:
        for c in held:
            c.close()
        srv.close()


def calibration(tmp_path: Path) -> Path:
    """pF -> N/cm² for a 2 x 3 mat (no spacer model: starts at once)."""
    cal = StageChain(
        [Linear("capacitance", "pF", "pressure", "N/cm2").fit(np.zeros(6), np.ones(6))]
    )
    return cal.save(tmp_path / "mat.json")


def status(server: ChildServer) -> dict:
    return server.get("api/status")


def close_a_viewer(url: str) -> None:
    """A browser tab that showed the page's WebSocket, then closed."""
    from websockets.sync.client import connect

    with connect(url) as ws:
        ws.send("hello")
        time.sleep(0.2)


def stop(proc: subprocess.Popen, sig: int, group: bool = False) -> float:
    """Send ``sig`` (to the process's whole group with ``group``: what a Ctrl-C on a terminal
    does); how long the process took to end (fails after 10 s)."""
    start = time.monotonic()
    if group:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        pytest.fail(f"still running 10 s after {signal.Signals(sig).name}")
    return time.monotonic() - start


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_the_monitor_stops_within_2_s_after_a_tab_closed_with_no_data(tmp_path, sig, fault_row):
    with silent_device() as device:
        m = ChildServer(tmp_path, "monitor", "--source", f"serial:{device}", "--grid", "2x3",
                        "--calibration", str(calibration(tmp_path)))  # fmt: skip
        try:
            m.until(lambda: status(m)["frames"], lambda n: n == 0)  # it serves
            close_a_viewer(f"ws://127.0.0.1:{m.port}/ws")
            took = stop(m.proc, sig)
        finally:
            m.stop()
    log = m.log()
    assert took < 2.0, f"{took:.2f} s:\n{log}"
    assert m.proc.returncode == 0 and "Traceback" not in log and "Error" not in log, log
    assert f"texsense monitor: stopped ({signal.Signals(sig).name})" in log
    name = "Ctrl-C" if sig == signal.SIGINT else "SIGTERM"
    fault_row("stop", f"monitor: {name} with no data flowing, after a browser tab closed",
              "stopped", f"{took:.1f} s")  # fmt: skip


def test_a_second_ctrl_c_stops_at_once_in_one_line(tmp_path, fault_row):
    m = ChildServer(tmp_path, "monitor", "--source", "virtual", "--speed", "10")
    try:
        m.until(lambda: status(m)["frames"], lambda n: n > 0)  # it serves, data flowing
        m.proc.send_signal(signal.SIGINT)
        time.sleep(0.05)
        took = stop(m.proc, signal.SIGINT)
    finally:
        m.stop()
    log = m.log()
    assert took < 2.0 and m.proc.returncode == 0, log
    assert "Traceback" not in log and "stopping now (second signal)" in log, log
    fault_row("stop", "monitor: Ctrl-C twice (data flowing)", "stopped", f"{took:.1f} s, one line")


def broker_processes(folder: Path) -> list[int]:
    """Ids of processes whose command line names something in ``folder``."""
    found = []
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit():
            with contextlib.suppress(OSError):
                if str(folder) in (proc / "cmdline").read_bytes().decode(errors="replace"):
                    found.append(int(proc.name))
    return found


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_the_station_stops_within_2_s_with_its_broker_and_its_folder(tmp_path, sig, fault_row):
    # the station's temporary folder, where only its broker's folder goes (one that the user
    # 'mosquitto' may enter: pytest's own are closed to others)
    own_tmp = Path(tempfile.mkdtemp(prefix="texsense-test-stop-"))
    own_tmp.chmod(0o755)
    (tmp_path / "ward.toml").write_text('[[mat]]\nid = "bed1"\nlayout = "grid:4x4"\n')
    port = free_port()
    log_path = tmp_path / "station.log"
    with log_path.open("wb") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "texsense.cli", "station", "--config", "ward.toml",
             "--port", str(port), "--db", "station.sqlite"],
            stdout=out, stderr=subprocess.STDOUT, cwd=tmp_path, env={**os.environ,
            "TMPDIR": str(own_tmp)}, start_new_session=True,
        )  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while True:
            with contextlib.suppress(OSError):
                url = f"http://127.0.0.1:{port}/api/ward"
                with urllib.request.urlopen(url, timeout=2) as r:
                    if json.load(r)["connected"]:  # logged in to its own broker
                        break
            assert proc.poll() is None and time.monotonic() < deadline, log_path.read_text()
            time.sleep(0.1)
        assert broker_processes(own_tmp), "no Mosquitto of the station's"
        close_a_viewer(f"ws://127.0.0.1:{port}/ws/ward")
        took = stop(proc, sig, group=sig == signal.SIGINT)  # Ctrl-C reaches the whole group
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        time.sleep(0.2)
        outlived = broker_processes(own_tmp)
        for pid in outlived:  # (a failing station's broker, started by this test)
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        left = list(own_tmp.iterdir())
        shutil.rmtree(own_tmp, ignore_errors=True)
    log = log_path.read_text()
    assert outlived == [], "the station's Mosquitto outlived it"
    assert left == [], "a texsense-broker-* folder was left behind"
    assert took < 2.0, f"{took:.2f} s:\n{log}"
    assert proc.returncode == 0 and "Traceback" not in log, log
    assert "lost the broker" not in log, log  # a clean stop is no loss (issue 33)
    assert (tmp_path / "mat-credentials.toml").stat().st_mode & 0o777 == 0o600
    name = "Ctrl-C" if sig == signal.SIGINT else "SIGTERM (a service manager)"
    fault_row("stop", f"station run as root: {name} after a ward tab closed", "stopped",
              f"{took:.1f} s, its Mosquitto and its folder gone")  # fmt: skip


@pytest.mark.slow
def test_a_missing_or_refusing_device_is_one_line_and_a_state(tmp_path, fault_row):
    cal = str(calibration(tmp_path))
    refusing = f"socket://127.0.0.1:{free_port()}"
    for port, reason in [("/dev/ttyTEXSENSE-NONE", "No such file or directory"),
                         (refusing, "Connection refused")]:  # fmt: skip
        m = ChildServer(tmp_path, "monitor", "--source", f"serial:{port}", "--grid", "2x3",
                        "--calibration", cal)  # fmt: skip
        try:
            feed = m.until(lambda m=m: status(m)["feed"], lambda f: f["state"] == "trouble")
            assert feed["text"] == (
                f"serial:{port}: cannot open it ({reason}); trying again every 2 s"
            )
            time.sleep(2.5)  # it tries again, and does not say so again
            took = stop(m.proc, signal.SIGTERM)
        finally:
            m.stop()
        log = m.log()
        assert took < 2.0 and m.proc.returncode == 0 and "Traceback" not in log, log
        assert log.count(reason) == 1, log
        assert f"serial:{port}: cannot open it ({reason})" in log
        what = "is missing" if "/dev/" in port else "refuses (a TCP device)"
        fault_row("hardware", f"monitor: a serial port that {what}", "said")


@pytest.mark.slow
def test_a_silent_device_is_said_on_the_console_and_on_the_page(tmp_path, fault_row):
    from playwright.sync_api import expect

    from faults.test_web import open_page  # (Debian's Chromium, as the dashboard's tests)

    with silent_device() as device:
        m = ChildServer(tmp_path, "monitor", "--source", f"serial:{device}", "--grid", "2x3",
                        "--calibration", str(calibration(tmp_path)))  # fmt: skip
        try:
            m.until(lambda: status(m)["feed"]["state"], lambda s: s == "waiting")
            with open_page(m.url, 900, 600) as (page, errors):
                line = page.locator("#feed-state")
                expect(line).to_contain_text(f"waiting for the first frame from serial:{device}")
                expect(line).to_contain_text(
                    f"no frames from serial:{device} for 1", timeout=15_000
                )  # 10 s, 12 s, ...
                expect(line).to_have_attribute("data-state", "silent")
                assert not errors, errors
            # the page asks for the state when it wants it; the console line comes from the
            # monitor's watch, which looks every 0.5 s: wait for it, then it is there once
            said = f"no frames from serial:{device} for 10 s"
            m.until(m.log, lambda log: said in log, timeout=10)
            assert m.log().count(said) == 1, m.log()
        finally:
            m.stop()
    fault_row("hardware", "monitor: a serial device that stays silent", "said")
