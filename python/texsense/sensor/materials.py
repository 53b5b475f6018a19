"""The spacer materials: the parameters of the virtual sensor's spacer laws and the presets
that name them (``textile-3mm``, ``textile-6mm``, ``foam-7mm``, ``foam-9mm``, ``foam-13mm``,
``bouc-wen-6mm``, ``iwan-6mm``).

One place for what both the simulator and the calibration need to know of a material: the
simulator (:mod:`texsense.sim.spacer`, :mod:`texsense.sim.iwan`) drives these laws, the
calibration (:mod:`texsense.calibration`, ``texsense calibrate mat --material PRESET``, the
monitor's calibration panel) offers the presets by name and their thickness. The laws
themselves (how a material responds) are the simulator's: here are only their parameters.

Presets follow thesis §2.3.3 (the compression at which the loading curve reaches the quoted
pressure is 50 %): textile spacers of 3 mm (1.8 N/cm²) and 6 mm (2.3 N/cm²), PU foams of
7 mm and 13 mm (2.0 N/cm²) and a 9 mm foam (1.7 N/cm²) that keeps a permanent set of
0.6-0.8 mm after a compression and recovers over hours; two laws of other families for
generalisation checks (Bouc–Wen, Iwan). A real material measured on a test machine is not a
preset: its record is given to ``calibrate mat --material RECORD`` (docs/calibration.md).

Examples
--------
>>> sorted(PRESETS)[:3]
['bouc-wen-6mm', 'foam-13mm', 'foam-7mm']
>>> PRESETS["textile-3mm"].thickness_mm
3.0
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from texsense.exceptions import ParameterError

__all__ = ["PRESETS", "BoucWenMaterial", "IwanMaterial", "Material", "SpacerMaterial"]


def _check_material(m: SpacerMaterial | BoucWenMaterial) -> None:
    """The checks every spacer material shares (its law's own are in the core)."""
    if not m.thickness_mm > 0:
        raise ParameterError(f"{m.name}: thickness must be > 0 mm, got {m.thickness_mm}")
    if not m.p50_ncm2 > 0:
        raise ParameterError(f"{m.name}: p50 must be > 0 N/cm², got {m.p50_ncm2}")
    if not 0.5 < m.densification < 1.0:
        raise ParameterError(f"{m.name}: densification must lie in (0.5, 1), got {m.densification}")
    if not 0 <= m.variation < 0.5:
        raise ParameterError(f"{m.name}: variation must lie in [0, 0.5)")


@dataclass(frozen=True)
class SpacerMaterial:
    """Parameters of a spacer material (see the module docstring and spacer.rs).

    Stresses are in N/cm², compressions in fractions of the thickness, times in s.
    """

    name: str
    thickness_mm: float
    p50_ncm2: float
    densification: float = 0.86
    backbone_m: float = 1.25
    linear_share: float = 0.15
    friction: tuple[tuple[float, float], ...] = ((0.09, 0.004), (0.14, 0.012), (0.14, 0.024))
    creep_a: float = 0.0
    creep_tc: float = 1.0
    rest_rate: float = 1e-7
    clutch: tuple[float, float] = (0.3, 0.108)
    viscous: tuple[tuple[float, float], ...] = ((0.01, 0.1), (0.01, 1.0), (0.005, 10.0))
    kelvin: tuple[tuple[float, float], ...] = ()
    recovery_factor: float = 3.0
    softening: tuple[tuple[float, float], ...] = ((0.03, 0.01), (0.05, 0.001))
    softening_recovery_s: float = 3.0 * 3600.0
    description: str = ""
    variation: float = 0.05  # relative specimen-to-specimen spread (1 sigma)

    @property
    def friction_share(self) -> float:
        """Share φ of the backbone stress carried by friction when fully dragged."""
        return float(sum(w for w, _ in self.friction))

    def backbone_amplitude(self) -> tuple[float, float]:
        """Backbone amplitude A and linear stiffness E_lin so that the loading curve (friction
        fully dragged) passes through p50 at 50 % compression."""
        e = 0.5
        shape = (e / (self.densification - e)) ** self.backbone_m
        total = self.p50_ncm2 / ((1.0 + self.friction_share) * (1.0 + self.clutch[0]))
        linear = self.linear_share * total / e
        amplitude = (1.0 - self.linear_share) * total / shape
        return amplitude, linear

    def validate(self) -> None:
        """Raise :class:`ParameterError` on a bad value (before the core sees it)."""
        _check_material(self)

    def varied(self, rng: np.random.Generator) -> SpacerMaterial:
        """One batch of the material: friction and creep varied by ``variation`` (1 sigma)."""
        f = float(np.exp(rng.normal(0.0, self.variation)))
        return replace(
            self,
            friction=tuple((w * f, r) for w, r in self.friction),
            creep_a=self.creep_a * float(np.exp(rng.normal(0.0, self.variation))),
            clutch=(
                self.clutch[0],
                self.clutch[1] * float(np.exp(rng.normal(0.0, self.variation))),
            ),
        )


@dataclass(frozen=True)
class BoucWenMaterial:
    """A spacer of the second law (``crates/core/src/bouc_wen.rs``): exponential backbone,
    Bouc–Wen friction, Norton (power-law) creep that runs on time, moving or not. Another
    family than the first law and than the compensation's models; used to check that results
    do not depend on one simulator.

    Stresses in N/cm², compressions in fractions of the thickness, times in s.
    """

    name: str
    thickness_mm: float
    p50_ncm2: float
    densification: float = 0.85
    exponent: float = 6.0
    friction: float = 0.35
    slip: float = 0.015
    bw_n: float = 1.5
    bw_beta: float = 0.6
    creep_share: float = 0.3
    creep_rate: float = 1e-3
    creep_exponent: float = 2.0
    description: str = ""
    variation: float = 0.05

    def stiffness(self) -> float:
        """Backbone stiffness E so that the loading curve passes through p50 at 50 %."""
        return self.p50_ncm2 / (
            (1.0 + self.friction) * (1.0 + self.creep_share) * (np.exp(0.5 * self.exponent) - 1)
        )

    def validate(self) -> None:
        """Raise :class:`ParameterError` on a bad value (before the core sees it)."""
        _check_material(self)

    def varied(self, rng: np.random.Generator) -> BoucWenMaterial:
        """One batch of the material: friction and creep rate varied by ``variation``."""
        return replace(
            self,
            friction=self.friction * float(np.exp(rng.normal(0.0, self.variation))),
            creep_rate=self.creep_rate * float(np.exp(rng.normal(0.0, self.variation))),
        )


@dataclass(frozen=True)
class IwanMaterial:
    """Parameters of the Iwan spacer law (see the module docstring)."""

    name: str
    thickness_mm: float
    p50_ncm2: float
    densification: float = 0.85
    cubic: float = 4.0
    # (stiffness as a share of E, slip strength as a share of p50) per Jenkins element
    elements: tuple[tuple[float, float], ...] = (
        (12.0, 0.01),
        (6.0, 0.02),
        (3.0, 0.03),
        (1.5, 0.04),
        (0.7, 0.05),
    )
    base_load: float = 0.3
    stiffening_strain: float = 0.35
    relax_s: float = 2000.0
    relax_exponent: float = 4.0
    description: str = ""
    variation: float = 0.05

    def stiffness(self) -> float:
        """Backbone modulus E so that the loading curve from rest passes through p50 at 50 %
        (elements all slipping forwards carry Σ τ_i (b p50 + σ_b))."""
        e = 0.5
        share = sum(t for _, t in self.elements)
        backbone = (self.p50_ncm2 - share * self.base_load * self.p50_ncm2) / (1 + share)
        shape = e * (1 + self.cubic * e * e) / (1 - e / self.densification)
        return backbone / shape

    def validate(self) -> None:
        """Raise :class:`ParameterError` on a bad value."""
        if not self.thickness_mm > 0 or not self.p50_ncm2 > 0:
            raise ParameterError(f"{self.name}: thickness and p50 must be > 0")
        if not 0.5 < self.densification < 1.0:
            raise ParameterError(f"{self.name}: densification must lie in (0.5, 1)")
        if not 0 <= self.variation < 0.5:
            raise ParameterError(f"{self.name}: variation must lie in [0, 0.5)")
        if not self.elements or any(k <= 0 or t <= 0 for k, t in self.elements):
            raise ParameterError(f"{self.name}: element stiffness and strength must be > 0")
        if not self.relax_s > 0 or self.relax_exponent < 0:
            raise ParameterError(f"{self.name}: relax_s must be > 0 and the exponent >= 0")

    def varied(self, rng: np.random.Generator) -> IwanMaterial:
        """One batch: slip strengths and relaxation time varied by ``variation``."""
        f = float(np.exp(rng.normal(0.0, self.variation)))
        return replace(
            self,
            elements=tuple((k, t * f) for k, t in self.elements),
            relax_s=self.relax_s * float(np.exp(rng.normal(0.0, self.variation))),
        )


#: Any spacer material.
Material = SpacerMaterial | BoucWenMaterial | IwanMaterial

#: The presets by name.
PRESETS: dict[str, Material] = {
    m.name: m
    for m in (
        SpacerMaterial(
            "textile-3mm",
            3.0,
            1.8,
            description="3D knit polyester spacer fabric, 3 mm (Müller Textil), 50 % at 1.8 N/cm²",
        ),
        SpacerMaterial(
            "textile-6mm",
            6.0,
            2.3,
            description="3D knit polyester spacer fabric, 6 mm (Müller Textil), 50 % at 2.3 N/cm²",
        ),
        SpacerMaterial(
            "foam-7mm",
            7.0,
            2.0,
            friction=((0.04, 0.008), (0.05, 0.02), (0.05, 0.05)),
            creep_a=0.12,
            kelvin=((0.004, 300.0), (0.006, 3000.0)),
            description="soft open-cell PU foam, 7 mm, 50 % at 2.0 N/cm², small hysteresis",
        ),
        SpacerMaterial(
            "foam-13mm",
            13.0,
            2.0,
            friction=((0.08, 0.006), (0.11, 0.02), (0.11, 0.05)),
            creep_a=0.12,
            kelvin=((0.004, 300.0), (0.006, 3000.0)),
            description="soft PU foam, 13 mm, 50 % at 2.0 N/cm², large hysteresis",
        ),
        SpacerMaterial(
            "foam-9mm",
            9.0,
            1.7,
            friction=((0.02, 0.006), (0.03, 0.02), (0.03, 0.05)),
            creep_a=0.12,
            kelvin=((0.16, 4.0),),
            recovery_factor=720.0,
            description="open-cell foam, 9 mm, 50 % at 1.7 N/cm²; after a compression it "
            "recovers only to 8.2-8.4 mm, and to > 8.9 mm after hours",
        ),
        BoucWenMaterial(
            "bouc-wen-6mm",
            6.0,
            2.3,
            description="second law (Bouc–Wen friction, Norton creep on time), 6 mm, 50 % at "
            "2.3 N/cm²: a spacer of another family for generalisation checks",
        ),
        IwanMaterial(
            "iwan-6mm",
            6.0,
            2.3,
            description="third law (Iwan bank of Jenkins elements with stiffening springs on a "
            "stiffening backbone, viscoplastic relaxation), 6 mm, 50 % at 2.3 N/cm²: a spacer "
            "of neither the textile nor the Bouc–Wen family, for generalisation checks",
        ),
    )
}
