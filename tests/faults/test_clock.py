"""Family "times on a scale no clock has" (harden14a): a recording whose times are x 1e300,
hold one stray stamp of 1e9 s in a 10 Hz file, advance by 1e-300 s or not at all made
``stocking report`` trace back or run on (an ``arange`` per hour over the span) and ``muscle
detect`` trace back (a window of ``round(5 / dt)`` frames with ``dt`` 0). Every reader's times
now pass one check, ``texsense.data.times.TimeCheck`` (a span over ten years, a time beyond
1e12 s, frames under 1 us apart on average: one line naming the file, the line or frame and
the time), and the apps size their work from time within the frame count
(``Recording.frames_in``, ``apps.stocking.report``), so that a real session of years costs
what its frames cost.

The table: every format of the registry that can hold a time x the time pathologies x the
commands that read a recording; each run is a clean run or one line naming the file, never a
traceback, a hang or numpy's warning.
"""

from __future__ import annotations

import contextlib
import datetime
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from conftest import SHARED_DATA
from faults._families import batch, call_main, small_recording
from texsense import Layout, Recording
from texsense.exceptions import ParameterError
from texsense.io import READER_CLASSES, load, save
from texsense.io.columns_csv import write_columns_csv

YEAR = 365.25 * 86400.0
VENDOR = SHARED_DATA / "vendor-formats"

#: time pathologies: (new times from a file's own times, whether a reader refuses them)
PATHOLOGIES: dict[str, tuple[Callable[[np.ndarray], np.ndarray], bool]] = {
    "x 1e300": (lambda t: (t - t[0]) * 1e300, True),
    "a stray 1e9 s last": (lambda t: np.r_[t[:-1], 1e9], True),
    "a stray 1e9 s inside": (lambda t: np.r_[t[: t.size // 2], 1e9, t[t.size // 2 + 1 :]], True),
    "steps of 1e-300 s": (lambda t: np.arange(t.size) * 1e-300, True),
    "all at one time": (lambda t: np.full(t.size, t[0]), True),
    # a clock a reader accepts: the apps bound what they size from it by the frame count
    "nine years over the frames": (lambda t: np.linspace(0.0, 9 * YEAR, t.size), False),
    "seconds since 1970": (lambda t: t + 1.7e9, False),
}

_CAL = {
    "strip": ["--calibration", "stock/calibration.json"],
    "sleeve": ["--calibration", "musc/calibration.json"],
}
#: the commands that read a recording, by the kind of recording they read
COMMANDS: dict[str, dict[str, Callable[[str], list[str]]]] = {
    "mat": {
        "info": lambda p: ["info", p],
        "convert": lambda p: ["convert", p, "out.h5"],
        "plot": lambda p: ["plot", p, "-o", "out.png"],
        "report": lambda p: ["report", p, "-o", "out.html"],
        "repair": lambda p: ["repair", p, "-o", "out.h5"],
        "muscle detect": lambda p: ["muscle", "detect", p],
    },
    "cap": {
        "process": lambda p: ["process", p, "--calibration", "lin.json", "-o", "out.h5"],
        "health": lambda p: ["health", p],
    },
    "strip": {"stocking report": lambda p: ["stocking", "report", p, *_CAL["strip"]]},
    "sleeve": {"muscle detect": lambda p: ["muscle", "detect", p, *_CAL["sleeve"]]},
}

#: by format: the kinds of recording it holds here (a Tekscan file holds a grid of pressure
#: and no element names; a columns table holds one element; the vendors' files are theirs)
KINDS = {
    "hdf5": ["mat", "cap", "strip", "sleeve"],
    "wide-csv": ["mat", "cap", "strip", "sleeve"],
    "tekscan": ["mat"],  # a grid of pressure, force or counts
    "columns-csv": ["mat"],
    "xsensor": ["mat"],
    "pliance": ["mat"],
    "pmd": [],  # no time in the file: the reader places frames 1 s apart
}


def _sources(root: Path) -> dict[str, Recording]:
    """The recordings of each kind (and their calibrations, written into ``root``)."""
    with contextlib.chdir(root):
        for argv in (["stocking", "simulate", "--hours", "0.5", "-o", "stock"],
                     ["muscle", "simulate", "--minutes", "0.5", "-o", "musc"]):  # fmt: skip
            assert call_main(argv)[0] == 0, argv
    rng = np.random.default_rng(3)
    cap = Recording(10 + 0.01 * rng.standard_normal((20, 12)), np.arange(20) * 0.1,
                    Layout.grid(3, 4), "capacitance", "pF")  # fmt: skip
    save(cap, root / "cap-source.h5")
    with contextlib.chdir(root):
        argv = ["calibrate", "linear", "--like", "cap-source.h5", "--gain", "2", "-o", "lin.json"]
        assert call_main(argv)[0] == 0
    return {"mat": small_recording(20), "cap": cap, "strip": load(root / "stock" / "strip.h5"),
            "sleeve": load(root / "musc" / "sleeve.h5")}  # fmt: skip


def _retimed(rec: Recording, times: np.ndarray) -> Recording:
    return Recording(rec.frames, times, rec.layout, rec.quantity, rec.unit, valid=rec.valid,
                     labels=rec.labels, meta=rec.meta)  # fmt: skip


def _xsensor(times: np.ndarray, path: Path) -> Path | None:
    """The vendor's XSENSOR file with its frames stamped ``times`` (s after its first); None
    for times its stamps (dates of years 1-9999, to the microsecond) cannot hold."""
    if not (np.all(np.abs(times) < 1e11) and np.array_equal(np.round(times, 6), times)):
        return None
    text = VENDOR.joinpath("xsensor_data.csv").read_text(encoding="utf-8-sig")
    start = datetime.datetime(2022, 8, 16, 8, 21, 17, 982000)
    stamps = iter(start + datetime.timedelta(seconds=float(t)) for t in times)
    lines = text.split("\n")
    for i, line in enumerate(lines):
        if line.startswith("Date,"):
            when = next(stamps)
            lines[i] = f"Date, {when:%Y %b %d}" + line[line.index(",,") :]
            j = next(k for k in range(i, len(lines)) if lines[k].startswith("Time,"))
            lines[j] = f"Time, {when:%H:%M:%S.%f}" + lines[j][lines[j].index(",,") :]
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def _pliance(times: np.ndarray, path: Path) -> Path:
    """The vendor's pliance file with its frame table's times ``times``."""
    lines = VENDOR.joinpath("pliance_test.asc").read_text(encoding="latin-1").split("\n")
    start = next(i for i, s in enumerate(lines) if s.startswith("time[secs]")) + 1
    for k, t in enumerate(times):
        token = lines[start + k].split(None, 1)
        lines[start + k] = f"{float(t)!r} {token[1]}"
    path.write_text("\n".join(lines), encoding="latin-1")
    return path


def _write(fmt: str, kind: str, rec: Recording, times: np.ndarray, path: Path) -> Path | None:
    """A file of format ``fmt`` holding ``rec`` (a ``kind``) with ``times``; None if the
    format cannot hold them."""
    if fmt in ("hdf5", "wide-csv", "tekscan"):
        suffix = {"hdf5": ".h5", "wide-csv": ".csv", "tekscan": ".asf"}[fmt]
        return save(_retimed(rec, times), path.with_suffix(suffix))
    if fmt == "columns-csv":
        cols = {"time_s": times, "pressure_ncm2": rec.frames[:, 0]}
        return write_columns_csv(path.with_suffix(".csv"), cols)
    if fmt == "xsensor":
        return _xsensor(times - times[0], path.with_suffix(".csv"))
    return _pliance(times, path.with_suffix(".asc"))


def _vendor_times(fmt: str) -> np.ndarray:
    return load(VENDOR / {"xsensor": "xsensor_data.csv", "pliance": "pliance_test.asc"}[fmt]).times


def cases(fmt: str, root: Path) -> list[tuple[str, list[str], str, bool]]:
    """The runs over the files of ``fmt`` (written into ``root``): (what it is, argv, the
    file, whether its times are refused)."""
    sources = _sources(root) if fmt not in ("xsensor", "pliance") else {}
    out = []
    for kind in KINDS[fmt]:
        rec = sources.get(kind)
        base = rec.times if rec is not None else _vendor_times(fmt)
        for name, (make, refused) in PATHOLOGIES.items():
            stem = re.sub(r"\W+", "-", f"{kind} {name}")
            path = _write(fmt, kind, rec, make(base.copy()), root / stem)
            if path is None:
                continue  # not a time this format can hold
            for command, argv in COMMANDS[kind].items():
                what = f"{fmt} {kind} {name} | {command}"
                out.append((what, argv(path.name), path.name, refused))
    return out


def _wrong(file: str, refused: bool, rc: int, err: str) -> str | None:
    """What is wrong with a run: a traceback, numpy's words, an exit other than 0 or 1, an
    exit 1 in more than one line; times to refuse not refused in one line naming the file
    and its time."""
    lines = [s for s in err.strip().splitlines() if s.strip()]
    if "Traceback" in err or "Warning" in err or rc not in (0, 1):
        return f"exit {rc}: {err[-600:]}"
    if rc == 1 and len(lines) != 1:
        return f"exit 1 in {len(lines)} lines: {err[-600:]}"
    if refused and not (rc == 1 and file in lines[0] and "time" in lines[0]):
        return f"exit {rc}: not one line naming {file} and its time: {err[-300:]}"
    return None


@pytest.mark.parametrize("fmt", list(KINDS))
def test_times_no_clock_has_are_one_line_or_a_clean_run(fmt, tmp_path, fault_row):
    runs = cases(fmt, tmp_path)
    if not runs:
        assert fmt == "pmd", f"{fmt} holds none of the time pathologies here"
        return
    results, _, _ = batch([argv for _, argv, _, _ in runs], tmp_path, timeout=600)
    wrong = []
    for (what, _, file, refused), (rc, _out, err) in zip(runs, results, strict=True):
        problem = _wrong(file, refused, rc, err)
        if problem:
            wrong.append(f"{what}: {problem}")
        if rc == 0:  # the next run starts from the same folder
            for made in ("out.h5", "out.png", "out.html"):
                (tmp_path / made).unlink(missing_ok=True)
    assert not wrong, f"{len(wrong)} of {len(runs)}:\n" + "\n".join(wrong)
    fault_row("clock", f"{fmt}: time pathologies x the commands that read a recording",
              "clear error or read", cases=len(runs))  # fmt: skip


def test_every_reader_is_in_the_table():
    assert set(KINDS) == set(READER_CLASSES)


def test_the_reader_names_the_file_and_the_first_bad_time(tmp_path):
    rec = small_recording(30)
    t = rec.times.copy()
    t[12] = 1e9
    path = save(_retimed(rec, t), tmp_path / "r.h5")
    with pytest.raises(Exception, match=r"r\.h5: frame 13: the time 1e\+09 s is 1e\+09 s after"):
        load(path)
    path = save(_retimed(rec, np.zeros(30)), tmp_path / "z.csv")
    with pytest.raises(Exception, match=r"z\.csv: all 30 frames have the time 0 s"):
        load(path)


@pytest.mark.parametrize("name", list(PATHOLOGIES))
def test_windows_from_time_stay_within_the_frames(name):
    """``Recording.frames_in`` (how the apps size a window from time) gives 1 .. n frames
    whatever the times (a recording made in Python is not read by a reader), or refuses
    times that do not advance in one line."""
    rec = small_recording(40)
    retimed = _retimed(rec, PATHOLOGIES[name][0](rec.times))
    for seconds in (0.0, 1e-300, 0.5, 5.0, 3600.0, 1e300, np.inf):
        try:
            k = retimed.frames_in(seconds)
        except ParameterError as e:
            assert "do not advance" in str(e) and name == "all at one time"
        else:
            assert 1 <= k <= rec.n_frames


def test_stocking_rows_are_bounded_by_the_frames():
    """A row every hour over nine years of 20 frames would be 78,894 rows (an ``arange`` and a
    pass over the frames each): refused in one line; every 10 min over 3 h of 20 frames is 18."""
    from texsense.apps.stocking import POINTS, report

    lay = Layout.points(np.c_[np.arange(4.0), np.zeros(4)], names=list(POINTS))
    rec = Recording(np.ones((20, 4)), np.linspace(0, 9 * YEAR, 20), lay, "pressure", "N/cm2")
    with pytest.raises(ParameterError, match="more than its 20 frames"):
        report(rec)
    short = _retimed(rec, np.linspace(0, 3 * 3600, 20))
    assert len(report(short, every_h=1 / 6).hours) == 18
