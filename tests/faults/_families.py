"""Helpers of the family tests of issue 32 (tests/faults/test_reach.py, test_budget.py,
test_entries.py, test_outputs.py, ...): a batch of command lines in one child process (with
its peak memory), the one-line check, a small valid recording to spoil."""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
import traceback
from pathlib import Path

import numpy as np

from texsense import Layout, Recording
from texsense.cli import main

#: Runs each argv of stdin's JSON through texsense.cli.main in this one process; prints the
#: results and the peak resident memory after the warm-up argv and at the end (KiB).
_BATCH = r"""
import json, resource, sys, time
sys.path.insert(0, TESTS)
from faults._families import call_main
warm, argvs = json.load(sys.stdin)
def run(argv):
    print("#", json.dumps(argv), file=sys.__stderr__, flush=True)  # which one, if it hangs
    start = time.monotonic()
    return [*call_main(argv), time.monotonic() - start]
for argv in warm:
    run(argv)
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
results = [run(argv) for argv in argvs]
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
json.dump({"results": results, "base_kib": base, "peak_kib": peak}, sys.stdout)
""".replace("TESTS", repr(str(Path(__file__).resolve().parents[1])))


def call_main(argv: list[str]) -> tuple[int, str, str]:
    """``texsense.cli.main(argv)`` in this process: (exit code, stdout, stderr), a traceback
    (what the fault tests look for) printed into the stderr it returns, exit code -1."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main(argv)
        except SystemExit as e:
            rc = e.code if isinstance(e.code, int) else 1
        except BaseException:
            traceback.print_exc()
            rc = -1
    return rc, out.getvalue(), err.getvalue()


def batch(
    argvs: list[list[str]],
    cwd: Path,
    *,
    warm: list[list[str]] = (),
    env: dict[str, str] | None = None,
    preexec=None,
    timeout: float = 600,
) -> tuple[list[tuple[int, str, str]], int, int]:
    """``texsense ARGV`` for each ARGV in one child process: the (exit code, stdout, stderr)
    of each, and the child's peak resident memory (KiB) after ``warm`` and at the end."""
    full_env = dict(os.environ, TEXSENSE_NO_PROGRESS="1", **(env or {}))
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _BATCH], input=json.dumps([list(warm), argvs]),
            capture_output=True, text=True, cwd=cwd, env=full_env, timeout=timeout,
            preexec_fn=preexec,
        )  # fmt: skip
    except subprocess.TimeoutExpired as e:
        text = e.stderr.decode(errors="replace") if isinstance(e.stderr, bytes) else e.stderr
        raise AssertionError(f"the batch hung; its last lines:\n{(text or '')[-2000:]}") from None
    assert proc.returncode == 0, proc.stderr[-3000:]
    doc = json.loads(proc.stdout)
    took = {" ".join(argv): r[3] for argv, r in zip(argvs, doc["results"], strict=True)}
    slow = sorted(took.items(), key=lambda kv: -kv[1])[:3]
    print("slowest:", "; ".join(f"{k[:80]} {v:.2f} s" for k, v in slow))
    return [tuple(r[:3]) for r in doc["results"]], doc["base_kib"], doc["peak_kib"]


def one_line(rc: int, err: str, *names: str) -> str:
    """Exit 1, one line on stderr, no traceback, naming each of ``names``; returns the line."""
    lines = [line for line in err.strip().splitlines() if line.strip()]
    assert rc == 1, f"exit {rc}, stderr:\n{err[-2000:]}"
    assert "Traceback" not in err, err[-3000:]
    assert len(lines) == 1, f"expected one line, got:\n{err[-2000:]}"
    for name in names:
        assert name in lines[0], f"{name!r} not named in: {lines[0]}"
    return lines[0]


def small_recording(frames: int = 5) -> Recording:
    """A 3 x 4 pressure recording with a string label, element names and a region."""
    lay = Layout.grid(3, 4, pitch_cm=1.0)
    lay = Layout(lay.xy_cm, lay.size_cm, shape=lay.shape, cells=lay.cells, pitch_cm=lay.pitch_cm,
                 neighbours=lay.neighbours, names=[f"s{k}" for k in range(12)],
                 regions={"r": [0, 1, 2]})  # fmt: skip
    values = np.linspace(0.1, 2.0, frames * 12, dtype=np.float32).reshape(frames, 12)
    return Recording(values, np.arange(frames, dtype=float) * 0.5, lay, "pressure", "N/cm2",
                     labels={"posture": np.array(["sit"] * frames)})  # fmt: skip


def two_postures(frames: int = 40) -> Recording:
    """A 4 x 4 pressure recording of two postures (``a`` and ``b`` in turn: ``--every 2``
    leaves one) by two subjects, with a number label ``back`` and a boolean ``seated``."""
    rng = np.random.default_rng(0)
    values = rng.random((frames, 16))
    posture = np.array(["a", "b"] * (frames // 2))
    values[posture == "a", :8] += 2.0
    subject = np.repeat(["s1", "s2"], frames // 2)
    labels = {"posture": posture, "subject": subject, "back": rng.random(frames),
              "seated": np.ones(frames, bool)}  # fmt: skip
    return Recording(values, np.arange(frames) * 0.5, Layout.grid(4, 4), "pressure", "N/cm2",
                     labels=labels)  # fmt: skip


def no_override():
    """A preexec function that takes from root the capabilities that let it write anywhere
    (CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH, CAP_FOWNER: dropped from the bounding set, so the
    program run keeps none of them), so that file permissions apply; None when not root."""
    if os.geteuid() != 0:
        return None
    import ctypes

    libc = ctypes.CDLL("libc.so.6", use_errno=True)

    def drop() -> None:
        for cap in (1, 2, 3):  # dac_override, dac_read_search, fowner
            if libc.prctl(24, cap, 0, 0, 0) != 0:  # PR_CAPBSET_DROP
                raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")

    return drop
