"""What a sensor strip under a compression stocking says: the pressure at the standard
measuring points, the gradient from the ankle up, and the compression class (docs/stocking.md).

Compression classes of RAL-GZ 387 (the German quality standard for medical compression
stockings, the reference of most European markets), by the pressure at the ankle, point B:
class I 18-21 mmHg, II 23-32, III 34-46, IV 49 and more. A pressure in a gap between two
classes belongs to neither and is reported as such.

Examples
--------
>>> compression_class(27.5), compression_class(22.0), compression_class(12.0)
('II', 'between I and II', 'below I')
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from texsense.data.recording import Recording
from texsense.data.units import convert
from texsense.exceptions import ParameterError

__all__ = ["POINTS", "RAL_GZ_387_MMHG", "StockingReport", "compression_class", "report"]

POINTS = ("B", "B1", "C", "D")
#: Compression classes of RAL-GZ 387: pressure at the ankle (B), mmHg.
RAL_GZ_387_MMHG = {
    "I": (18.0, 21.0),
    "II": (23.0, 32.0),
    "III": (34.0, 46.0),
    "IV": (49.0, math.inf),
}


def compression_class(ankle_mmhg: float) -> str:
    """The RAL-GZ 387 class of a pressure at B, or where it falls between the classes."""
    names = list(RAL_GZ_387_MMHG)
    for k, (lo, hi) in enumerate(RAL_GZ_387_MMHG.values()):
        if lo <= ankle_mmhg <= hi:
            return names[k]
        if ankle_mmhg < lo:
            return "below I" if k == 0 else f"between {names[k - 1]} and {names[k]}"
    return names[-1]  # unreachable: the last class has no upper bound


@dataclass
class StockingReport:
    """Pressure at the points hour by hour (mean of the last 10 minutes before each mark)."""

    hours: list[float]
    mmhg: np.ndarray  # (H, 4) compensated
    uncompensated_mmhg: np.ndarray | None  # (H, 4): the first-loading curve alone

    @property
    def gradient(self) -> np.ndarray:
        """Pressure at B1, C and D as a share of B, hour by hour (H, 3)."""
        return self.mmhg[:, 1:] / self.mmhg[:, :1]

    def classes(self, uncompensated: bool = False) -> list[str]:
        """The class at B, hour by hour."""
        m = self.uncompensated_mmhg if uncompensated else self.mmhg
        if m is None:
            raise ParameterError("no uncompensated values in this report")
        return [compression_class(float(v)) for v in m[:, 0]]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        out = {
            "hours": self.hours,
            "points": list(POINTS),
            "mmHg": np.round(self.mmhg, 2).tolist(),
            "gradient": np.round(self.gradient, 3).tolist(),
            "class": self.classes(),
        }
        if self.uncompensated_mmhg is not None:
            out["uncompensated_mmHg"] = np.round(self.uncompensated_mmhg, 2).tolist()
            out["uncompensated_class"] = self.classes(uncompensated=True)
        return out


def _points(rec: Recording) -> np.ndarray:
    names = rec.layout.names
    if names is None or any(p not in names for p in POINTS):
        raise ParameterError(
            f"the strip's elements must be named {', '.join(POINTS)} (got {names})"
        )
    return np.array([names.index(p) for p in POINTS])


def _hourly(rec: Recording, cols: np.ndarray, hours: list[float]) -> np.ndarray:
    """Per hour ``h`` the mean pressure (mmHg) over the frames of the 10 minutes up to it, or
    at the frames nearest to it when none is there: found by bisection, so that the work is
    in the frames and the rows, never the rows times the frames."""
    v = np.where(rec.valid, rec.frames, np.nan)[:, cols].astype(np.float64)
    mm = np.asarray(convert(v, rec.unit, "mmHg"))
    order = np.argsort(rec.times, kind="stable")  # (a reader's times never go back)
    t, mm = (rec.times[order] - rec.times[order[0]]) / 3600.0, mm[order]
    rows = []
    for h in hours:
        lo, hi = np.searchsorted(t, [h - 1 / 6, h + 1e-9], side="right")
        sel: slice | np.ndarray = slice(lo, hi)
        if hi <= lo:  # no frame in the window: the frames nearest to h (either side)
            near = [float(t[k]) for k in (lo - 1, lo) if 0 <= k < t.size]
            d = min(abs(x - h) for x in near)
            at = sorted({x for x in near if abs(x - h) == d})
            sel = np.concatenate(
                [
                    np.arange(np.searchsorted(t, x, "left"), np.searchsorted(t, x, "right"))
                    for x in at
                ]
            )
        rows.append(np.nanmean(mm[sel], axis=0))
    return np.array(rows)


def report(
    pressure: Recording, uncompensated: Recording | None = None, every_h: float = 1.0
) -> StockingReport:
    """Hour by hour (from the first full ``every_h``) the pressure at B, B1, C, D of a pressure
    recording of the strip, and beside it an uncompensated one if given.

    Raises
    ------
    ParameterError
        When the rows would outnumber the recording's frames (a span of years, or
        ``every_h`` a second in a day's recording): rows are sized from time, the work they
        cost is bounded by the frames.
    """
    if pressure.quantity != "pressure":
        raise ParameterError(f"the report reads pressure, not {pressure.quantity}")
    if not every_h > 0:
        raise ParameterError(f"hours between rows must be > 0, got {every_h}")
    cols = _points(pressure)
    n = pressure.n_frames
    if n == 0:
        raise ParameterError("the recording has no frames")
    span = float(pressure.times[-1] - pressure.times[0]) / 3600.0
    with np.errstate(over="ignore", invalid="ignore"):
        count = np.floor((span + 1e-9) / every_h)
    if not count <= max(n, 1):
        raise ParameterError(
            f"a row every {every_h:g} h over the recording's {span:.4g} h makes {count:.4g} "
            f"rows, more than its {n} frames: choose a longer --every"
        )
    hours = [round(h, 6) for h in np.arange(every_h, span + 1e-9, every_h)] or [round(span, 6)]
    unc = None if uncompensated is None else _hourly(uncompensated, cols, hours)
    return StockingReport(hours, _hourly(pressure, cols, hours), unc)
