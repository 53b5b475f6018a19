"""Family "an output place that cannot be written" and "a stop signal mid-write" (issue 32,
item 7): every command that writes x every kind of bad place (a folder where a file is wanted,
a file where a folder is wanted, a missing folder, no permission, a read-only file system, a
device), in one child process (without root's power to write anywhere when the tests run
as root, so that permissions apply; the read-only file system in a mount namespace of its
own). Each is one line and exit 1, and no temporary file is left anywhere. Then SIGTERM in
the middle of ``convert`` and ``process``: exit 143, one line, no temporary file, no output.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import free_port
from faults._families import batch, no_override, one_line, small_recording
from texsense import Layout, Recording
from texsense.io import save

#: command -> argv; OUT is the output: a file when it has a suffix (OUT.h5), else a folder
COMMANDS = {
    "convert .h5": ["convert", "rec.h5", "OUT.h5"],
    "convert .csv": ["convert", "rec.h5", "OUT.csv"],
    "convert .asf": ["convert", "rec.h5", "OUT.asf"],
    "plot": ["plot", "rec.h5", "-o", "OUT.png"],
    "report": ["report", "rec.h5", "-o", "OUT.html"],
    "repair": ["repair", "rec.h5", "-o", "OUT.h5"],
    "process": ["process", "cap.h5", "--calibration", "lin.json", "-o", "OUT.h5"],
    "calibrate linear": ["calibrate", "linear", "--like", "cap.h5", "--gain", "2", "--to",
                         "pressure:N/cm2", "-o", "OUT.json"],
    "simulate": ["simulate", "ramp", "--cycles", "1", "-o", "OUT.h5"],
    "muscle simulate": ["muscle", "simulate", "--minutes", "0.2", "-o", "OUT"],
    "stocking simulate": ["stocking", "simulate", "--hours", "0.2", "-o", "OUT"],
    "monitor --record-dir": ["monitor", "--no-posture", "--record-dir", "OUT", "--port", "PORT"],
    "monitor --db": ["monitor", "--no-posture", "--db", "OUT.sqlite", "--port", "PORT"],
    "station --record-dir": ["station", "--virtual-mats", "1", "--record-dir", "OUT",
                             "--port", "PORT"],
}  # fmt: skip
#: kind of bad place -> (OUT for a file output, OUT for a folder output (None: not a bad
#: place for a folder), what the one line says)
PLACES = {
    "a folder where a file is wanted": ("afolder/x", None, "is a folder"),
    "a file where a folder is wanted": ("afile/x", "afile", "is a file"),
    "a missing folder": ("missing/x", None, "does not exist"),
    "no permission": ("closed/x", "closed/x", "ermission"),
    "a device where a file is wanted": ("dev", None, "not a regular file"),
}


def _cases(root: Path, port: int) -> list[tuple[str, str, str, list[str]]]:
    """(kind, command, what is said, argv) of every bad place of every command."""
    out = []
    for kind, (file_out, folder_out, said) in PLACES.items():
        for k, (name, template) in enumerate(COMMANDS.items()):
            word = next(a for a in template if "OUT" in a)
            suffix = word.split("OUT", 1)[1]
            where = file_out if suffix else folder_out
            if where is None or (
                name == "process"
                and kind in ("a missing folder", "a folder where a file is wanted")
            ):
                continue  # (process makes the folder of its output; into a folder: an archive)
            where = where.replace("afolder/", f"afolder-{k}/").replace("missing/", f"missing-{k}/")
            target = root / (where + suffix)
            if kind == "a folder where a file is wanted":
                target.mkdir(parents=True, exist_ok=True)
            if kind.startswith("a device") and not target.exists():
                target.symlink_to("/dev/full")
            argv = [str(target) if "OUT" in a else str(port) if a == "PORT" else a
                    for a in template]  # fmt: skip
            out.append((kind, name, said, argv))
    return out


def _argv(template: list[str], out: str) -> list[str]:
    return [a.replace("OUT", out) for a in template]


@pytest.fixture(scope="module")
def root():
    """A folder everybody may enter, with the inputs, a file, a closed folder."""
    folder = Path(tempfile.mkdtemp(prefix="texsense-outputs-"))
    folder.chmod(0o755)
    save(small_recording(), folder / "rec.h5")
    cap = Recording(np.full((4, 12), 10.0), np.arange(4.0), Layout.grid(3, 4), "capacitance", "pF")
    save(cap, folder / "cap.h5")
    from texsense.cli import main

    assert main(["calibrate", "linear", "--like", str(folder / "cap.h5"), "--gain", "2",
                 "--to", "pressure:N/cm2", "-o", str(folder / "lin.json")]) == 0  # fmt: skip
    (folder / "afile").write_text("a file")
    (folder / "closed").mkdir(mode=0o555)
    (folder / "home").mkdir(mode=0o777)
    for p in folder.iterdir():
        if p.is_file():
            p.chmod(0o644)
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def _leftovers(folder: Path) -> list[str]:
    return [str(p) for p in folder.rglob(".texsense-tmp-*")]


def test_every_output_place_fails_the_same_clean_way(root, fault_row):
    cases = _cases(root, free_port())
    env = {"HOME": str(root / "home"), "MPLCONFIGDIR": str(root / "home")}
    results, _, _ = batch([c[3] for c in cases], root, env=env, preexec=no_override(), timeout=300)
    wrong = []
    for (kind, name, said, _), (rc, _out, err) in zip(cases, results, strict=True):
        try:
            line = one_line(rc, err)
            assert said in line, line
        except AssertionError as e:
            wrong.append(f"{kind} / {name}: {str(e)[:300]}")
    assert wrong == [], "\n".join(wrong)
    assert _leftovers(root) == []
    for kind in PLACES:
        done = [name for k, name, _, _ in cases if k == kind]
        fault_row("output place", f"{kind}: {len(done)} commands", "clear error",
                  ", ".join(done), cases=len(done))  # fmt: skip


def test_a_read_only_file_system(root, fault_row):
    if shutil.which("unshare") is None:
        pytest.skip("no unshare: no mount namespace for a read-only file system")
    ro = root / "ro"
    ro.mkdir(exist_ok=True)
    port = str(free_port())
    argvs = [
        [port if a == "PORT" else a for a in _argv(t, str(ro / "x"))] for t in COMMANDS.values()
    ]
    script = (f"mount -t tmpfs -o ro,size=1m tmpfs {ro} && exec {sys.executable} "
              '-c "$0"')  # fmt: skip
    from faults._families import _BATCH

    env = dict(os.environ, TEXSENSE_NO_PROGRESS="1", HOME=str(root / "home"),
               MPLCONFIGDIR=str(root / "home"))  # fmt: skip
    import json

    proc = subprocess.run(["unshare", "-rm", "sh", "-c", script, _BATCH],
                          input=json.dumps([[], argvs]), capture_output=True, text=True,
                          cwd=root, env=env, timeout=300)  # fmt: skip
    if proc.returncode != 0 and "mount" in proc.stderr:
        pytest.skip(f"no mount namespace here: {proc.stderr.strip()[:200]}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = json.loads(proc.stdout)["results"]
    for name, (rc, _out, err, _took) in zip(COMMANDS, results, strict=True):
        line = one_line(rc, err)
        assert "ead-only" in line, (name, line)
    fault_row("output place", f"a read-only file system: {len(COMMANDS)} commands",
              "clear error", ", ".join(COMMANDS), cases=len(COMMANDS))  # fmt: skip


def _big(folder: Path) -> tuple[Path, Path]:
    n, t = 400, 12_000
    rng = np.random.default_rng(0)
    lay = Layout.grid(20, 20)
    frames = rng.random((t, n), dtype=np.float32) + 9.0
    cap = save(Recording(frames, np.arange(t) * 0.01, lay, "capacitance", "pF"), folder / "big.h5")
    from texsense.cli import main

    cal = folder / "lin.json"
    assert main(["calibrate", "linear", "--like", str(cap), "--gain", "2", "--to",
                 "pressure:N/cm2", "-o", str(cal)]) == 0  # fmt: skip
    return cap, cal


@pytest.mark.parametrize("command", ["convert", "process"])
def test_sigterm_mid_write_leaves_no_temporary_file(tmp_path, command, fault_row):
    cap, cal = _big(tmp_path)
    out = tmp_path / ("out.csv" if command == "convert" else "out.h5")
    argv = ["convert", str(cap), str(out)] if command == "convert" else [
        "process", str(cap), "--calibration", str(cal), "-o", str(out)]  # fmt: skip
    proc = subprocess.Popen([sys.executable, "-m", "texsense.cli", *argv], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    deadline = time.monotonic() + 120
    while not _leftovers(tmp_path) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert _leftovers(tmp_path), f"no temporary file seen; exit {proc.poll()}"
    proc.send_signal(signal.SIGTERM)
    _stdout, err = proc.communicate(timeout=30)
    line = one_line(1, err, command, "SIGTERM")
    assert proc.returncode == 128 + signal.SIGTERM, (proc.returncode, line)
    assert _leftovers(tmp_path) == [] and not out.exists(), err
    fault_row("stop mid-write", f"SIGTERM during {command}", "data kept",
              "exit 143, one line, no temporary file")  # fmt: skip
