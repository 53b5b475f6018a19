"""From raw capacitance frames to pressure maps: a mat's chain of stages
(:class:`~texsense.compensation.stages.StageChain`) compiled into one pass of the Rust core,
streaming frame by frame or in batch over a recording.

- **detect** (:class:`~texsense.compensation.health.FailureDetector`): the chain's detect stage, or
  the detector its conversion implies (the expected capacitance range of every element);
- **convert** (:class:`~texsense.compensation.stages.Convert`): capacitance -> compression per
  element (eq. 2.1, zeroed and equilibrated), or a linear calibration
  (:class:`~texsense.compensation.stages.Linear`);
- **hysteresis + drift** (:class:`~texsense.compensation.stages.Hysteresis`,
  :class:`~texsense.compensation.stages.Drift`) in one pass (eq. 4.15-4.22, eq. 5.8). A failed
  reading is skipped: the element's Preisach and drift states stay frozen until it reads again.
  Without the hysteresis stage the compression is converted with the first-loading curve (what an
  uncompensated system does);
- **repair** (:class:`~texsense.compensation.repair.Repair`): failed elements are filled (eq. 6.14
  or a better method) and stay marked False in the output's ``valid`` mask.

The compiled chain (``crates/core/src/chain.rs``) runs the stages' own kernels one after the
other over the whole block of frames, in parallel over blocks of elements; the harmonic
repairs solve a sparse system per frame in scipy afterwards. ``chain.run(rec)`` (the stages
in Python, float64 between them) gives the same numbers (tested, to the bit), and so do
batch and streaming: ``step`` is the same code with one frame.
"""

from __future__ import annotations

import inspect
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense._core import Chain, Compensation, __version__
from texsense.compensation.health import FailureDetector
from texsense.compensation.repair import GLOBAL_METHODS, METHODS, Repair, local_repair
from texsense.compensation.stage import time_steps
from texsense.compensation.stages import Convert, Drift, Hysteresis, Linear, StageChain
from texsense.data.layout import Layout
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

__all__ = ["Pipeline", "layout_mismatch"]


def layout_mismatch(expected: Layout, given: Layout) -> str | None:
    """How the elements of ``given`` differ from those of ``expected`` (None: the same
    elements): their count, the grid's shape, the cells they sit in; a calibration per element
    applied to elements in other places would put each element's curve on another."""
    if expected.n_elements != given.n_elements:
        return f"{expected.n_elements} elements, not {given.n_elements}"
    if (expected.shape is None) != (given.shape is None):
        return f"a {expected.kind} layout, not a {given.kind} layout"
    if expected.shape is not None and expected.shape != given.shape:
        (r, c), (gr, gc) = expected.shape, given.shape  # type: ignore[misc]
        return f"a grid of {r} x {c}, not {gr} x {gc}"
    if expected.cells is not None and (
        given.cells is None or not np.array_equal(expected.cells, given.cells)
    ):
        return "the same grid with its elements in other cells"
    return None


class Pipeline:
    """The capacitance-to-pressure chain of one mat, compiled.

    Parameters
    ----------
    chain : StageChain
        The mat's calibration: a conversion stage (convert or linear), the spacer's stages
        (hysteresis, optionally drift) and optionally a detect stage.
    layout : Layout
        The mat's elements (neighbours for detection and repair).
    detect, hysteresis, drift : bool
        Switch stages off to see what each contributes (``hysteresis=False``: the
        first-loading curve).
    repair : str or None
        A method of :data:`texsense.compensation.repair.METHODS`, or None to leave failed elements
        NaN (an unknown name raises :class:`ParameterError`).
    """

    def __init__(
        self,
        chain: StageChain,
        layout: Layout,
        *,
        detect: bool = True,
        hysteresis: bool = True,
        drift: bool = True,
        repair: str | None = "harmonic",
    ) -> None:
        if not isinstance(chain, StageChain):
            raise ParameterError(f"a Pipeline compiles a StageChain, not {type(chain).__name__}")
        conversion = chain.conversion
        if conversion is None:
            raise ParameterError(f"the chain {chain.names} has no convert or linear stage")
        if chain.n_elements != layout.n_elements:
            raise ParameterError(
                f"the calibration is for {chain.n_elements} elements, the layout has "
                f"{layout.n_elements}"
            )
        for stage in chain.stages:
            made_for = getattr(stage, "layout", None)
            why = layout_mismatch(made_for, layout) if isinstance(made_for, Layout) else None
            if why:
                raise ParameterError(f"the calibration was made for another mat: {why}")
        if repair is not None and repair not in METHODS:
            raise ParameterError(f"unknown repair method {repair!r}; known: {', '.join(METHODS)}")
        if isinstance(conversion, Convert) and "hysteresis" not in chain:
            raise ParameterError("the calibration has no spacer model (compression -> pressure)")
        self.chain = chain
        self.layout = layout
        self.detect, self.hysteresis, self.drift, self.repair = detect, hysteresis, drift, repair
        self.calibration_id = chain.id
        linear = isinstance(conversion, Linear)
        self.stages = {
            "detect": detect,
            "hysteresis": hysteresis and not linear,
            "drift": drift and hysteresis and "drift" in chain,
        }
        self.detector: FailureDetector = chain.find(FailureDetector) or conversion.detector(layout)
        self._repair = None
        if repair is not None and repair in GLOBAL_METHODS:
            self._repair = Repair(layout, repair).fit()
        self._chain = self._compile(conversion)
        self._chain.reset()  # the kernels' copies start a stream of their own
        self._last_t: float | None = None
        self._dt1 = np.zeros(1)
        self._all_valid = np.ones(layout.n_elements, bool)
        #: the failure codes of the last frames (0: measured)
        self.codes_ = np.zeros((0, layout.n_elements), np.uint8)

    def get_params(self) -> dict[str, Any]:
        """The constructor's arguments, by name (as every stage has them)."""
        names = [p for p in inspect.signature(type(self).__init__).parameters if p != "self"]
        return {name: getattr(self, name) for name in names}

    @property
    def input_quantity(self) -> tuple[str, str]:
        """(quantity, unit) of the readings the pipeline takes."""
        return self.chain.reads

    @property
    def output_quantity(self) -> tuple[str, str]:
        """(quantity, unit) of the values the pipeline gives."""
        return self.chain.gives

    def _compile(self, conversion: Convert | Linear) -> Chain:
        """The compiled chain: the stages' own kernels, one after the other."""
        n = self.layout.n_elements
        response: dict[str, Any] = {}
        hyst = self.chain.find(Hysteresis)
        if hyst is not None and isinstance(conversion, Convert):
            if self.stages["hysteresis"]:
                drift = self.chain.find(Drift) if self.stages["drift"] else None
                bank = None if drift is None else drift.bank(n)
                level = None if drift is None else drift.model_.level_curve()
                response["compensation"] = Compensation(hyst.bank(n), bank, level)
            else:
                response["loading"] = hyst.loading_curve()
        method = self.repair
        local = method is not None and method not in GLOBAL_METHODS
        return Chain(
            conversion.kernel(),
            detector=self.detector.core if self.stages["detect"] else None,
            repair=local_repair(self.layout, method) if local and method else None,
            **response,
        )

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
        convert = "convert:linear" if "linear" in self.chain else "convert"
        return {
            "calibration_id": self.calibration_id,
            "software": f"texsense {__version__}",
            "stages": [k for k, v in self.stages.items() if v]
            + [convert]
            + ([f"repair:{self.repair}"] if self.repair else []),
        }

    def process(
        self, frames_pF: npt.ArrayLike, times_s: npt.ArrayLike, valid: npt.ArrayLike | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Frames of readings (T, N) at ``times_s`` (T,) -> values (T, N) float64, the mask of
        measured (not repaired) readings and the failure codes, both (T, N); continues from
        the present state (so a long recording can go in chunks)."""
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
        return self._pass(time_steps(t, self._last_t), cap, v, float(t[-1]))

    def _pass(
        self, dt: np.ndarray, cap: np.ndarray, valid: np.ndarray, last_t: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The compiled chain (and a harmonic repair) over checked arrays: what ``process``
        and ``step`` share."""
        values, codes = self._chain.run(dt, cap, valid)
        self._last_t = last_t
        ok = codes == 0
        if self._repair is not None:
            values, _ = self._repair._block(values, ok & np.isfinite(values), dt)
        self.codes_ = codes
        return values, ok, codes

    def step(
        self, values: npt.ArrayLike, valid: npt.ArrayLike | None, t: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """One frame of readings (N,) with their validity (None: all valid) at ``t`` (s) ->
        values (N,) and the mask of measured (not repaired) elements; the failure codes in
        ``codes_``."""
        n = self.layout.n_elements
        x = np.ascontiguousarray(values, dtype=np.float64)
        if x.shape != (n,):
            raise ParameterError(f"expected a frame of {n} elements, got shape {x.shape}")
        v = self._all_valid if valid is None else np.ascontiguousarray(valid, dtype=bool)
        if v.shape != (n,):
            raise ParameterError(f"expected {n} validity flags, got shape {v.shape}")
        t = float(t)
        dt = 0.0 if self._last_t is None else t - self._last_t
        if not (dt >= 0 and np.isfinite(t)):
            raise ParameterError("frame times must be numbers and must not decrease")
        self._dt1[0] = dt
        # the same compiled chain as a batch, with one frame (no per-frame numpy glue)
        out, ok, codes = self._pass(self._dt1, x.reshape(1, n), v.reshape(1, n), t)
        self.codes_ = codes[0]
        return out[0], ok[0]

    def run(self, rec: Recording) -> Recording:
        """A recording of readings -> a recording of values (pressure in N/cm² for a mat
        calibration) with the validity mask (False where a value was repaired or is
        missing), the failure codes in ``codes_`` and the provenance in ``meta``."""
        quantity, unit = self.input_quantity
        if rec.quantity != quantity:
            raise ParameterError(f"the pipeline reads {quantity}, not {rec.quantity}")
        if rec.n_elements != self.layout.n_elements:
            raise ParameterError(
                f"the recording has {rec.n_elements} elements, the pipeline "
                f"{self.layout.n_elements}"
            )
        why = layout_mismatch(self.layout, rec.layout)
        if why:
            raise ParameterError(f"the recording is of another mat than the pipeline's: {why}")
        values = rec.to_unit(unit).frames if rec.unit != unit else rec.frames
        p, ok, _ = self.process(values, rec.times, rec.valid)
        meta = {**rec.meta, **self.provenance()}
        out_quantity, out_unit = self.output_quantity
        return rec._with(frames=p, valid=ok, quantity=out_quantity, unit=out_unit, meta=meta)
