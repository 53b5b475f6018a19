"""Family "an index that is no whole number": a layout's integer fields (the grid's shape, the
cell of each element, the neighbour graph, the regions' members) come from files and messages
(a wide CSV's layout line, HDF5 attributes and datasets, a device's ``#layout`` line); each
goes through :func:`texsense.data.layout.whole_numbers`, which refuses ``1.5`` (it was
truncated to 1), ``inf``, ``NaN``, text, ``null`` and numbers beyond int64 (``inf`` and
``2**64`` were an ``OverflowError`` traceback) naming the field."""

from __future__ import annotations

import json
import re

import h5py
import numpy as np
import pytest

from faults._families import batch, one_line, small_recording
from texsense.data.layout import Layout
from texsense.data.protocol import ProtocolError, parse_announcement
from texsense.exceptions import ParameterError
from texsense.io import save

#: values an index field may hold in JSON that are not whole numbers within int64
BAD = {"1.5": 1.5, "inf": float("inf"), "-inf": float("-inf"), "nan": float("nan"),
       "1e300": 1e300, "2**64": 2**64, "text": "2", "null": None}  # fmt: skip
#: (field of Layout.to_dict, where in it the bad value goes)
FIELDS = {"shape": 0, "cells": 1, "neighbours_indptr": 1, "neighbours_indices": 0,
          "regions": ("r", 0)}  # fmt: skip


def _spoilt(field: str, value) -> dict:
    d = small_recording().layout.to_dict()
    where = FIELDS[field]
    if isinstance(where, tuple):
        d[field][where[0]][where[1]] = value
    else:
        d[field][where] = value
    return d


def test_layout_from_dict_refuses_every_index_that_is_no_whole_number():
    for field in FIELDS:
        for name, value in BAD.items():
            with pytest.raises(ParameterError, match="whole numbers"):
                Layout.from_dict(_spoilt(field, value))
            assert name
    assert Layout.from_dict(_spoilt("cells", 1.0)) == small_recording().layout  # 1.0 is 1


def test_a_wide_csv_layout_line_with_such_an_index_is_one_line(tmp_path, fault_row):
    argvs, names = [], []
    for field in FIELDS:
        for name, value in BAD.items():
            path = tmp_path / f"{field}-{len(argvs)}.csv"
            save(small_recording(), path)
            line = json.dumps(_spoilt(field, value))  # inf, nan as JSON's Infinity, NaN
            text = re.sub(r"(?m)^# layout: .*$", lambda m, t=line: f"# layout: {t}",
                          path.read_text(encoding="utf-8"))  # fmt: skip
            path.write_text(text, encoding="utf-8")
            argvs.append(["info", str(path)])
            names.append((field, name, path.name))
    results, _, _ = batch(argvs, tmp_path)
    for (field, name, file), (rc, _out, err) in zip(names, results, strict=True):
        line = one_line(rc, err, file)
        assert "whole numbers" in line, (field, name, line)
    fault_row("indices", f"{len(BAD)} values that are no whole number x {len(FIELDS)} index "
              "fields of a wide CSV's layout line", "clear error", cases=len(argvs))  # fmt: skip


def test_hdf5_layout_indices_that_are_no_whole_number_are_one_line(tmp_path, fault_row):
    argvs, names = [], []
    for what, value in [("rows", np.inf), ("cols", 2.0**64), ("rows", 1.5), ("cols", np.nan),
                        ("cells", 1.5), ("cells", np.inf)]:  # fmt: skip
        path = tmp_path / f"{what}-{len(argvs)}.h5"
        save(small_recording(), path)
        with h5py.File(path, "a") as f:
            if what == "cells":
                cells = f["layout/cells"][()].astype(np.float64)
                cells[1] = value
                del f["layout/cells"]
                f["layout/cells"] = cells
            else:
                f["layout"].attrs[what] = value
        argvs.append(["info", str(path)])
        names.append((what, value, path.name))
    results, _, _ = batch(argvs, tmp_path)
    for (what, value, file), (rc, _out, err) in zip(names, results, strict=True):
        line = one_line(rc, err, file)
        assert "whole numbers" in line, (what, value, line)
    fault_row("indices", "HDF5 layout: rows, cols and cells of inf, NaN, 1.5, 2**64",
              "clear error", cases=len(argvs))  # fmt: skip


def test_a_device_announcing_a_grid_of_no_whole_numbers_is_a_protocol_error(fault_row):
    tried = 0
    for value in BAD.values():
        for grid in ([value, 4], [3, value]):
            line = "#layout " + json.dumps({"grid": grid, "pitch_cm": [1, 1]})
            with pytest.raises(ProtocolError):
                parse_announcement(line)
            tried += 1
    assert parse_announcement('#layout {"grid": [3, 4.0], "pitch_cm": [1, 1]}')[0].n_elements == 12
    fault_row("indices", "a device's #layout line: a grid of inf, NaN, 1.5, 2**64, text",
              "refused", "ProtocolError: counted and skipped", cases=tried)  # fmt: skip


#: (field, where) of a layout's real numbers, and values no layout holds there
REALS = {"xy_cm": (0, 0), "size_cm": (3, 1), "area_cm2": (5,), "pitch_cm": (1,)}
ODD_REALS = {"10**400": 10**400, "inf": float("inf"), "nan": float("nan"), "text": "x",
             "list": [1.0], "-1": -1.0, "0": 0.0}  # fmt: skip


def test_a_layout_line_with_numbers_no_layout_has_is_one_line(tmp_path, fault_row):
    """The real numbers of a layout line (centres, sizes, areas, pitch): an integer of 400
    digits (an OverflowError traceback), text, a list, a size, area or pitch that is not
    positive and finite (an infinite size was read): one line naming the file."""
    argvs, names = [], []
    for field, where in REALS.items():
        for name, value in ODD_REALS.items():
            if field == "xy_cm" and name in ("-1", "0"):
                continue  # a centre may lie anywhere
            d = small_recording().layout.to_dict()
            target = d[field]
            for k in where[:-1]:
                target = target[k]
            target[where[-1]] = value
            path = tmp_path / f"{field}-{name}.csv"
            save(small_recording(), path)
            line = json.dumps(d)
            text = re.sub(r"(?m)^# layout: .*$", lambda m, t=line: f"# layout: {t}",
                          path.read_text(encoding="utf-8"))  # fmt: skip
            path.write_text(text, encoding="utf-8")
            argvs.append(["info", str(path)])
            names.append(path.name)
    results, _, _ = batch(argvs, tmp_path)
    for file, (rc, _out, err) in zip(names, results, strict=True):
        one_line(rc, err, file, "layout")
    fault_row("indices", f"{len(argvs)} real numbers no layout has (10**400, inf, NaN, text, a "
              "list, sizes of 0 or -1) in a wide CSV's layout line", "clear error",
              cases=len(argvs))  # fmt: skip
