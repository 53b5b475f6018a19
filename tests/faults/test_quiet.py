"""Family "numpy's warnings on stderr" (harden12): a recording whose readings are all invalid,
NaN or of odd types made numpy print a ``RuntimeWarning`` and a line of its source beside the
command's output (``Mean of empty slice`` from ``report``, ``overflow encountered in cast``
from a layout's cells in float16). ``texsense.cli.quiet_arithmetic`` keeps numpy's words about
arithmetic off the stderr of every command; what they mean (invalid readings) the readers say.

The table: odd recordings x the commands that compute over them; stderr holds only the
command's own lines.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from faults._families import batch, small_recording
from texsense import Recording
from texsense.io import save


def _like(rec, frames=None, valid=None):
    return Recording(rec.frames if frames is None else frames, rec.times, rec.layout,
                     rec.quantity, rec.unit, valid=valid, labels=rec.labels)  # fmt: skip


def _recordings(folder):
    rec = small_recording(6)
    frames = rec.frames.copy()
    odd = {
        "all invalid": _like(rec, valid=np.zeros(frames.shape, bool)),
        "all NaN": _like(rec, np.full_like(frames, np.nan)),
        "one element valid": _like(rec, valid=np.eye(6, 12, dtype=bool)),
        "zeros": _like(rec, np.zeros_like(frames)),
        "beyond any sensor": _like(rec, np.full_like(frames, 1e30)),
        "one frame": rec.select(slice(0, 1)),
        "no frames": rec.select(slice(0, 0)),
    }
    paths = {}
    for name, r in odd.items():
        paths[name] = folder / f"{name.replace(' ', '-')}.h5"
        save(r, paths[name])
    for kind, values in (("float16", np.float16), ("big-endian", ">f8")):
        path = folder / f"cells-{kind}.h5"
        save(rec, path)
        with h5py.File(path, "a") as f:
            cells = f["layout/cells"][()]
            del f["layout/cells"]
            f["layout/cells"] = cells.astype(values)
        paths[f"cells in {kind}"] = path
    return paths


COMMANDS = {
    "info": lambda p: ["info", str(p)],
    "info --json": lambda p: ["info", "--json", str(p)],
    "report": lambda p: ["report", str(p), "-o", f"{p}.html"],
    "plot": lambda p: ["plot", str(p), "-o", f"{p}.png"],
    "convert": lambda p: ["convert", str(p), f"{p}.csv"],
    "repair": lambda p: ["repair", str(p), "-o", f"{p}.repaired.h5"],
}


@pytest.mark.slow
def test_no_numpy_warning_reaches_stderr(tmp_path, fault_row):
    paths = _recordings(tmp_path)
    cases = [(r, c) for r in paths for c in COMMANDS]
    results, _, _ = batch([COMMANDS[c](paths[r]) for r, c in cases], tmp_path, timeout=900)
    bad = []
    for (r, c), (rc, _out, err) in zip(cases, results, strict=True):
        lines = [s for s in err.strip().splitlines() if s.strip()]
        stray = [s for s in lines if "Warning" in s or s.startswith(" ") or "Traceback" in s]
        if stray or rc not in (0, 1) or (rc == 1 and len(lines) != 1):
            bad.append(f"{c} {r}: exit {rc}: {' | '.join(lines)[:300]}")
    print(f"{len(cases) - len(bad)} of {len(cases)} cases held")
    assert not bad, "\n".join(bad)
    fault_row("values", f"{len(paths)} odd recordings (all invalid, NaN, cells in float16, ...) "
              f"x {len(COMMANDS)} commands: no numpy warning on stderr", "clear error or read",
              cases=len(cases))  # fmt: skip


def test_only_the_words_of_odd_data_are_kept_off_stderr():
    """What the quiet keeps off: numpy's words on a file's odd values (no valid reading, a
    cell beyond float16). An overflow or underflow of texsense's own arithmetic is a fault
    to see, and still warns."""
    import warnings

    from texsense.cli import quiet_arithmetic

    big, tiny = np.array([1e300]), np.array([1e-300])
    with warnings.catch_warnings(record=True) as seen, np.errstate(all="warn"):
        warnings.simplefilter("always")  # (the quiet's filters come before this one)
        with quiet_arithmetic():
            np.nanmean(np.full(3, np.nan))
            np.array([1e30]).astype(np.float16)
            np.array([0.0]) / 0.0
            assert not seen, [str(w.message) for w in seen]
            big * big
            tiny * tiny
    words = sorted(str(w.message) for w in seen)
    assert words == ["overflow encountered in multiply", "underflow encountered in multiply"]


def test_a_table_of_values_beyond_any_sensor_is_read_as_not_numbers(tmp_path, fault_row):
    """A columns table whose values lie beyond any sensor (x 1e300) is read as the recording
    readers read such values (``io._base.impossible``): not numbers, counted in one warning
    line. Before, ``hysteresis apply``, ``validate`` and ``fit`` computed on them and printed
    numpy's overflow warnings (harden13), which ``quiet_arithmetic`` rightly lets through."""
    from texsense.io.columns_csv import write_columns_csv

    t = np.arange(2000) * 0.1
    u = 2.0 + 1.5 * np.sin(t / 7.0) * np.sin(t / 31.0)
    p = 0.8 * u**2 + 0.3 * np.cos(t / 7.0)
    write_columns_csv(tmp_path / "r.csv", {"time_s": t, "compression_mm": u, "pressure_ncm2": p})
    big = {"time_s": t, "compression_mm": u * 1e300, "pressure_ncm2": p * 1e300}
    write_columns_csv(tmp_path / "big.csv", big)
    model = str(tmp_path / "model.json")
    argvs = [["hysteresis", "apply", model, "big.csv", "-o", "out.csv"],
             ["hysteresis", "validate", model, "big.csv"],
             ["hysteresis", "fit", "big.csv", "-o", "m2.json"]]  # fmt: skip
    warm = [["hysteresis", "fit", "r.csv", "-o", model]]
    results, _, _ = batch(argvs, tmp_path, warm=warm, timeout=300)
    for argv, (rc, _out, err) in zip(argvs, results, strict=True):
        lines = [s for s in err.strip().splitlines() if s.strip()]
        assert not [s for s in lines if "Warning" in s or "Traceback" in s or s.startswith(" ")]
        assert "beyond any sensor, read as not a number" in lines[0], (argv, lines)
        assert rc in (0, 1) and len(lines) == 1 + rc, (argv, lines)
    fault_row("values", "a columns table of values beyond any sensor x hysteresis apply, "
              "validate, fit: read as not numbers, one warning line", "clear error or read",
              cases=len(argvs))  # fmt: skip
