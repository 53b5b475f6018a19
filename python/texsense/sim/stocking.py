"""Compression stockings on a virtual leg, read by a textile sensor strip (docs/stocking.md).

The interface pressure of an elastic garment follows Laplace's law, ``P = T / r``: the fabric's
tension per unit length ``T`` over the local radius of the limb ``r``. A stocking is knitted so
that the pressure is highest at the ankle (point B) and falls towards the knee. Here it is
given by its pressure at B and a graduated design profile at the standard measuring points:
B (ankle), B1 (where the Achilles tendon meets the calf), C (the calf at its widest), D (below
the knee). The knit's tension relaxes over a day's wear; an assumption of this model, a 3 %
loss over 8 h growing with the logarithm of time, marked as such in the docs.

A strip of four 2 x 2 cm textile elements (textile-3mm spacer) lies under the stocking, one
element at each point, read by the virtual sensor: its spacer creeps under the held load as
the thesis's does, which is what the drift compensation has to undo.

Examples
--------
>>> leg = LEGS["medium"]
>>> p = truth_mmhg(design("II", leg), leg, hours=0.0)
>>> [round(v) for v in p]
[28, 23, 19, 15]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from texsense.data.layout import Layout
from texsense.data.units import convert
from texsense.exceptions import ParameterError
from texsense.sim.mat import MatScan, VirtualMat

__all__ = [
    "DESIGN_PROFILE",
    "LEGS",
    "POINTS",
    "Leg",
    "design",
    "strip_layout",
    "truth_mmhg",
    "wear",
]

#: The standard measuring points, ankle to knee.
POINTS = ("B", "B1", "C", "D")
#: Pressure of the design at each point as a share of the pressure at B (a graduated design
#: of this model, decreasing from the ankle up).
DESIGN_PROFILE = np.array([1.0, 0.85, 0.7, 0.55])
#: Design pressure at B (mmHg) per compression class: the middle of the class's range
#: (RAL-GZ 387; class IV: 4 mmHg above its lower bound of 49).
CLASS_DESIGN_MMHG = {"I": 19.5, "II": 27.5, "III": 40.0, "IV": 53.0}
#: Relaxation of the knit's tension over 8 h of wear (an assumption of the model).
RELAXATION_8H = 0.03


@dataclass(frozen=True)
class Leg:
    """Circumferences (cm) at B, B1, C, D and their heights above the floor (cm)."""

    circumference_cm: tuple[float, float, float, float]
    height_cm: tuple[float, float, float, float] = (12.0, 24.0, 34.0, 44.0)

    @property
    def radius_cm(self) -> np.ndarray:
        """Radius of the (round) leg at each point."""
        return np.asarray(self.circumference_cm) / (2 * np.pi)


#: Three leg sizes (circumferences at B, B1, C, D in cm).
LEGS = {
    "small": Leg((20.0, 26.0, 33.0, 31.0)),
    "medium": Leg((22.0, 29.0, 37.0, 35.0)),
    "large": Leg((25.0, 33.0, 42.0, 39.0)),
}


def design(cls: str, leg: Leg) -> np.ndarray:
    """The knit's tension (N/cm) at each point that gives the class's design pressure on this
    leg: ``T = P r`` (Laplace)."""
    if cls not in CLASS_DESIGN_MMHG:
        raise ParameterError(f"unknown class {cls!r}; known: {', '.join(CLASS_DESIGN_MMHG)}")
    p_ncm2 = convert(CLASS_DESIGN_MMHG[cls] * DESIGN_PROFILE, "mmHg", "N/cm2")
    return np.asarray(p_ncm2) * leg.radius_cm


def truth_mmhg(tension: npt.ArrayLike, leg: Leg, hours: npt.ArrayLike) -> np.ndarray:
    """Interface pressure (mmHg) at the points after ``hours`` of wear: ``P = T(t) / r``
    with the knit relaxing (shape (4,) for a scalar time, (T, 4) for times)."""
    t = np.asarray(hours, dtype=np.float64)
    loss = RELAXATION_8H * np.log1p(t[..., None] / 0.25) / np.log1p(8.0 / 0.25)
    p_ncm2 = np.asarray(tension) * (1.0 - loss) / leg.radius_cm
    return np.asarray(convert(p_ncm2, "N/cm2", "mmHg"))


def strip_layout() -> Layout:
    """Four 2 x 2 cm elements along the leg, one at each point (named B, B1, C, D)."""
    leg = LEGS["medium"]
    xy = np.column_stack([np.zeros(4), np.asarray(leg.height_cm)])
    return Layout.points(xy, size_cm=2.0, names=list(POINTS))


def wear(
    cls: str, leg: Leg, *, hours: float = 8.0, frame_s: float = 10.0, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, MatScan]:
    """Put the stocking on (a 10 s ramp from nothing) and wear it for ``hours``: frame times
    (s), the true pressure (T, 4) in N/cm² and the strip's scan (a :class:`MatScan`: the
    capacitance the strip reads)."""
    if hours <= 0 or frame_s <= 0:
        raise ParameterError("hours and frame_s must be > 0")
    times = np.arange(0.0, hours * 3600.0 + frame_s / 2, frame_s)
    on = np.clip(times / 10.0, 0.0, 1.0)[:, None]  # donning
    p = convert(truth_mmhg(design(cls, leg), leg, times / 3600.0), "mmHg", "N/cm2") * on
    strip = VirtualMat(strip_layout(), "textile-3mm", seed=seed)
    return times, np.asarray(p), strip.scan(times, p)
