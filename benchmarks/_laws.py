"""Spacer laws texsense never saw, for the identification benchmarks: variants of the three
laws of the virtual sensor (the textile law of ``crates/core/src/spacer.rs``, Bouc–Wen,
the Iwan bank of ``texsense.sim.iwan``) with their parameters drawn at random from wide
ranges by a fixed seed. No rule of the identification was chosen on them: the seeds and
ranges were fixed before any of them was run (docs/hysteresis.md, "Laws texsense never
saw"). :data:`DEVELOPMENT` are the hand-made variants on which the default's tail rule
(issue 37) was chosen: they are reported apart.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from texsense.data.recording import Recording
from texsense.exceptions import ParameterError
from texsense.sim import protocols
from texsense.sim.iwan import IwanMaterial
from texsense.sim.spacer import PRESETS, BoucWenMaterial, Spacer, SpacerMaterial

Material = SpacerMaterial | BoucWenMaterial | IwanMaterial

#: The draws of the benchmark: (family, seed).
DRAWS: tuple[tuple[str, int], ...] = tuple(
    (family, seed) for family in ("textile", "bouc-wen", "iwan") for seed in range(1, 10)
)


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def draw_law(family: str, rng: np.random.Generator) -> Material:
    """One material of ``family`` with parameters drawn from wide ranges around the preset."""
    name = f"{family}-drawn"
    if family == "textile":
        base = PRESETS["textile-6mm"]
        friction = tuple(
            (_log_uniform(rng, 0.03, 0.25), _log_uniform(rng, 0.002, 0.06))
            for _ in range(int(rng.integers(2, 5)))
        )
        return replace(
            base,
            name=name,
            friction=friction,
            backbone_m=float(rng.uniform(0.9, 1.8)),
            linear_share=float(rng.uniform(0.05, 0.35)),
            densification=float(rng.uniform(0.8, 0.9)),
            clutch=(float(rng.uniform(0.1, 0.6)), _log_uniform(rng, 0.05, 0.3)),
        )
    if family == "bouc-wen":
        return replace(
            PRESETS["bouc-wen-6mm"],
            name=name,
            exponent=float(rng.uniform(5.0, 9.0)),
            friction=float(rng.uniform(0.15, 0.6)),
            slip=_log_uniform(rng, 0.005, 0.04),
            bw_n=float(rng.uniform(1.0, 3.0)),
            bw_beta=float(rng.uniform(0.2, 0.9)),
            creep_share=float(rng.uniform(0.05, 0.4)),
        )
    if family == "iwan":
        elements = tuple(
            (_log_uniform(rng, 0.5, 20.0), _log_uniform(rng, 0.005, 0.08))
            for _ in range(int(rng.integers(2, 7)))
        )
        return replace(
            PRESETS["iwan-6mm"],
            name=name,
            elements=elements,
            base_load=float(rng.uniform(0.1, 0.6)),
            stiffening_strain=float(rng.uniform(0.2, 0.6)),
            cubic=float(rng.uniform(1.0, 6.0)),
        )
    raise ParameterError(f"unknown law family {family!r}")


def held_out_law(family: str, seed: int) -> tuple[Material, Recording, Recording, Recording]:
    """The material of draw ``seed`` of ``family`` and its thesis calibration record and 10
    validation cycles (§4.5) of the same and of another specimen; a draw whose spacer does
    not reach 10 N/cm² before densification is drawn again (same generator)."""
    rng = np.random.default_rng([seed, ("textile", "bouc-wen", "iwan").index(family)])
    for _ in range(20):
        material = draw_law(family, rng)
        try:
            return (material, *records(material))
        except ParameterError:
            continue
    raise ParameterError(f"no usable draw of {family} for seed {seed}")


def _development() -> dict[str, Material]:
    text, bw, iwan = PRESETS["textile-6mm"], PRESETS["bouc-wen-6mm"], PRESETS["iwan-6mm"]
    assert isinstance(text, SpacerMaterial) and isinstance(bw, BoucWenMaterial)
    assert isinstance(iwan, IwanMaterial)
    return {
        "textile-v1": replace(
            text, name="textile-v1", friction=((0.05, 0.002), (0.1, 0.02), (0.2, 0.05)),
            clutch=(0.5, 0.2), backbone_m=1.6,
        ),
        "textile-v2": replace(
            text, name="textile-v2", friction=((0.15, 0.003), (0.2, 0.03)), backbone_m=1.0,
            linear_share=0.3, densification=0.8,
        ),
        "bouc-wen-v1": replace(
            bw, name="bouc-wen-v1", friction=0.5, slip=0.03, bw_n=1.0, bw_beta=0.3,
        ),
        "bouc-wen-v2": replace(
            bw, name="bouc-wen-v2", exponent=8.0, friction=0.25, slip=0.005, bw_n=2.0,
            bw_beta=0.9, creep_share=0.1,
        ),
        "iwan-v1": replace(
            iwan, name="iwan-v1",
            elements=((20.0, 0.005), (8.0, 0.015), (2.0, 0.04), (0.5, 0.08)),
            base_load=0.1, stiffening_strain=0.25, cubic=2.0,
        ),
        "iwan-v2": replace(
            iwan, name="iwan-v2", elements=((5.0, 0.02), (1.0, 0.06)), base_load=0.5,
            stiffening_strain=0.5, relax_s=500.0,
        ),
    }  # fmt: skip


#: Hand-made variants of the three laws, on which the tail rule of issue 37 was chosen.
DEVELOPMENT: dict[str, Material] = _development()


def records(material: Material) -> tuple[Recording, Recording, Recording]:
    """The thesis calibration of specimen 0 and 10 validation cycles (§4.5) of specimen 0
    (rested) and of specimen 1, as the generalisation benchmark runs them."""
    sp0, sp1 = Spacer(material, 1, seed=0), Spacer(material, 1, seed=1)
    cal = protocols.run_protocol("calibration", sp0, seed=0, sample_hz=None)
    sp0.reset()
    val0 = protocols.run_protocol("validation", sp0, seed=0, sample_hz=None, cycles=10)
    val1 = protocols.run_protocol("validation", sp1, seed=1, sample_hz=None, cycles=10)
    return cal, val0, val1
