"""Calibration of a whole mat: capacitance -> compression per element, then the spacer's
hysteresis and drift model (thesis eq. 2.1, §3.4.1, chapters 4-5).

A textile capacitive element reads ``C = C_par + ε0 εr(e) A / (d - e)`` (eq. 2.1, with the
permittivity growing with the compression ``e``, §3.4.1, and a parasitic/stray term in
parallel). Elements of one mat share the spacer and the shape of this curve but differ in
electrode area, stray capacitance and channel offset. :class:`MatCalibration` therefore keeps

- one **material curve** ``C_ref(e)``: the capacitance of a reference element against its
  compression, measured on a test machine (any record with ``compression_mm`` and
  ``capacitance_pF`` columns; the relation has no hysteresis, so every sample counts);
- per element an **offset** ``a_i`` and a **gain** ``b_i`` with ``C_i = a_i + b_i C_ref(e)``,
  identified from two mat recordings: unloaded (zeroing, ``e = 0``) and under a uniform known
  load (equilibration: every element sees the same pressure, hence on the first-loading curve
  the same compression, as commercial mats are equilibrated);
- the spacer's :class:`~texsense.hysteresis.HysteresisModel` (compression_mm -> pressure,
  with its drift stage if any).

The calibration file is JSON (``"format": "texsense.calibration"``, version 1) with an id
(content hash) that the pipeline writes into the provenance of every output.

Examples
--------
>>> import numpy as np
>>> curve_e = np.linspace(0, 2.5, 6)
>>> cal = MatCalibration.from_parts(curve_e, 3 + curve_e, offset_pF=[0.0, 0.1],
...                                 gain=[1.0, 2.0], model=None, thickness_mm=3.0)
>>> cal.to_compression(np.array([[3.5, 0.1 + 2 * 3.5]]))
array([[0.5, 0.5]])
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.exceptions import FormatError, ParameterError
from texsense.recording import Recording

__all__ = [
    "CALIBRATION_FORMAT",
    "LinearCalibration",
    "MatCalibration",
    "calibration_from_dict",
    "fit_conversion",
    "load_calibration",
    "material_curve",
    "rising_compression",
]

CALIBRATION_FORMAT = "texsense.calibration"
CALIBRATION_VERSION = 1


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
    material: dict[str, np.ndarray],
    baseline: Recording,
    uniform: Recording,
    uniform_pressure_ncm2: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 2.1 per element from zeroing and equilibration: the material curve
    (compression, capacitance) and every element's offset and gain (see
    :meth:`MatCalibration.fit` for the arguments)."""
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
    c0 = _mean_reading(baseline, "baseline")
    cu = _mean_reading(uniform, "uniform")
    gain = (cu - c0) / (cu_ref - c0_ref)
    bad = ~(gain > 0.05)
    if bad.any():
        raise ParameterError(
            f"elements {np.flatnonzero(bad).tolist()[:20]} do not respond to the uniform "
            "load (failed during calibration?)"
        )
    return ce, cc, c0 - gain * c0_ref, gain


class _CalibrationFile:
    """The file side shared by every calibration kind: a content-hash id over the numbers
    (``_body``) and the versioned JSON envelope around them."""

    provenance: dict[str, Any]

    def _body(self) -> dict[str, Any]:
        raise NotImplementedError

    @property
    def id(self) -> str:
        """Content hash: changes whenever any number of the calibration does."""
        body = json.dumps(self._body(), sort_keys=True).encode()
        return hashlib.sha256(body).hexdigest()[:16]

    def to_dict(self) -> dict[str, Any]:
        """The versioned, JSON-able description."""
        from texsense import __version__

        return {
            "format": CALIBRATION_FORMAT,
            "version": CALIBRATION_VERSION,
            "id": self.id,
            "software": f"texsense {__version__}",
            "provenance": self.provenance,
            **self._body(),
        }

    def save(self, path: str | Path) -> Path:
        """Write the calibration file (JSON)."""
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=1), encoding="utf-8")
        return path


@dataclass
class MatCalibration(_CalibrationFile):
    """Per-element capacitance -> compression conversion plus the spacer model.

    Use :meth:`fit` (from recordings) or :meth:`load` (from a file).
    """

    curve_compression_mm: np.ndarray
    curve_capacitance_pF: np.ndarray
    offset_pF: np.ndarray
    gain: np.ndarray
    thickness_mm: float
    model: Any = None  # HysteresisModel or None
    uniform_pressure_ncm2: float | None = None
    provenance: dict[str, Any] = field(default_factory=dict)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_parts(
        cls,
        curve_compression_mm: npt.ArrayLike,
        curve_capacitance_pF: npt.ArrayLike,
        offset_pF: npt.ArrayLike,
        gain: npt.ArrayLike,
        model: Any,
        thickness_mm: float,
        uniform_pressure_ncm2: float | None = None,
        provenance: dict[str, Any] | None = None,
    ) -> MatCalibration:
        """Build and check a calibration from its numbers."""
        cal = cls(
            np.asarray(curve_compression_mm, dtype=np.float64),
            np.asarray(curve_capacitance_pF, dtype=np.float64),
            np.asarray(offset_pF, dtype=np.float64),
            np.asarray(gain, dtype=np.float64),
            float(thickness_mm),
            model,
            uniform_pressure_ncm2,
            dict(provenance or {}),
        )
        cal.check()
        return cal

    def check(self) -> None:
        """Raise :class:`ParameterError` when the numbers cannot describe a mat."""
        e, c = self.curve_compression_mm, self.curve_capacitance_pF
        if e.ndim != 1 or e.shape != c.shape or e.size < 2:
            raise ParameterError("the material curve needs >= 2 (compression, capacitance) pairs")
        if not (np.all(np.diff(e) > 0) and np.all(np.diff(c) > 0)):
            raise ParameterError("the material curve must increase in compression and capacitance")
        if self.offset_pF.ndim != 1 or self.offset_pF.shape != self.gain.shape:
            raise ParameterError("offset_pF and gain need one entry per element")
        if not np.all(np.isfinite(self.offset_pF)) or not np.all(self.gain > 0):
            raise ParameterError("offsets must be finite and gains > 0 for every element")
        if not self.thickness_mm > 0:
            raise ParameterError(f"thickness must be > 0 mm, got {self.thickness_mm}")

    @classmethod
    def fit(
        cls,
        material: dict[str, np.ndarray],
        baseline: Recording,
        uniform: Recording,
        uniform_pressure_ncm2: float,
        thickness_mm: float,
        model: Any = None,
    ) -> MatCalibration:
        """Identify a mat.

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
        thickness_mm : float
            Spacer thickness.
        model : HysteresisModel, optional
            compression_mm -> pressure; default: fitted to ``material``.
        """
        ce, cc, offset, gain = fit_conversion(material, baseline, uniform, uniform_pressure_ncm2)
        if model is None:
            from texsense.hysteresis import HysteresisModel

            model = HysteresisModel(input_name="compression_mm", output_name="pressure_ncm2")
            model.fit(material["compression_mm"], material["pressure_ncm2"])
        return cls.from_parts(
            ce, cc, offset, gain, model, thickness_mm, uniform_pressure_ncm2,
            {"baseline_frames": baseline.n_frames, "uniform_frames": uniform.n_frames},
        )  # fmt: skip

    # ------------------------------------------------------------------ use
    @property
    def n_elements(self) -> int:
        """Number of elements of the mat."""
        return int(self.gain.size)

    def expected_range_pF(self) -> tuple[np.ndarray, np.ndarray]:
        """Per element: capacitance unloaded and at the end of the material curve."""
        return (
            self.offset_pF + self.gain * self.curve_capacitance_pF[0],
            self.offset_pF + self.gain * self.curve_capacitance_pF[-1],
        )

    def to_compression(self, capacitance_pF: npt.ArrayLike) -> np.ndarray:
        """Compression (mm) of every element, (T, N) or (N,); clipped to the material curve
        (readings beyond it are for the failure detector to judge)."""
        c = np.asarray(capacitance_pF, dtype=np.float64)
        if c.shape[-1] != self.n_elements:
            raise ParameterError(
                f"the calibration is for {self.n_elements} elements, the data have {c.shape[-1]}"
            )
        ref = (c - self.offset_pF) / self.gain
        return np.interp(ref, self.curve_capacitance_pF, self.curve_compression_mm)

    # ------------------------------------------------------------------ files
    def _body(self) -> dict[str, Any]:
        return {
            "thickness_mm": self.thickness_mm,
            "uniform_pressure_ncm2": self.uniform_pressure_ncm2,
            "curve": {
                "compression_mm": self.curve_compression_mm.tolist(),
                "capacitance_pF": self.curve_capacitance_pF.tolist(),
            },
            "elements": {"offset_pF": self.offset_pF.tolist(), "gain": self.gain.tolist()},
            "model": None if self.model is None else self.model.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: Any, source: str | Path = "<dict>") -> MatCalibration:
        """Inverse of :meth:`to_dict`; every problem raises :class:`FormatError` naming it."""
        _check_envelope(d, source)
        if d.get("kind", "mat") != "mat":
            raise FormatError(
                source, f"a {d.get('kind')!r} calibration: read it with load_calibration"
            )
        try:
            model = None
            if d.get("model") is not None:
                from texsense.hysteresis import HysteresisModel

                model = HysteresisModel.from_dict(d["model"], source)
            cal = cls.from_parts(
                d["curve"]["compression_mm"],
                d["curve"]["capacitance_pF"],
                d["elements"]["offset_pF"],
                d["elements"]["gain"],
                model,
                d["thickness_mm"],
                d.get("uniform_pressure_ncm2"),
                d.get("provenance", {}),
            )
        except KeyError as e:
            raise FormatError(source, f"missing field {e}") from None
        except (TypeError, ValueError, ParameterError) as e:
            if isinstance(e, FormatError):
                raise
            raise FormatError(source, f"bad value: {e}") from None
        if "id" in d and d["id"] != cal.id:
            raise FormatError(
                source, f"id {d['id']} does not match the content ({cal.id}): edited or damaged"
            )
        return cal

    @classmethod
    def load(cls, path: str | Path) -> MatCalibration:
        """Read a calibration file."""
        from texsense.stages import read_json

        return cls.from_dict(read_json(path), path)


def _mean_reading(rec: Recording, name: str) -> np.ndarray:
    """Mean capacitance of every element over the recording's valid readings."""
    f = np.where(rec.valid, rec.frames.astype(np.float64), np.nan)
    with np.errstate(invalid="ignore"):
        n = np.sum(np.isfinite(f), axis=0)
        m = np.nansum(f, axis=0) / np.maximum(n, 1)
    if np.any(n == 0):
        raise ParameterError(
            f"elements {np.flatnonzero(n == 0).tolist()[:20]} have no valid reading in the "
            f"{name} recording"
        )
    return m


@dataclass
class LinearCalibration(_CalibrationFile):
    """A mat with a static per-element calibration and no spacer model:
    ``value = (reading - offset_i) / gain_i``.

    For mats whose readings are already (nearly) linear in pressure — resistive mats such as
    the Vista FSA of the PhysioNet PMD data, or any mat whose vendor calibration is trusted —
    and for reprocessing archives where only failure detection and repair are wanted: with
    offset 0 and gain 1 (:meth:`identity`) the values keep their units. Failure detection on
    such readings uses the tests that do not need an unloaded level: not a number, beyond
    ``full_scale`` (out of range), stuck while the neighbours move; a reading of 0 is a mat
    without load, not a short.

    The file is the calibration JSON (``"format": "texsense.calibration"``, version 1) with
    ``"kind": "linear"``; :func:`load_calibration` reads either kind.
    """

    offset: np.ndarray
    gain: np.ndarray
    input_quantity: str
    input_unit: str
    output_quantity: str
    output_unit: str
    full_scale: float | None = None
    provenance: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def identity(
        cls,
        n_elements: int,
        quantity: str,
        unit: str,
        full_scale: float | None = None,
        provenance: dict[str, Any] | None = None,
    ) -> LinearCalibration:
        """Values unchanged (offset 0, gain 1): detection and repair only."""
        cal = cls(
            np.zeros(n_elements), np.ones(n_elements), quantity, unit, quantity, unit,
            full_scale, dict(provenance or {}),
        )  # fmt: skip
        cal.check()
        return cal

    def check(self) -> None:
        """Raise :class:`ParameterError` when the numbers cannot describe a mat."""
        from texsense import units
        from texsense.recording import QUANTITIES

        self.offset = np.asarray(self.offset, dtype=np.float64)
        self.gain = np.asarray(self.gain, dtype=np.float64)
        if self.offset.ndim != 1 or self.offset.shape != self.gain.shape or not self.gain.size:
            raise ParameterError("offset and gain need one entry per element")
        if not np.all(np.isfinite(self.offset)) or not np.all(self.gain > 0):
            raise ParameterError("offsets must be finite and gains > 0 for every element")
        for q, u in (
            (self.input_quantity, self.input_unit),
            (self.output_quantity, self.output_unit),
        ):
            if q not in QUANTITIES or units.quantity_of(units.canonical(u)) != QUANTITIES[q]:
                raise ParameterError(f"unit {u!r} does not measure {q!r}")
        if self.full_scale is not None and not np.isfinite(self.full_scale):
            raise ParameterError(f"full_scale must be a number, got {self.full_scale}")

    @property
    def n_elements(self) -> int:
        """Number of elements of the mat."""
        return int(self.gain.size)

    def _body(self) -> dict[str, Any]:
        return {
            "kind": "linear",
            "input": {"quantity": self.input_quantity, "unit": self.input_unit},
            "output": {"quantity": self.output_quantity, "unit": self.output_unit},
            "full_scale": self.full_scale,
            "elements": {"offset": self.offset.tolist(), "gain": self.gain.tolist()},
        }

    @classmethod
    def from_dict(cls, d: Any, source: str | Path = "<dict>") -> LinearCalibration:
        """Inverse of :meth:`to_dict`; every problem raises :class:`FormatError` naming it."""
        _check_envelope(d, source)
        try:
            cal = cls(
                np.asarray(d["elements"]["offset"], dtype=np.float64),
                np.asarray(d["elements"]["gain"], dtype=np.float64),
                str(d["input"]["quantity"]),
                str(d["input"]["unit"]),
                str(d["output"]["quantity"]),
                str(d["output"]["unit"]),
                None if d.get("full_scale") is None else float(d["full_scale"]),
                d.get("provenance", {}),
            )
            cal.check()
        except KeyError as e:
            raise FormatError(source, f"missing field {e}") from None
        except (TypeError, ValueError, ParameterError) as e:
            raise FormatError(source, f"bad value: {e}") from None
        if "id" in d and d["id"] != cal.id:
            raise FormatError(
                source, f"id {d['id']} does not match the content ({cal.id}): edited or damaged"
            )
        return cal


def _check_envelope(d: Any, source: str | Path) -> None:
    if not isinstance(d, dict) or d.get("format") != CALIBRATION_FORMAT:
        raise FormatError(source, f"not a {CALIBRATION_FORMAT} file (no 'format' field)")
    if d.get("version") != CALIBRATION_VERSION:
        raise FormatError(
            source,
            f"calibration version {d.get('version')!r}; this texsense reads version "
            f"{CALIBRATION_VERSION}",
        )


def calibration_from_dict(d: Any, source: str | Path = "<dict>") -> Any:
    """A calibration from its JSON description: a stage chain (``texsense.chain``, what
    ``texsense calibrate mat`` writes), a first-round mat calibration or a linear one."""
    from texsense.stages import CHAIN_FORMAT, StageChain

    if isinstance(d, dict) and d.get("format") == CHAIN_FORMAT:
        return StageChain.from_dict(d, source)
    _check_envelope(d, source)
    kind = d.get("kind", "mat")
    if kind == "linear":
        return LinearCalibration.from_dict(d, source)
    if kind != "mat":
        raise FormatError(source, f"unknown calibration kind {kind!r} (known: mat, linear)")
    return MatCalibration.from_dict(d, source)


def load_calibration(path: str | Path) -> Any:
    """Read a calibration file: a stage chain (:class:`texsense.stages.StageChain`), a
    first-round mat calibration or a linear one (:func:`calibration_from_dict`)."""
    from texsense.stages import read_json

    return calibration_from_dict(read_json(path), path)
