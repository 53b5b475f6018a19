"""From raw capacitance frames to pressure maps: detect -> convert -> hysteresis -> drift ->
repair, streaming frame by frame or in batch over a recording.

- **detect** (:class:`~texsense.health.FailureDetector`): failure codes per reading, from
  the raw capacitance and the calibration's expected range;
- **convert** (:class:`~texsense.calibration.MatCalibration`): capacitance -> compression
  per element (eq. 2.1, zeroed and equilibrated);
- **hysteresis + drift**: the calibration's Preisach model and drift stage in one pass of the
  Rust core (eq. 4.15-4.22, eq. 5.8). A failed reading is skipped: the element's Preisach and
  drift states stay frozen until it reads again. Without the hysteresis stage the
  compression is converted with the first-loading curve (what an uncompensated system does);
- **repair** (:class:`~texsense.repair.Repair`): failed elements are filled (eq. 6.14 or a
  better method) and stay marked False in the output's ``valid`` mask.

Detection, conversion, hysteresis + drift and the local repair methods (``zero``,
``last-value``, ``neighbour-mean``, ``idw8``) run as one compiled pass of the Rust core
(``crates/core/src/chain.rs``) over the whole block of frames, in parallel over blocks of
elements; the harmonic repairs solve a sparse system per frame in scipy afterwards. Batch and
streaming give the same numbers (tested); ``step`` is the same code with one frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from texsense._core import Chain
from texsense.calibration import LinearCalibration, MatCalibration
from texsense.exceptions import ParameterError
from texsense.health import FailureDetector
from texsense.layout import Layout
from texsense.recording import Recording
from texsense.repair import METHODS, Repair, idw_weights
from texsense.stages import StageChain

__all__ = ["Pipeline"]

#: Repair methods that solve for all failed elements of a frame together (scipy, per frame).
_GLOBAL_REPAIRS = ("harmonic", "harmonic-temporal")


class Pipeline:
    """The capacitance-to-pressure chain of one mat.

    Parameters
    ----------
    calibration : MatCalibration
        Conversion and spacer model (with its drift stage, if any).
    layout : Layout
        The mat's elements (neighbours for detection and repair).
    detect, hysteresis, drift : bool
        Switch stages off to see what each contributes.
    repair : str or None
        A method of :data:`texsense.repair.METHODS`, or None to leave failed elements NaN
        (an unknown name raises :class:`ParameterError`).
    detector : FailureDetector, optional
        Default: one with the calibration's expected capacitance range.
    """

    def __init__(
        self,
        calibration: MatCalibration | LinearCalibration | StageChain,
        layout: Layout,
        *,
        detect: bool = True,
        hysteresis: bool = True,
        drift: bool = True,
        repair: str | None = "harmonic",
        detector: FailureDetector | None = None,
    ) -> None:
        if calibration.n_elements != layout.n_elements:
            raise ParameterError(
                f"the calibration is for {calibration.n_elements} elements, the layout has "
                f"{layout.n_elements}"
            )
        self.calibration_id = calibration.id
        if isinstance(calibration, StageChain):
            # the chain's stages, compiled: its detect stage's thresholds, its numbers
            detector = detector or calibration.detector()
            calibration = calibration.calibration()
        linear = isinstance(calibration, LinearCalibration)
        model = None if linear else calibration.model
        if not linear and model is None:
            raise ParameterError("the calibration has no spacer model (compression -> pressure)")
        if repair is not None and repair not in METHODS:
            raise ParameterError(f"unknown repair method {repair!r}; known: {', '.join(METHODS)}")
        if linear:
            hysteresis = drift = False  # a linear calibration has no spacer model
        if drift and hysteresis and getattr(model, "drift_", None) is None:
            drift = False  # nothing to apply: recorded in the provenance
        self.calibration = calibration
        self.layout = layout
        self.stages = {"detect": detect, "hysteresis": hysteresis, "drift": drift}
        self.repair_method = repair
        if detector is None:
            detector = _default_detector(calibration, layout)
        self.detector = detector
        # the harmonic methods solve a sparse system per frame (scipy); the others run in
        # the compiled chain
        self._repair = Repair(layout, repair) if repair in _GLOBAL_REPAIRS else None
        self._chain = self._build_chain()
        self._last_t: float | None = None
        self._dt1 = np.zeros(1)
        self._all_valid = np.ones(layout.n_elements, bool)
        self.codes_: np.ndarray | None = None

    @property
    def input_quantity(self) -> tuple[str, str]:
        """(quantity, unit) of the readings the pipeline takes."""
        cal = self.calibration
        if isinstance(cal, LinearCalibration):
            return cal.input_quantity, cal.input_unit
        return "capacitance", "pF"

    @property
    def output_quantity(self) -> tuple[str, str]:
        """(quantity, unit) of the values the pipeline gives."""
        cal = self.calibration
        if isinstance(cal, LinearCalibration):
            return cal.output_quantity, cal.output_unit
        return "pressure", "N/cm2"

    def _build_chain(self) -> Chain:
        from texsense._core import Converter, Curve, LocalRepair

        cal = self.calibration
        c = np.ascontiguousarray
        detector = self.detector.core if self.stages["detect"] else None
        response: dict[str, Any] = {}
        if isinstance(cal, LinearCalibration):
            converter = Converter(c(cal.offset, dtype=np.float64), c(cal.gain, dtype=np.float64))
        else:
            model = cal.model
            curve = Curve(
                c(cal.curve_capacitance_pF, dtype=np.float64),
                c(cal.curve_compression_mm, dtype=np.float64),
            )
            converter = Converter(
                c(cal.offset_pF, dtype=np.float64), c(cal.gain, dtype=np.float64), curve
            )
            if self.stages["hysteresis"]:
                response = {
                    "compensation": model.compensation(
                        self.layout.n_elements, drift=self.stages["drift"]
                    )
                }
            else:
                e = np.linspace(model.u_min_, model.u_max_, 400)
                p = np.maximum.accumulate(model.predict(e))
                response = {"loading": Curve(c(e), c(p, dtype=np.float64))}
        method = self.repair_method
        repair = None
        n = self.layout.n_elements
        if method == "neighbour-mean":
            indptr, indices = self.layout.neighbours
            repair = LocalRepair(method, n, c(indptr, dtype=np.int64), c(indices, dtype=np.int64))
        elif method == "idw8":
            w = idw_weights(self.layout)
            repair = LocalRepair(
                "weighted", n, c(w.indptr, dtype=np.int64), c(w.indices, dtype=np.int64),
                c(w.data, dtype=np.float64),
            )  # fmt: skip
        elif method in ("zero", "last-value"):
            repair = LocalRepair(method, n)
        return Chain(converter, detector=detector, repair=repair, **response)

    def reset(self) -> Pipeline:
        """Start over: unloaded spacer states, no history."""
        self._chain.reset()
        if self._repair is not None:
            self._repair.reset()
        self._last_t = None
        return self

    def state_bytes_per_element(self) -> int:
        """Bytes of streaming state per element (all compiled stages, with the per-element
        parameters they read)."""
        return int(self._chain.state_bytes_per_element())

    def provenance(self) -> dict[str, Any]:
        """What produced the output: calibration id, software version, stages."""
        from texsense import __version__

        return {
            "calibration_id": self.calibration_id,
            "software": f"texsense {__version__}",
            "stages": [k for k, v in self.stages.items() if v]
            + ["convert" if isinstance(self.calibration, MatCalibration) else "convert:linear"]
            + ([f"repair:{self.repair_method}"] if self.repair_method else []),
        }

    def process(
        self, frames_pF: npt.ArrayLike, times_s: npt.ArrayLike, valid: npt.ArrayLike | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Frames of capacitance (T, N) in pF at ``times_s`` (T,) -> pressure (T, N) float64
        in N/cm², the mask of measured (not repaired) readings and the failure codes, both
        (T, N); continues from the present state (so a long recording can go in chunks)."""
        cap = np.ascontiguousarray(frames_pF, dtype=np.float64)
        n = self.layout.n_elements
        if cap.ndim != 2 or cap.shape[1] != n:
            raise ParameterError(f"expected frames (T, {n}), got shape {cap.shape}")
        t = np.asarray(times_s, dtype=np.float64)
        if t.shape != (cap.shape[0],):
            raise ParameterError(f"expected {cap.shape[0]} frame times, got shape {t.shape}")
        v = (
            np.ones(cap.shape, bool)
            if valid is None
            else np.ascontiguousarray(np.broadcast_to(np.asarray(valid, bool), cap.shape))
        )
        if cap.shape[0] == 0:
            return np.empty(cap.shape), np.zeros(cap.shape, bool), np.zeros(cap.shape, np.uint8)
        return self._process(cap, v, t)

    def _process(
        self, cap: np.ndarray, valid: np.ndarray, times: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t0 = times[0] if self._last_t is None else self._last_t
        dt = np.diff(times, prepend=t0)
        if np.any(dt < 0):
            raise ParameterError("frame times must not decrease")
        pressure, codes = self._chain.run(dt, cap, valid)
        self._last_t = float(times[-1])
        ok = codes == 0
        if self._repair is not None:
            for k in range(cap.shape[0]):
                pressure[k], _ = self._repair.step(pressure[k], ok[k])
        return pressure, ok, codes

    def step(
        self, frame_pF: npt.ArrayLike, time_s: float, valid: npt.ArrayLike | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """One frame of capacitance (N,) at ``time_s`` -> pressure (N,) and the mask of
        measured (not repaired) elements."""
        n = self.layout.n_elements
        c = np.ascontiguousarray(frame_pF, dtype=np.float64)
        if c.shape != (n,):
            raise ParameterError(f"expected a frame of {n} elements, got shape {c.shape}")
        if valid is None:
            v = self._all_valid
        else:
            v = np.ascontiguousarray(valid, dtype=bool)
            if v.shape != (n,):
                raise ParameterError(f"expected {n} validity flags, got shape {v.shape}")
        t = float(time_s)
        dt = 0.0 if self._last_t is None else t - self._last_t
        if not dt >= 0:
            raise ParameterError("frame times must not decrease")
        self._dt1[0] = dt
        # the same compiled chain as a batch, with one frame (no per-frame numpy glue)
        p, codes = self._chain.run(self._dt1, c.reshape(1, n), v.reshape(1, n))
        self._last_t = t
        self.codes_ = codes[0]
        ok = self.codes_ == 0
        if self._repair is not None:
            p[0], _ = self._repair.step(p[0], ok)
        return p[0], ok

    def run(self, rec: Recording) -> Recording:
        """A capacitance recording -> a pressure recording (N/cm²) with the validity mask
        (False where a value was repaired or is missing), the failure codes in ``codes_``
        and the provenance in ``meta``."""
        quantity, unit = self.input_quantity
        if rec.quantity != quantity:
            raise ParameterError(f"the pipeline reads {quantity}, not {rec.quantity}")
        if rec.n_elements != self.layout.n_elements:
            raise ParameterError(
                f"the recording has {rec.n_elements} elements, the pipeline "
                f"{self.layout.n_elements}"
            )
        values = rec.to_unit(unit).frames if rec.unit != unit else rec.frames
        p, ok, codes = self._process(
            np.ascontiguousarray(values, dtype=np.float64),
            np.ascontiguousarray(rec.valid, dtype=bool),
            np.asarray(rec.times, np.float64),
        )
        self.codes_ = codes
        meta = {**rec.meta, **self.provenance()}
        out_quantity, out_unit = self.output_quantity
        return rec._with(frames=p, valid=ok, quantity=out_quantity, unit=out_unit, meta=meta)


def _default_detector(
    calibration: MatCalibration | LinearCalibration, layout: Layout
) -> FailureDetector:
    """The detector a calibration implies: with a mat calibration, the expected capacitance
    range per element; with a linear one, only the tests that need no unloaded level (a 0
    reading is an unloaded mat there, not a short), the jump test off, and readings within
    1 % of full scale of the offset never stuck (low readings of an integer-count mat hold
    still at rest)."""
    if isinstance(calibration, LinearCalibration):
        top, floor = None, float(np.max(calibration.offset))
        if calibration.full_scale is not None:
            top = np.full(layout.n_elements, float(calibration.full_scale))
            floor += 0.01 * float(calibration.full_scale)
        return FailureDetector(
            layout,
            max_pF=top,
            high_share=1.0,
            min_pF=-np.inf,
            jump_pF=np.inf,
            stuck_floor_pF=floor,
        )
    lo, hi = calibration.expected_range_pF()
    return FailureDetector(layout, baseline_pF=lo, max_pF=hi)
