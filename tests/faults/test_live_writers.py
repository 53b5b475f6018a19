"""Family "a live recording written over a file" (harden12): a live recording is written in
place (it survives a crash: a killed recorder keeps all but its last second), so it must be a
new file. ``RecordingWriter`` (``live=True``) now creates its file exclusively, the one place
under every live writer: ``texsense record``, the monitor's recorder, ``simulate device
--truth`` and the API. Before, ``simulate device --truth night.h5`` wrote over an existing
``night.h5`` without a word, and the recorders that checked (``record``, the monitor) looked
with ``exists()``, which a dangling link passes: the recording was then made where the link
pointed, outside the folder.

The table: every live writer x what is at the path (a file, a link to a file, a link to
nothing, a folder): refused in one line, the file and the link's target unchanged, nothing
made at a dangling link's target.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import types
from pathlib import Path

import pytest

from faults._families import batch, small_recording
from texsense import Layout
from texsense.exceptions import ParameterError
from texsense.io import save
from texsense.io.hdf5 import RecordingWriter
from texsense.monitor.record import Recorder

#: what may be at the path a live recording is to be written to
TARGETS = ("a file", "a link to a file", "a link to nothing", "a folder")


def _target(folder: Path, kind: str, name: str) -> tuple[Path, Path]:
    """``folder/name`` made as ``kind``; returns it and the file whose bytes must stay (or,
    for a dangling link, the path that must not be made)."""
    folder.mkdir(parents=True, exist_ok=True)
    outside = folder.parent / f"outside-{folder.name}"
    outside.mkdir(exist_ok=True)
    path = folder / name
    if kind == "a file":
        save(small_recording(), path)
        return path, path
    if kind == "a link to a file":
        save(small_recording(), outside / "kept.h5")
        path.symlink_to(outside / "kept.h5")
        return path, outside / "kept.h5"
    if kind == "a link to nothing":
        path.symlink_to(outside / "made-there.h5")
        return path, outside / "made-there.h5"
    path.mkdir()
    return path, path


def _state(p: Path) -> str | None:
    if p.is_dir():
        return "folder:" + ",".join(sorted(x.name for x in p.iterdir()))
    return hashlib.sha256(p.read_bytes()).hexdigest() if p.exists() else None


def _api_writer(path: Path) -> None:
    RecordingWriter(path, Layout.grid(2, 2), "pressure", "N/cm2").close()


def _monitor_recorder(path: Path) -> None:
    source = types.SimpleNamespace(layout=Layout.grid(2, 2), quantity="pressure", unit="N/cm2")
    assert path.name.endswith("-raw.h5")
    Recorder(path.parent, path.name[: -len("-raw.h5")], source, {}).close()  # type: ignore[arg-type]


def _simulate_device(path: Path) -> tuple[int, str]:
    """``simulate device --truth PATH`` in a child (before, it served for ever: a timeout)."""
    link = path.parent / f"link-{os.getpid()}-{path.name}"
    argv = ["simulate", "device", "--mat", "seat", "--link", str(link), "--truth", str(path)]
    code = "import sys; from texsense.cli import main; sys.exit(main(sys.argv[1:]))"
    try:
        proc = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True,
                              text=True, timeout=60, stdin=subprocess.DEVNULL)  # fmt: skip
    except subprocess.TimeoutExpired:
        return -9, "served: wrote the truth over what was there"
    if link.is_symlink():
        return proc.returncode, proc.stderr + " (and the device's link was left behind)"
    return proc.returncode, proc.stderr


@pytest.mark.slow
def test_a_live_recording_never_writes_over_a_path(tmp_path, fault_row):
    bad, cases = [], 0
    for kind in TARGETS:  # the API and the monitor's recorder, in this process
        for name, write in (("api", _api_writer), ("monitor", _monitor_recorder)):
            path, kept = _target(tmp_path / f"{name}-{TARGETS.index(kind)}", kind, "x-raw.h5")
            before = _state(kept)
            try:
                write(path)
                bad.append(f"{name} over {kind}: taken")
            except ParameterError as e:
                if "exists" not in str(e):
                    bad.append(f"{name} over {kind}: {e}")
            except OSError as e:  # (what the test looks for: not said as a recorder says it)
                bad.append(f"{name} over {kind}: {type(e).__name__}: {e}")
            if _state(kept) != before:
                bad.append(f"{name} over {kind}: {kept.name} changed or made")
            cases += 1
    paths, argvs = [], []
    for kind in TARGETS:  # texsense record, in one child
        path, kept = _target(tmp_path / f"record-{TARGETS.index(kind)}", kind, "x.h5")
        paths.append((kind, kept, _state(kept)))
        argvs.append(["record", "--source", "virtual", "--speed", "0", "--frames", "2", "-o",
                      str(path)])  # fmt: skip
    results, _, _ = batch(argvs, tmp_path, timeout=300)
    for (kind, kept, before), (rc, _out, err) in zip(paths, results, strict=True):
        if rc != 1 or "Traceback" in err or len(err.strip().splitlines()) != 1:
            bad.append(f"record over {kind}: exit {rc}: {err.strip()[-200:]}")
        if _state(kept) != before:
            bad.append(f"record over {kind}: {kept.name} changed or made")
        cases += 1
    for kind in TARGETS:
        path, kept = _target(tmp_path / f"device-{TARGETS.index(kind)}", kind, "truth.h5")
        before = _state(kept)
        rc, err = _simulate_device(path)
        if rc != 1 or "exists" not in err or "Traceback" in err or "left behind" in err:
            bad.append(f"simulate device --truth over {kind}: exit {rc}: {err.strip()[-200:]}")
        if _state(kept) != before:
            bad.append(f"simulate device --truth over {kind}: {kept.name} changed or made")
        cases += 1
    print(f"{cases - len({b.split(':')[0] for b in bad})} of {cases} cases held")
    assert not bad, "\n".join(bad)
    fault_row("output place", f"{len(TARGETS)} things at the path x 4 live writers (API, "
              "monitor, record, simulate device --truth)", "data kept", cases=cases)  # fmt: skip
