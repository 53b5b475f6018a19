"""Calibration of a mat's elements: capacitance -> compression (thesis eq. 2.1, §3.4.1).

A textile capacitive element reads ``C = C_par + ε0 εr(e) A / (d - e)`` (eq. 2.1, with the
permittivity growing with the compression ``e``, §3.4.1, and a parasitic/stray term in
parallel). Elements of one mat share the spacer and the shape of this curve but differ in
electrode area, stray capacitance and channel offset. The ``convert`` stage
(:class:`texsense.compensation.stages.Convert`) therefore keeps

- one **material curve** ``C_ref(e)``: the capacitance of a reference element against its
  compression, measured on a test machine (any record with ``compression_mm`` and
  ``capacitance_pF`` columns; the relation has no hysteresis, so every sample counts):
  :func:`material_curve`;
- per element an **offset** ``a_i`` and a **gain** ``b_i`` with ``C_i = a_i + b_i C_ref(e)``,
  identified from two mat recordings: unloaded (zeroing, ``e = 0``) and under a uniform known
  load (equilibration: every element sees the same pressure, hence on the first-loading curve
  the same compression, as commercial mats are equilibrated): :func:`fit_conversion`.

The whole calibration of a mat is its chain of stages
(:class:`texsense.compensation.stages.StageChain`, docs/pipeline.md); this module holds the fitting
of eq. 2.1 it uses.

Examples
--------
>>> import numpy as np
>>> e, c = material_curve(np.linspace(0, 2.5, 50), 3 + np.linspace(0, 2.5, 50))
>>> round(float(e[0]), 3), round(float(c[-1]), 3)
(0.0, 5.5)
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from texsense.compensation.health import mean_reading
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

__all__ = ["fit_conversion", "material_curve", "rising_compression"]


def material_curve(
    compression_mm: npt.ArrayLike, capacitance_pF: npt.ArrayLike, points: int = 200
) -> tuple[np.ndarray, np.ndarray]:
    """The reference curve ``C_ref(e)`` from test-machine samples: bin means over ``points``
    compressions, made strictly increasing (capacitance grows with compression, eq. 2.1)."""
    e = np.asarray(compression_mm, dtype=np.float64)
    c = np.asarray(capacitance_pF, dtype=np.float64)
    ok = np.isfinite(e) & np.isfinite(c)
    e, c = e[ok], c[ok]
    if e.size < 10 or np.ptp(e) <= 0:
        raise ParameterError(
            f"the material record needs >= 10 samples over a range of compressions, got {e.size}"
        )
    edges = np.linspace(e.min(), e.max(), points + 1)
    idx = np.clip(np.searchsorted(edges, e, side="right") - 1, 0, points - 1)
    count = np.bincount(idx, minlength=points)
    have = count > 0
    ee = (np.bincount(idx, e, points)[have]) / count[have]
    cc = (np.bincount(idx, c, points)[have]) / count[have]
    cc = np.maximum.accumulate(cc)
    # strictly increasing for the inverse
    cc = cc + np.arange(cc.size) * 1e-9 * max(1.0, float(np.abs(cc).max()))
    if not np.all(np.diff(cc) > 0):
        raise ParameterError("the capacitance does not grow with the compression")
    return ee, cc


def rising_compression(
    compression_mm: npt.ArrayLike, pressure_ncm2: npt.ArrayLike, level_ncm2: float
) -> float:
    """Compression at which a first loading from rest reaches ``level_ncm2`` (the start of a
    test-machine record, up to its first maximum)."""
    e = np.asarray(compression_mm, dtype=np.float64)
    p = np.asarray(pressure_ncm2, dtype=np.float64)
    top = int(np.argmax(p))
    if p[top] < level_ncm2:
        raise ParameterError(
            f"the material record never reaches the uniform load {level_ncm2} N/cm² "
            f"(its maximum is {p[top]:.3g})"
        )
    first = int(np.argmax(p[: top + 1] >= level_ncm2))
    if first == 0:
        return float(e[0])
    p0, p1 = p[first - 1], p[first]
    w = (level_ncm2 - p0) / (p1 - p0) if p1 > p0 else 1.0
    return float(e[first - 1] + w * (e[first] - e[first - 1]))


def fit_conversion(
    material: Mapping[str, np.ndarray],
    baseline: Recording,
    uniform: Recording,
    uniform_pressure_ncm2: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 2.1 per element from zeroing and equilibration: the material curve
    (compression, capacitance) and every element's offset and gain.

    Parameters
    ----------
    material : dict of arrays
        Test-machine record of one element of the spacer: ``compression_mm``,
        ``capacitance_pF`` and ``pressure_ncm2`` (first loading from rest).
    baseline, uniform : Recording
        Capacitance of the mat unloaded, and under ``uniform_pressure_ncm2`` everywhere
        (loaded from rest). Frames are averaged over the valid readings.
    uniform_pressure_ncm2 : float
        The uniform load of ``uniform`` (N/cm²).
    """
    for name in ("compression_mm", "capacitance_pF", "pressure_ncm2"):
        if name not in material:
            raise ParameterError(f"the material record has no column {name!r}")
    for name, rec in (("baseline", baseline), ("uniform", uniform)):
        if rec.quantity != "capacitance":
            raise ParameterError(f"the {name} recording holds {rec.quantity}, not capacitance")
    if baseline.n_elements != uniform.n_elements:
        raise ParameterError(
            f"baseline has {baseline.n_elements} elements, uniform {uniform.n_elements}"
        )
    ce, cc = material_curve(material["compression_mm"], material["capacitance_pF"])
    e_u = rising_compression(
        material["compression_mm"], material["pressure_ncm2"], uniform_pressure_ncm2
    )
    c0_ref = float(np.interp(0.0, ce, cc))
    cu_ref = float(np.interp(e_u, ce, cc))
    c0 = mean_reading(baseline, "baseline")
    cu = mean_reading(uniform, "uniform")
    gain = (cu - c0) / (cu_ref - c0_ref)
    bad = ~(gain > 0.05)
    if bad.any():
        raise ParameterError(
            f"elements {np.flatnonzero(bad).tolist()[:20]} do not respond to the uniform "
            "load (failed during calibration?)"
        )
    return ce, cc, c0 - gain * c0_ref, gain
