"""Shared fixtures: the real data in ../shared/data, read in place (never copied)."""

from __future__ import annotations

import concurrent.futures
import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from texsense import Recording

ROOT = Path(__file__).resolve().parents[1]

#: the script that made the model fixtures runs on the code of its time only (its docstring)
collect_ignore = ["fixtures/models/make_fixtures.py"]
SHARED_DATA = Path(os.environ.get("TEXSENSE_SHARED_DATA", ROOT.parent / "shared" / "data"))

#: The tour of the docs (tests/test_tour.py), started in the background when collected.
TOUR = pytest.StashKey[concurrent.futures.Future]()
_TOUR_FOLDER = pytest.StashKey[tempfile.TemporaryDirectory]()
_TOUR_CANCEL = pytest.StashKey[threading.Event]()


#: The C builds of tests/test_mcu.py (host, arm), started in the background when collected.
MCU_BUILDS: dict[str, concurrent.futures.Future] = {}

#: Set in the workers of ``pytest -n N`` (pytest-xdist, as scripts/test.sh runs the suite):
#: every worker collects every test, so nothing is started in the background at collection;
#: each page of the tour runs in its test, the C builds in the first test that needs them.
IN_WORKER = "PYTEST_XDIST_WORKER" in os.environ


def _start_mcu_builds(session: pytest.Session) -> None:
    """Build the C ABI and its test program for the host and the Cortex-M4 (tests/mcu/
    build.py: a minute the first time, cached in target/mcu/) while other tests run."""
    if session.config.option.collectonly or not any(
        item.nodeid.startswith("tests/test_mcu.py") for item in session.items
    ):
        return
    sys.path.insert(0, str(ROOT / "tests" / "mcu"))
    import build

    pool = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="mcu")
    for kind in ("host", "arm"):
        MCU_BUILDS[kind] = pool.submit(build.build, kind)
    pool.shutdown(wait=False)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The tests marked ``slow`` first, each kind in its collected order. ``pytest -n 2`` hands
    tests out in this order (after the multi-test ``xdist_group`` groups): the long ones start
    while there is short work to fill the other worker, instead of one worker running the
    tour's longest pages at the end while the other has nothing left to do. The tour's pages
    lead (the README's alone is 1.5-4 min)."""
    items.sort(
        key=lambda item: (
            item.get_closest_marker("slow") is None,
            getattr(item, "originalname", None) != "test_page_runs_as_written",
        )
    )


def pytest_collection_finish(session: pytest.Session) -> None:
    """Start the selected pages of the tour (every console block of the docs, about 2 min
    of child processes) now, in the background: the other tests run meanwhile. The
    environment is this moment's (tests that change os.environ do not reach the tour).
    Start the C builds of the microcontroller tests too. Not in a worker of ``pytest -n``
    (:data:`IN_WORKER`): there the workers run tests side by side already."""
    from tour import start_pages

    if IN_WORKER:
        return
    _start_mcu_builds(session)
    pages = [
        item.callspec.params["page"]
        for item in session.items
        if getattr(item, "originalname", None) == "test_page_runs_as_written"
    ]
    if not pages or session.config.option.collectonly or not SHARED_DATA.is_dir():
        return
    folder = tempfile.TemporaryDirectory(prefix="texsense-tour-")
    session.config.stash[_TOUR_FOLDER] = folder
    alone = len(pages) == len(session.items)
    cancel = session.config.stash[_TOUR_CANCEL] = threading.Event()
    session.config.stash[TOUR] = start_pages(
        pages, Path(folder.name), SHARED_DATA.parent, jobs=2 if alone else 1,
        base_env=dict(os.environ, TEXSENSE_NO_PROGRESS="1"), cancel=cancel,
    )  # fmt: skip


def _interrupt(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def pytest_configure(config: pytest.Config) -> None:
    """SIGTERM ends a run as Ctrl-C does: the session finishes, so the tour's servers stop
    and its folder goes (a terminated run left them running)."""
    signal.signal(signal.SIGTERM, _interrupt)


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Stop the tour if it is still running (an interrupted or failed-fast session: its
    current command ends, its servers stop) and remove its folder."""
    tour = session.config.stash.get(TOUR, None)
    if tour is not None:
        session.config.stash[_TOUR_CANCEL].set()
        with contextlib.suppress(Exception):
            tour.result(timeout=300)
    folder = session.config.stash.get(_TOUR_FOLDER, None)
    if folder is not None:
        folder.cleanup()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.fail(
            f"real data not found at {SHARED_DATA}; clone beside shared/ or set "
            "TEXSENSE_SHARED_DATA"
        )
    return SHARED_DATA


@pytest.fixture(autouse=True)
def _no_progress(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TEXSENSE_NO_PROGRESS", "1")


@pytest.fixture(autouse=True)
def _signals_as_found() -> Iterator[None]:
    """No test leaves Ctrl-C or SIGTERM blocked or ignored in the test process: every child
    a later test starts would inherit it (a wizard that a test stops with Ctrl-C did not
    stop). The test that does fails, and the signals are restored for the next."""
    stops = {signal.SIGINT, signal.SIGTERM}
    before = {s: signal.getsignal(s) for s in stops}
    yield
    blocked = stops & signal.pthread_sigmask(signal.SIG_BLOCK, [])
    if blocked:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, blocked)
    changed = {s for s in stops if signal.getsignal(s) is not before[s]}
    for s in changed:
        signal.signal(s, before[s])
    assert not blocked and not changed, (
        f"the test left {sorted(map(signal.Signals, blocked | changed))} blocked or changed"
    )


def check_recording(rec: Recording, tmp_path: Path) -> None:
    """Conformance battery every reader's output must pass (cf. MNE's _test_raw_reader)."""
    from texsense import load
    from texsense.apps import stats
    from texsense.io import write_hdf5

    assert rec.frames.dtype == np.float32
    assert rec.frames.shape == (rec.n_frames, rec.layout.n_elements)
    assert rec.times.shape == (rec.n_frames,)
    assert rec.valid.shape == rec.frames.shape
    assert np.all(np.isfinite(rec.times))
    assert np.all(np.diff(rec.times) >= 0), "times must not run backwards"
    for name, values in rec.labels.items():
        assert values.shape == (rec.n_frames,), name
    # HDF5 round trip is exact, whatever the reader produced.
    back = load(write_hdf5(rec, tmp_path / "roundtrip.h5"))
    assert back.equals(rec)
    # Statistics run on it and give one value per frame.
    assert stats.peak_pressure(rec).shape == (rec.n_frames,)
    assert stats.centre_of_force(rec).shape == (rec.n_frames, 2)
    assert stats.peak_pressure_index(rec).shape == (rec.n_frames,)


_TARGETS: list[tuple[str, str]] = []


@pytest.fixture
def target_report():
    """Record a measured target number; all of them are printed at the end of the run."""

    def report(target: str, text: str) -> None:
        _TARGETS.append((target, text))

    return report


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if _TARGETS:
        terminalreporter.section("virtual sensor targets (measured)")
        for target, text in sorted(_TARGETS):
            terminalreporter.write_line(f"{target}: {text}")


def free_port() -> int:
    """A TCP port nobody listens on right now."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ChildServer:
    """``texsense COMMAND ARGS`` as a real child process on a free port (its own SQLite file
    ``db_path`` = ``tmp_path/COMMAND.sqlite`` unless ``--db`` is given, then ``None``), its
    output in ``tmp_path/COMMAND.log``."""

    def __init__(self, tmp_path: Path, command: str, *args: str) -> None:
        self.name = command
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}/"
        self.log_path = tmp_path / f"{command}.log"
        cmd = [sys.executable, "-m", "texsense.cli", command, *args]
        self.db_path = None if "--db" in args else tmp_path / f"{command}.sqlite"
        if self.db_path is not None:
            cmd += ["--db", str(self.db_path)]
        cmd += ["--port", str(self.port)]
        with self.log_path.open("wb") as log:
            self.proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=tmp_path)

    def get(self, path: str, token: str | None = None):
        """GET ``path`` (JSON), with a bearer token if given."""
        import json
        import urllib.request

        req = urllib.request.Request(self.url + path)
        if token:
            req.add_header("Authorization", f"Bearer {token}")
        with urllib.request.urlopen(req, timeout=3) as r:
            return json.load(r)

    def until(self, what, cond, timeout: float = 30.0):
        """Poll ``what()`` until ``cond`` holds; fail with the server's log otherwise."""
        deadline = time.monotonic() + timeout
        while True:
            if self.proc.poll() is not None:
                pytest.fail(f"the {self.name} exited ({self.proc.returncode}):\n{self.log()}")
            try:
                value = what()
                if cond(value):
                    return value
            except (OSError, KeyError):
                value = None
            if time.monotonic() > deadline:
                pytest.fail(f"condition not reached (last: {value}):\n{self.log()[-3000:]}")
            time.sleep(0.05)

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def stop(self) -> None:
        self.proc.kill()
        self.proc.wait(timeout=20)


class MonitorProcess(ChildServer):
    """``texsense monitor ARGS``; ``status()`` reads /api/status."""

    def __init__(self, tmp_path: Path, *args: str) -> None:
        super().__init__(tmp_path, "monitor", *args)

    def status(self) -> dict:
        return self.get("api/status")

    def wait_for_frames(self, frames: int = 1, timeout: float = 60.0) -> None:
        """Until the monitor has processed ``frames`` frames (fails with its log otherwise)."""
        self.until(lambda: self.status()["frames"], lambda n: n >= frames, timeout)


@pytest.fixture
def monitor_process(tmp_path: Path):
    """Start ``texsense monitor`` with the given arguments; killed at the end of the test."""
    started: list[MonitorProcess] = []

    def start(*args: str) -> MonitorProcess:
        started.append(MonitorProcess(tmp_path, *args))
        return started[-1]

    yield start
    for m in started:
        m.stop()


@pytest.fixture
def device(tmp_path: Path):
    """``texsense simulate device`` as a child process on a pseudo-terminal (its link in
    ``tmp_path``); yields a starter ``start(*args, link=...) -> (link path, process)`` whose
    stdin takes load lines (``uniform:1.0``). Stopped with Ctrl-C at the end of the test."""
    procs: list[subprocess.Popen] = []

    def start(*args: str, link: str = "ttyTEX0"):
        path = tmp_path / link
        cmd = [sys.executable, "-m", "texsense.cli", "simulate", "device", "--link", link, *args]
        proc = subprocess.Popen(cmd, cwd=tmp_path, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)  # fmt: skip
        procs.append(proc)
        deadline = time.monotonic() + 30
        while not path.is_symlink():
            assert proc.poll() is None, proc.stdout.read() if proc.stdout else ""
            assert time.monotonic() < deadline, "the device did not come up"
            time.sleep(0.05)
        return path, proc

    yield start
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
        p.communicate(timeout=10)


@pytest.fixture(scope="session")
def seat_mat():
    """A ward's virtual seat (its mat config, 8x real time) and 60 of its MQTT payloads with
    their arrival times, as `texsense station` would receive them."""
    import asyncio

    from texsense.calibration.workflows import seat_calibration
    from texsense.monitor.virtual import VirtualSeatSource
    from texsense.station.virtual import VirtualMats, frame_payload

    speed = 8.0
    config = VirtualMats(1, None, speed=speed).configs(seat_calibration(), None, 5.0, None, 120.0)
    src = VirtualSeatSource(speed=0, seed=3)

    async def take() -> list[tuple[bytes, float]]:
        out = []
        async for f in src.frames():
            out.append((frame_payload(f), 1000.0 + float(f.element_times[0]) / speed))
            if len(out) == 60:
                break
        return out

    return config[0], asyncio.run(take())
