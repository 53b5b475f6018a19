"""Times no clock has, at the entries the readers' time check (``data.times.TimeCheck``) did
not cover (harden15): a column table's ``time_s`` read by the tools of one element (the
hysteresis and drift fits, ``read_columns``), a player's frames read out of order
(``RecordingReader.frames_at``), the elements' own times in a file (every reader's blocks
and ``frames_at``), and live frames (the monitor, and so the station's mats,
``texsense record`` and ``calibrate wizard``: ``FrameClock.place_frame``). Every entry x
every pathology: a refusal in one line naming where and what (files), or the frame refused,
counted and said (live), and never a time off the scale downstream.
``benchmarks/time_cases.py`` counts the same cases.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import numpy as np
import pytest

from faults._families import call_main
from texsense import Layout, Recording
from texsense.data.protocol import Frame
from texsense.exceptions import FormatError

LAY = Layout.grid(1, 2)
N = 6  # frames of a case, 1 s apart from 100 s
YEARS = 3.2e8  # ten years and more, back

#: name -> (index of the bad frame or None for all, its time from the good one)
PATHOLOGIES: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "times x 1e300": lambda t: t * 1e300,
    "NaN first": lambda t: np.r_[np.nan, t[1:]],
    "NaN inside": lambda t: np.r_[t[:3], np.nan, t[4:]],
    "inf inside": lambda t: np.r_[t[:3], np.inf, t[4:]],
    "1e300 first": lambda t: np.r_[1e300, t[1:]],
    "1e300 inside": lambda t: np.r_[t[:3], 1e300, t[4:]],
    "-1e300 inside": lambda t: np.r_[t[:3], -1e300, t[4:]],
    "9e12 s (serial's largest)": lambda t: np.r_[t[:3], 9.2e12, t[4:]],
    "back by years inside": lambda t: np.r_[t[:3], t[3] - YEARS, t[4:]],
}


def _times(name: str, n: int = N) -> np.ndarray:
    return PATHOLOGIES.get(name, lambda t: t)(100.0 + np.arange(n, dtype=np.float64))


# ------------------------------------------------------------------ files


def _table(folder: Path, name: str) -> Path:
    """A step of 1 mm held for 50 s (a drift fit's and a hysteresis fit's record, 1 Hz) with
    the pathology's times (``"good"``: none)."""
    path = folder / "table.csv"
    mm = np.r_[np.linspace(0.0, 1.0, 10), np.full(50, 1.0)].tolist()
    ncm2 = np.r_[np.linspace(0.0, 2.0, 10), 2.0 - 0.05 * np.log1p(np.arange(50))].tolist()
    times = _times(name, 60)
    rows = [f"{float(t)!r},{c!r},{p!r}" for t, c, p in zip(times, mm, ncm2, strict=True)]
    path.write_text("time_s,compression_mm,pressure_ncm2\n" + "\n".join(rows) + "\n")
    return path


def _read_columns(folder: Path, name: str) -> str | None:
    from texsense.io.columns import read_columns

    path = _table(folder, name)
    try:
        read_columns(path, required=("time_s", "pressure_ncm2"))
    except FormatError as e:
        return None if "line" in str(e) and str(path) in str(e) else f"unclear: {e}"
    return "read"


def _command(argv: list[str]) -> Callable[[Path, str], str | None]:
    def run(folder: Path, name: str) -> str | None:
        path = _table(folder, name)
        code, _out, err = call_main([a.replace("TABLE", str(path)) for a in argv])
        lines = err.strip().splitlines()
        if code == 1 and len(lines) == 1 and str(path) in err and "time" in err:
            return None
        return f"exit {code}: {err.strip()[-200:]!r}"

    return run


def _frames_at(folder: Path, name: str) -> str | None:
    import h5py

    from texsense.io.hdf5 import HDF5Reader

    path = folder / "r.h5"
    Recording(np.ones((N, 2)), 100.0 + np.arange(N), LAY, "pressure", "N/cm2").save(path)
    with h5py.File(path, "r+") as f:
        f["times"][...] = _times(name)
    with HDF5Reader(path) as reader:
        try:
            piece = reader.frames_at(0, N)
        except FormatError as e:
            return None if "frame" in str(e) and str(path) in str(e) else f"unclear: {e}"
    return f"read times {piece.times.tolist()}"


def _element_times(folder: Path, name: str) -> str | None:
    """A recording whose frame times are right and whose second element's times have the
    pathology: read whole (``load``, every reader's blocks) and out of order (``frames_at``)."""
    from texsense.io import load
    from texsense.io.hdf5 import HDF5Reader

    path = folder / "r.h5"
    t = 100.0 + np.arange(N)
    et = np.c_[t, _times(name)]
    Recording(np.ones((N, 2)), t, LAY, "pressure", "N/cm2", element_times=et).save(path)
    read = []
    for how, what in (("load", lambda: load(path)),
                      ("frames_at", lambda: HDF5Reader(path).frames_at(0, N))):  # fmt: skip
        try:
            what()
            read.append(how)
        except FormatError as e:
            if "element 2" not in str(e) or str(path) not in str(e):
                return f"unclear: {e}"
    if name == "back by years inside":  # on the scale: an element's time is not judged more
        return None
    return f"read by {read}" if read else None


FILE_ENTRIES: dict[str, Callable[[Path, str], str | None]] = {
    "read_columns": _read_columns,
    "hysteresis fit": _command(["hysteresis", "fit", "TABLE", "-o", "TABLE.json"]),
    "drift fit": _command(["drift", "fit", "TABLE"]),
    "frames_at": _frames_at,
    "element times (load, frames_at)": _element_times,
}


# ------------------------------------------------------------------ live


def _frames(name: str) -> list[Frame]:
    return [Frame(k, np.full(2, t), np.full(2, 1.0), "N/cm2") for k, t in enumerate(_times(name))]


def _off_scale(t: float | None) -> bool:
    return t is None or not math.isfinite(t) or abs(t) > 1e12


def _monitor(name: str) -> str | None:
    from texsense.monitor import ExposureTracker, Monitor, ReplaySource

    source = ReplaySource(Recording(np.ones((2, 2)), [0.0, 1.0], LAY, "pressure", "N/cm2"))
    monitor = Monitor(source, tracker=ExposureTracker(LAY))
    try:
        placed = []
        for k, frame in enumerate(_frames(name)):
            if monitor.process(frame, wall=1000.0 + k) is not None:
                placed.append(monitor.clock.last_t)
    finally:
        monitor.close()
    if any(_off_scale(t) for t in placed):
        return f"times downstream {placed}"
    if name != "back by years inside" and source.errors == 0:
        return "not counted"
    return None


class _ListSource:
    """Frames of a case, as a live source hands them."""

    @staticmethod
    def make(frames: list[Frame]) -> object:
        from texsense.monitor.sources import Source

        class ListSource(Source):
            name = "list source"
            quantity, unit = "pressure", "N/cm2"

            def __init__(self) -> None:
                super().__init__()
                self.layout = LAY

            async def frames(self) -> AsyncIterator[Frame]:
                for frame in frames:
                    yield frame

        return ListSource()


def _record(folder: Path, name: str) -> str | None:
    from texsense.io import load
    from texsense.monitor.record import record

    path = folder / "live.h5"
    source = _ListSource.make(_frames(name))
    stats = asyncio.run(record(source, path))  # type: ignore[arg-type]
    try:
        rec = load(path)
    except FormatError as e:
        return f"recorded, not read back: {e}"
    if any(_off_scale(float(t)) for t in rec.times):
        return f"times recorded {rec.times.tolist()}"
    if name != "back by years inside" and stats.dropped == 0:
        return "not counted"
    return None


def _wizard(_folder: Path, name: str) -> str | None:
    from texsense.commands.wizard import _Feed

    source = _ListSource.make(_frames(name))

    async def read() -> list[Frame]:
        feed = _Feed(source)  # type: ignore[arg-type]
        await feed.task
        return list(feed.recent)

    kept = asyncio.run(read())
    if any(_off_scale(float(t)) for frame in kept for t in frame.element_times):
        return f"frames kept at {[frame.t for frame in kept]}"
    if name != "back by years inside" and source.errors == 0:  # type: ignore[attr-defined]
        return "not counted"
    return None


LIVE_ENTRIES: dict[str, Callable[[Path, str], str | None]] = {
    "monitor (station mats)": lambda _folder, name: _monitor(name),
    "record": _record,
    "calibrate wizard": _wizard,
}
ENTRIES = {**FILE_ENTRIES, **LIVE_ENTRIES}


def case(entry: str, pathology: str, folder: Path) -> str | None:
    """What went wrong with ``pathology`` at ``entry`` (None: right), a traceback included."""
    try:
        return ENTRIES[entry](folder, pathology)
    except Exception as e:
        return f"{type(e).__name__}: {e}"


@pytest.mark.parametrize("command", [["hysteresis", "fit", "TABLE", "-o", "TABLE.json"],
                                     ["drift", "fit", "TABLE"]])  # fmt: skip
def test_the_table_without_a_pathology_is_fitted(command, tmp_path, monkeypatch):
    """The control: the fits' failures above are the times', not the record's."""
    monkeypatch.chdir(tmp_path)
    path = _table(tmp_path, "good")
    code, _out, err = call_main([a.replace("TABLE", str(path)) for a in command])
    assert code == 0, err


@pytest.mark.parametrize("pathology", list(PATHOLOGIES))
@pytest.mark.parametrize("entry", list(ENTRIES))
def test_a_time_no_clock_has_is_refused_at_every_entry(entry, pathology, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert case(entry, pathology, tmp_path) is None


def test_a_refused_live_frame_is_said_once_naming_the_source(caplog):
    from texsense.monitor import ExposureTracker, Monitor, ReplaySource

    source = ReplaySource(Recording(np.ones((2, 2)), [0.0, 1.0], LAY, "pressure", "N/cm2"))
    monitor = Monitor(source, tracker=ExposureTracker(LAY))
    for k, frame in enumerate(_frames("NaN inside") + _frames("NaN inside")):
        monitor.process(frame, wall=1000.0 + k)
    monitor.close()
    said = [r.getMessage() for r in caplog.records if "not a number" in r.getMessage()]
    assert len(said) == 1 and source.name in said[0] and "refused frame 3" in said[0]
    assert monitor.clock.unclocked == 2 and source.errors >= 2


def test_one_bad_element_time_refuses_the_frame():
    from texsense.monitor.clock import FrameClock

    clock = FrameClock()
    good = Frame(0, np.array([1.0, 1.1]), np.ones(2))
    bad = Frame(1, np.array([2.0, np.nan]), np.ones(2))
    assert clock.place_frame(good, wall=1.0)[0] == "ok"
    assert clock.place_frame(bad, wall=2.0)[0] == "unclocked"
    assert clock.fault == "the time nan is not a number" and clock.last_t == 1.0
