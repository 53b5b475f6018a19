"""Simulated people as live sources: a person on the virtual 96-element seat and one on the
virtual 64 x 32 bed mat, read through the virtual sensor (docs/monitor.md, "Sources"); also
importable from :mod:`texsense.monitor.sources`."""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Iterator
from typing import Any

import numpy as np

from texsense.calibration.workflows import bed_calibration, seat_calibration
from texsense.compensation.stages import StageChain
from texsense.data.protocol import Frame
from texsense.exceptions import ParameterError
from texsense.monitor.sources import Source, SourceOptions, _pace
from texsense.sim.bed import BED_CONVERTERS, Sleeper, bed_mat, night_frames, night_plan
from texsense.sim.mat import VirtualMat
from texsense.sim.seated import POSTURES, SEAT_FAILURES, Subject, posture_pressure

__all__ = ["VirtualBedSource", "VirtualSeatSource"]


class VirtualSeatSource(Source):
    """A simulated person on the 96-element textile seat (thesis §6.2) read through the
    virtual sensor: hysteresis, drift, noise and failing elements (SEAT_FAILURES).

    The person takes the 16 postures in a random order, holding each ``hold_s`` (± 30 %),
    and stands up for ``away_s`` after every ``postures_per_sitting`` postures. ``speed`` runs
    simulated time faster than the wall clock (the seat gives a frame every 1.6 s).
    """

    name = "virtual seat"
    scheme = "virtual"
    reads = frozenset({"--speed"})
    summary = "a simulated person on the thesis's 96-element textile seat (the default)"

    @classmethod
    def from_option(cls, argument: str, options: SourceOptions) -> Source:
        """``virtual``."""
        return cls(speed=options.speed)

    @classmethod
    def default_calibration(cls) -> StageChain:
        """The seat calibrated as a user would
        (:func:`texsense.calibration.workflows.seat_calibration`)."""
        return seat_calibration()

    def __init__(
        self,
        *,
        speed: float = 1.0,
        seed: int = 0,
        hold_s: float = 90.0,
        postures_per_sitting: int = 20,
        away_s: float = 120.0,
    ) -> None:

        super().__init__()
        if speed < 0 or hold_s <= 0 or away_s < 0 or postures_per_sitting < 1:
            raise ParameterError("speed >= 0, hold_s > 0, away_s >= 0, postures >= 1 required")
        self.mat = VirtualMat.seat(seed=5, failures=SEAT_FAILURES)
        self.layout = self.mat.layout
        self.subject = Subject.random(seed, seed=101)
        self.speed, self.hold_s, self.away_s = float(speed), float(hold_s), float(away_s)
        self.rate = self.speed
        self.per_sitting = int(postures_per_sitting)
        self._rng = np.random.default_rng(seed)
        self.frame_s = self.mat.cdc.frame_time_s(self.layout.n_elements)
        self.posture = 0  # the true posture now (0: nobody seated)
        self.failed: np.ndarray = np.zeros(self.layout.n_elements, bool)

    def _plan(self) -> list[tuple[float, int]]:
        """(duration, posture) segments of one sitting and the break after it."""
        postures = self._rng.integers(1, 17, self.per_sitting)
        out = [(self.hold_s * self._rng.uniform(0.7, 1.3), int(p)) for p in postures]
        return [*out, (self.away_s, 0)]

    async def frames(self) -> AsyncIterator[Frame]:
        """Endless frames, paced to ``speed``."""

        n = self.layout.n_elements
        start = time.monotonic()
        t, seq = 0.0, 0
        while True:
            for duration, posture in self._plan():
                take = self._rng.normal(0.0, 0.5, 2)
                end = t + duration
                while t < end:
                    self.posture = posture
                    if posture:
                        jitter = tuple(take + self._rng.normal(0.0, 0.15, 2))
                        p = posture_pressure(self.layout, posture, self.subject, jitter)
                    else:
                        p = np.zeros(n)
                    scan = self.mat.scan(np.array([t]), p[None, :])
                    self.failed = scan.failed[0]
                    cap = scan.capacitance
                    assert cap.element_times is not None  # a scan times every element
                    await _pace(start, t, self.speed)
                    yield Frame(seq, cap.element_times[0].copy(), cap.frames[0].astype(float))
                    seq += 1
                    t += self.frame_s

    def info(self) -> dict[str, Any]:
        """Status, with the simulated truth (the posture's name now, None when away)."""

        truth = POSTURES[self.posture] if self.posture else None
        return {**super().info(), "speed": self.speed, "true_posture": truth}


class VirtualBedSource(Source):
    """A simulated person on the virtual 64 x 32 bed mat (:func:`texsense.sim.bed.bed_mat`:
    textile spacer, failing elements, 32 converters in parallel: a frame about every second):
    lying positions of every
    side and their variants in a random order, each held ``hold_s`` times 0.3-2.2 (the
    default: 18 min to 2 h 12 min, so a 2 h turning schedule is sometimes overrun), turning
    for a few seconds between them, sitting up after every 5 positions and out of bed for
    ``away_s`` after every ``positions_per_stay``."""

    name = "virtual bed"
    scheme = "virtual-bed"
    reads = frozenset({"--speed"})
    summary = "a simulated sleeper on the virtual 64 x 32 bed mat"

    @classmethod
    def from_option(cls, argument: str, options: SourceOptions) -> Source:
        """``virtual-bed``."""
        return cls(speed=options.speed)

    @classmethod
    def default_calibration(cls) -> StageChain:
        """The bed mat calibrated as a user would
        (:func:`texsense.calibration.workflows.bed_calibration`)."""
        return bed_calibration()

    def __init__(
        self,
        *,
        speed: float = 1.0,
        seed: int = 0,
        hold_s: float = 3600.0,
        positions_per_stay: int = 8,
        away_s: float = 300.0,
    ) -> None:

        super().__init__()
        if speed < 0 or hold_s <= 0 or away_s < 0 or positions_per_stay < 1:
            raise ParameterError("speed >= 0, hold_s > 0, away_s >= 0, positions >= 1 required")
        self.mat = bed_mat()
        self.layout = self.mat.layout
        self.speed, self.hold_s, self.away_s = float(speed), float(hold_s), float(away_s)
        self.rate = self.speed
        self.per_stay = int(positions_per_stay)
        self._rng = np.random.default_rng(seed)
        self.sleeper = Sleeper.random(seed, seed=202)
        self.frame_s = self.mat.cdc.frame_time_s(self.layout.n_elements, BED_CONVERTERS)
        self.position: str | None = None
        self.side: str | None = None

    def _plan(self) -> Iterator[tuple[str, float]]:

        while True:
            yield from night_plan(
                self._rng, self.per_stay, self.hold_s, out_every=self.per_stay,
                away_s=self.away_s, spread=(0.3, 2.2),
            )  # fmt: skip

    async def frames(self) -> AsyncIterator[Frame]:
        """Endless frames, paced to ``speed``."""

        start = time.monotonic()
        turn_s = min(6.0, self.hold_s / 3)
        plan = self._plan()
        frames = night_frames(self.sleeper, plan, self._rng, frame_s=self.frame_s, turn_s=turn_s)
        for seq, f in enumerate(frames):
            self.position = None if f.position == "out" else f.position
            self.side = None if f.side == "out" else f.side
            cap = self.mat.scan(np.array([f.t]), f.pressure[None, :]).capacitance
            assert cap.element_times is not None  # a scan times every element
            await _pace(start, f.t, self.speed)
            yield Frame(seq, cap.element_times[0].copy(), cap.frames[0].astype(float))

    def info(self) -> dict[str, Any]:
        """Status, with the simulated truth (the position and side now, None when out of
        bed)."""
        return {
            **super().info(),
            "speed": self.speed,
            "true_position": self.position,
            "true_side": self.side,
        }
