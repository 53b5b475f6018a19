"""Checks of what a mat calibration is made from (``texsense calibrate mat`` and ``calibrate
wizard``; docs/calibration.md).

A calibration is only as good as its inputs, and the usual mistakes give a file that loads and
runs but reads wrong by a factor: a material record of another spacer (the README once paired
a 6 mm record with ``--thickness-mm 3``: gains 2.1-2.6 instead of 0.9-1.1), a load given in
kPa or mmHg, a "uniform" load that missed part of the mat, a recording taken while the spacer
was still creeping. Every check here returns :class:`Finding` objects: ``refuse`` when the
calibration would be wrong, ``warn`` when it would be usable but worse than it could be.

The thickness check uses eq. 2.1, ``C = C_par + ε A / (d - e)``: the capacitance of the
material record grows without bound as the compression ``e`` approaches the spacer thickness
``d``, so fitting ``C_par``, ``ε A`` and ``d`` to the record estimates the thickness of the
spacer the record was made on (the permittivity's growth with compression, §3.4.1, makes the
estimate a little low: the check allows ±35 %).

Examples
--------
>>> import numpy as np
>>> e = np.linspace(0, 2.4, 200)
>>> record = {"compression_mm": e, "capacitance_pF": 1.0 + 12.0 / (6.0 - e),
...           "pressure_ncm2": np.linspace(0, 10, 200)}
>>> round(record_thickness_mm(record), 2)
6.0
>>> [f.level for f in check_material(record, 3.0, 1.0, "record.csv")]
['refuse']
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from texsense.data.layout import Layout
from texsense.data.recording import Recording
from texsense.data.units import UnitError, convert, quantity_of
from texsense.exceptions import ParameterError

__all__ = [
    "Finding",
    "check_declared_spacer",
    "check_gains",
    "check_material",
    "check_recordings",
    "edge_of_press",
    "parse_pressure",
    "raise_if_refused",
    "record_thickness_mm",
    "typical_reading",
]

#: Least frames of a zeroing or an equilibration recording.
MIN_FRAMES = 5
#: An element whose response to the uniform load is below this share of the median response
#: does not respond.
SILENT_SHARE = 0.25
#: More silent elements than this share of the mat: the load was not uniform (refused).
SILENT_REFUSE_SHARE = 0.2
#: Readings that still move by more than this share of the load response: not steady.
STEADY_SHARE = 0.05
#: The estimated thickness may differ from the given one by this factor.
THICKNESS_TOLERANCE = 0.35


@dataclass(frozen=True)
class Finding:
    """One result of a check: ``level`` is ``"refuse"`` or ``"warn"``, ``text`` says what was
    found, with the numbers, and what to do."""

    level: str
    text: str

    def __str__(self) -> str:
        return f"{'refused' if self.level == 'refuse' else 'warning'}: {self.text}"


def parse_pressure(text: str | float) -> float:
    """A pressure in N/cm² from a number (N/cm²) or a number with a unit: ``1.0``, ``10kPa``,
    ``75 mmHg``, ``1 N/cm2``.

    >>> parse_pressure("10kPa"), round(parse_pressure("75mmHg"), 3), parse_pressure(2)
    (1.0, 1.0, 2.0)
    >>> parse_pressure("1 N/cm2"), parse_pressure("0.5 N/cm²"), parse_pressure("1.5")
    (1.0, 0.5, 1.5)
    """
    if isinstance(text, int | float):
        value, unit = float(text), "N/cm2"
    else:
        found = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*", text)
        if found is None:
            raise ParameterError(f"a pressure must be a number with a unit, got {text!r}")
        value, unit = float(found.group(1)), found.group(2) or "N/cm2"
        try:
            if quantity_of(unit) != "pressure":
                raise ParameterError(f"{unit!r} in {text!r} is not a pressure unit")
        except UnitError:
            raise ParameterError(f"unknown pressure unit {unit!r} in {text!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise ParameterError(f"a pressure must be > 0, got {text!r}")
    return float(convert(value, unit, "N/cm2"))


def record_thickness_mm(material: Mapping[str, np.ndarray]) -> float:
    """The spacer thickness that the material record's capacitance implies: ``d`` of
    ``C = C_par + ε A / (d - e)`` (eq. 2.1) fitted by least squares (``C_par`` and ``ε A``
    linear for each ``d``, ``d`` by a bounded scalar search)."""
    from scipy.optimize import minimize_scalar  # heavy: only the check that fits needs it

    e = np.asarray(material["compression_mm"], dtype=np.float64)
    c = np.asarray(material["capacitance_pF"], dtype=np.float64)
    ok = np.isfinite(e) & np.isfinite(c)
    e, c = e[ok], c[ok]
    top = float(e.max())

    def residual(log_gap: float) -> float:
        x = 1.0 / (top + np.exp(log_gap) - e)
        design = np.column_stack([np.ones_like(x), x])
        coef, *_ = np.linalg.lstsq(design, c, rcond=None)
        return float(np.sum((design @ coef - c) ** 2))

    best = minimize_scalar(residual, bounds=(np.log(1e-3), np.log(100.0)), method="bounded")
    return top + float(np.exp(best.x))


def check_material(
    material: Mapping[str, np.ndarray],
    thickness_mm: float,
    pressure_ncm2: float,
    source: str,
) -> list[Finding]:
    """The material record against the spacer thickness and the uniform load: a record that
    compresses further than the spacer is thick, a capacitance curve of a spacer of another
    thickness (:func:`record_thickness_mm`), a uniform load outside the record's pressures."""
    found = []
    e = np.asarray(material["compression_mm"], dtype=np.float64)
    p = np.asarray(material["pressure_ncm2"], dtype=np.float64)
    implied = record_thickness_mm(material)
    if np.nanmax(e) >= thickness_mm:
        found.append(Finding("refuse", (
            f"{source} compresses its spacer to {np.nanmax(e):.2f} mm, beyond the spacer's "
            f"{thickness_mm:g} mm: the record is of a thicker spacer (its capacitance says "
            f"about {implied:.1f} mm)")))  # fmt: skip
    elif abs(implied / thickness_mm - 1) > THICKNESS_TOLERANCE:
        found.append(Finding("refuse", (
            f"{source}'s capacitance curve is that of a spacer about {implied:.1f} mm thick "
            f"(eq. 2.1 fitted), but the spacer is {thickness_mm:g} mm: use the record of this "
            "mat's spacer, or the right --thickness-mm")))  # fmt: skip
    top = float(np.nanmax(p))
    if pressure_ncm2 > top:
        found.append(Finding("refuse", (
            f"the uniform load {pressure_ncm2:g} N/cm² is beyond the {top:.3g} N/cm² that "
            f"{source} reaches (the load is in N/cm²: 1 N/cm² = 10 kPa = 75 mmHg; or give a "
            "unit, e.g. --pressure 10kPa)")))  # fmt: skip
    elif pressure_ncm2 < 0.02 * top:
        found.append(Finding("warn", (
            f"the uniform load {pressure_ncm2:g} N/cm² is below 2 % of the record's "
            f"{top:.3g} N/cm²: the gains rest on a small change; a load near the mat's "
            "working range calibrates better")))  # fmt: skip
    return found


def typical_reading(rec: Recording) -> np.ndarray:
    """Every element's median over the frames where it read (NaN if it never did)."""
    x = np.where(rec.valid, rec.frames.astype(np.float64), np.nan)
    out = np.full(rec.n_elements, np.nan)
    seen = np.isfinite(x).any(axis=0)
    out[seen] = np.nanmedian(x[:, seen], axis=0)
    return out


def edge_of_press(values: np.ndarray, reference: np.ndarray, layout: Layout) -> str:
    """The edge of the map (``top``: row 0, ``bottom``, ``left``: column 0, ``right``)
    nearest to where a hand presses on the mat: the centroid of the readings' rise above the
    empty mat (``reference``), weighted by the rise (the orientation step of the wizard and
    the page: "press on the mat at its head end"). A press that raises nothing is a
    :class:`ParameterError`."""
    rise = np.clip(np.nan_to_num(np.asarray(values, np.float64) - reference), 0.0, None)
    if rise.sum() <= 0:
        raise ParameterError("no element rose above the empty mat: press harder, or type the edge")
    x0, x1, y0, y1 = layout.extent_cm
    fx = float(rise @ (layout.xy_cm[:, 0] - x0)) / rise.sum() / max(x1 - x0, 1e-9)
    fy = float(rise @ (layout.xy_cm[:, 1] - y0)) / rise.sum() / max(y1 - y0, 1e-9)
    gaps = {"top": fy, "bottom": 1 - fy, "left": fx, "right": 1 - fx}
    return min(gaps, key=lambda k: gaps[k])


def _settling(rec: Recording) -> float:
    """How far the mat's median reading moved between the first and the last third of the
    recording (pF; 0 for fewer than 3 frames)."""
    x = np.where(rec.valid, rec.frames.astype(np.float64), np.nan)
    third = x.shape[0] // 3
    if third < 1:
        return 0.0
    first = np.nanmedian(x[:third], axis=0)
    last = np.nanmedian(x[-third:], axis=0)
    change = last - first
    return float(np.nanmedian(change)) if np.isfinite(change).any() else 0.0


def check_recordings(
    baseline: Recording, uniform: Recording, names: tuple[str, str] = ("baseline", "uniform")
) -> list[Finding]:
    """The zeroing and equilibration recordings: the same mat, long enough, steady, and every
    element responding to the load (an element that does not is named; too many and the load
    was not uniform)."""
    found: list[Finding] = []
    if baseline.n_elements != uniform.n_elements:
        return [Finding("refuse", (
            f"{names[0]} has {baseline.n_elements} elements and {names[1]} "
            f"{uniform.n_elements}: both must be recordings of the same mat"))]  # fmt: skip
    for name, rec in zip(names, (baseline, uniform), strict=True):
        if rec.n_frames < MIN_FRAMES:
            found.append(Finding("refuse", (
                f"{name} holds {rec.n_frames} frames: record at least {MIN_FRAMES} (e.g. "
                "'texsense record ... --frames 10')")))  # fmt: skip
    if found:
        return found
    zero, loaded = typical_reading(baseline), typical_reading(uniform)
    response = loaded - zero
    working = np.isfinite(response)
    if not working.any() or np.nanmedian(response) <= 0:
        return [Finding("refuse", (
            f"{names[1]} does not read more than {names[0]} (median change "
            f"{np.nanmedian(response) if working.any() else float('nan'):+.3g} pF): are the "
            "two recordings swapped, or was the load missing?"))]  # fmt: skip
    typical = float(np.nanmedian(response))
    silent = np.flatnonzero(~working | (response < SILENT_SHARE * typical))
    if silent.size:
        listed = ", ".join(uniform.layout.element_name(int(k)) for k in silent[:12])
        more = f" and {silent.size - 12} more" if silent.size > 12 else ""
        share = silent.size / uniform.n_elements
        level = "refuse" if share > SILENT_REFUSE_SHARE else "warn"
        advice = (
            "the load did not cover the mat evenly: use a bladder or a plate over all of it"
            if level == "refuse"
            else "the detector will treat them as failed; check their wiring"
        )
        found.append(Finding(level, (
            f"{silent.size} of {uniform.n_elements} elements ({100 * share:.0f} %) did not "
            f"respond to the uniform load (change < {100 * SILENT_SHARE:.0f} % of the median "
            f"{typical:.3g} pF): {listed}{more}; {advice}")))  # fmt: skip
    for name, rec in zip(names, (baseline, uniform), strict=True):
        moved = _settling(rec)
        if abs(moved) > STEADY_SHARE * typical:
            ratio = abs(moved) / typical  # a tiny response makes a share meaningless
            said = f"{100 * ratio:.0f} % of" if ratio < 10 else f"{ratio:.3g} times"
            found.append(Finding("warn", (
                f"{name} was not steady: the readings moved by {moved:+.3g} pF "
                f"({said} the load response, {typical:.3g} pF) from its first to "
                "its last third (the spacer creeping, or the load settling): wait until the "
                "readings are steady, or record longer")))  # fmt: skip
    return found


def check_declared_spacer(recording: Recording, material: str, name: str) -> list[Finding]:
    """A recording from a device that declares its spacer (the ``#layout`` announcement of
    the serial protocol, kept in the recording's meta) against the preset chosen."""
    declared = recording.meta.get("spacer")
    if declared is None or declared == material:
        return []
    return [Finding("refuse", (
        f"{name} comes from a device that declares the spacer {declared}, but the material is "
        f"{material}: use --material {declared}"))]  # fmt: skip


def check_gains(gain: np.ndarray, material_name: str) -> list[Finding]:
    """Gains (eq. 2.1) far from 1: the mat's elements read a multiple of the material
    record's element: right if they are larger than the test specimen, else a record of
    another spacer."""
    typical = float(np.median(gain))
    if 0.5 <= typical <= 2.0:
        return []
    return [Finding("warn", (
        f"the elements read {typical:.2f} x the capacitance change of {material_name}'s "
        "reference element: if they are the size of the test specimen, the material is of "
        "another spacer"))]  # fmt: skip


def raise_if_refused(findings: list[Finding]) -> None:
    """A :class:`ParameterError` with every reason if any finding refuses."""
    refused = [f.text for f in findings if f.level == "refuse"]
    if refused:
        raise ParameterError("calibration refused: " + "; ".join(refused))
