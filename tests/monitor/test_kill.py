"""A monitor killed with SIGKILL keeps everything it recorded up to a second before."""

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import pytest

from texsense import load


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def status(port):
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status", timeout=2) as r:
        return json.load(r)


@pytest.mark.slow
def test_kill_9_loses_at_most_the_last_second(tmp_path):
    port = free_port()
    cmd = [
        sys.executable,
        "-m",
        "texsense.cli",
        "monitor",
        "--speed",
        "0",
        "--no-posture",
        "--record",
        "--record-dir",
        str(tmp_path / "rec"),
        "--db",
        str(tmp_path / "m.sqlite"),
        "--port",
        str(port),
    ]
    log = (tmp_path / "monitor.log").open("wb")
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
    try:
        seen = []  # (wall time, frames processed)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            with contextlib.suppress(OSError):
                seen.append((time.monotonic(), status(port)["frames"]))
            if seen and seen[-1][1] > 600 and seen[-1][0] - seen[0][0] > 2.5:
                break
            time.sleep(0.1)
        output = (tmp_path / "monitor.log").read_text(errors="replace")
        assert seen and seen[-1][1] > 600, f"the monitor did not come up and record:\n{output}"
        files = status(port)["recording"]
        os.kill(proc.pid, signal.SIGKILL)
        killed = time.monotonic()
    finally:
        proc.kill()
        proc.wait()
        log.close()
    # everything processed more than a second before the kill must be in the files
    before = max(n for t, n in seen if t <= killed - 1.0)
    for path in files:
        rec = load(path)
        assert rec.n_frames >= before, (path, rec.n_frames, before)
        assert rec.element_times is not None and rec.n_frames > 0
