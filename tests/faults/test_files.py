"""Fault battery: files (issue 28, items 3 and 4). Corrupted recordings of every format, failed
writes (a file-size limit in the child process) and killed writes (SIGKILL), and outputs that
would replace an input. Each case asserts its outcome and records a row (docs/reliability.md).

The reading cases (tests/faults/_file_cases.py) run through ``texsense info --json`` in one
child process that calls the command line once per case (a fresh interpreter per case would
take minutes): stdout and stderr are captured per case, and an exception that escapes the
command is recorded as a traceback, which fails the case.
"""

from __future__ import annotations

import hashlib
import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from faults._families import batch
from faults._file_cases import ISCAN, ROWS, Case, all_cases
from faults.conftest import assert_clear_error, run_cli

CASES = all_cases()


def cli_batch(argvs: list[list[str]], cwd: Path) -> list[tuple[int, str, str]]:
    """``texsense ARGV`` for each ARGV, in one child process: (exit code, stdout, stderr)."""
    return batch(argvs, cwd, timeout=900)[0]


@pytest.fixture(scope="module")
def reading(tmp_path_factory):
    """Every reading case built and run: {case id: (path, rc, stdout, stderr)}."""
    root = tmp_path_factory.mktemp("reading")
    paths, argvs = {}, []
    for k, case in enumerate(CASES):
        folder = root / f"{k:03d}"
        folder.mkdir()
        paths[case.id] = case.make(folder)
        argvs.append(["info", "--json", *case.args, str(paths[case.id])])
    results = cli_batch(argvs, root)
    return {c.id: (paths[c.id], *r) for c, r in zip(CASES, results, strict=True)}


def _warning_lines(err: str) -> list[str]:
    assert "Traceback" not in err, err
    return [line for line in err.strip().splitlines() if line.strip()]


def check_case(case: Case, path: Path, rc: int, out: str, err: str) -> str:
    """Assert the case's outcome; returns a detail for the table."""
    if case.outcome == "clear error":
        line = assert_clear_error(rc, err, path.name)
        assert case.expect in line, f"{case.expect!r} not in: {line}"
        return ""
    assert rc == 0, f"exit {rc}: {err}"
    info = json.loads(out)
    lines = _warning_lines(err)
    if case.frames is not None:
        assert info["frames"] == case.frames, info["frames"]
    if case.outcome == "read":
        assert lines == [], lines
        return f"{info['frames']} frames, as the original"
    assert len(lines) == 1 and path.name in lines[0], lines
    if case.outcome == "invalid readings":
        assert info["invalid_readings"] == case.invalid, info["invalid_readings"]
        assert f"{case.invalid} reading(s) marked invalid" in lines[0], lines[0]
        return f"{case.invalid} counted"
    assert case.outcome == "read, warned", case.outcome
    assert case.expect in lines[0], f"{case.expect!r} not in: {lines[0]}"
    return f"{info['frames']} frames read"


@pytest.mark.xdist_group("reading")  # one worker builds and reads the cases (20 s), not both
@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_reading(case, reading, fault_row):
    path, rc, out, err = reading[case.id]
    detail = check_case(case, path, rc, out, err)
    fault_row(case.area, case.name, case.outcome, detail)


def test_every_issue_row_has_cases():
    covered = {c.row for c in CASES} | {"write", "onto-input"}
    assert covered >= set(ROWS)


# ---------------------------------------------------------------------------- writes
def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _leftovers(folder: Path) -> list[Path]:
    return [p for p in folder.iterdir() if p.name.startswith(".texsense-tmp-")]


def _limit(nbytes: int):
    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, nbytes))


@pytest.fixture(scope="module")
def previous(tmp_path_factory):
    """A small valid recording, the 'previous file' a failed write must keep."""
    from texsense import Layout, Recording

    folder = tmp_path_factory.mktemp("previous")
    rec = Recording(
        np.ones((4, 9)), np.arange(4.0), Layout.grid(3, 3, pitch_cm=1.0), "raw", "count"
    )
    return rec.save(folder / "previous.h5")


def _place_previous(previous: Path, target: Path) -> str:
    if target.suffix == ".h5":
        target.write_bytes(previous.read_bytes())
    else:  # any earlier content: the write must not touch it
        target.write_bytes(b"earlier content of " + target.name.encode())
    return _digest(target)


@pytest.mark.parametrize("limit", [4096, 65536], ids=["4 KiB", "64 KiB"])
@pytest.mark.parametrize("suffix", [".h5", ".csv", ".asf"])
def test_convert_with_the_disk_full(tmp_path, previous, fault_row, suffix, limit):
    target = tmp_path / f"out{suffix}"
    before = _place_previous(previous, target)
    rc, _, err = run_cli("convert", ISCAN, target, cwd=tmp_path, preexec=_limit(limit))
    assert_clear_error(rc, err, target.name, "File too large")
    assert _digest(target) == before and _leftovers(tmp_path) == []
    fault_row("writes", f"convert to {suffix} with a file-size limit of {limit // 1024} KiB",
              "data kept")  # fmt: skip


def _capacitance(path: Path, frames: int, n: int = 1024) -> Path:
    """A capacitance recording of random values (slow to compress: a long write)."""
    from texsense import Layout
    from texsense.io import RecordingWriter

    rng = np.random.default_rng(1)
    with RecordingWriter(path, Layout.grid(32, n // 32, pitch_cm=1.0), "capacitance", "pF") as w:
        for a in range(0, frames, 1000):
            k = min(1000, frames - a)
            w.append(5 + rng.random((k, n)), np.arange(a, a + k) * 0.1)
    return path


@pytest.fixture(scope="module")
def linear_calibration(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cal")
    raw = _capacitance(folder / "raw.h5", 200)
    rc, _, err = run_cli("calibrate", "linear", "--like", raw, "-o", folder / "lin.json")
    assert rc == 0, err
    return folder / "lin.json"


@pytest.mark.parametrize("what", ["process", "plot"])
def test_process_and_plot_with_the_disk_full(tmp_path, previous, linear_calibration, what,
                                             fault_row):  # fmt: skip
    raw = _capacitance(tmp_path / "raw.h5", 300)
    target = tmp_path / ("out.h5" if what == "process" else "out.png")
    before = _place_previous(previous, target)
    args = (
        ("process", raw, "--calibration", linear_calibration, "-o", target)
        if what == "process"
        else ("plot", raw, "-o", target)
    )
    # a matplotlib without its font cache tries to save one too, under the same limit
    fresh = dict(os.environ, MPLCONFIGDIR=str(tmp_path / "mpl"))
    rc, _, err = run_cli(*args, cwd=tmp_path, preexec=_limit(4096), env=fresh)
    assert_clear_error(rc, err, target.name, "File too large")
    assert _digest(target) == before and _leftovers(tmp_path) == []
    fault_row("writes", f"{what} with a file-size limit of 4 KiB", "data kept")


def _kill_while_writing(args: list, target: Path, cwd: Path) -> None:
    """Start ``texsense ARGS`` and SIGKILL it 0.3 s after it starts writing ``target``
    (its temporary file appears, or ``target`` itself changes)."""
    before = target.stat().st_mtime_ns
    proc = subprocess.Popen([sys.executable, "-m", "texsense.cli", *map(str, args)], cwd=cwd,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            if _leftovers(cwd) or target.stat().st_mtime_ns != before:
                time.sleep(0.3)
                break
            time.sleep(0.005)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the write ended before it was killed"


@pytest.mark.parametrize("suffix", [".h5", ".csv"])
def test_convert_killed_mid_write(tmp_path, previous, fault_row, suffix):
    src = _capacitance(tmp_path / "big.h5", 12000 if suffix == ".h5" else 2000)
    target = tmp_path / f"out{suffix}"
    before = _place_previous(previous, target)
    _kill_while_writing(["convert", src, target], target, tmp_path)
    assert _digest(target) == before
    if suffix == ".h5":
        rc, out, err = run_cli("info", "--json", target, cwd=tmp_path)
        assert rc == 0 and json.loads(out)["frames"] == 4, (rc, err)
    left = _leftovers(tmp_path)
    for tmp in left:  # never read as a valid (0-frame) recording
        rc, _, err = run_cli("info", tmp, cwd=tmp_path)
        assert_clear_error(rc, err, tmp.name)
    detail = f"{len(left)} temporary file left, refused by info" if left else "nothing left"
    fault_row("writes", f"convert to {suffix} killed (SIGKILL) mid-write", "data kept", detail)


def test_live_recording_killed(tmp_path, fault_row):
    """The live recorder's appendable HDF5 stays readable after kill -9 (minus what was not
    flushed), and the reader says so."""
    path = tmp_path / "live.h5"
    script = (
        "import time, numpy as np\n"
        "from texsense import Layout\n"
        "from texsense.io import RecordingWriter\n"
        f"w = RecordingWriter({str(path)!r}, Layout.grid(8, 8), 'pressure', 'N/cm2',"
        " flush_interval_s=0.2)\n"
        "k = 0\n"
        "while True:\n"
        "    w.append(np.full((5, 64), k, np.float32), np.arange(k, k + 5) * 0.1)\n"
        "    k += 5\n"
        "    if k == 100: print('ready', flush=True)\n"
        "    time.sleep(0.002)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.5)
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
    rc, out, err = run_cli("info", "--json", path, cwd=tmp_path)
    assert rc == 0, err
    frames = json.loads(out)["frames"]
    lines = _warning_lines(err)
    assert frames >= 100 and len(lines) == 1 and "not closed by its recorder" in lines[0]
    fault_row("writes", "live recording killed (SIGKILL) while recording", "read, warned",
              "the frames flushed before the kill")  # fmt: skip


# ---------------------------------------------------------------------------- onto an input
@pytest.fixture(scope="module")
def onto_input(tmp_path_factory, linear_calibration):
    folder = tmp_path_factory.mktemp("onto")
    raw = _capacitance(folder / "raw.h5", 100)
    (folder / "archive").mkdir()
    arch = _capacitance(folder / "archive" / "a.h5", 50)
    cal = str(linear_calibration)
    cases = {
        "process raw.h5 -o raw.h5": ["process", "raw.h5", "--calibration", cal, "-o", "raw.h5"],
        "process raw.h5 -o ./raw.h5 (another spelling)":
            ["process", "raw.h5", "--calibration", cal, "-o", "./sub/../raw.h5"],
        "process raw.h5 -o link.h5 (a link to raw.h5)":
            ["process", "raw.h5", "--calibration", cal, "-o", "link.h5"],
        "process an archive into its own folder":
            ["process", "archive", "--calibration", cal, "-o", "archive"],
        "convert raw.h5 raw.h5": ["convert", "raw.h5", "raw.h5"],
        "repair raw.h5 -o raw.h5": ["repair", "raw.h5", "-o", "raw.h5"],
        "plot raw.h5 -o raw.h5": ["plot", "raw.h5", "-o", "raw.h5"],
        "calibrate linear --like raw.h5 -o raw.h5":
            ["calibrate", "linear", "--like", "raw.h5", "-o", "raw.h5"],
    }  # fmt: skip
    (folder / "sub").mkdir()
    (folder / "link.h5").symlink_to(raw)
    before = {p: _digest(p) for p in (raw, arch)}
    results = dict(zip(cases, cli_batch(list(cases.values()), folder), strict=True))
    return results, before


@pytest.mark.parametrize(
    "name",
    [
        "process raw.h5 -o raw.h5",
        "process raw.h5 -o ./raw.h5 (another spelling)",
        "process raw.h5 -o link.h5 (a link to raw.h5)",
        "process an archive into its own folder",
        "convert raw.h5 raw.h5",
        "repair raw.h5 -o raw.h5",
        "plot raw.h5 -o raw.h5",
        "calibrate linear --like raw.h5 -o raw.h5",
    ],
)
def test_output_onto_an_input_is_refused(onto_input, name, fault_row):
    results, before = onto_input
    rc, _, err = results[name]
    assert_clear_error(rc, err, "is also an input")
    assert all(_digest(p) == d for p, d in before.items())
    fault_row("output onto input", name, "clear error", "the input is unchanged")


def test_written_files_keep_their_permissions(tmp_path, previous):
    """Writing through a temporary file does not make outputs private: a new file gets
    0666 less the umask, a replaced file keeps its mode."""
    from texsense.io import load, save

    rec = load(previous)
    new = save(rec, tmp_path / "new.h5")
    umask = os.umask(0o022)
    os.umask(umask)
    assert new.stat().st_mode & 0o777 == 0o666 & ~umask
    new.chmod(0o640)
    save(rec, new)
    assert new.stat().st_mode & 0o777 == 0o640
