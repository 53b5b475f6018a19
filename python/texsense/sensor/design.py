"""Design rules of a textile capacitive pressure sensor (thesis §2.3.2, §7.2).

- capacitance of an element for an electrode and a spacer (eq. 2.1 with §3.4, see
  :mod:`texsense.sensor.electrode`);
- the smallest square electrode that keeps the capacitance above a target (§7.2: "C > 2 pF"),
  and the grid pitch it allows with the embroidery spacing (≥ 2 mm);
- the thesis's own rule of thumb, area / thickness > 1.9 cm (printed "cm⁻¹" in §7.2), which
  gives "electrodes greater than 6 mm" for a 3 mm spacer;
- connections: perpendicular stripes need ns1 + ns2 for ns1 x ns2 elements (eq. 2.2), single
  electrodes N + 1 (one common electrode);
- lines routable between two electrodes, nl = ds / dl (eq. 2.3), where a line needs the
  distance dl to each neighbour, so floor(ds / dl) - 1 lines fit (7 mm / 2 mm -> 2 lines, as
  in §2.3.2.2), and the routing layers an array needs;
- elements per update rate, n = f / fs (§7.2), times k parallel converters.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from scipy.optimize import brentq

from texsense.exceptions import ParameterError
from texsense.sensor.electrode import Electrode
from texsense.sensor.readout import CDC

__all__ = [
    "THESIS_AREA_PER_THICKNESS_CM",
    "DesignReport",
    "connections",
    "design_report",
    "elements_per_update",
    "lines_between",
    "min_electrode_side_cm",
    "routing_layers",
    "thesis_min_side_cm",
]

#: §7.2: "the ratio between the area of the electrode and thickness of the spacer has to be
#: greater than 1.9" (cm² / cm).
THESIS_AREA_PER_THICKNESS_CM = 1.9


def min_electrode_side_cm(
    thickness_mm: float, target_pF: float = 2.0, *, stray_pF: float = 0.0, eps_r0: float = 1.14
) -> float:
    """Smallest square electrode side (cm) whose unloaded capacitance reaches ``target_pF``
    with the physical model (plate + edge field + stray)."""
    if not thickness_mm > 0 or not target_pF > stray_pF:
        raise ParameterError("need thickness > 0 mm and a target above the stray capacitance")

    def excess(side: float) -> float:
        e = Electrode(side_cm=side, eps_r0=eps_r0, stray_pF=stray_pF)
        return float(e.capacitance_pF(thickness_mm, [0.0])[0]) - target_pF

    return float(brentq(excess, 1e-3, 100.0))


def thesis_min_side_cm(thickness_mm: float) -> float:
    """Electrode side from the thesis's rule area / thickness > 1.9 cm (§7.2)."""
    return math.sqrt(THESIS_AREA_PER_THICKNESS_CM * thickness_mm / 10.0)


def connections(n_elements: int = 0, stripes: tuple[int, int] | None = None) -> int:
    """Connections to the electronics: ns1 + ns2 for stripes (ns1 x ns2 elements, eq. 2.2),
    N + 1 for single electrodes with a common electrode."""
    if stripes is not None:
        ns1, ns2 = stripes
        if ns1 < 1 or ns2 < 1:
            raise ParameterError("stripe counts must be >= 1")
        return ns1 + ns2
    if n_elements < 1:
        raise ParameterError("n_elements must be >= 1")
    return n_elements + 1


def lines_between(spacing_mm: float, line_distance_mm: float = 2.0) -> int:
    """Lines routable between two electrodes ``spacing_mm`` apart (eq. 2.3 with a distance
    ``line_distance_mm`` kept on both sides of every line)."""
    if not spacing_mm > 0 or not line_distance_mm > 0:
        raise ParameterError("spacing and line distance must be > 0 mm")
    return max(0, math.floor(spacing_mm / line_distance_mm + 1e-9) - 1)


def routing_layers(rows: int, lines_per_gap: int, borders: int = 2) -> int:
    """Extra routing layers for single electrodes in ``rows`` rows.

    Each column's lines run in the gap beside it to the nearer of ``borders`` (1 or 2)
    opposite borders, as in the 240-element prototype whose connections are "mirrored in the
    middle of the array" (§2.3.2.2); the row at a border needs no line in the gap. What does
    not fit into the gap goes to extra layers of the same capacity. 15 rows with 2 lines per
    gap give 3 layers, as the thesis's 240-element seat needed.
    """
    if rows < 1:
        raise ParameterError("rows must be >= 1")
    if borders not in (1, 2):
        raise ParameterError("borders must be 1 or 2")
    needed = math.ceil(rows / borders) - 1
    if needed == 0:
        return 0
    if lines_per_gap < 1:
        raise ParameterError("no line fits between the electrodes: widen the spacing")
    return max(0, math.ceil(needed / lines_per_gap) - 1)


def elements_per_update(update_hz: float, cdc: CDC | None = None, converters: int = 1) -> int:
    """Elements that can be read at ``update_hz`` frames per second: n = k f / fs (§7.2), with
    f the converter's element rate (conversion + settling)."""
    if not update_hz > 0 or converters < 1:
        raise ParameterError("update rate must be > 0 Hz and converters >= 1")
    cdc = cdc or CDC()
    return int(converters / (update_hz * cdc.element_time_s) + 1e-9)


@dataclass(frozen=True)
class DesignReport:
    """Everything :func:`design_report` computes (all lengths in mm unless named cm)."""

    thickness_mm: float
    electrode_side_cm: float
    capacitance_unloaded_pF: float
    capacitance_70pct_pF: float
    min_side_physics_cm: float
    min_side_thesis_rule_cm: float
    min_pitch_mm: float
    rows: int
    cols: int
    connections_single: int
    connections_stripes: int
    lines_between: int
    routing_layers: int
    frame_time_s: float
    max_elements_at_update: int
    converters: int

    def as_dict(self) -> dict[str, Any]:
        """A JSON-able dict."""
        return asdict(self)


def design_report(
    *,
    thickness_mm: float = 3.0,
    electrode_side_cm: float = 2.0,
    target_pF: float = 2.0,
    spacing_mm: float = 7.0,
    embroidery_spacing_mm: float = 2.0,
    line_distance_mm: float = 2.0,
    rows: int = 15,
    cols: int = 16,
    update_hz: float = 0.625,
    converters: int = 1,
    stray_pF: float = 0.5,
) -> DesignReport:
    """Apply every design rule to one sensor specification."""
    if rows < 1 or cols < 1:
        raise ParameterError("rows and cols must be >= 1")
    electrode = Electrode(side_cm=electrode_side_cm, stray_pF=stray_pF)
    c0, c70 = electrode.capacitance_pF(thickness_mm, [0.0, 0.7 * thickness_mm])
    side = min_electrode_side_cm(thickness_mm, target_pF, stray_pF=stray_pF)
    nl = lines_between(spacing_mm, line_distance_mm)
    cdc = CDC()
    n = rows * cols
    return DesignReport(
        thickness_mm=thickness_mm,
        electrode_side_cm=electrode_side_cm,
        capacitance_unloaded_pF=float(c0),
        capacitance_70pct_pF=float(c70),
        min_side_physics_cm=side,
        min_side_thesis_rule_cm=thesis_min_side_cm(thickness_mm),
        min_pitch_mm=side * 10 + embroidery_spacing_mm,
        rows=rows,
        cols=cols,
        connections_single=connections(n),
        connections_stripes=connections(stripes=(rows, cols)),
        lines_between=nl,
        routing_layers=routing_layers(rows, nl) if nl else -1,
        frame_time_s=cdc.frame_time_s(n, converters),
        max_elements_at_update=elements_per_update(update_hz, cdc, converters),
        converters=converters,
    )
