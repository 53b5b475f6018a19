"""A virtual materials-testing machine: one spacer specimen between two platens.

It moves the upper platen at a set speed until a pressure is reached, holds a compression or a
pressure, and records everything it did (time, platen compression, the specimen's own
compression, pressure), like the test machine of thesis §4.1 and §5.1.2.

Examples
--------
>>> from texsense.sim.spacer import Spacer
>>> m = TestMachine(Spacer.preset("textile-6mm"))
>>> m.ramp_to_pressure(10.0, speed_mm_min=50).ramp_to_pressure(0.0, speed_mm_min=50)
TestMachine(textile-6mm, ...)
>>> trace = m.trace()
>>> round(float(trace.pressure_ncm2.max()), 1)
10.0
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError
from texsense.sim.spacer import DriveResult, Spacer

__all__ = ["TestMachine"]

#: Largest platen step (mm) per simulation step during a ramp.
MAX_STEP_MM = 0.002
#: Longest simulation step (s) during a ramp.
MAX_DT_S = 0.5


class TestMachine:
    """Drive one spacer specimen like a universal test machine and record it.

    Parameters
    ----------
    spacer : Spacer
        A single-specimen spacer (``n_specimens == 1``).
    """

    __test__ = False  # not a pytest test class

    def __init__(self, spacer: Spacer) -> None:
        if spacer.n_specimens != 1:
            raise ParameterError("TestMachine holds one specimen (n_specimens == 1)")
        self.spacer = spacer
        self._t: list[np.ndarray] = [np.zeros(1)]
        self._e: list[np.ndarray] = [np.zeros(1)]
        self._p: list[np.ndarray] = [np.zeros(1)]
        self._s: list[np.ndarray] = [np.zeros(1)]
        self.time_s = 0.0
        self.compression_mm = 0.0
        self.pressure_ncm2 = 0.0

    def __repr__(self) -> str:
        return f"TestMachine({self.spacer.material.name}, t={self.time_s:.6g} s, ...)"

    def _append(self, t: np.ndarray, e_mm: np.ndarray, p: np.ndarray, s_mm: np.ndarray) -> None:
        if t.size == 0:
            return
        self._t.append(t)
        self._e.append(e_mm)
        self._p.append(p)
        self._s.append(s_mm)
        self.time_s = float(t[-1])
        self.compression_mm = float(e_mm[-1])
        self.pressure_ncm2 = float(p[-1])

    def ramp_to_pressure(
        self, target_ncm2: float, speed_mm_min: float, max_time_s: float = 1e6
    ) -> TestMachine:
        """Move the platen at ``speed_mm_min`` towards the specimen (target above the current
        pressure) or away from it (target below) until the pressure reaches the target."""
        if not speed_mm_min > 0:
            raise ParameterError(f"speed must be > 0 mm/min, got {speed_mm_min}")
        if not target_ncm2 >= 0:
            raise ParameterError(f"target pressure must be >= 0 N/cm², got {target_ncm2}")
        speed = speed_mm_min / 60.0  # mm/s
        dt = min(MAX_DT_S, MAX_STEP_MM / speed)
        rising = target_ncm2 > self.pressure_ncm2
        rate = (speed if rising else -speed) / self.spacer.thickness_mm
        bank = self.spacer._bank
        try:
            e, p, s, done = bank.ramp_until(dt, rate, float(target_ncm2), int(max_time_s / dt) + 1)
        except ValueError as err:
            raise ParameterError(f"{self.spacer.material.name}: {err}") from None
        if not done:
            raise ParameterError(f"target {target_ncm2} N/cm² not reached in {max_time_s} s")
        th = self.spacer.thickness_mm
        t = self.time_s + dt * np.arange(1, e.size + 1)
        self._append(t, e * th, p, s * th)
        return self

    def ramp_to_compression(self, compression_mm: float, speed_mm_min: float) -> TestMachine:
        """Move the platen at ``speed_mm_min`` to ``compression_mm``."""
        if not speed_mm_min > 0:
            raise ParameterError(f"speed must be > 0 mm/min, got {speed_mm_min}")
        distance = compression_mm - self.compression_mm
        speed = speed_mm_min / 60.0
        n = max(1, int(np.ceil(abs(distance) / MAX_STEP_MM)))
        dt = abs(distance) / speed / n if distance else MAX_DT_S
        t = self.time_s + dt * np.arange(1, n + 1)
        path = self.compression_mm + distance * np.arange(1, n + 1) / n
        self._record(
            self.spacer.drive_displacement(
                np.concatenate([[self.time_s], t]), np.concatenate([[self.compression_mm], path])
            )
        )
        return self

    def _record(self, r: DriveResult, platen_mm: npt.NDArray[np.float64] | None = None) -> None:
        # the first sample repeats the current state (dt = 0): drop it
        e = r.compression_mm[1:, 0] if platen_mm is None else platen_mm[1:]
        self._append(r.times_s[1:], e, r.pressure_ncm2[1:, 0], r.compression_mm[1:, 0])

    def hold_compression(self, duration_s: float, sample_s: float | None = None) -> TestMachine:
        """Hold the platen for ``duration_s``; samples every ``sample_s`` s, or on a
        logarithmic time grid (0.05 s .. duration, 60 per decade) when None."""
        t = self._hold_times(duration_s, sample_s)
        path = np.full(t.size, self.compression_mm)
        r = self.spacer.drive_displacement(t, path)
        self._record(r, platen_mm=path)
        return self

    def hold_pressure(self, duration_s: float, sample_s: float | None = None) -> TestMachine:
        """Hold the current pressure for ``duration_s`` (the specimen creeps)."""
        t = self._hold_times(duration_s, sample_s)
        r = self.spacer.drive_pressure(t, np.full(t.size, self.pressure_ncm2))
        self._record(r)
        return self

    def _hold_times(self, duration_s: float, sample_s: float | None) -> np.ndarray:
        if not duration_s > 0:
            raise ParameterError(f"hold duration must be > 0 s, got {duration_s}")
        if sample_s is None:
            decades = np.log10(max(duration_s, 0.1) / 0.05)
            rel = np.concatenate([[0.0], np.geomspace(0.05, duration_s, int(60 * decades) + 2)])
            rel = rel[rel <= duration_s]
        else:
            rel = np.arange(0.0, duration_s + sample_s / 2, sample_s)
        return self.time_s + rel

    def trace(self) -> DriveResult:
        """Everything recorded so far: times, platen compression, pressure, and in
        ``meta["specimen_compression_mm"]`` the specimen's own compression."""
        return DriveResult(
            np.concatenate(self._t),
            np.concatenate(self._e),
            np.concatenate(self._p),
            {
                "specimen_compression_mm": np.concatenate(self._s),
                "spacer": self.spacer.material.name,
                "seed": self.spacer.seed,
            },
        )
