"""Test-machine protocols of the thesis, run on the virtual spacer and read out as a sensor.

Each protocol drives a :class:`~texsense.sim.machine.TestMachine`, then samples the record at
``sample_hz`` (default 10 Hz) and reads the element's capacitance through the electrode model
and the AD7745-class converter. It returns a one-element :class:`~texsense.Recording` of the
measured capacitance (pF) whose labels hold the ground truth: ``pressure_ncm2``,
``compression_mm`` (the specimen's own), ``platen_mm`` and ``segment``.

============== =============================================================== ===========
protocol       what                                                            thesis
============== =============================================================== ===========
``ramp``       0 -> max -> 0 at a given speed (default 10 N/cm², 10 mm/min)      §4.1
``calibration`` rising curve to max, falling curves from 100/70/30 % of max     §4.4.2
``validation`` 0 -> 10 -> 1.3 -> 10 -> 0 -> 1.3 -> 0 N/cm², repeated 50 times   §4.5
``steps``      steps to 2.5/5/7.5/10 N/cm² (fresh specimen each), held 1 h      §5.1.2
``cyclic``     0 <-> p3 for 4 h                                                 §5.1.2.2, §5.3
``random``     band-limited random pressure (pressure controlled)               —
``sawtooth``   ramps to random levels at constant speed (nested minor loops)    —
============== =============================================================== ===========
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from texsense.data.layout import Layout
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError
from texsense.sensor.electrode import Electrode
from texsense.sensor.readout import CDC
from texsense.sim.machine import TestMachine
from texsense.sim.spacer import DriveResult, Spacer

__all__ = [
    "PROTOCOLS",
    "calibration",
    "cyclic",
    "loads",
    "ramp",
    "random_pressure",
    "run_protocol",
    "steps",
    "validation",
]


def _read_out(
    traces: Sequence[DriveResult],
    spacer: Spacer,
    *,
    sample_hz: float | None,
    electrode: Electrode,
    cdc: CDC,
    seed: int | None,
    meta: dict[str, Any],
) -> Recording:
    """Sample the machine traces, convert compression to capacitance and read it out."""
    rng = np.random.default_rng(seed)
    times, pressure, comp, platen, segment = [], [], [], [], []
    for k, tr in enumerate(traces):
        spec = tr.meta["specimen_compression_mm"]
        if sample_hz is None:
            t = tr.times_s
        else:
            if not sample_hz > 0:
                raise ParameterError(f"sample_hz must be > 0, got {sample_hz}")
            t = np.arange(tr.times_s[0], tr.times_s[-1] + 0.5 / sample_hz, 1.0 / sample_hz)
            t = t[t <= tr.times_s[-1]]
        times.append(t)
        pressure.append(np.interp(t, tr.times_s, tr.pressure_ncm2))
        comp.append(np.interp(t, tr.times_s, spec))
        platen.append(np.interp(t, tr.times_s, tr.compression_mm))
        segment.append(np.full(t.size, k, dtype=np.int32))
    t = np.concatenate(times)
    compression = np.concatenate(comp)
    true_c = electrode.capacitance_pF(spacer.thickness_mm, compression)
    _, measured, saturated = cdc.convert(true_c, rng, cdc.channel_offsets(1, rng))
    layout = Layout.points(
        [[electrode.side_cm / 2, electrode.side_cm / 2]], size_cm=electrode.side_cm
    )
    return Recording(
        measured[:, None],
        t,
        layout,
        "capacitance",
        "pF",
        valid=~saturated[:, None],
        labels={
            "pressure_ncm2": np.concatenate(pressure),
            "compression_mm": compression,
            "platen_mm": np.concatenate(platen),
            "segment": np.concatenate(segment),
        },
        meta={
            "source": "texsense virtual sensor",
            "spacer": spacer.material.name,
            "thickness_mm": spacer.thickness_mm,
            "seed": seed,
            "electrode_side_cm": electrode.side_cm,
            "cdc_rate_hz": cdc.rate_hz,
            "capdac_pF": cdc.capdac_effective_pF,
            **meta,
        },
    )


def ramp(
    spacer: Spacer, *, max_ncm2: float = 10.0, speed_mm_min: float = 10.0, cycles: int = 1
) -> list[DriveResult]:
    """0 -> max -> 0 at constant platen speed, ``cycles`` times (§4.1, fig. 4.1/4.3)."""
    m = TestMachine(spacer)
    for _ in range(cycles):
        m.ramp_to_pressure(max_ncm2, speed_mm_min).ramp_to_pressure(0.0, speed_mm_min)
    return [m.trace()]


def calibration(
    spacer: Spacer,
    *,
    max_ncm2: float = 10.0,
    speed_mm_min: float = 10.0,
    falling_from: Sequence[float] = (1.0, 0.7, 0.3),
) -> list[DriveResult]:
    """The thesis's identification record (§4.4.2): the rising curve to ``max_ncm2`` and
    falling curves to 0 from 100, 70 and 30 % of the maximum."""
    m = TestMachine(spacer)
    for share in falling_from:
        if not 0 < share <= 1:
            raise ParameterError(f"falling_from shares must lie in (0, 1], got {share}")
        m.ramp_to_pressure(share * max_ncm2, speed_mm_min).ramp_to_pressure(0.0, speed_mm_min)
    return [m.trace()]


def validation(
    spacer: Spacer,
    *,
    cycles: int = 50,
    speed_mm_min: float = 50.0,
    path: Sequence[float] = (10.0, 1.3, 10.0, 0.0, 1.3, 0.0),
) -> list[DriveResult]:
    """The validation cycle of §4.5: 0 -> 10 -> 1.3 -> 10 -> 0 -> 1.3 -> 0 N/cm², repeated."""
    m = TestMachine(spacer)
    for _ in range(cycles):
        for target in path:
            m.ramp_to_pressure(target, speed_mm_min)
    return [m.trace()]


def steps(
    spacer: Spacer,
    *,
    levels: Sequence[float] = (2.5, 5.0, 7.5, 10.0),
    hold_s: float = 3600.0,
    speed_mm_min: float = 50.0,
    falling: bool = False,
    start_ncm2: float = 10.0,
    prehold_s: float = 3600.0,
    gap_s: float = 60.0,
) -> list[DriveResult]:
    """Step-and-hold at constant compression (§5.1.2): one fresh specimen per level; rising
    steps from 0 to each level, or (``falling``) steps down to each level from ``start_ncm2``
    after holding that compression for ``prehold_s`` (as the thesis held the compression for
    an hour before its second steps)."""
    out = []
    offset = 0.0
    for level in levels:
        spacer.reset()
        m = TestMachine(spacer)
        if falling:
            m.ramp_to_pressure(start_ncm2, speed_mm_min).hold_compression(prehold_s)
        m.ramp_to_pressure(level, speed_mm_min).hold_compression(hold_s, sample_s=None)
        tr = m.trace()
        tr.times_s = tr.times_s + offset
        offset = float(tr.times_s[-1]) + gap_s
        tr.meta["level_ncm2"] = level
        out.append(tr)
    return out


def loads(
    spacer: Spacer,
    *,
    levels: Sequence[float] = (2.0, 2.0, 2.0, 2.0),
    hold_s: float = 1500.0,
    rest_s: float = 600.0,
    speed_mm_min: float = 50.0,
) -> list[DriveResult]:
    """Held loads, like sitting bouts: for each level, ramp to it, hold the *load* for
    ``hold_s`` (pressure control: the spacer creeps), unload and rest ``rest_s`` at zero
    compression. A mat in use is load-controlled; its drift is identified on this record plus
    cycles (docs/drift.md), not on held compressions."""
    m = TestMachine(spacer)
    for level in levels:
        if not level > 0:
            raise ParameterError(f"load levels must be > 0 N/cm², got {level}")
        m.ramp_to_pressure(level, speed_mm_min).hold_pressure(hold_s, sample_s=1.0)
        m.ramp_to_pressure(0.0, speed_mm_min).hold_compression(rest_s, sample_s=1.0)
    return [m.trace()]


def cyclic(
    spacer: Spacer,
    *,
    p3_ncm2: float = 5.0,
    duration_s: float = 4 * 3600.0,
    speed_mm_min: float = 10.0,
) -> list[DriveResult]:
    """Cyclic compression 0 <-> p3 at constant speed for ``duration_s`` (§5.1.2.2, §5.3)."""
    m = TestMachine(spacer)
    while m.time_s < duration_s:
        m.ramp_to_pressure(p3_ncm2, speed_mm_min).ramp_to_pressure(0.0, speed_mm_min)
    return [m.trace()]


def random_pressure(
    spacer: Spacer,
    *,
    duration_s: float = 600.0,
    max_ncm2: float = 8.0,
    cutoff_hz: float = 0.05,
    dt_s: float = 0.05,
    seed: int | None = 0,
) -> list[DriveResult]:
    """Band-limited random pressure between 0 and ``max_ncm2`` (pressure controlled)."""
    if not (duration_s > 0 and max_ncm2 > 0 and cutoff_hz > 0 and dt_s > 0):
        raise ParameterError("duration, max pressure, cutoff and dt must be > 0")
    rng = np.random.default_rng(seed)
    n = int(duration_s / dt_s) + 1
    spectrum = np.fft.rfft(rng.standard_normal(n))
    freqs = np.fft.rfftfreq(n, dt_s)
    spectrum[freqs > cutoff_hz] = 0.0
    x = np.fft.irfft(spectrum, n)
    x = (x - x.min()) / (np.ptp(x) or 1.0) * max_ncm2
    t = np.asarray(np.arange(n) * dt_s, dtype=np.float64)
    r = spacer.drive_pressure(t, x)
    return [
        DriveResult(
            t,
            r.compression_mm[:, 0],
            np.asarray(x, dtype=np.float64),
            {"specimen_compression_mm": r.compression_mm[:, 0]},
        )
    ]


def sawtooth(
    spacer: Spacer,
    *,
    reversals: int = 60,
    max_ncm2: float = 10.0,
    speed_mm_min: float = 50.0,
    seed: int | None = 0,
) -> list[DriveResult]:
    """Random-amplitude sawtooth: alternating ramps to random pressures, each reversal at a
    level drawn uniformly between 0 and ``max_ncm2`` (the kind of cyclic record least-squares
    identification needs: reversals at many levels, nested minor loops)."""
    if reversals < 2:
        raise ParameterError("reversals must be >= 2")
    rng = np.random.default_rng(seed)
    m = TestMachine(spacer)
    m.ramp_to_pressure(max_ncm2, speed_mm_min).ramp_to_pressure(0.0, speed_mm_min)
    level = 0.0
    for k in range(reversals):
        if k % 2 == 0:
            level = float(rng.uniform(level, max_ncm2))
        else:
            level = float(rng.uniform(0.0, level))
        m.ramp_to_pressure(level, speed_mm_min)
    m.ramp_to_pressure(0.0, speed_mm_min)
    return [m.trace()]


PROTOCOLS: dict[str, Callable[..., list[DriveResult]]] = {
    "ramp": ramp,
    "calibration": calibration,
    "validation": validation,
    "steps": steps,
    "loads": loads,
    "cyclic": cyclic,
    "random": random_pressure,
    "sawtooth": sawtooth,
}


def run_protocol(
    name: str,
    spacer: str | Spacer = "textile-6mm",
    *,
    seed: int | None = 0,
    sample_hz: float | None = 10.0,
    electrode: Electrode | None = None,
    cdc: CDC | None = None,
    **options: Any,
) -> Recording:
    """Run a protocol by name and read it out as a one-element capacitance recording.

    Parameters
    ----------
    name : str
        One of :data:`PROTOCOLS`.
    spacer : str or Spacer
        A preset name or a single-specimen :class:`Spacer`.
    seed : int, optional
        Specimen variation and readout noise seed.
    sample_hz : float, optional
        Output sample rate; None keeps the machine's own (irregular) samples.
    electrode, cdc : optional
        Electrode and converter (defaults: 2 x 2 cm electrode, AD7745 at 83.8 Hz with the
        CAPDAC centred on the spacer's capacitance range).
    **options
        Protocol parameters (``max_ncm2``, ``speed_mm_min``, ``cycles``, ``levels``, ...).

    Examples
    --------
    >>> rec = run_protocol("ramp", "textile-6mm", speed_mm_min=50, sample_hz=None)
    >>> rec.quantity, rec.unit, round(float(rec.labels["pressure_ncm2"].max()))
    ('capacitance', 'pF', 10)
    """
    if name not in PROTOCOLS:
        raise ParameterError(f"unknown protocol {name!r}; known: {', '.join(PROTOCOLS)}")
    sp = Spacer.preset(spacer, seed=seed) if isinstance(spacer, str) else spacer
    electrode = electrode or Electrode()
    if cdc is None:
        lo, hi = electrode.capacitance_pF(sp.thickness_mm, [0.0, 0.8 * sp.max_compression_mm])
        cdc = CDC(capdac_pF=float(np.clip((lo + hi) / 2, 0.0, 17.0)))
    try:
        traces = PROTOCOLS[name](sp, **options)
    except TypeError as e:
        raise ParameterError(f"protocol {name!r}: {e}") from None
    return _read_out(
        traces,
        sp,
        sample_hz=sample_hz,
        electrode=electrode,
        cdc=cdc,
        seed=seed,
        meta={
            "protocol": name,
            "options": {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()},
        },
    )
