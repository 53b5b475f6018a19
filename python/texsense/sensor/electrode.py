"""Capacitance of a textile sensor element (thesis eq. 2.1, §2.3.2, §3.4).

``C = ε0 εr(c) A / d`` with the spacer's remaining thickness ``d`` and a relative permittivity
that rises as air is pressed out of the spacer: 1.14 unloaded and 1.6 at 30 % of the thickness
for the 6 mm textile spacer (fig. 3.17). We use

    εr(c) = 1 + (εr0 - 1) (1 - c)^(-k),   k = 1.21,

which passes through both measured points (c = compression / thickness). The field that
bulges out at the electrode edges adds to the plate capacitance; Palmer's correction for a
square plate of side w, ``(1 + d / (π w) (1 + ln(2π w / d)))²``, accounts for it, and a small
stray capacitance (embroidered lines next to the electrode) is added in parallel. For 2 x 2 cm
electrodes this gives 2.0-7.4 pF on the 3 mm spacer and 1.3-4.2 pF on the 6 mm spacer between
unloaded and 70 % compression, plus 0.5 pF stray — the 2.5-8 pF of §3.1.

A wet spacer follows eq. 3.22, ``εr(wet) = εr(dry) (1 - Vw) + εr(water) Vw``, with the water
content rising as air is pressed out (``Vw ∝ (1 - c)^-0.51``); the default 0.275 % water gives
the measured capacitance ratios wet/dry of 1.19 unloaded and 1.25 at 30 % thickness (fig. 3.18).
Drying is exponential in time.

Examples
--------
>>> e = Electrode(side_cm=2.0)
>>> [round(float(v), 2) for v in e.capacitance_pF(3.0, [0.0, 2.1])]
[2.52, 7.91]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError

__all__ = ["EPSILON_0_PF_PER_MM", "EPS_WATER", "Electrode", "permittivity", "wet_factor"]

#: Vacuum permittivity in pF/mm.
EPSILON_0_PF_PER_MM = 8.8541878128e-3
#: Relative permittivity of water (eq. 3.22).
EPS_WATER = 80.0
#: Exponent k of the permittivity-compression curve, fitted to fig. 3.17 (1.14 -> 1.6 at 30 %).
PERMITTIVITY_EXPONENT = float(np.log(0.6 / 0.14) / np.log(1 / 0.3))
#: Exponent of the water content with compression, fitted to fig. 3.18 (1.19 -> 1.25).
WATER_EXPONENT = 0.513


def permittivity(
    compression_fraction: npt.ArrayLike, eps_r0: float = 1.14
) -> npt.NDArray[np.float64]:
    """Relative permittivity of the dry spacer at a compression (fraction of thickness)."""
    c = np.asarray(compression_fraction, dtype=np.float64)
    if np.any((c < 0) | (c >= 1)):
        raise ParameterError("compression must lie in [0, 1) of the thickness")
    return 1.0 + (eps_r0 - 1.0) * (1.0 - c) ** (-PERMITTIVITY_EXPONENT)


def wet_factor(
    compression_fraction: npt.ArrayLike, water_fraction: npt.ArrayLike, eps_r0: float = 1.14
) -> npt.NDArray[np.float64]:
    """εr(wet) / εr(dry) for a spacer holding ``water_fraction`` (by volume, unloaded), eq. 3.22."""
    c = np.asarray(compression_fraction, dtype=np.float64)
    dry = permittivity(c, eps_r0)
    vw = np.clip(np.asarray(water_fraction) * (1.0 - c) ** (-WATER_EXPONENT), 0.0, 1.0)
    return (dry * (1.0 - vw) + EPS_WATER * vw) / dry


@dataclass(frozen=True)
class Electrode:
    """A square electrode over the spacer (single-electrode architecture, §2.3.2.2).

    Parameters
    ----------
    side_cm : float
        Electrode side (the thesis's prototypes: 2 cm).
    eps_r0 : float
        Relative permittivity of the unloaded spacer (1.14 for the textile spacer).
    fringe : bool
        Add Palmer's edge-field correction.
    stray_pF : float
        Capacitance in parallel (lines, embroidery), pF.
    """

    side_cm: float = 2.0
    eps_r0: float = 1.14
    fringe: bool = True
    stray_pF: float = 0.5

    def __post_init__(self) -> None:
        if not self.side_cm > 0:
            raise ParameterError(f"electrode side must be > 0 cm, got {self.side_cm}")
        if not self.eps_r0 >= 1.0:
            raise ParameterError(f"eps_r0 must be >= 1, got {self.eps_r0}")
        if not self.stray_pF >= 0:
            raise ParameterError(f"stray capacitance must be >= 0 pF, got {self.stray_pF}")

    @property
    def area_cm2(self) -> float:
        """Electrode area in cm²."""
        return self.side_cm**2

    def capacitance_pF(
        self,
        thickness_mm: float,
        compression_mm: npt.ArrayLike,
        water_fraction: npt.ArrayLike = 0.0,
    ) -> npt.NDArray[np.float64]:
        """Capacitance in pF at a spacer compression (mm), eq. 2.1 with §3.4's permittivity.

        Raises
        ------
        ParameterError
            For a non-positive thickness or a compression outside [0, thickness).
        """
        if not thickness_mm > 0:
            raise ParameterError(f"spacer thickness must be > 0 mm, got {thickness_mm}")
        comp = np.asarray(compression_mm, dtype=np.float64)
        if np.any((comp < 0) | (comp >= thickness_mm)) or not np.all(np.isfinite(comp)):
            raise ParameterError(
                f"compression must lie in [0, {thickness_mm}) mm for a {thickness_mm} mm spacer"
            )
        c = comp / thickness_mm
        d = thickness_mm - comp
        w = self.side_cm * 10.0
        eps = permittivity(c, self.eps_r0)
        if np.any(water_fraction):
            eps = eps * wet_factor(c, water_fraction, self.eps_r0)
        plate = EPSILON_0_PF_PER_MM * eps * w * w / d
        if self.fringe:
            plate = plate * (1.0 + d / (np.pi * w) * (1.0 + np.log(2.0 * np.pi * w / d))) ** 2
        return plate + self.stray_pF
