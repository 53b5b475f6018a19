"""Family "a setting a recording declares" (harden9, further attack): the alert settings a
live recording carries in its ``meta`` (``threshold_mmhg``, ``reposition_min``,
``offload_min``, ``turn_every_min``, used by ``report`` and the playback) are checked like the
options that set them (``--threshold``, ``--reposition-min``, ``--offload-min``,
``--turn-every``: the same ranges, a test keeps them equal): a recording declaring ``true``,
``NaN``, ``-5``, ``0`` or ``1e308`` was taken (clamped without a word, a turning schedule of
NaN minutes, or a run of warnings on stderr), now one line naming the file and the setting.
"""

from __future__ import annotations

import json

import h5py
import pytest

from faults._families import batch, one_line, small_recording
from texsense.apps.review import SETTING_RANGES
from texsense.commands._options import RANGES
from texsense.io import save

OPTIONS = {"threshold_mmhg": "--threshold", "reposition_min": "--reposition-min",
           "offload_min": "--offload-min", "turn_every_min": "--turn-every"}  # fmt: skip
ODD = ["NaN", "Infinity", "-Infinity", "-5", "1e308", "true", "false", '"20"', "[1]", "null"]


def test_the_ranges_are_the_options():
    for key, option in OPTIONS.items():
        r = RANGES[option]
        assert SETTING_RANGES[key] == (r.lo, r.hi, r.lo_open), key
        assert not r.hi_open


def _declaring(folder, key: str, value: str, k: int):
    path = save(small_recording(), folder / f"{key}-{k}.h5")
    with h5py.File(path, "a") as f:
        meta = json.loads(f.attrs["meta"])
        meta["alerts"] = {"threshold_mmhg": 32, "reposition_min": 20, "offload_min": 1,
                          "turn_every_min": 120}  # fmt: skip
        text = json.dumps(meta).replace(f'"{key}": {json.dumps(meta["alerts"][key])}',
                                        f'"{key}": {value}')  # fmt: skip
        f.attrs["meta"] = text
    return path


@pytest.mark.parametrize("mode", ["seat", "bed"])
def test_a_setting_a_recording_declares_out_of_range_is_one_line(tmp_path, mode, fault_row):
    argvs, cases = [], []
    for key, option in OPTIONS.items():
        r = RANGES[option]
        values = [*ODD, f"{r.lo:g}" if r.lo_open else f"{r.lo - 1:g}", f"{r.hi * 10:g}"]
        for value in values:
            path = _declaring(tmp_path, key, value, len(argvs))
            argvs.append(["report", str(path), "--mode", mode, "-o",
                          str(tmp_path / f"{len(argvs)}.html")])  # fmt: skip
            cases.append((key, value, path.name))
    good = _declaring(tmp_path, "turn_every_min", "90", 999)
    argvs.append(["report", str(good), "--mode", mode, "-o", str(tmp_path / "good.html")])
    results, _, _ = batch(argvs, tmp_path, timeout=600)
    wrong = []
    for (key, value, name), (rc, _out, err) in zip(cases, results[:-1], strict=True):
        try:
            one_line(rc, err, name, key)
        except AssertionError as e:
            wrong.append(f"{key} = {value}: {str(e)[:200]}")
    assert results[-1][0] == 0, results[-1][2][-500:]
    assert wrong == [], f"{len(wrong)} of {len(cases)}:\n" + "\n".join(wrong)
    fault_row("settings", f"{len(cases)} alert settings a recording declares out of their "
              f"options' ranges (report, {mode})", "clear error", "the file and the setting "
              "named", cases=len(cases))  # fmt: skip
