"""Families "a setting that means nothing" and "a value that is not a reading" (issue 32,
item 6): every numeric option of every command with values outside its declared range (and
not numbers at all); every key of a ward file misspelt, of the wrong type, and the mat ids a
mat may not have; a mat calibration applied to mats with the same element count in other
places; impossible readings under ``valid = True`` in every file texsense writes with a mask.
"""

from __future__ import annotations

import argparse
import math

import h5py
import numpy as np
import pytest

from faults._families import batch
from texsense import Layout, Recording
from texsense.cli import build_parser
from texsense.commands import COMMANDS
from texsense.commands._options import numeric_options, range_of
from texsense.exceptions import FormatError, ParameterError
from texsense.io import load, save


def _outside(allowed, kind) -> list[str]:
    """Values a range refuses: not numbers, not finite, just below and above it."""
    values = ["nan", "inf", "-inf", "1e999", "abc", ""]
    step = 1 if kind is int else max(1e-6, abs(allowed.lo or allowed.hi or 1.0) * 1e-3)
    if allowed.lo is not None:
        values.append(repr(kind(allowed.lo) if allowed.lo_open else kind(allowed.lo - step)))
    if allowed.hi is not None:
        values.append(repr(kind(allowed.hi) if allowed.hi_open else kind(allowed.hi + step)))
    if allowed.nonzero:
        values.append("0")
    if kind is int:
        values.append("1.5")
    return values


def _inside(allowed, kind) -> str:
    lo = allowed.lo if allowed.lo is not None else -1.0
    hi = allowed.hi if allowed.hi is not None else lo + 10.0
    mid = (lo + hi) / 2 if math.isfinite(hi - lo) else lo + 1
    value = kind(mid) if kind is float else math.ceil(mid)
    return "1" if allowed.nonzero and value == 0 else repr(value)


OPTIONS = list(numeric_options(build_parser(COMMANDS)))


def test_every_numeric_option_refuses_what_lies_outside_its_range(fault_row):
    tried = refused = 0
    for command, action in OPTIONS:
        name = action.option_strings[-1]
        allowed = range_of(command, name)
        assert allowed is not None, f"texsense {command} {name} has no declared range"
        kind = action.type.kind
        for text in _outside(allowed, kind):
            tried += 1
            with pytest.raises(argparse.ArgumentTypeError):
                action.type(text)
            refused += 1
        assert allowed.holds(action.type(_inside(allowed, kind))), (command, name)
    fault_row("settings", f"{len(OPTIONS)} numeric options of every command x values outside "
              "their range", "refused", f"{refused} of {tried} values refused (argparse, exit 2); "
              "a value inside each range accepted", cases=tried)  # fmt: skip


def test_out_of_range_options_end_to_end(tmp_path, fault_row):
    argvs = [
        ["station", "--refuse-after", "-5"],
        ["monitor", "--reposition-min", "nan"],
        ["station", "--virtual-mats", "1e9"],
        ["calibrate", "linear", "--like", "x.h5", "--gain", "0", "-o", "c.json"],
        ["plot", "x.h5", "-o", "x.png", "--frame", "-1"],
    ]
    results, _, _ = batch(argvs, tmp_path)
    for argv, (rc, _out, err) in zip(argvs, results, strict=True):
        assert rc == 2 and "Traceback" not in err, err
        assert err.strip().splitlines()[-1].startswith(f"texsense {argv[0]}"), err
        assert "argument " in err.strip().splitlines()[-1], err
    fault_row("settings", f"{len(argvs)} of them on the command line", "refused",
              "usage and one error line naming the option, exit 2", cases=len(argvs))  # fmt: skip


def _misspellings(key: str) -> list[str]:
    swapped = key[1] + key[0] + key[2:] if len(key) > 2 else key + "x"
    return sorted({key.upper(), key.capitalize(), key[:-1], key + "s", swapped} - {key})


WARD_KEYS = {"id": '"a"', "layout": '"grid:4x4"', "calibration": '"c.json"', "source": '"mqtt"',
             "bed": "false", "model": '"m.joblib"', "reposition_min": "20",
             "turn_every_min": "120", "orientation": '"bed"'}  # fmt: skip
WRONG_TYPES = {"id": "3", "layout": "[4, 4]", "calibration": "true", "source": "1", "bed": '"yes"',
               "model": "0", "reposition_min": '"20"', "turn_every_min": "true",
               "orientation": "1"}  # fmt: skip
BAD_IDS = ["texsense-station", "TEXSENSE-STATION", "a/b", "../x", "", ".hidden", "a b",
           "x" * 65, "é", "-a", "a#", "a+"]  # fmt: skip


def _ward(path, extra: str, mat_id: str = '"a"') -> None:
    path.write_text(f'[[mat]]\nid = {mat_id}\nlayout = "grid:4x4"\n{extra}\n')


def test_every_ward_key_is_checked(tmp_path, fault_row):
    from texsense.commands.station import MAT_KEYS, read_config

    assert set(WARD_KEYS) == set(MAT_KEYS)  # (orientation, documented, was refused as unknown)

    path = tmp_path / "ward.toml"
    tried = 0
    for key in WARD_KEYS:
        for wrong in _misspellings(key):
            _ward(path, f"{wrong} = {WARD_KEYS[key]}")
            with pytest.raises(FormatError, match=f"unknown key '{wrong}'") as e:
                read_config(path, 20.0)
            assert "ward.toml" in str(e.value)
            tried += 1
        if key not in ("id", "layout"):
            _ward(path, f"{key} = {WRONG_TYPES[key]}")
            with pytest.raises(FormatError, match=f"{key} must be"):
                read_config(path, 20.0)
            tried += 1
    for bad in BAD_IDS:
        _ward(path, "", mat_id=f'"{bad}"')
        with pytest.raises(FormatError, match="mat id"):
            read_config(path, 20.0)
        tried += 1
    for extra in ("reposition_min = -5", "reposition_min = 1e9", "turn_every_min = 0",
                  "reposition_min = nan"):  # fmt: skip
        _ward(path, extra)
        with pytest.raises(FormatError, match="must"):
            read_config(path, 20.0)
        tried += 1
    path.write_text('[[mats]]\nid = "a"\nlayout = "grid:4x4"\n')
    with pytest.raises(FormatError, match="did you mean 'mat'"):
        read_config(path, 20.0)
    fault_row("settings", f"{tried + 1} ward files: every key misspelt and of the wrong type, "
              "ids a mat may not have, intervals out of range", "clear error",
              "the nearest known key named", cases=tried + 1)  # fmt: skip


#: TOML texts that tomllib reads with another exception than its own, or that a grid refuses
ODD_TOML = {
    "arrays nested too deeply": "x = " + "[" * 3000 + "]" * 3000,
    "inline tables nested too deeply": "x = " + "{a = " * 3000 + "1" + "}" * 3000,
    "an integer of 5000 digits": "x = 1" + "0" * 5000,
}
ODD_GRIDS = ["grid:0x4", "grid:4x0", "grid:-4x4", "grid:\uff14x4", "grid:4x4x4", "grid:4.5x4",
             "grid:1e400x4", "grid: x4"]  # fmt: skip


def test_ward_and_credential_files_that_are_no_toml_or_no_grid(tmp_path, fault_row):
    """Every odd TOML text in the ward file and the mats' credentials, and every odd grid in a
    ward file: one FormatError or ParameterError naming the file and the [[mat]] (a
    RecursionError and int's ValueError came out of tomllib as tracebacks; a grid of 0 rows
    did not name the ward file, one of full-width digits was read)."""
    from texsense.commands.station import read_config
    from texsense.station.broker import read_mat_credentials

    tried = 0
    for what, text in ODD_TOML.items():
        for kind in ("ward", "credentials"):
            path = tmp_path / f"{kind}.toml"
            path.write_text(text + "\n", encoding="utf-8")
            with pytest.raises(FormatError, match=rf"{kind}.toml: ") as e:
                if kind == "ward":
                    read_config(path, 20.0)
                else:
                    read_mat_credentials(path)
            assert "\n" not in str(e.value) and len(str(e.value)) < 300, (what, str(e.value))
            tried += 1
    path = tmp_path / "ward.toml"
    for grid in ODD_GRIDS:
        path.write_text(f'[[mat]]\nid = "a"\nlayout = "{grid}"\n', encoding="utf-8")
        with pytest.raises((FormatError, ParameterError), match=r"ward.toml \[\[mat\]\] #1"):
            read_config(path, 20.0)
        tried += 1
    path.write_bytes(b'\xef\xbb\xbf[[mat]]\nid = "a"\nlayout = "grid:4x4"\n')  # Notepad's BOM
    assert read_config(path, 20.0)[0][0].layout.n_elements == 16
    fault_row("settings", f"{tried} ward and credential files: nested too deeply, 5000 digits, "
              "grids of 0, negative, full-width or fractional rows", "clear error",
              "the file and the [[mat]] named; a BOM read", cases=tried + 1)  # fmt: skip


def test_a_calibration_for_another_mat_is_refused(fault_row):
    from texsense.calibration.workflows import seat_calibration
    from texsense.compensation.pipeline import Pipeline

    cal = seat_calibration()
    made_for = next(s.layout for s in cal.stages if getattr(s, "layout", None) is not None)
    rows, cols = made_for.shape
    active = np.zeros(made_for.shape, bool)
    active.flat[np.sort(np.random.default_rng(0).choice(rows * cols, 96, replace=False))] = True
    others = {
        "8 x 12": Layout.grid(8, 12), "12 x 8": Layout.grid(12, 8), "96 x 1": Layout.grid(96, 1),
        "96 points": Layout.points(np.c_[np.arange(96.0), np.zeros(96)]),
        f"{rows} x {cols}, other cells": Layout.grid(rows, cols, active=active),
    }  # fmt: skip
    for lay in others.values():
        assert lay.n_elements == made_for.n_elements
        with pytest.raises(ParameterError, match="another mat"):
            Pipeline(cal, lay)
    Pipeline(cal, made_for)  # its own mat
    fault_row("settings", f"a mat calibration applied to {len(others)} mats of the same element "
              "count in other places", "refused", ", ".join(others), cases=len(others))  # fmt: skip


def _moved(lay: Layout, xy: np.ndarray) -> Layout:
    """``lay`` with its elements' centres at ``xy`` (cells, shape, pitch kept)."""
    return Layout(xy, lay.size_cm, shape=lay.shape, cells=lay.cells, pitch_cm=lay.pitch_cm)


def _rearranged(xy: np.ndarray, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Generated arrangements of the same elements in other places."""
    span = np.ptp(xy, axis=0)
    i, j = rng.choice(len(xy), 2, replace=False)
    moved = xy.copy()
    moved[i] += span * rng.uniform(0.05, 0.3, 2) * rng.choice([-1, 1], 2)
    swapped = xy.copy()
    swapped[[i, j]] = swapped[[j, i]]
    return {"one moved": moved, "two swapped": swapped,
            "mirrored in x": np.c_[-xy[:, 0], xy[:, 1]],
            "mirrored in y": np.c_[xy[:, 0], -xy[:, 1]],
            "shuffled": xy[rng.permutation(len(xy))]}  # fmt: skip


def test_a_calibration_for_the_same_count_in_other_places_is_refused(fault_row):
    """Generated: element centres moved, swapped, mirrored, shuffled (same count, same grid and
    cells) are another mat; the same places at another offset, pitch or within 0.1 % are not."""
    from texsense.calibration.workflows import seat_calibration
    from texsense.compensation.pipeline import Pipeline, layout_mismatch

    cal = seat_calibration()
    grid = next(s.layout for s in cal.stages if getattr(s, "layout", None) is not None)
    rng = np.random.default_rng(9)
    refused = accepted = 0
    wrong = []
    for k in range(12):
        points = Layout.points(rng.uniform(0, 40, (96, 2)))
        for base, check in ((points, lambda a, b: layout_mismatch(a, b)),
                            (grid, lambda _a, b: _pipeline_refuses(Pipeline, cal, b))):  # fmt: skip
            xy = np.asarray(base.xy_cm)
            for name, other in _rearranged(xy, rng).items():
                if not check(base, _moved(base, other)):
                    wrong.append(f"#{k} {base.kind} {name}: taken")
                refused += 1
            scale = rng.uniform(0.5, 3.0, 2)
            for name, same in {"shifted": xy + rng.uniform(-50, 50, 2), "another pitch": xy * scale,
                               "within 0.1 %": xy + rng.normal(0, 1e-3 * np.ptp(xy), xy.shape)
                               }.items():  # fmt: skip
                if check(base, _moved(base, same)):
                    wrong.append(f"#{k} {base.kind} {name}: refused")
                accepted += 1
    assert wrong == [], f"{len(wrong)} of {refused + accepted}:\n" + "\n".join(wrong)
    fault_row("settings", "a calibration applied to the same elements in other places "
              "(generated: moved, swapped, mirrored, shuffled; points and a grid)", "refused",
              f"{refused} refused; {accepted} at another offset or pitch accepted",
              cases=refused + accepted)  # fmt: skip


def _pipeline_refuses(pipeline, cal, layout: Layout) -> bool:
    try:
        pipeline(cal, layout)
    except ParameterError as e:
        assert "another mat" in str(e), e
        return True
    return False


IMPOSSIBLE = {"pressure": [np.inf, -np.inf, np.nan, -5.0, 3e38, 2e5],
              "capacitance": [np.nan, -1.0, 5e9], "raw": [np.inf, 2e15]}  # fmt: skip
UNITS = {"pressure": "N/cm2", "capacitance": "pF", "raw": "count"}


@pytest.mark.parametrize("suffix", [".h5", ".csv", ".asf"])
def test_impossible_readings_are_invalid_whatever_the_file_says(tmp_path, suffix, fault_row):
    for quantity, bad in IMPOSSIBLE.items():
        if suffix == ".asf" and quantity == "capacitance":
            continue  # (a Tekscan export holds pressure, force or raw counts)
        frames = np.ones((3, 12), np.float32)
        frames[1, : len(bad)] = bad
        rec = Recording(frames, [0.0, 1.0, 2.0], Layout.grid(3, 4), quantity, UNITS[quantity])
        path = tmp_path / f"{quantity}{suffix}"
        save(rec, path)
        if suffix == ".h5":  # what another program may write: all valid, whatever the values
            with h5py.File(path, "a") as f:
                f["valid"][...] = True
        back = load(path)
        assert int((~back.valid).sum()) == len(bad), (quantity, suffix)
        assert not back.valid[1, : len(bad)].any()
    case = f"inf, -inf, NaN, negative, beyond any sensor under valid = True ({suffix})"
    fault_row("values", case, "invalid readings", cases=sum(map(len, IMPOSSIBLE.values())))


def test_values_that_are_no_numbers_are_refused(tmp_path, fault_row):
    base = save(Recording(np.ones((3, 4)), [0.0, 1.0, 2.0], Layout.grid(2, 2)), tmp_path / "b.h5")
    for name, data in {"complex": np.full((3, 4), 1 + 5j, np.complex64),
                       "text": np.full((3, 4), "1", "S3"),
                       "compound": np.zeros((3, 4), [("a", "f4")])}.items():  # fmt: skip
        path = tmp_path / f"{name}.h5"
        path.write_bytes(base.read_bytes())
        with h5py.File(path, "a") as f:
            del f["frames"]
            f["frames"] = data
        with pytest.raises(FormatError, match="/frames"):
            load(path)
        fault_row("values", f"HDF5 frames of {name} values", "clear error")
