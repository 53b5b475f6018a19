"""Family "a bad option file" (issue 32, item 7: every bad option file gives one line and
exit 1): every option that names a file to read (a calibration, a model, a posture model,
regions, a ward file, credentials, a CSV of steps or of a calibration record) x every kind of
file that is not what it should be (missing, a folder, a FIFO, a device, empty, binary
garbage), in one child process that must not hang: servers included, which must refuse
before they start.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from conftest import free_port
from faults._families import batch, one_line, small_recording
from texsense import Layout, Recording
from texsense.io import save

#: option -> argv with BAD where the file goes (the other files are valid)
OPTIONS = {
    "process --calibration": ["process", "cap.h5", "--calibration", "BAD.json", "-o", "o.h5"],
    "health --calibration": ["health", "cap.h5", "--calibration", "BAD.json"],
    "calibrate linear --like": ["calibrate", "linear", "--like", "BAD.h5", "--gain", "2",
                                "--to", "pressure:N/cm2", "-o", "o.json"],
    "hysteresis fit CALIBRATION": ["hysteresis", "fit", "BAD.csv", "-o", "o.json"],
    "hysteresis apply MODEL": ["hysteresis", "apply", "BAD.json", "r.csv", "-o", "o.csv"],
    "hysteresis validate MODEL": ["hysteresis", "validate", "BAD.json", "r.csv"],
    "hysteresis plot MODEL": ["hysteresis", "plot", "BAD.json", "-o", "o.png"],
    "drift fit STEPS": ["drift", "fit", "BAD.csv"],
    "drift fit --history": ["drift", "fit", "r.csv", "--history", "BAD.json", "-o", "o.json"],
    "rehash FILE": ["rehash", "BAD.json"],
    "muscle detect --calibration": ["muscle", "detect", "cap.h5", "--calibration", "BAD.json"],
    "stocking report --calibration": ["stocking", "report", "cap.h5", "--calibration",
                                      "BAD.json"],
    "report --rois": ["report", "rec.h5", "--rois", "BAD.json", "-o", "o.html"],
    "report --model": ["report", "rec.h5", "--model", "BAD.joblib", "-o", "o.html"],
    "monitor --calibration": ["monitor", "--no-posture", "--calibration", "BAD.json",
                              "--port", "PORT"],
    "monitor --model": ["monitor", "--model", "BAD.joblib", "--port", "PORT"],
    "station --config": ["station", "--config", "BAD.toml", "--port", "PORT"],
    "station --mat-credentials": ["station", "--config", "ward.toml", "--mat-credentials",
                                  "BAD.toml", "--port", "PORT"],
    "station --broker-password-file": ["station", "--virtual-mats", "1", "--broker",
                                       "mqtt://u@127.0.0.1:1", "--broker-password-file",
                                       "BAD.txt", "--port", "PORT"],
}  # fmt: skip
#: kind -> how to make it at a path
KINDS = {
    "missing": lambda p: None,
    "folder": lambda p: p.mkdir(),
    "fifo": lambda p: os.mkfifo(p),
    "device": lambda p: p.symlink_to("/dev/zero"),
    "empty": lambda p: p.write_bytes(b""),
    "garbage": lambda p: p.write_bytes(np.random.default_rng(0).bytes(3000)),
}
#: kind -> what its one line says (any of, ignoring case)
SAID = {
    "missing": ("no such file", "does not exist"),
    "folder": ("folder", "directory"),
    "fifo": ("fifo",),
    "device": ("device",),
    "empty": ("",),
    "garbage": ("",),
}
#: the names of programming errors, which a one-line refusal must not show
BUGS = ("nameerror", "attributeerror", "typeerror", "unboundlocalerror")
#: (option, kind) pairs that are not faults: the station makes missing credentials, and an
#: empty file is credentials for no mat yet (the station adds the ward's)
VALID = {("station --mat-credentials", "missing"), ("station --mat-credentials", "empty")}
WARD = """[[mat]]
id = "bed1"
layout = "grid:4x4"
source = "mqtt"
"""


def _inputs(root: Path) -> None:
    """The valid files the other arguments name."""
    save(small_recording(), root / "rec.h5")
    cap = Recording(np.full((4, 12), 10.0), np.arange(4.0), Layout.grid(3, 4), "capacitance", "pF")
    save(cap, root / "cap.h5")
    t = np.linspace(0.0, 10.0, 64)
    x = np.abs(np.sin(t))
    rows = "\n".join(f"{a:.4f},{b:.4f},{3 * b:.4f},{1 + b:.4f}" for a, b in zip(t, x, strict=True))
    (root / "r.csv").write_text(
        "time_s,compression_mm,pressure_ncm2,capacitance_pF\n" + rows + "\n", encoding="utf-8"
    )
    (root / "ward.toml").write_text(WARD, encoding="utf-8")


def test_every_option_file_that_is_no_such_file(tmp_path, fault_row):
    _inputs(tmp_path)
    port = str(free_port())
    cases, argvs = [], []
    for option, template in OPTIONS.items():
        bad = next(a for a in template if a.startswith("BAD"))
        for kind, make in KINDS.items():
            if (option, kind) in VALID:
                continue
            path = tmp_path / f"{kind}{Path(bad).suffix}"
            if not os.path.lexists(path):
                make(path)
            cases.append((option, kind, path.name))
            argvs.append([str(path) if a == bad else port if a == "PORT" else a for a in template])
    results, _, _ = batch(argvs, tmp_path, timeout=240)  # a hang (or a server started) fails
    wrong = []
    for (option, kind, name), (rc, _out, err) in zip(cases, results, strict=True):
        try:
            line = one_line(rc, err, name).lower()
            assert any(w in line for w in SAID[kind]), line
            assert not any(bug in line for bug in BUGS), line
        except AssertionError as e:
            wrong.append(f"{option} / {kind}: {str(e)[:300]}")
    assert wrong == [], "\n".join(wrong)
    for option in OPTIONS:
        done = [kind for o, kind, _ in cases if o == option]
        fault_row("option file", f"{option}: {', '.join(done)}", "clear error", cases=len(done))
