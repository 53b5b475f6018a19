"""A lying person on a virtual bed mat: the station's virtual bed mats (docs/station.md).

A simple figure, not the virtual bed of issue 17: supine, left and right lateral, each a sum of
Gaussian pressure blobs over the body's bony prominences (occiput, scapulae, sacrum, buttocks,
calves and heels lying on the back; head, shoulder, trochanter, knee and ankle on the side), on
a 32 x 16 mat of 5 cm elements (160 x 80 cm, the area of a common 64 x 32 bed mat at half its
resolution), scaled so that the total force is the body weight. The peaks come out as
interface pressures on a standard mattress do: about 80 mmHg at the sacrum lying on the back,
100 mmHg at the trochanter on the side.

Examples
--------
>>> from texsense.sim.bed import bed_layout, lying_pressure
>>> p = lying_pressure(bed_layout(), "supine", weight=1.0)
>>> p.shape, round(float(p.sum() * 25.0)), round(float(p.max()) * 75.0)  # N, peak mmHg
((512,), 736, 79)
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError
from texsense.layout import Layout

__all__ = [
    "BED_COLS",
    "BED_PITCH_CM",
    "BED_ROWS",
    "BODY_N",
    "POSITIONS",
    "bed_layout",
    "lying_pressure",
]

BED_ROWS, BED_COLS, BED_PITCH_CM = 32, 16, 5.0
#: The weight of the model person (75 kg) in N.
BODY_N = 75.0 * 9.81

#: (y cm from the head end, x cm from the mat's centre line, σ cm, peak N/cm²) per position
_BLOBS: dict[str, list[tuple[float, float, float, float]]] = {
    "supine": [
        (14, 0, 4, 1.3),  # occiput
        (38, -10, 6, 1.0),
        (38, 10, 6, 1.0),  # scapulae
        (80, 0, 5, 2.6),  # sacrum
        (84, -9, 8, 1.0),
        (84, 9, 8, 1.0),  # buttocks
        (122, -8, 6, 0.5),
        (122, 8, 6, 0.5),  # calves
        (152, -8, 3, 2.2),
        (152, 8, 3, 2.2),  # heels
    ],
    "left": [
        (14, -4, 4, 1.1),  # head on its side
        (38, -12, 6, 1.8),  # shoulder
        (82, -13, 6, 2.7),  # trochanter
        (112, -6, 5, 1.1),  # knee
        (150, -5, 3, 1.6),  # ankle
    ],
}
_BLOBS["right"] = [(y, -x, s, p) for y, x, s, p in _BLOBS["left"]]
#: The positions a virtual person lies in.
POSITIONS = tuple(_BLOBS)


def bed_layout() -> Layout:
    """The 32 x 16 bed mat, 5 cm pitch, head end at row 0."""
    return Layout.grid(BED_ROWS, BED_COLS, pitch_cm=BED_PITCH_CM, element_size_cm=4.5)


def lying_pressure(
    layout: Layout,
    position: str,
    weight: float = 1.0,
    shift_cm: npt.ArrayLike = (0.0, 0.0),
) -> np.ndarray:
    """True pressure (N/cm²) of a person lying in ``position`` (see :data:`POSITIONS`), body
    weight relative to the model (1 = 75 kg, 736 N on the mat: the blobs give the shape, the
    total force is the body weight), shifted by (along, across) cm."""
    if position not in _BLOBS:
        raise ParameterError(f"unknown position {position!r}; known: {', '.join(POSITIONS)}")
    xy = np.asarray(layout.xy_cm)
    across = xy[:, 0] - xy[:, 0].mean()
    along = xy[:, 1] - xy[:, 1].min()
    dy, dx = (float(v) for v in np.asarray(shift_cm, dtype=float))
    p = np.zeros(layout.n_elements)
    for y, x, s, peak in _BLOBS[position]:
        p += peak * np.exp(-((along - y - dy) ** 2 + (across - x - dx) ** 2) / (2 * s * s))
    cell_cm2 = BED_PITCH_CM**2  # each element stands for its cell of the mat
    return weight * BODY_N * p / (p.sum() * cell_cm2)
