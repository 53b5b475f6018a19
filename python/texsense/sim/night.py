"""A night on the virtual bed mat, for judging drift correction in use (issue 37, docs/drift.md).

:func:`virtual_night` puts one virtual person (:class:`~texsense.sim.bed.Sleeper`) through a
night on the 64 x 32 bed mat made of any spacer preset (the textile spacer of the bed, or the
second and third laws, ``bouc-wen-6mm`` and ``iwan-6mm``): the mat is switched on empty, the
person lies down, holds positions for 20 min to over 2 h, turns, sits up now and then, gets
out of bed once (10 min) around the middle of the night and comes back. The mat reads every
frame (a frame every ``frame_s``) with elements failing at the thesis's rates; the truth is
the pressure every element carried when it was read (the same layout and frames).

Nothing here knows the compensation: the spacer laws are the simulator's
(:mod:`texsense.sim.spacer`), the body is anatomy (:mod:`texsense.sim.bed`).

Examples
--------
>>> n = virtual_night("textile-3mm", hours=0.1, seed=1)
>>> n.raw.quantity, n.truth.quantity, n.raw.n_frames == n.truth.n_frames
('capacitance', 'pressure', True)
>>> sorted(str(s) for s in set(n.truth.labels["side"]))  # empty for 5 min, then lying
['out', 'supine', 'transition']
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from texsense.data.recording import Recording
from texsense.exceptions import ParameterError
from texsense.sim.bed import BED_CONVERTERS, Sleeper, bed_layout, night_frames, night_plan
from texsense.sim.mat import VirtualMat
from texsense.sim.seated import SEAT_FAILURES
from texsense.sim.spacer import PRESETS

__all__ = ["NIGHT_MAT_SEED", "Night", "night_mat", "night_positions", "virtual_night"]

#: The physical bed mat of the virtual nights (its elements, offsets and failures).
NIGHT_MAT_SEED = 7
#: The mat is switched on this long before the person lies down (s).
EMPTY_FIRST_S = 300.0
#: Out of bed once, this long (s).
AWAY_S = 600.0


@dataclass
class Night:
    """What :func:`virtual_night` returns: the capacitance the mat read (labels ``position``,
    ``side`` — ``out`` for an empty mat, ``transition`` while turning — and ``hold``) and the
    true pressure of the same frames and elements."""

    raw: Recording
    truth: Recording
    sleeper: Sleeper
    spacer: str


def night_mat(
    spacer: str = "textile-3mm", seed: int = NIGHT_MAT_SEED, failures: bool = True
) -> VirtualMat:
    """The bed mat (:func:`texsense.sim.bed.bed_layout`, 32 converters) made of ``spacer``; with
    ``failures`` its elements fail at the thesis's rates. The same ``seed`` and spacer are the
    same physical mat."""
    if spacer not in PRESETS:
        raise ParameterError(f"unknown spacer {spacer!r}; known: {', '.join(PRESETS)}")
    return VirtualMat(
        bed_layout(),
        spacer,
        converters=BED_CONVERTERS,
        seed=seed,
        failures=SEAT_FAILURES if failures else None,
    )


def night_positions(hours: float, seed: int) -> list[tuple[str, float]]:
    """The plan of a night of ``hours``: empty first (:data:`EMPTY_FIRST_S`), then positions held
    20 min to 2 h 12 min with turns between them, sitting up after every fourth, out of bed once
    (:data:`AWAY_S`) at the first change of position after half the night."""
    if not 0 < hours <= 24:
        raise ParameterError(f"hours must lie in (0, 24], got {hours}")
    rng = np.random.default_rng([seed, 37])
    end = hours * 3600.0
    plan: list[tuple[str, float]] = [("out", min(EMPTY_FIRST_S, end))]
    total, away = plan[0][1], False
    while total < end:
        for position, seconds in night_plan(rng, 4, 3600.0, sit_every=4, out_every=0,
                                            spread=(0.33, 2.2)):  # fmt: skip
            # out of bed after half the night, once a position was held (a short night's half
            # may fall inside the empty start)
            if not away and total >= end / 2 and len(plan) > 1:
                plan.append(("out", min(AWAY_S, end - total)))
                total += plan[-1][1]
                away = True
            if total >= end:
                break
            plan.append((position, min(seconds, end - total)))
            total += plan[-1][1]
    return [(p, s) for p, s in plan if s > 0]


def virtual_night(
    spacer: str = "textile-3mm",
    hours: float = 8.0,
    seed: int = 0,
    *,
    frame_s: float = 10.0,
    mat_seed: int = NIGHT_MAT_SEED,
) -> Night:
    """Person ``seed`` (:meth:`Sleeper.random`) through a night of ``hours``
    (:func:`night_positions`) on :func:`night_mat`, a frame every ``frame_s``: the raw
    capacitance and the true pressure at the times each element was read."""
    if not frame_s > 0:
        raise ParameterError(f"frame_s must be > 0, got {frame_s}")
    sleeper = Sleeper.random(seed)
    rng = np.random.default_rng([seed, 91])
    frames = list(night_frames(sleeper, night_positions(hours, seed), rng, frame_s=frame_s))
    labels = {
        "position": np.array([f.position for f in frames]),
        "side": np.array([f.side for f in frames]),
        "hold": np.array([f.side not in ("out", "transition") for f in frames]),
    }
    mat = night_mat(spacer, mat_seed)
    scan = mat.scan(np.array([f.t for f in frames]), np.vstack([f.pressure for f in frames]))
    meta = {"source": f"virtual night ({sleeper.name}, {spacer}, {hours:g} h)", "spacer": spacer}
    raw = scan.capacitance._with(labels=labels, meta={**scan.capacitance.meta, **meta})
    truth = scan.pressure._with(labels=dict(labels), meta={**scan.pressure.meta, **meta})
    return Night(raw, truth, sleeper, spacer)
