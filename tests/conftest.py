"""Shared fixtures: the real data in ../shared/data, read in place (never copied)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from texsense import Recording

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("TEXSENSE_SHARED_DATA", ROOT.parent / "shared" / "data"))


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


def check_recording(rec: Recording, tmp_path: Path) -> None:
    """Conformance battery every reader's output must pass (cf. MNE's _test_raw_reader)."""
    from texsense import load, stats
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
