"""Fault battery: the column tools and posture given the wrong file (issue 25 item 4). Each
wrong input gives one line naming the file and what was expected, exit 1, no traceback."""

from __future__ import annotations

import numpy as np
import pytest

from faults.conftest import assert_clear_error
from faults.test_files import cli_batch
from texsense import Layout, Recording


def _rec(n_elements: int, labels: dict | None = None) -> Recording:
    return Recording(
        np.ones((4, n_elements), dtype=np.float32),
        np.arange(4) * 0.1,
        Layout.grid(1, n_elements),
        "capacitance",
        "pF",
        labels=labels,
    )


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    d = tmp_path_factory.mktemp("columns")
    _rec(96).save(d / "mat.h5")
    _rec(1).save(d / "bare.h5")
    (d / "model.json").write_text('{"format": "texsense-model"}', encoding="utf-8")
    (d / "empty").mkdir()
    (d / "empty" / "notes.txt").write_text("no recording here\n", encoding="utf-8")
    (d / "mixed").mkdir()
    _rec(4, {"posture": [1, 1, 2, 2]}).save(d / "mixed" / "a.h5")
    _rec(6, {"posture": [1, 1, 2, 2]}).save(d / "mixed" / "b.h5")
    cases = {
        "a mat's recording (many elements) to hysteresis fit": (
            ["hysteresis", "fit", "mat.h5", "-o", "m.json"],
            ("mat.h5", "96 elements"),
        ),
        "a model file to drift fit": (["drift", "fit", "model.json"], ("model.json", "column")),
        "a folder to drift fit": (["drift", "fit", "empty"], ("empty", "folder")),
        "a recording without the needed column to drift fit": (
            ["drift", "fit", "bare.h5"],
            ("bare.h5", "compression_mm"),
        ),
        "a folder without recordings to posture evaluate": (
            ["posture", "evaluate", "empty"],
            ("empty", "no recording"),
        ),
        "a folder of recordings of two layouts to posture train": (
            ["posture", "train", "mixed", "-o", "p.joblib"],
            ("b.h5", "layout"),
        ),
    }
    outs = cli_batch([argv for argv, _ in cases.values()], d)
    return {case: (out, names) for (case, (_, names)), out in zip(cases.items(), outs, strict=True)}


CASES = [
    "a mat's recording (many elements) to hysteresis fit",
    "a model file to drift fit",
    "a folder to drift fit",
    "a recording without the needed column to drift fit",
    "a folder without recordings to posture evaluate",
    "a folder of recordings of two layouts to posture train",
]


@pytest.mark.parametrize("case", CASES)
def test_wrong_input_gives_one_clear_line(results, case, fault_row):
    (rc, _, err), names = results[case]
    line = assert_clear_error(rc, err, *names)
    fault_row("column tools and folders", case, "clear error", line)
