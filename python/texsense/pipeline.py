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

Batch and streaming give the same numbers (tested): :meth:`Pipeline.run` is the streaming
path applied to all frames at once, stage by stage.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.calibration import MatCalibration
from texsense.exceptions import ParameterError
from texsense.health import FailureDetector
from texsense.layout import Layout
from texsense.recording import Recording
from texsense.repair import Repair

__all__ = ["Pipeline"]


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
        calibration: MatCalibration,
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
        model = calibration.model
        if model is None:
            raise ParameterError("the calibration has no spacer model (compression -> pressure)")
        if drift and hysteresis and getattr(model, "drift_", None) is None:
            drift = False  # nothing to apply: recorded in the provenance
        self.calibration = calibration
        self.layout = layout
        self.stages = {"detect": detect, "hysteresis": hysteresis, "drift": drift}
        self.repair_method = repair
        lo, hi = calibration.expected_range_pF()
        self.detector = detector or FailureDetector(layout, baseline_pF=lo, max_pF=hi)
        self._repair = Repair(layout, repair) if repair is not None else None
        e = np.linspace(model.u_min_, model.u_max_, 400)
        self._loading = (e, np.maximum.accumulate(model.predict(e)))
        self._stage: Any = None
        self._last_t: float | None = None
        self.codes_: np.ndarray | None = None
        self.reset()

    def reset(self) -> Pipeline:
        """Start over: unloaded spacer states, no history."""
        self.detector.reset()
        if self._repair is not None:
            self._repair.reset()
        if self.stages["hysteresis"]:
            self._stage = self.calibration.model.compensation(
                self.layout.n_elements, drift=self.stages["drift"]
            )
        self._last_t = None
        return self

    def provenance(self) -> dict[str, Any]:
        """What produced the output: calibration id, software version, stages."""
        from texsense import __version__

        return {
            "calibration_id": self.calibration.id,
            "software": f"texsense {__version__}",
            "stages": [k for k, v in self.stages.items() if v]
            + ["convert"]
            + ([f"repair:{self.repair_method}"] if self.repair_method else []),
        }

    def _process(
        self, cap: np.ndarray, valid: np.ndarray, times: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Frames (T, N) -> pressure (T, N), measured mask (T, N), failure codes (T, N)."""
        n_t = cap.shape[0]
        if self.stages["detect"]:
            codes = np.stack([self.detector.step(cap[k], valid[k]) for k in range(n_t)])
        else:
            codes = np.where(valid & np.isfinite(cap), 0, 2).astype(np.uint8)
        ok = codes == 0
        comp = self.calibration.to_compression(cap)
        if self._stage is not None:
            t0 = times[0] if self._last_t is None else self._last_t
            dt = np.diff(times, prepend=t0)
            if np.any(dt < 0):
                raise ParameterError("frame times must not decrease")
            pressure = self._stage.run(
                np.ascontiguousarray(dt), np.ascontiguousarray(comp), np.ascontiguousarray(ok)
            )
        else:
            e, p = self._loading
            pressure = np.where(ok, np.interp(comp, e, p), np.nan)
        self._last_t = float(times[-1])  # failed readings are NaN from either branch
        if self._repair is not None:
            for k in range(n_t):
                pressure[k], _ = self._repair.step(pressure[k], ok[k])
        return pressure, ok, codes

    def step(
        self, frame_pF: npt.ArrayLike, time_s: float, valid: npt.ArrayLike | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """One frame of capacitance (N,) at ``time_s`` -> pressure (N,) and the mask of
        measured (not repaired) elements."""
        c = np.asarray(frame_pF, dtype=np.float64)[None, :]
        v = np.ones_like(c, bool) if valid is None else np.asarray(valid, bool)[None, :]
        if c.shape[1] != self.layout.n_elements:
            raise ParameterError(
                f"expected a frame of {self.layout.n_elements} elements, got {c.shape[1]}"
            )
        p, ok, codes = self._process(c, v, np.array([float(time_s)]))
        self.codes_ = codes[0]
        return p[0], ok[0]

    def run(self, rec: Recording) -> Recording:
        """A capacitance recording -> a pressure recording (N/cm²) with the validity mask
        (False where a value was repaired or is missing), the failure codes in ``codes_``
        and the provenance in ``meta``."""
        if rec.quantity != "capacitance":
            raise ParameterError(f"the pipeline reads capacitance, not {rec.quantity}")
        if rec.n_elements != self.layout.n_elements:
            raise ParameterError(
                f"the recording has {rec.n_elements} elements, the pipeline "
                f"{self.layout.n_elements}"
            )
        cap = rec.to_unit("pF").frames.astype(np.float64) if rec.unit != "pF" else rec.frames
        p, ok, codes = self._process(
            np.asarray(cap, dtype=np.float64), rec.valid, np.asarray(rec.times, np.float64)
        )
        self.codes_ = codes
        meta = {**rec.meta, **self.provenance()}
        return rec._with(frames=p, valid=ok, quantity="pressure", unit="N/cm2", meta=meta)
