"""One element's record as named columns, from a column CSV or from any texsense recording.

The hysteresis and drift tools (``texsense hysteresis fit|validate|apply``, ``texsense drift
fit``) work on the record of one element — a specimen on a test machine: columns such as
``time_s``, ``compression_mm``, ``pressure_ncm2``, ``capacitance_pF``. :func:`read_columns`
reads them from either

- a column CSV (:mod:`texsense.io.columns_csv`: ``texsense simulate ... --csv``, a
  test-machine export), or
- a one-element recording in any format texsense reads (``texsense simulate ... -o x.h5``,
  ``texsense record``, a wide CSV): ``time_s``, the values as ``<quantity>_<unit>`` (e.g.
  ``capacitance_pF``; invalid readings as NaN) and every numeric per-frame label (the
  simulator's ``compression_mm`` and ``pressure_ncm2``).

:func:`write_columns` writes a column CSV (``.csv``) or, the other way round, a one-element
texsense HDF5 recording (``.h5``) whose values are one named column and whose labels are the
others, so that ``info``, ``plot``, ``convert`` and the dashboard read the result.

Examples
--------
>>> import tempfile, os
>>> from texsense.sim.protocols import run_protocol
>>> folder = tempfile.mkdtemp()
>>> rec = run_protocol("ramp", "textile-6mm", cycles=1, sample_hz=5.0)
>>> _ = rec.save(os.path.join(folder, "ramp.h5"))
>>> cols = read_columns(os.path.join(folder, "ramp.h5"), required=("compression_mm",))
>>> sorted(cols)
['capacitance_pF', 'compression_mm', 'platen_mm', 'pressure_ncm2', 'segment', 'time_s']
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

from texsense.data import units
from texsense.data.layout import Layout
from texsense.data.recording import QUANTITIES, Recording
from texsense.exceptions import FormatError, ParameterError, UnitError
from texsense.io import load, sniff_format
from texsense.io.columns_csv import (
    column_name,
    is_columns_csv,
    read_columns_csv,
    unit_of_column,
    write_columns_csv,
)
from texsense.io.hdf5 import write_hdf5

__all__ = [
    "column_name",
    "is_columns_csv",
    "read_columns",
    "unit_of_column",
    "write_columns",
]

#: What a column table is, for the error line on a file that is none.
WHAT = (
    "a column CSV (a header such as time_s,compression_mm,pressure_ncm2) or a one-element "
    "texsense recording (e.g. 'texsense simulate steps -o steps.h5')"
)


def _from_recording(rec: Recording, path: Path) -> dict[str, npt.NDArray[np.float64]]:
    if rec.n_elements != 1:
        raise FormatError(
            path,
            f"holds {rec.n_elements} elements; the column tools read one element's record: {WHAT}",
        )
    values = rec.frames[:, 0].astype(np.float64)
    values[~rec.valid[:, 0]] = np.nan
    written = rec.meta.get("columns")  # by write_columns: the values column's own name
    name = written[0] if isinstance(written, list) and written else None
    cols = {
        "time_s": rec.times.astype(np.float64),
        name or column_name(rec.quantity, rec.unit): values,
    }
    for name, label in rec.labels.items():
        if name not in cols and np.issubdtype(np.asarray(label).dtype, np.number):
            cols[name] = np.asarray(label, dtype=np.float64)
    return cols


def read_columns(
    path: str | Path, required: Sequence[str] = (), *, accept_truncated: bool = False
) -> dict[str, npt.NDArray[np.float64]]:
    """One element's record as {column: array}, from a column CSV or a one-element recording.

    Parameters
    ----------
    path : str or Path
        A column CSV, or a recording of one element in any format texsense reads.
    required : sequence of str
        Columns that must be there (the first missing one is named in the error). A CSV
        whose header holds all of them is read as a column table: the caller named its
        columns (:func:`is_columns_csv`), so a first column ``time_s`` followed by names
        without a unit (``field_oe``) does not make it a wide CSV.
    accept_truncated : bool
        Read a file cut short up to its last complete row or frame, with a warning.

    Raises
    ------
    FormatError
        One line naming the file and what is wrong: not a table or recording, more than one
        element, a missing column, a bad row.
    """
    path = Path(path)
    if path.is_dir():
        raise FormatError(path, f"a folder: expected {WHAT}")
    if is_columns_csv(path, required):
        return read_columns_csv(path, required, accept_truncated=accept_truncated)
    try:
        sniff_format(path)
    except FormatError as e:
        if not path.exists():
            raise
        raise FormatError(path, f"neither a column table nor a recording: expected {WHAT}") from e
    cols = _from_recording(load(path, accept_truncated=accept_truncated), path)
    for name in required:
        if name not in cols:
            raise FormatError(path, f"no column {name!r}; columns are {', '.join(cols)}")
    return cols


def write_columns(
    path: str | Path,
    columns: Mapping[str, npt.ArrayLike],
    *,
    values: str | None = None,
    unit: str | None = None,
) -> Path:
    """Write a column table: a column CSV (any ending but ``.h5``/``.hdf5``), or a one-element
    texsense HDF5 recording whose frames are the column ``values`` in ``unit`` (by default
    the unit its suffix names) and whose labels are the other columns (``time_s`` gives the
    times).

    Parameters
    ----------
    path : str or Path
        The file to write (temporary name, then renamed: :mod:`texsense.data.files`).
    columns : mapping of str to array_like
        Equal-length columns.
    values : str, optional
        HDF5 only: the column that becomes the recording's values (default: the last one).
    unit : str, optional
        HDF5 only: the unit of ``values``, when its name carries none.
    """
    path = Path(path)
    if path.suffix.lower() not in (".h5", ".hdf5"):
        return write_columns_csv(path, columns)
    cols = {k: np.asarray(v, dtype=np.float64).ravel() for k, v in columns.items()}
    if not cols:
        raise ParameterError("no columns to write")
    name = values or list(cols)[-1]
    if name not in cols:
        raise ParameterError(f"no column {name!r} to write as the values")
    unit = unit or unit_of_column(name.removesuffix("_model"))
    if unit is None:
        raise ParameterError(f"cannot tell the unit of {name!r}: name it (e.g. force_n)")
    try:
        kind = units.quantity_of(unit)
    except UnitError as e:
        raise ParameterError(str(e)) from None
    quantity = next((q for q, k in QUANTITIES.items() if k == kind), "raw")
    n = cols[name].size
    times = cols.pop("time_s", np.arange(n, dtype=np.float64))
    frames = cols.pop(name)[:, None]
    rec = Recording(
        frames.astype(np.float32),
        times,
        Layout.grid(1, 1, pitch_cm=1.0),
        quantity,
        unit,
        valid=np.isfinite(frames),
        labels=cols,
        meta={"columns": [name, *cols]},
    )
    return write_hdf5(rec, path)
