"""A sequence of sensor frames with everything needed to interpret it: :class:`Recording`.

A frame is one reading of every element (float32, length N). A recording holds T frames, their
time stamps in s (and, for multiplexed scans where elements are read one after another, each
element's own time stamp), the :class:`~texsense.Layout`, the quantity and unit of the values,
a per-element validity mask, per-frame labels (posture, subject, ...) and provenance metadata.

Examples
--------
>>> import numpy as np
>>> from texsense import Layout, Recording
>>> lay = Layout.grid(2, 3, pitch_cm=1.0)
>>> rec = Recording(np.ones((4, 6)), times=np.arange(4) * 0.1, layout=lay,
...                 quantity="pressure", unit="N/cm2", labels={"posture": [1, 1, 2, 2]})
>>> rec.n_frames, rec.n_elements, round(rec.frame_period_s, 3)
(4, 6, 0.1)
"""

from __future__ import annotations

import importlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.data import units
from texsense.data.layout import Layout
from texsense.exceptions import ParameterError, UnitError

__all__ = ["QUANTITIES", "Recording"]

#: Quantities a recording can hold, and which kind of unit each one takes.
QUANTITIES: dict[str, str] = {
    "pressure": "pressure",
    "capacitance": "capacitance",
    "compression": "length",
    "displacement": "length",
    "force": "force",
    "resistance": "resistance",
    "raw": "raw",
}


def _as_label(name: str, values: npt.ArrayLike, n_frames: int) -> np.ndarray:
    arr = np.asarray(values)
    if arr.dtype == object:
        arr = arr.astype(str)
    if arr.dtype.kind not in "biufUS":
        raise ParameterError(f"label {name!r}: unsupported dtype {arr.dtype}")
    if arr.dtype.kind == "S":
        arr = arr.astype(str)
    if arr.shape != (n_frames,):
        raise ParameterError(f"label {name!r}: expected {n_frames} values, got shape {arr.shape}")
    return arr


class Recording:
    """Frames of N elements over time, with layout, unit, validity, labels and provenance.

    Parameters
    ----------
    frames : array_like, shape (T, N)
        Element values, stored as float32.
    times : array_like, shape (T,)
        Frame time stamps in s (the start of each scan for multiplexed sensors).
    layout : Layout
        Element positions and topology; must have N elements.
    quantity : str
        One of :data:`QUANTITIES` (``"pressure"``, ``"capacitance"``, ``"raw"``, ...).
    unit : str
        Unit of the values; must measure ``quantity`` (pressure values in ``"kPa"`` are fine
        but texsense works in ``"N/cm2"``: see :meth:`to_unit`).
    valid : array_like of bool, shape (T, N), optional
        False where a reading is known to be bad (failed element). Default all True.
    element_times : array_like, shape (T, N), optional
        Per-element time stamps in s for multiplexed scans.
    labels : mapping of str to array_like (T,), optional
        Per-frame labels such as ``posture`` and ``subject`` (numbers or strings).
    meta : mapping, optional
        JSON-able provenance: source file, device, calibration id, software version, ...
    """

    def __init__(
        self,
        frames: npt.ArrayLike,
        times: npt.ArrayLike,
        layout: Layout,
        quantity: str = "pressure",
        unit: str = "N/cm2",
        *,
        valid: npt.ArrayLike | None = None,
        element_times: npt.ArrayLike | None = None,
        labels: Mapping[str, npt.ArrayLike] | None = None,
        meta: Mapping[str, Any] | None = None,
    ) -> None:
        f = np.ascontiguousarray(frames, dtype=np.float32)
        if f.ndim != 2:
            raise ParameterError(f"frames: expected shape (T, N), got {f.shape}")
        t_count, n = f.shape
        if not isinstance(layout, Layout):
            raise ParameterError(f"layout: expected a texsense.Layout, got {type(layout).__name__}")
        if layout.n_elements != n:
            raise ParameterError(f"layout has {layout.n_elements} elements but frames have {n}")
        t = np.ascontiguousarray(times, dtype=np.float64)
        if t.shape != (t_count,):
            raise ParameterError(f"times: expected shape ({t_count},), got {t.shape}")
        if quantity not in QUANTITIES:
            raise ParameterError(
                f"quantity: expected one of {', '.join(QUANTITIES)}, got {quantity!r}"
            )
        unit = units.canonical(unit)
        if units.quantity_of(unit) != QUANTITIES[quantity]:
            raise UnitError(f"unit {unit!r} does not measure {quantity}")
        if valid is None:
            v = np.ones((t_count, n), dtype=bool)
        else:
            v = np.ascontiguousarray(valid, dtype=bool)
            if v.shape != (t_count, n):
                raise ParameterError(f"valid: expected shape ({t_count}, {n}), got {v.shape}")
        et = None
        if element_times is not None:
            et = np.ascontiguousarray(element_times, dtype=np.float64)
            if et.shape != (t_count, n):
                raise ParameterError(
                    f"element_times: expected shape ({t_count}, {n}), got {et.shape}"
                )
        lab = {str(k): _as_label(str(k), val, t_count) for k, val in (labels or {}).items()}
        m = dict(meta or {})
        try:
            json.dumps(m)
        except TypeError as e:
            raise ParameterError(f"meta must be JSON-serialisable: {e}") from None
        self.frames: npt.NDArray[np.float32] = f
        self.times: npt.NDArray[np.float64] = t
        self.layout = layout
        self.quantity = quantity
        self.unit = unit
        self.valid: npt.NDArray[np.bool_] = v
        self.element_times = et
        self.labels: dict[str, np.ndarray] = lab
        self.meta: dict[str, Any] = m

    # ------------------------------------------------------------------ basic facts
    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.frames.shape[0])

    @property
    def n_elements(self) -> int:
        """Number of elements N."""
        return int(self.frames.shape[1])

    @property
    def duration_s(self) -> float:
        """Time from the first to the last frame plus one frame period, in s."""
        if self.n_frames == 0:
            return 0.0
        period = self.frame_period_s
        return float(self.times[-1] - self.times[0]) + (period if np.isfinite(period) else 0.0)

    @property
    def frame_period_s(self) -> float:
        """Median time between frames in s (NaN with fewer than two frames)."""
        if self.n_frames < 2:
            return float("nan")
        return float(np.median(np.diff(self.times)))

    def frames_in(self, seconds: float) -> int:
        """How many frames ``seconds`` hold, the one way an app sizes a window from time: at
        the median frame period (their mean step where more than half the frames share a
        time stamp), rounded, at least 1 and at most :attr:`n_frames`, so that a window never
        outgrows the recording however its times run (steps of 1e-300 s: a window of 5 s
        was 5e300 frames); 1 for a recording of fewer than two frames.

        Raises
        ------
        ParameterError
            When the times do not advance (every frame at one time), or are not numbers.

        >>> import numpy as np
        >>> from texsense import Layout
        >>> rec = Recording(np.ones((50, 1)), np.arange(50) * 0.1, Layout.grid(1, 1))
        >>> rec.frames_in(0.5), rec.frames_in(1e9), rec.frames_in(0.0)
        (5, 50, 1)
        """
        n = self.n_frames
        if n < 2:
            return 1
        with np.errstate(invalid="ignore", over="ignore"):
            period = float(np.median(np.diff(self.times)))
            if not period > 0:
                period = float(self.times[-1] - self.times[0]) / (n - 1)
        if not (np.isfinite(period) and period > 0):
            raise ParameterError(
                f"the {n} frames' times do not advance ({self.times[0]:.9g} to "
                f"{self.times[-1]:.9g} s): no window in s can be sized in frames"
            )
        with np.errstate(over="ignore"):
            frames = float(seconds) / period
        return int(min(max(round(frames) if np.isfinite(frames) else n, 1), n))

    def maps(self) -> np.ndarray:
        """Frames as (T, rows, cols) maps with NaN in empty cells (grid layouts only)."""
        return self.layout.to_grid(self.frames)

    def masked_frames(self) -> npt.NDArray[np.float32]:
        """Frames with invalid readings replaced by NaN."""
        return np.where(self.valid, self.frames, np.float32(np.nan))

    # ------------------------------------------------------------------ derived recordings
    def _with(self, **changes: Any) -> Recording:
        args: dict[str, Any] = {
            "frames": self.frames,
            "times": self.times,
            "layout": self.layout,
            "quantity": self.quantity,
            "unit": self.unit,
            "valid": self.valid,
            "element_times": self.element_times,
            "labels": self.labels,
            "meta": self.meta,
        }
        args.update(changes)
        return Recording(
            args.pop("frames"),
            args.pop("times"),
            args.pop("layout"),
            args.pop("quantity"),
            args.pop("unit"),
            **args,
        )

    def with_labels(self, labels: Mapping[str, npt.ArrayLike]) -> Recording:
        """A copy with ``labels`` in place of the per-frame labels (same frames and rest)."""
        return self._with(labels=labels)

    def to_unit(self, unit: str) -> Recording:
        """A copy with the values converted to ``unit`` (same quantity)."""
        f = units.factor(self.unit, unit)
        if f == 1.0:
            return self._with(unit=units.canonical(unit))
        frames = (self.frames.astype(np.float64) * f).astype(np.float32)
        return self._with(frames=frames, unit=units.canonical(unit))

    def select(self, index: slice | Sequence[int] | npt.NDArray[Any]) -> Recording:
        """A recording of the frames picked by ``index`` (slice, indices or boolean mask)."""
        idx = index if isinstance(index, slice) else np.asarray(index)
        return self._with(
            frames=self.frames[idx],
            times=self.times[idx],
            valid=self.valid[idx],
            element_times=None if self.element_times is None else self.element_times[idx],
            labels={k: v[idx] for k, v in self.labels.items()},
        )

    @classmethod
    def concatenate(cls, recordings: Sequence[Recording]) -> Recording:
        """Join recordings of the same layout, quantity and unit frame-wise.

        Labels must have the same names in all parts; ``meta`` is taken from the first.
        """
        if not recordings:
            raise ParameterError("concatenate: no recordings given")
        first = recordings[0]
        for i, r in enumerate(recordings[1:], start=1):
            if r.layout != first.layout:
                raise ParameterError(f"concatenate: recording {i} has another layout")
            if (r.quantity, r.unit) != (first.quantity, first.unit):
                raise ParameterError(
                    f"concatenate: recording {i} holds {r.quantity} in {r.unit}, "
                    f"expected {first.quantity} in {first.unit}"
                )
            if r.labels.keys() != first.labels.keys():
                raise ParameterError(f"concatenate: recording {i} has other label names")
            if (r.element_times is None) != (first.element_times is None):
                raise ParameterError("concatenate: element_times present in only some parts")
        et = None
        if first.element_times is not None:
            et = np.concatenate([r.element_times for r in recordings])
        return cls(
            np.concatenate([r.frames for r in recordings]),
            np.concatenate([r.times for r in recordings]),
            first.layout,
            first.quantity,
            first.unit,
            valid=np.concatenate([r.valid for r in recordings]),
            element_times=et,
            labels={k: np.concatenate([r.labels[k] for r in recordings]) for k in first.labels},
            meta=first.meta,
        )

    # ------------------------------------------------------------------ comparison, I/O
    def equals(self, other: Recording) -> bool:
        """True if both recordings hold exactly the same data (bit for bit, NaN == NaN)."""

        def same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
            if a is None or b is None:
                return a is None and b is None
            return (
                a.shape == b.shape
                and a.dtype.kind == b.dtype.kind
                and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
            )

        return (
            same(self.frames, other.frames)
            and same(self.times, other.times)
            and self.layout == other.layout
            and (self.quantity, self.unit) == (other.quantity, other.unit)
            and same(self.valid, other.valid)
            and same(self.element_times, other.element_times)
            and self.labels.keys() == other.labels.keys()
            and all(same(v, other.labels[k]) for k, v in self.labels.items())
            and self.meta == other.meta
        )

    def save(self, path: str | Path, *, format: str | None = None) -> Path:
        """Write the recording by the path's extension through :func:`texsense.io.save`:
        HDF5 (``.h5``, schema in ``docs/data-model.md``), wide CSV (``.csv``) or Tekscan ASCII
        (``.asf``); ``format`` names a writer explicitly."""
        # texsense.io reads files into recordings, so it depends on this module; the façade
        # reaches it at call time (the one late-bound import of the package, allowed by
        # tests/test_imports.py)
        io = importlib.import_module("texsense.io")
        return io.save(self, path, format=format)

    def __repr__(self) -> str:
        return (
            f"Recording({self.n_frames} frames x {self.n_elements} elements, "
            f"{self.quantity} in {self.unit}, {self.duration_s:.3g} s, {self.layout!r}, "
            f"labels={sorted(self.labels)})"
        )
