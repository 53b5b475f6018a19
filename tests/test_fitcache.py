"""Fits made once (texsense.data.fitcache): a kept fit is the fit the code makes, other
inputs make another, a damaged file is made again, and the cache can be turned off."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from texsense.compensation.stages import Hysteresis
from texsense.data import fitcache
from texsense.sim import protocols


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("TEXSENSE_NO_FIT_CACHE", raising=False)
    monkeypatch.setattr(fitcache, "_memory", type(fitcache._memory)())
    return tmp_path / "texsense"


@pytest.fixture(scope="module")
def record():
    rec = protocols.run_protocol("calibration", "textile-3mm", seed=4, sample_hz=None)
    return rec.labels["compression_mm"], rec.labels["pressure_ncm2"]


def _counting(monkeypatch) -> list[int]:
    made: list[int] = []
    real = fitcache.remembered

    def spy(kind, parts, make, build):
        return real(kind, parts, lambda: made.append(1) or make(), build)

    monkeypatch.setattr("texsense.compensation.hysteresis._model.remembered", spy)
    return made


def test_a_kept_fit_is_the_fit(cache, record, monkeypatch):
    made = _counting(monkeypatch)
    e, p = record
    first = Hysteresis().fit(e, p)
    fitcache._memory.clear()  # the next one from the file
    from_file = Hysteresis().fit(e, p)
    from_memory = Hysteresis().fit(e, p)
    assert made == [1]
    assert len(list(cache.glob("fit-hysteresis-*.json"))) == 1
    probe = np.concatenate([e, e[::-1] * 0.7])
    for again in (from_file, from_memory):
        assert again.model_ is not first.model_
        np.testing.assert_array_equal(again.model_.everett_, first.model_.everett_)
        np.testing.assert_array_equal(again.model_.predict(probe), first.model_.predict(probe))
        assert again.model_.to_content() == first.model_.to_content()


def test_other_inputs_make_another_fit(cache, record, monkeypatch):
    made = _counting(monkeypatch)
    e, p = record
    a = Hysteresis(method="thesis").fit(e, p)
    b = Hysteresis(method="thesis").fit(e, p * 1.01)
    c = Hysteresis(method="thesis", grid=50).fit(e, p)
    assert made == [1, 1, 1]
    assert not np.array_equal(a.model_.everett_, b.model_.everett_)
    assert c.model_.everett_.shape == (50, 50)


def test_a_damaged_file_is_made_again(cache, record, monkeypatch, caplog):
    e, p = record
    first = Hysteresis(method="thesis").fit(e, p)
    (kept,) = cache.glob("fit-hysteresis-*.json")
    for damage in ("{not json", '{"method": "lsq"}'):
        kept.write_text(damage)
        fitcache._memory.clear()
        made = _counting(monkeypatch)
        with caplog.at_level(logging.WARNING, "texsense.fitcache"):
            again = Hysteresis(method="thesis").fit(e, p)
        assert made == [1]
        assert "making again" in caplog.text
        np.testing.assert_array_equal(again.model_.everett_, first.model_.everett_)


def test_the_cache_can_be_turned_off(cache, record, monkeypatch):
    monkeypatch.setenv("TEXSENSE_NO_FIT_CACHE", "1")
    made = _counting(monkeypatch)
    e, p = record
    Hysteresis(method="thesis").fit(e, p)
    Hysteresis(method="thesis").fit(e, p)
    assert made == [1, 1]
    assert not cache.exists()


_MAKER = """
import json, sys, time
from pathlib import Path
from texsense.data import fitcache

def make():
    with open(sys.argv[1], "a") as f:
        f.write("made\\n")
    time.sleep(0.5)  # the work: the others arrive while it is made
    return {"value": 42}

print(json.dumps(fitcache.remembered("test", ["together"], make, lambda c: c)))
"""


def test_processes_started_together_make_it_once(cache, tmp_path):
    """Three processes that need the same fit at once: one makes it, the others wait for it
    and read it (a fresh machine starting several monitors or test workers)."""
    import os
    import subprocess
    import sys

    log = tmp_path / "made.log"
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path))
    procs = [
        subprocess.Popen([sys.executable, "-c", _MAKER, str(log)], env=env, stdout=subprocess.PIPE)
        for _ in range(3)
    ]
    outs = [p.communicate(timeout=120)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0]
    assert [o.decode().strip() for o in outs] == ['{"value": 42}'] * 3
    assert log.read_text().splitlines() == ["made"]


def test_a_lock_that_cannot_be_made_does_not_stop_the_work(tmp_path):
    from texsense.data.files import made_once

    with made_once(tmp_path / "no-such-folder" / "x.lock") as held:
        assert held is False
    with made_once(tmp_path / "x.lock") as held:
        assert held is True
