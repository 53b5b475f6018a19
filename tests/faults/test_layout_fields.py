"""Family "a layout field of the wrong kind or size" (harden12): every layout, from a file (a
wide CSV's layout line, an HDF5 file's ``/layout``, a device's announcement) or the Python API,
is built by the one constructor ``Layout.__init__``, which checks each field's type and size:
the pitch is two numbers, the regions a mapping, centres within ``MAX_CM`` (1 km), sizes,
areas and pitch between ``MIN_CM`` (1 nm) and ``MAX_CM``. Before, a pitch of ``[]`` or ``[1]``
was an ``IndexError``, regions given as a list an ``AttributeError`` (tracebacks from every
command that reads the file), and centres at 1e308 cm a ``LinAlgError`` out of ``report``.

The table: every field of a layout description x odd JSON values, through ``Layout.from_dict``
and ``texsense info`` of a wide CSV holding it; the extreme sizes through ``report`` and
``plot``.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from faults._families import batch, small_recording
from texsense.data.layout import MAX_CM, MIN_CM, Layout
from texsense.exceptions import ParameterError
from texsense.io import save

#: values of the wrong kind or shape for any field
ODD = ["x", "", [], [1], [1, 2, 3], {}, {"a": 1}, None, True, 0, -1, 1.5, 1e308, [["a", "b"]],
       [[1, 2, 3]], [[None, None]], [[True, False]], [-1.0, -1.0], [0, 0], ["1", "2"],
       [[1, 2]] * 13, [{"a": 1}], [[[1]]], {"r": "x"}, {"r": [99]}, {"r": [-1]}, {"r": [[0]]},
       {"r": None}, {"top": 5}, [1e308, 1e308], [5e-324, 5e-324]]  # fmt: skip


def _extremes(lay: dict) -> dict[str, dict]:
    """Numbers just inside and beyond the bounds for the centres, sizes, areas and pitch."""
    n = len(lay["xy_cm"])
    out: dict[str, dict] = {}
    for v in (MAX_CM, MAX_CM * 1.01, 1e308, -1e308):
        out[f"a centre at {v:g}"] = {"xy_cm": [[v, v], *lay["xy_cm"][1:]]}
    for v in (MIN_CM, MAX_CM, MIN_CM / 10, MAX_CM * 2, 5e-324, 1e308):
        out[f"sizes {v:g}"] = {"size_cm": [[v, v]] * n, "area_cm2": [v * v] * n}
        out[f"pitch {v:g}"] = {"pitch_cm": [v, v]}
    return out


def _ok(rc: int, err: str) -> bool:
    lines = [s for s in err.strip().splitlines() if s.strip()]
    return "Traceback" not in err and ((rc == 0 and not lines) or (rc == 1 and len(lines) == 1))


@pytest.mark.slow
def test_every_layout_field_checked(tmp_path, fault_row):
    src = tmp_path / "base.csv"
    save(small_recording(), src)
    lines = src.read_text("utf-8").splitlines(keepends=True)
    k = next(i for i, s in enumerate(lines) if s.startswith("# layout: "))
    lay = json.loads(lines[k][len("# layout: ") :])
    variants = {f"{f}={json.dumps(v)[:30]}": {f: v} for f in lay for v in ODD}
    variants.update({f"{f} left out": {f: ...} for f in lay})
    extremes = _extremes(lay)
    variants.update(extremes)
    bad, argvs, names = [], [], []
    for j, (name, change) in enumerate(variants.items()):
        d = {key: value for key, value in {**lay, **change}.items() if value is not ...}
        try:  # the API: a layout or a ParameterError
            Layout.from_dict(d)
        except ParameterError:
            pass
        except Exception as e:
            bad.append(f"from_dict {name}: {type(e).__name__}: {e}")
        path = tmp_path / f"v{j}.csv"
        path.write_text("".join([*lines[:k], f"# layout: {json.dumps(d)}\n", *lines[k + 1 :]]))
        argvs.append(["info", str(path)])
        names.append(f"info {name}")
        if name in extremes:
            for cmd in (["report", str(path), "-o", f"{path}.html"], ["plot", str(path), "-o",
                                                                      f"{path}.png"]):  # fmt: skip
                argvs.append(cmd)
                names.append(f"{cmd[0]} {name}")
    results, _, _ = batch(argvs, tmp_path, timeout=900)
    for name, (rc, _out, err) in zip(names, results, strict=True):
        if not _ok(rc, err):
            bad.append(f"{name}: exit {rc}: {err.strip().splitlines()[-1:]}")
    cases = len(variants) + len(argvs)
    print(f"{cases - len(bad)} of {cases} cases held")
    assert not bad, "\n".join(bad)
    fault_row("layout fields", f"{len(lay)} fields of a layout x {len(ODD)} odd values, "
              f"{len(extremes)} extreme sizes (from_dict, info, report, plot)",
              "clear error or read", cases=cases)  # fmt: skip


def test_hdf5_layout_error_names_the_file_once(tmp_path):
    """A damaged /layout of an HDF5 recording: one line, the file named once (it was twice:
    ``x.h5: damaged or incomplete recording: x.h5: /layout is damaged: ...``)."""
    path = tmp_path / "pitch.h5"
    save(small_recording(), path)
    with h5py.File(path, "a") as f:
        f["layout"].attrs["pitch_cm"] = np.zeros(0)
    (rc, _out, err), *_ = batch([["info", str(path)]], tmp_path)[0]
    assert rc == 1 and err.count(str(path)) == 1 and "pitch_cm" in err, err
