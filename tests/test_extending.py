"""The worked examples of docs/development.md ("Adding a format, a source or a stage"): each
is one module (examples/extending/) that registers itself, and passes the same checks as the
built-in ones: the reader conformance battery, the source contract, the stage contract. The
registrations are removed again after each test (the registries are global)."""

from __future__ import annotations

import importlib.util
import re
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent / "readers"))
sys.path.insert(0, str(Path(__file__).parent / "monitor"))

from _conformance import check_reader
from test_source_contract import check_source

import texsense
from texsense import Layout, Recording
from texsense.compensation.stage import STAGES
from texsense.compensation.stages import stage_from_dict
from texsense.compensation.testing import check_stage
from texsense.io import READER_CLASSES, formats_table, sniff_format
from texsense.monitor.sources import SOURCES, SourceOptions, open_source, source_help

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "extending"


@pytest.fixture
def example(request) -> Iterator[ModuleType]:
    """The example module named by the test's parameter, imported; what it registered is
    removed afterwards."""
    before = {id(r): set(r) for r in (READER_CLASSES, SOURCES, STAGES)}
    spec = importlib.util.spec_from_file_location(f"example_{request.param}",
                                                  EXAMPLES / f"{request.param}.py")  # fmt: skip
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # (pickle finds its classes)
    spec.loader.exec_module(module)
    yield module
    del sys.modules[spec.name]
    for registry in (READER_CLASSES, SOURCES, STAGES):
        for key in set(registry) - before[id(registry)]:
            del registry[key]


@pytest.mark.parametrize("example", ["dat_format"], indirect=True)
def test_a_new_format_in_one_module(example, tmp_path, caplog):
    assert "example-dat" in READER_CLASSES
    path = tmp_path / "walk.dat"
    rng = np.random.default_rng(0)
    lines = [f"{example.MAGIC} 2 3 kPa"]
    lines += [" ".join([f"{0.1 * k:g}", *(f"{v:.3f}" for v in rng.random(6) * 20)])
              for k in range(40)]  # fmt: skip
    path.write_text("\n".join(lines) + "\n")
    assert sniff_format(path) == "example-dat"
    rec = texsense.load(path)
    assert rec.layout.shape == (2, 3) and rec.unit == "N/cm2" and rec.n_frames == 40
    assert np.isclose(rec.frames[0, 0], float(lines[1].split()[1]) / 10, rtol=1e-6)  # kPa
    assert "| example .dat export | `example-dat` | yes | no |" in formats_table()
    read = texsense.io.read_example_dat
    assert read(path).n_frames == 40
    check_reader(path, tmp_path / "battery", caplog)


@pytest.mark.parametrize("example", ["pattern_source"], indirect=True)
def test_a_new_source_in_one_module(example):
    assert "pattern" in source_help()
    source = open_source("pattern", SourceOptions(grid=Layout.grid(3, 4), speed=0))
    frames = check_source(source, 5)
    assert [int(np.argmax(f.values[:4])) for f in frames] == [0, 1, 2, 3, 0]


@pytest.mark.parametrize("example", ["clip_stage"], indirect=True)
def test_a_new_stage_in_one_module(example):
    assert STAGES["example-clip"] is example.Clip
    rng = np.random.default_rng(1)
    p = rng.random((30, 12)) * 3
    valid = rng.random((30, 12)) > 0.1
    rec = Recording(p, np.arange(30) * 0.5, Layout.grid(3, 4), "pressure", "N/cm2", valid=valid)
    check_stage(example.Clip(), lambda s: s.fit(np.linspace(0, 2, 50)), rec)
    stage = example.Clip(margin=1.0).fit([0.0, 2.0])
    again = stage_from_dict(stage.to_dict())  # found by name, from its file content
    _, ok = again.step(np.array([1.0, 2.5, 1.9, 3.0, 0.0, 2.1]), None, 0.0)
    assert ok.tolist() == [True, False, True, False, True, False]


def test_the_docs_show_the_example_files():
    """docs/development.md shows each example as it is (the blocks are the files)."""
    text = (ROOT / "docs" / "development.md").read_text(encoding="utf-8")
    for name in ("dat_format", "pattern_source", "clip_stage"):
        block = re.search(rf"```python title=examples/extending/{name}.py\n(.*?)```", text, re.S)
        assert block, f"docs/development.md does not show examples/extending/{name}.py"
        assert block.group(1) == (EXAMPLES / f"{name}.py").read_text(encoding="utf-8")
