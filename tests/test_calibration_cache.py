"""The virtual mats' calibrations (texsense.calibration.workflows: seat, bed) are fitted once
per version of the code and read from the cache after that (each monitor or station with a
virtual mat used to spend seconds of Preisach identification at start); a cache that cannot
be read is fitted again, one that cannot be written is skipped, each said in the log."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from texsense.calibration import workflows
from texsense.compensation.stages import Linear, StageChain
from texsense.data import fitcache


@pytest.fixture
def fits(tmp_path, monkeypatch):
    """The cache in ``tmp_path``; the fit replaced by a cheap one that counts its calls."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("TEXSENSE_NO_FIT_CACHE", raising=False)
    monkeypatch.setattr(fitcache, "_memory", type(fitcache._memory)())
    calls = []

    def fit(mat, material_seed=11):
        calls.append(mat.layout.n_elements)
        n = mat.layout.n_elements
        return StageChain([Linear("capacitance", "pF").fit(np.arange(n) * 0.5, np.ones(n))])

    monkeypatch.setattr(workflows, "calibrate_virtual_mat", fit)
    return calls


def test_fitted_once_then_read_back_the_same(fits, tmp_path):
    first = workflows.seat_calibration()
    again = workflows.seat_calibration()
    fitcache._memory.clear()  # the next one from the file
    from_file = workflows.seat_calibration()
    assert fits == [first.stages[0].offset_.size]  # the others came from the cache
    for chain in (again, from_file):
        assert chain.id == first.id and chain.to_dict() == first.to_dict()
    assert len(list((tmp_path / "texsense").glob("fit-calibration-*.json"))) == 1
    workflows.bed_calibration()
    assert len(fits) == 2  # another mat: another entry


def test_a_broken_cache_is_fitted_again_and_said(fits, tmp_path, caplog):
    workflows.seat_calibration()
    (cached,) = (tmp_path / "texsense").glob("fit-calibration-*.json")
    cached.write_text("{not json")
    fitcache._memory.clear()
    with caplog.at_level(logging.WARNING, logger="texsense.fitcache"):
        chain = workflows.seat_calibration()
    assert len(fits) == 2 and "making again" in caplog.text and cached.name in caplog.text
    assert workflows.seat_calibration().id == chain.id and len(fits) == 2  # repaired


def test_a_cache_that_cannot_be_written_is_skipped_and_said(fits, tmp_path, caplog):
    (tmp_path / "texsense").write_text("a file where the cache folder goes")
    with caplog.at_level(logging.WARNING, logger="texsense.fitcache"):
        chain = workflows.seat_calibration()
    assert isinstance(chain, StageChain) and "not kept" in caplog.text
