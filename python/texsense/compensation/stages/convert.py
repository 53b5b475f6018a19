"""The conversion stages: capacitance -> compression per element (``convert``, eq. 2.1) and a
linear calibration, offset and gain per element (``linear``). Both run the compiled
``Converter`` (``crates/core/src/convert.rs``), the one the pipeline's chain runs."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from texsense._core import Converter, Curve
from texsense.compensation.conversion import fit_conversion
from texsense.compensation.health import FailureDetector
from texsense.compensation.stage import Stage
from texsense.data import units
from texsense.data.layout import Layout
from texsense.data.modelfile import Fields
from texsense.data.ranges import Kind, Maybe, OneOf, Real, UnitOf
from texsense.data.recording import QUANTITIES, Recording
from texsense.exceptions import ParameterError

__all__ = ["Convert", "Linear"]

#: The bounds of a conversion's learned numbers in a file: the material curve (mm, pF), the
#: elements' offsets (pF) and gains (fit_conversion refuses gains below 0.05), a linear
#: calibration's offsets and gains (the range of ``--offset`` and ``--gain``).
_CURVE_MM = Real(-1e3, 1e3, unit="mm")
_CURVE_PF = Real(-1e6, 1e6, unit="pF")
_GAIN = Real(0.0, 1e3, lo_open=True, least=1e-12)
_LINEAR_OFFSET = Real(-1e15, 1e15)
_LINEAR_GAIN = Real(-1e15, 1e15, nonzero=True, least=1e-12)


class _Conversion(Stage):
    """What the two conversions share: the compiled converter and the number of elements."""

    gain_: np.ndarray
    _kernel: Converter

    @property
    def n_elements(self) -> int:
        """Number of elements of the mat."""
        self._check_fitted()
        return int(self.gain_.size)

    def kernel(self) -> Converter:
        """The compiled converter (``crates/core/src/convert.rs``)."""
        self._check_fitted()
        return self._kernel

    def detector(self, layout: Layout) -> FailureDetector:
        """The failure detector this calibration implies."""
        raise NotImplementedError

    def _block(
        self, values: np.ndarray, valid: np.ndarray, dt: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        return self._kernel.run(values, valid), valid.copy()


class Convert(_Conversion):
    """Capacitance -> compression per element (eq. 2.1): ``C_i = a_i + b_i C_ref(e)`` with the
    material curve ``C_ref(e)`` and per element an offset ``a_i`` and a gain ``b_i``
    (:mod:`texsense.compensation.conversion`).

    Parameters
    ----------
    thickness_mm : float
        Spacer thickness.
    uniform_pressure_ncm2 : float
        The uniform load of the equilibration recording (N/cm²).
    """

    name = "convert"
    _reads = ("capacitance", "pF")
    _gives = ("compression", "mm")

    #: the range of every parameter (:mod:`texsense.data.ranges`)
    ranges: ClassVar[Mapping[str, Kind]] = {
        "thickness_mm": Real(0.0, 100.0, lo_open=True, unit="mm"),
        "uniform_pressure_ncm2": Real(0.0, 1e4, lo_open=True, unit="N/cm2"),
    }

    #: learned: the material curve (compression in mm, capacitance in pF of a reference
    #: element) and every element's offset (pF) and gain (eq. 2.1)
    curve_compression_mm_: np.ndarray
    curve_capacitance_pF_: np.ndarray
    offset_pF_: np.ndarray
    gain_: np.ndarray

    def __init__(self, thickness_mm: float, uniform_pressure_ncm2: float = 1.0) -> None:
        self.thickness_mm = thickness_mm
        self.uniform_pressure_ncm2 = uniform_pressure_ncm2

    def fit(
        self, material: Mapping[str, np.ndarray], baseline: Recording, uniform: Recording
    ) -> Convert:
        """Zeroing (``baseline``, unloaded) and equilibration (``uniform``, under
        ``uniform_pressure_ncm2``) against the material curve of a test-machine record
        (``compression_mm``, ``capacitance_pF``, ``pressure_ncm2``)."""
        ce, cc, offset, gain = fit_conversion(
            material, baseline, uniform, float(self.uniform_pressure_ncm2)
        )
        return self.set_fitted(
            curve_compression_mm=ce, curve_capacitance_pF=cc, offset_pF=offset, gain=gain
        )

    def _prepare(self) -> None:
        e = np.asarray(self.curve_compression_mm_, np.float64)
        c = np.asarray(self.curve_capacitance_pF_, np.float64)
        offset = np.asarray(self.offset_pF_, np.float64)
        gain = np.asarray(self.gain_, np.float64)
        if e.ndim != 1 or e.shape != c.shape or e.size < 2:
            raise ParameterError("the material curve needs >= 2 (compression, capacitance) pairs")
        if not (np.all(np.diff(e) > 0) and np.all(np.diff(c) > 0)):
            raise ParameterError("the material curve must increase in compression and capacitance")
        if offset.ndim != 1 or offset.shape != gain.shape:
            raise ParameterError("offset_pF and gain need one entry per element")
        if not float(self.thickness_mm) > 0:
            raise ParameterError(f"thickness must be > 0 mm, got {self.thickness_mm}")
        self.curve_compression_mm_, self.curve_capacitance_pF_ = e, c
        self.offset_pF_, self.gain_ = offset, gain
        self._kernel = Converter(offset, gain, Curve(c, e))

    def expected_range_pF(self) -> tuple[np.ndarray, np.ndarray]:
        """Per element: capacitance unloaded and at the end of the material curve."""
        self._check_fitted()
        c = self.curve_capacitance_pF_
        return self.offset_pF_ + self.gain_ * c[0], self.offset_pF_ + self.gain_ * c[-1]

    def detector(self, layout: Layout) -> FailureDetector:
        """The failure detector this calibration implies: the expected capacitance range of
        every element."""
        lo, hi = self.expected_range_pF()
        return FailureDetector(layout).fit(lo, hi)

    def _fitted_json(self) -> dict[str, Any]:
        return {
            "curve": {
                "compression_mm": self.curve_compression_mm_.tolist(),
                "capacitance_pF": self.curve_capacitance_pF_.tolist(),
            },
            "elements": {"offset_pF": self.offset_pF_.tolist(), "gain": self.gain_.tolist()},
        }

    @classmethod
    def _fitted_from_json(cls, fields: Fields, params: Mapping[str, Any]) -> dict[str, Any]:
        return {
            "curve_compression_mm": fields.array("curve.compression_mm", 1, within=_CURVE_MM),
            "curve_capacitance_pF": fields.array("curve.capacitance_pF", 1, within=_CURVE_PF),
            "offset_pF": fields.array("elements.offset_pF", 1, within=_CURVE_PF),
            "gain": fields.array("elements.gain", 1, within=_GAIN),
        }


class Linear(_Conversion):
    """A static calibration per element, ``value = (reading - offset_i) / gain_i``, and no
    spacer model.

    For mats whose readings are already (nearly) linear in pressure — resistive mats such as
    the Vista FSA of the PhysioNet PMD data, or any mat whose vendor calibration is trusted —
    and for reprocessing archives where only failure detection and repair are wanted: with
    offset 0 and gain 1 the values keep their units. Failure detection on such readings uses
    the tests that do not need an unloaded level (:meth:`detector`).

    Parameters
    ----------
    input_quantity, input_unit : str
        What the readings are (e.g. ``"capacitance"``, ``"pF"``).
    output_quantity, output_unit : str, optional
        What the values become (default: the readings' own).
    full_scale : float, optional
        Readings beyond it are out of range.
    """

    name = "linear"

    #: the range of every parameter (:mod:`texsense.data.ranges`)
    ranges: ClassVar[Mapping[str, Kind]] = {
        "input_quantity": OneOf(tuple(QUANTITIES)),
        "input_unit": UnitOf(),
        "output_quantity": Maybe(OneOf(tuple(QUANTITIES)), "the readings' own"),
        "output_unit": Maybe(UnitOf(), "the readings' own"),
        "full_scale": Maybe(Real(0.0, 1e15, lo_open=True), "no top"),
    }

    #: learned: every element's offset and gain
    offset_: np.ndarray
    gain_: np.ndarray

    def __init__(
        self,
        input_quantity: str,
        input_unit: str,
        output_quantity: str | None = None,
        output_unit: str | None = None,
        full_scale: float | None = None,
    ) -> None:
        self.input_quantity = input_quantity
        self.input_unit = input_unit
        self.output_quantity = output_quantity
        self.output_unit = output_unit
        self.full_scale = full_scale

    @property
    def reads(self) -> tuple[str, str]:
        """(quantity, unit) of the readings."""
        return self.input_quantity, self.input_unit

    @property
    def gives(self) -> tuple[str, str]:
        """(quantity, unit) of the values (the readings' own unless given)."""
        return (
            self.output_quantity or self.input_quantity,
            self.output_unit or self.input_unit,
        )

    def fit(self, offset: npt.ArrayLike, gain: npt.ArrayLike) -> Linear:
        """Take the offset and gain of every element (e.g. zeros and ones: values keep their
        unit)."""
        return self.set_fitted(
            offset=np.asarray(offset, np.float64), gain=np.asarray(gain, np.float64)
        )

    def _prepare(self) -> None:
        offset = np.asarray(self.offset_, np.float64)
        gain = np.asarray(self.gain_, np.float64)
        if offset.ndim != 1 or offset.shape != gain.shape or not gain.size:
            raise ParameterError("offset and gain need one entry per element")
        for q, u in (self.reads, self.gives):
            if q not in QUANTITIES or units.quantity_of(units.canonical(u)) != QUANTITIES[q]:
                raise ParameterError(f"unit {u!r} does not measure {q!r}")
        held = _LINEAR_GAIN.holds_array(gain)
        if not held.all():  # the file's bound: readings are divided by the gain (eq. 2.1)
            i = int(np.argmin(held))
            raise ParameterError(
                f"the gain of element {i} must be {_LINEAR_GAIN.text()}, got {gain[i]:g}"
            )
        self.offset_, self.gain_ = offset, gain
        self._kernel = Converter(offset, gain)

    def detector(self, layout: Layout) -> FailureDetector:
        """The detector a linear calibration implies: only the tests that need no unloaded
        level (a 0 reading is an unloaded mat there, not a short), the jump test off, and
        readings within 1 % of full scale of the offset never stuck (low readings of an
        integer-count mat hold still at rest)."""
        self._check_fitted()
        top, floor = None, float(np.max(self.offset_))
        if self.full_scale is not None:
            top = np.full(layout.n_elements, float(self.full_scale))
            floor += 0.01 * float(self.full_scale)
        return FailureDetector(
            layout, min_pF=-np.inf, high_share=1.0, jump_pF=np.inf, stuck_floor_pF=floor
        ).fit(None, top)

    def _fitted_json(self) -> dict[str, Any]:
        return {"offset": self.offset_.tolist(), "gain": self.gain_.tolist()}

    @classmethod
    def _fitted_from_json(cls, fields: Fields, params: Mapping[str, Any]) -> dict[str, Any]:
        return {
            "offset": fields.array("offset", 1, within=_LINEAR_OFFSET),
            "gain": fields.array("gain", 1, within=_LINEAR_GAIN),
        }
