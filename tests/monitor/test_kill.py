"""A monitor killed with SIGKILL keeps everything it recorded up to a second before."""

import contextlib
import os
import signal
import time

import pytest

from texsense import load


@pytest.mark.slow
def test_kill_9_loses_at_most_the_last_second(tmp_path, monitor_process):
    rec_dir = str(tmp_path / "rec")
    m = monitor_process("--speed", "0", "--no-posture", "--record", "--record-dir", rec_dir)
    m.wait_for_frames(1)
    seen = []  # (wall time, frames processed)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError):
            seen.append((time.monotonic(), m.status()["frames"]))
        if seen and seen[-1][1] > 600 and seen[-1][0] - seen[0][0] > 2.5:
            break
        time.sleep(0.1)
    assert seen and seen[-1][1] > 600, f"the monitor did not come up and record:\n{m.log()}"
    files = m.status()["recording"]
    os.kill(m.proc.pid, signal.SIGKILL)
    killed = time.monotonic()
    m.proc.wait()
    # everything processed more than a second before the kill must be in the files
    before = max(n for t, n in seen if t <= killed - 1.0)
    for path in files:
        rec = load(path)
        assert rec.n_frames >= before, (path, rec.n_frames, before)
        assert rec.element_times is not None and rec.n_frames > 0
