"""From raw capacitance frames to pressure maps: a mat's chain of stages
(:class:`~texsense.compensation.stages.StageChain`) compiled into passes of the Rust core,
streaming frame by frame or in batch over a recording.

The pipeline runs the chain **as written**, stage after stage, each with the compiled kernel
its Python stage runs (``crates/core/src/chain.rs``):

- **detect** (:class:`~texsense.compensation.health.FailureDetector`): every detect stage of
  the chain; a chain without one gets the detector its conversion implies (the expected capacitance
  range of every element), right before the conversion;
- **convert** (:class:`~texsense.compensation.stages.Convert`,
  :class:`~texsense.compensation.stages.Linear`):
  eq. 2.1 per element;
- **hysteresis** and **drift** (:class:`~texsense.compensation.stages.Hysteresis`,
  :class:`~texsense.compensation.stages.Drift`, eq. 4.15-4.22 and 5.8; a drift right after a
  hysteresis stage runs in the same pass, QLV included). A failed reading is skipped: the
  element's Preisach and drift states stay frozen until it reads again;
- **repair** (:class:`~texsense.compensation.repair.Repair`): the chain's repair stages where they
  stand; a chain without one gets the method of ``repair=`` after its last stage. Failed
  elements are filled and stay marked False in the output's ``valid`` mask;
- **in-use drift** (``in_use=True``, :class:`~texsense.compensation.inuse.InUseDrift`): the
  drift read from the mat in use (stillness, an empty mat) right after the hysteresis stage, in
  place of the laboratory drift stage; it needs a spacer model and says why when it cannot run
  (:attr:`Pipeline.in_use_note`). With ``interval`` every value gets a bound
  (:mod:`texsense.compensation.intervals`, ``bounds_``).

What is shown and written of the output (the monitor's map, statistics and recording,
``texsense process``'s file) is :func:`no_negative`'s: an empty element's estimate just below
zero as 0, a lower bound never below zero.

Any order the stage contract allows runs; a stage without a compiled kernel is refused in
one line naming it. The local repairs run in the compiled pass; the harmonic ones solve a
sparse system per frame in scipy between compiled passes. ``chain.run(rec)`` (the stages in
Python, float64 between them) gives the same numbers (tested, to the bit, on chains of every
allowed shape), and so do batch and streaming: ``step`` is the same code with one frame.
:meth:`Pipeline.snapshot` and :meth:`Pipeline.restore` carry the whole state (every
element's detector, Preisach memory, drift history and last repaired value, and the time of
the last frame) to another process.
"""

from __future__ import annotations

import inspect
import json
import struct
from math import isfinite
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense._core import Chain, Compensation, __version__
from texsense.compensation.health import FailureDetector
from texsense.compensation.hysteresis import DEFAULT_CAPACITY
from texsense.compensation.intervals import bounds, drift_share, frame_bounds, multiplier
from texsense.compensation.inuse import InUseDrift, InUseState
from texsense.compensation.repair import GLOBAL_METHODS, METHODS, Repair, local_repair
from texsense.compensation.stage import Stage, time_steps
from texsense.compensation.stages import Convert, Drift, Hysteresis, Linear, StageChain
from texsense.data.files import json_loads
from texsense.data.layout import Layout
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError

_F64, _BOOL = np.dtype(np.float64), np.dtype(bool)
#: The strides of a 1-D contiguous array of each (a 2-D array's have two entries).
_STEP_F64, _STEP_BOOL = (_F64.itemsize,), (_BOOL.itemsize,)

__all__ = ["NEAR_ZERO_NCM2", "Pipeline", "layout_mismatch", "no_negative"]


def _arrangement(layout: Layout) -> np.ndarray:
    """The element centres with the layout's offset and scale taken out (each axis onto 0..1):
    what stays the same when a mat's layout is given with another origin or pitch
    (``grid:8x12`` at 1 cm, its recording at its real pitch) and differs when an element sits
    elsewhere among the others (moved, swapped, mirrored)."""
    xy = np.asarray(layout.xy_cm, dtype=np.float64)
    if xy.size == 0:
        return xy
    low, span = xy.min(axis=0), np.ptp(xy, axis=0)
    return (xy - low) / np.where(span > 0, span, 1.0)


def layout_mismatch(expected: Layout, given: Layout) -> str | None:
    """How the elements of ``given`` differ from those of ``expected`` (None: the same
    elements): their count, the grid's shape, the cells they sit in, their places among each
    other (centres, up to the layout's offset and scale on each axis: 1 % of the mat's
    extent); a calibration per element applied to elements in other places would put each
    element's curve on another."""
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
    off = np.abs(_arrangement(expected) - _arrangement(given)).max(axis=1, initial=0.0)
    if off.size and off.max() > 0.01:
        k = int(np.argmax(off))
        (x, y), (gx, gy) = expected.xy_cm[k], given.xy_cm[k]
        return (
            f"the same count with its elements in other places (element {k} at "
            f"({gx:g}, {gy:g}) cm among the others, not ({x:g}, {y:g}))"
        )
    return None


#: A compensated pressure down to this far below zero (N/cm², about 7.5 mmHg: the level under
#: which the in-use correction calls an element empty) is an unloaded element's estimate.
NEAR_ZERO_NCM2 = 0.1


def no_negative(
    values: np.ndarray, lower: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """The pipeline's output as it is shown and written (the monitor's map, statistics and
    recording, ``texsense process``'s file): ``values`` with those at most
    :data:`NEAR_ZERO_NCM2` below zero as 0 (an empty element: its conversion reads about
    -0.001 N/cm², which a file would otherwise mark invalid, so an empty mat read "100 %
    invalid" and its load not a number; further below zero stays, and is flagged invalid by
    the writer: a fault to see), and ``lower`` bounds never below zero (no pressure is).

    >>> v, lo = no_negative(np.array([-0.001, 0.5, -5.0]), np.array([-0.08, 0.42, -5.1]))
    >>> v.tolist(), lo.tolist()
    ([0.0, 0.5, -5.0], [0.0, 0.42, 0.0])
    """
    v = np.asarray(values)
    near = (v < 0) & (v >= -NEAR_ZERO_NCM2)
    if near.any():
        v = np.where(near, np.zeros((), v.dtype), v)
    lo = None if lower is None else np.maximum(lower, 0)
    return v, lo


#: The first bytes of a pipeline's state (:meth:`Pipeline.snapshot`).
STATE_MAGIC = b"TXSNPIPE"
#: The version of that format this build writes and reads.
STATE_VERSION = 1


class _Loading:
    """The first-loading curve in place of a hysteresis stage (``hysteresis=False``)."""

    name = "loading"

    def __init__(self, hysteresis: Hysteresis) -> None:
        self.hysteresis = hysteresis


class _InUse:
    """The in-use drift estimator's place in the plan (right after the hysteresis stage)."""

    name = "in-use drift"

    def __init__(self, estimator: InUseDrift) -> None:
        self.estimator = estimator


class Pipeline:
    """The capacitance-to-pressure chain of one mat, compiled.

    Parameters
    ----------
    chain : StageChain
        The mat's calibration, run as written (see the module documentation).
    layout : Layout
        The mat's elements (neighbours for detection and repair).
    detect, hysteresis, drift : bool
        Switch stages off to see what each contributes (``detect=False``: no detect stage,
        the chain's included; ``hysteresis=False``: the first-loading curve in place of the
        hysteresis stage, and no drift).
    repair : str or None
        A method of :data:`texsense.compensation.repair.METHODS` added after the last stage of
        a chain that holds no repair stage (a chain's own repair stages run where they stand);
        None: no repair at all, failed elements stay NaN (an unknown name raises
        :class:`ParameterError`).
    capacity : int
        Preisach turning points each element keeps (eq. 4.18-4.22); when a stack is full the
        innermost minor loop is forgotten. The default holds every loop seen on real and
        simulated records; a microcontroller keeps fewer (``texsense export mcu
        --capacity``), and the same value here gives its numbers in float64.
    in_use : bool
        Correct the drift in use (:class:`~texsense.compensation.inuse.InUseDrift`) instead of
        with the calibration's drift stage; where the calibration cannot (no spacer model, the
        hysteresis stage off) the pipeline runs without it and :attr:`in_use_note` says why.
    in_use_options : dict, optional
        Settings of :class:`~texsense.compensation.inuse.InUseDrift`.
    interval : float, optional
        Give every value a bound at this level (e.g. 0.95; :mod:`texsense.compensation.intervals`):
        ``bounds_`` holds the lower and upper maps of the last frames. The calibration's
        hysteresis model needs held-out residuals (a preset's, or a held-out record).
    """

    #: A frame of the stream gets its bounds in one compiled pass (False: the numpy reference,
    #: :func:`~texsense.compensation.intervals.bounds`; the same bits, tested).
    compiled_bounds = True

    def __init__(
        self,
        chain: StageChain,
        layout: Layout,
        *,
        detect: bool = True,
        hysteresis: bool = True,
        drift: bool = True,
        repair: str | None = "harmonic",
        capacity: int = DEFAULT_CAPACITY,
        in_use: bool = False,
        in_use_options: dict[str, Any] | None = None,
        interval: float | None = None,
    ) -> None:
        if not isinstance(chain, StageChain):
            raise ParameterError(f"a Pipeline compiles a StageChain, not {type(chain).__name__}")
        if chain.n_elements not in (None, layout.n_elements):
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
        self.chain = chain
        self.layout = layout
        self.detect, self.hysteresis, self.drift, self.repair = detect, hysteresis, drift, repair
        if not 4 <= capacity <= 1 << 16:
            raise ParameterError(f"capacity must be 4 ..= 65536 turning points, got {capacity}")
        self.capacity = int(capacity)
        self.calibration_id = chain.id
        self._in_use_setup(in_use, in_use_options, interval)
        #: the stages the pipeline runs, in order (the chain's, switched, plus what it adds)
        self.plan: list[Stage | _Loading | _InUse] = self._plan()
        found = next((s for s in self.plan if isinstance(s, FailureDetector)), None)
        conversion = chain.conversion
        #: the (first) detector the pipeline runs (or the one the conversion implies)
        self.detector: FailureDetector | None = found or (
            conversion.detector(layout) if conversion is not None else None
        )
        self._parts = self._compile()
        # a stream of one compiled pass steps in one call of its chain, which keeps the
        # stream's clock (Chain.step_at, issue 34)
        one = self._parts[0] if len(self._parts) == 1 and self.interval is None else None
        self._live = one if isinstance(one, Chain) else None
        self._clock: float | None = None  # the clock of a pipeline of several passes
        self.reset()
        self._dt1 = np.zeros(1)
        self._n = layout.n_elements
        self._all_valid = np.ones(layout.n_elements, bool)
        n = layout.n_elements
        self._held = (np.empty(n), np.empty(n, np.uint8), np.empty(n, bool))
        #: the failure codes of the last frames (0: measured)
        self.codes_: np.ndarray = np.zeros((0, layout.n_elements), np.uint8)

    def _in_use_setup(
        self, in_use: bool, options: dict[str, Any] | None, interval: float | None
    ) -> None:
        """The in-use drift estimator (or why not) and the bounds' held-out residuals."""
        self.in_use, self.in_use_options = in_use, options
        hyst, conversion = self.chain.find(Hysteresis), self.chain.conversion
        #: why the in-use drift correction does not run although asked for (None: it runs)
        self.in_use_note: str | None = None
        self.estimator: InUseDrift | None = None
        if in_use and (hyst is None or not isinstance(conversion, Convert)):
            self.in_use_note = "the calibration has no spacer model (hysteresis stage)"
        elif in_use and not self.hysteresis:
            self.in_use_note = "the hysteresis stage is off"
        elif in_use and hyst is not None and isinstance(conversion, Convert):
            opts = {
                "converter": conversion.kernel(),
                "rest_input": float(conversion.curve_compression_mm_[0]),
                **(options or {}),
            }
            self.estimator = InUseDrift(*hyst.loading_points(), self.layout, **opts)
        self.interval = interval
        self._held_out = None
        self._range_max: float | None = None
        if interval is not None:
            self._held_out = None if hyst is None else getattr(hyst.model_, "held_out_", None)
            if self._held_out is None:
                raise ParameterError(
                    "bounds need the calibration's held-out residuals: calibrate with a spacer "
                    "preset, held steps or a held-out record (docs/drift.md, Bounds)"
                )
            multiplier(interval)  # the level is in range and its scores are calibrated
            self._range_max = float(hyst.loading_points()[1][-1]) if hyst is not None else None
        #: the conformal multiplier (None: the calibrated one of the level, ``SCORES``); 1
        #: gives the score's scale σ (what ``benchmarks/night_drift.py --calibrate`` needs)
        self.interval_multiplier: float | None = None
        #: lower and upper maps of the last frames (with ``interval``)
        self.bounds_: tuple[np.ndarray, np.ndarray] | None = None
        self._t_first: float | None = None

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

    # ------------------------------------------------------------------ compiling
    def _plan(self) -> list[Stage | _Loading | _InUse]:
        """The stages to run: the chain's in order, switched off where asked, the implied
        detector before the conversion of a chain without a detect stage, and the repair
        after the last stage of a chain without a repair stage."""
        stages = self.chain.stages
        has_detect = any(isinstance(s, FailureDetector) for s in stages)
        has_repair = any(isinstance(s, Repair) for s in stages)
        plan: list[Stage | _Loading | _InUse] = []
        for k, s in enumerate(stages, 1):
            if isinstance(s, FailureDetector):
                if self.detect:
                    plan.append(s)
            elif isinstance(s, Convert | Linear):
                if self.detect and not has_detect:
                    plan.append(s.detector(self.layout))
                    has_detect = True
                plan.append(s)
            elif isinstance(s, Hysteresis):
                plan.append(s if self.hysteresis else _Loading(s))
                if self.estimator is not None and self.hysteresis:
                    plan.append(_InUse(self.estimator))
            elif isinstance(s, Drift):
                if self.drift and self.hysteresis and self.estimator is None:
                    plan.append(s)
            elif isinstance(s, Repair):
                if self.repair is not None:
                    plan.append(s)
            else:
                raise ParameterError(
                    f"stage {k} of the chain {self.chain.names} ({s.name}, "
                    f"{type(s).__name__}) has no compiled kernel: run it stage by stage "
                    "(chain.run)"
                )
        if self.repair is not None and not has_repair:
            plan.append(Repair(self.layout, self.repair).fit())
        return plan

    def _compile(self) -> list[Chain | Repair | InUseDrift]:
        """The plan as passes: compiled chains of kernels, and the harmonic repairs (scipy)
        between them."""
        n = self.layout.n_elements
        parts: list[Chain | Repair | InUseDrift] = []
        kernels: list[Any] = []
        plan = self.plan
        k = 0
        while k < len(plan):
            s = plan[k]
            if isinstance(s, FailureDetector):
                kernels.append(s.core)
            elif isinstance(s, Convert | Linear):
                kernels.append(s.kernel())
            elif isinstance(s, _InUse):  # between compiled passes, like a harmonic repair
                parts.append(Chain(n, kernels))
                kernels = []
                parts.append(s.estimator)
            elif isinstance(s, _Loading):
                kernels.append(s.hysteresis.loading_curve())
            elif isinstance(s, Hysteresis):
                after = plan[k + 1] if k + 1 < len(plan) else None
                if isinstance(after, Drift):  # one pass: Preisach, then its drift (QLV too)
                    bank, level = after.bank(n), after.model_.level_curve()
                    kernels.append(Compensation(s.bank(n, self.capacity), bank, level))
                    k += 1
                else:
                    kernels.append(Compensation(s.bank(n, self.capacity)))
            elif isinstance(s, Drift):
                if s.needs_inputs:
                    raise ParameterError(
                        "a drift stage on the elastic response (QLV) must follow its "
                        "hysteresis stage directly"
                    )
                kernels.append(s.bank(n))
            elif isinstance(s, Repair) and s.method in GLOBAL_METHODS:
                if kernels or not parts:  # a compiled pass first: it codes the validity
                    parts.append(Chain(n, kernels))
                    kernels = []
                parts.append(Repair(s.layout, s.method).fit())
            elif isinstance(s, Repair):
                kernels.append(local_repair(s.layout, s.method))
            k += 1
        if kernels or not parts:
            parts.append(Chain(n, kernels))
        return parts

    def stage_names(self) -> list[str]:
        """The stages run, in order (a repair with its method, the first-loading curve as
        ``loading``)."""
        return [f"repair:{s.method}" if isinstance(s, Repair) else s.name for s in self.plan]

    def compiled(self) -> Chain:
        """The whole pipeline as one compiled chain (its model blob is what a
        microcontroller runs: :meth:`texsense._core.Chain.mcu_blob`); a pipeline with a
        harmonic repair has none (the repair solves in scipy)."""
        if len(self._parts) != 1 or not isinstance(self._parts[0], Chain):
            raise ParameterError(
                f"the pipeline {self.stage_names()} is not one compiled pass: the harmonic "
                "repairs solve in scipy (use a local repair: zero, last-value, "
                "neighbour-mean, idw8)"
            )
        return self._parts[0]

    # ------------------------------------------------------------------ the stream
    def reset(self) -> Pipeline:
        """Start over: unloaded spacer states, no history."""
        for p in self._parts:
            if isinstance(p, InUseDrift):
                p.forget()
            else:
                p.reset()
        self._last_t: float | None = None
        self._t_first = None
        return self

    def state_bytes_per_element(self) -> int:
        """Bytes of streaming state per element (all compiled stages, with the per-element
        parameters they read)."""
        return sum(int(p.state_bytes_per_element()) for p in self._parts if isinstance(p, Chain))

    def provenance(self) -> dict[str, Any]:
        """What produced the output: calibration id, software version, stages."""
        out: dict[str, Any] = {
            "calibration_id": self.calibration_id,
            "software": f"texsense {__version__}",
            "stages": self.stage_names(),
        }
        if self.in_use:
            out["in_use_drift"] = self.in_use_status()
        return out

    def in_use_status(self) -> dict[str, Any]:
        """The in-use drift correction now (:meth:`InUseState.status`), or why it is off."""
        if self.estimator is None:
            return {"state": "off", "why": self.in_use_note or "not asked for"}
        return self.estimator.state.status(self.estimator.last_t)

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
        """The passes over checked arrays: what ``process`` and ``step`` share."""
        values, ok = cap, valid
        codes: np.ndarray | None = None
        times = None
        if self.estimator is not None or self.interval is not None:  # the frames' times
            if dt.size == 1:  # a frame of the stream (step): at the time it came with
                times = np.full(1, last_t)
            else:
                after = np.concatenate([np.cumsum(dt[::-1])[::-1][1:], [0.0]])
                times = last_t - after
        for p in self._parts:
            if isinstance(p, Chain):
                values, found = p.run(dt, values, np.ascontiguousarray(ok))
                codes = found if codes is None else np.where(codes != 0, codes, found)
                ok = codes == 0
            elif isinstance(p, InUseDrift):
                assert times is not None  # set above when there is an estimator
                values = p.run(values, ok, times, raw=cap)
            else:
                values, _ = p._block(values, ok & np.isfinite(values), dt)
        assert codes is not None  # a compiled pass always runs (_compile)
        self._last_t = last_t
        self.codes_ = codes
        if self.interval is not None and times is not None:
            self.bounds_ = self._bounds(values, ok, times)
        return values, ok, codes

    def _bounds(
        self, values: np.ndarray, ok: np.ndarray, times: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The bounds of a block (:func:`texsense.compensation.intervals.bounds`): the drift
        share from the in-use correction of every frame, or from the time since the stream
        began (the calibration taken as made just before)."""
        assert self._held_out is not None and self.interval is not None
        if self._t_first is None:
            self._t_first = float(times[0])
        hours = (np.asarray(times, dtype=np.float64) - self._t_first) / 3600.0
        est = self.estimator
        corr = est.corrections_ if est is not None else np.full(hours.shape, np.nan)
        ages = est.ages_ if est is not None else np.zeros(hours.shape)
        if hours.size == 1 and self.compiled_bounds:  # a frame of the stream: one compiled pass
            c0 = float(corr[0])
            d0 = drift_share(float(hours[0]), None if c0 != c0 else c0, float(ages[0]))
            lo, hi = frame_bounds(values[0], ok[0], self.interval, self._held_out, drift=d0,
                                  range_max=self._range_max,
                                  multiplier_value=self.interval_multiplier)  # fmt: skip
            return lo[None, :], hi[None, :]
        rows = zip(
            hours.tolist(), np.asarray(corr).tolist(), np.asarray(ages).tolist(), strict=True
        )
        d = np.array([drift_share(h, None if c != c else c, a) for h, c, a in rows])  # c != c: NaN
        return bounds(
            values,
            self.interval,
            self._held_out,
            drift=d[:, None],
            repaired=~ok,
            range_max=self._range_max,
            multiplier_value=self.interval_multiplier,
        )

    @property
    def _last_t(self) -> float | None:
        """The time of the last frame (s; None before the first): the chain's clock for a
        pipeline of one compiled pass, which steps in one call (:meth:`step`)."""
        live = self._live
        return self._clock if live is None else live.last_t

    @_last_t.setter
    def _last_t(self, t: float | None) -> None:
        if self._live is None:
            self._clock = t
        else:
            self._live.last_t = t

    def step(
        self, values: npt.ArrayLike, valid: npt.ArrayLike | None, t: float, *, keep: bool = True
    ) -> tuple[np.ndarray, np.ndarray]:
        """One frame of readings (N,) with their validity (None: all valid) at ``t`` (s) ->
        values (N,) and the mask of measured (not repaired) elements; the failure codes in
        ``codes_``. ``keep=False``: the caller keeps nothing of the frame past the next step,
        so a pipeline of one compiled pass hands out the arrays it steps into (overwritten by
        the next step) instead of copies of them."""
        live = self._live
        if live is not None and keep:  # one call: the chain checks the time and the arrays
            try:
                done = live.step_at(t, values, valid)
            except TypeError:  # a time the binding does not read as a float (float() may)
                done = None
            if done is not None:  # None: readings or validity to convert first (_frame)
                out, self.codes_, ok = done
                return out, ok
        return self._step(values, valid, t, keep)

    def _step(
        self, values: npt.ArrayLike, valid: npt.ArrayLike | None, t: float, keep: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`step` for everything its one call does not take as given."""
        t = float(t)
        last = self._last_t
        dt = 0.0 if last is None else t - last
        if not (dt >= 0 and isfinite(t)):
            raise ParameterError("frame times must be numbers and must not decrease")
        live, n = self._live, self._n
        if live is None:  # several passes: the same compiled chain as a batch, with one frame
            x, v = self._frame(values, valid)
            self._dt1[0] = dt
            v = self._all_valid if v is None else v
            out, ok, codes = self._pass(self._dt1, x.reshape(1, n), v.reshape(1, n), t)
            self.codes_ = codes[0]
            return out[0], ok[0]
        if not (  # what the chain reads is handed to it as given (issue 34): float64 / bool
            (values.__class__ is np.ndarray and values.dtype is _F64)  # arrays of n elements,
            and (values.strides == _STEP_F64 and len(values) == n)  # 1-D, contiguous
            and (
                valid is None
                or (
                    (valid.__class__ is np.ndarray and valid.dtype is _BOOL)
                    and (valid.strides == _STEP_BOOL and len(valid) == n)
                )
            )
        ):
            values, valid = self._frame(values, valid)  # anything else converted first
        if keep:  # new arrays, written once by the chain (the caller may keep them)
            out, self.codes_, ok = live.step_new(dt, values, valid)
        else:  # into the arrays held, overwritten by the next step
            out, codes, ok = self._held
            live.step(dt, values, valid, out, codes, ok)
            self.codes_ = codes
        self._last_t = t
        return out, ok

    def _frame(
        self, values: npt.ArrayLike, valid: npt.ArrayLike | None
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """A frame (N,) float64 and its validity (N,) bool (or None), contiguous, converted
        from what :meth:`step` was given; a frame or validity of another length is one
        ParameterError line."""
        n = self._n
        x = np.ascontiguousarray(values, dtype=np.float64)
        if x.shape != (n,):
            raise ParameterError(f"expected a frame of {n} elements, got shape {x.shape}")
        v = None if valid is None else np.ascontiguousarray(valid, dtype=bool)
        if v is not None and v.shape != (n,):
            raise ParameterError(f"expected {n} validity flags, got shape {v.shape}")
        return x, v

    def run(self, rec: Recording) -> Recording:
        """A recording of readings -> a recording of values (pressure in N/cm² for a mat
        calibration) with the validity mask (False where a value was repaired or is
        missing), the failure codes in ``codes_`` and the provenance in ``meta``."""
        quantity, unit = self.input_quantity
        if quantity and rec.quantity != quantity:
            raise ParameterError(f"the pipeline reads {quantity}, not {rec.quantity}")
        if rec.n_elements != self.layout.n_elements:
            raise ParameterError(
                f"the recording has {rec.n_elements} elements, the pipeline "
                f"{self.layout.n_elements}"
            )
        why = layout_mismatch(self.layout, rec.layout)
        if why:
            raise ParameterError(f"the recording is of another mat than the pipeline's: {why}")
        values = rec.to_unit(unit).frames if unit and rec.unit != unit else rec.frames
        if self._live is not None and rec.n_frames:  # float32 in and out (issue 34)
            p, ok = self._run_f32(values, rec.times, rec.valid)
        else:
            p, ok, _ = self.process(values, rec.times, rec.valid)
        meta = {**rec.meta, **self.provenance()}
        out_quantity, out_unit = self.output_quantity
        return rec._with(
            frames=p,
            valid=ok,
            quantity=out_quantity or rec.quantity,
            unit=out_unit or rec.unit,
            meta=meta,
        )

    def _run_f32(
        self, frames: np.ndarray, times: np.ndarray, valid: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """What ``process`` does for a pipeline of one compiled pass, on a recording's float32
        frames: the chain reads and writes float32 a tile at a time (``Chain.run_f32``: the
        float64 values rounded to float32, as the recording would store them, bit for bit),
        so the batch is never copied to float64 and back."""
        assert self._live is not None
        t = np.asarray(times, dtype=np.float64)
        dt = time_steps(t, self._last_t)
        out, codes = self._live.run_f32(dt, frames, np.ascontiguousarray(valid, dtype=bool))
        self._last_t = float(t[-1])
        self.codes_ = codes
        return out, codes == 0

    # ------------------------------------------------------------------ state
    def snapshot(self) -> bytes:
        """The whole streaming state as bytes (versioned): every element's detector,
        Preisach memory, drift history and last repaired value, the harmonic repairs' last
        frames and the time of the last frame. :meth:`restore` in a pipeline of the same
        calibration (in any process) continues the stream exactly where it stopped."""
        sections = [_part_state(p) for p in self._parts]
        head = json.dumps(
            {
                "calibration_id": self.calibration_id,
                "stages": self.stage_names(),
                "last_t": self._last_t,
                "sections": [len(s) for s in sections],
            }
        ).encode()
        size = struct.pack("<II", STATE_VERSION, len(head))
        return b"".join([STATE_MAGIC, size, head, *sections])

    def restore(self, state: bytes) -> Pipeline:
        """Continue from a :meth:`snapshot` of a pipeline of the same calibration and stages
        (all or nothing: a snapshot that does not fit raises :class:`ParameterError` naming
        why and leaves the state as it was)."""
        head, sections = _read_state(bytes(state))
        if head.get("calibration_id") != self.calibration_id:
            raise ParameterError(
                f"the state is of calibration {head.get('calibration_id')}, this pipeline's is "
                f"{self.calibration_id}"
            )
        if head.get("stages") != self.stage_names() or len(sections) != len(self._parts):
            raise ParameterError(
                f"the state is of the stages {head.get('stages')}, this pipeline runs "
                f"{self.stage_names()}"
            )
        last_t = head.get("last_t")
        if last_t is not None and not isinstance(last_t, int | float):
            raise ParameterError("the state's last frame time is not a number")
        before = [_part_state(p) for p in self._parts]
        try:
            for p, s in zip(self._parts, sections, strict=True):
                _restore_part(p, s)
        except ValueError as e:  # the core's errors are ValueErrors
            for p, s in zip(self._parts, before, strict=True):
                _restore_part(p, s)
            raise ParameterError(f"the state does not fit this pipeline: {e}") from None
        self._last_t = None if last_t is None else float(last_t)
        self.codes_ = np.zeros((0, self.layout.n_elements), np.uint8)
        return self


def _part_state(p: Chain | Repair | InUseDrift) -> bytes:
    """One part's state: a compiled pass's, a harmonic repair's, the in-use state (JSON; a still
    period under way starts again after a restore)."""
    if isinstance(p, Chain):
        return bytes(p.snapshot())
    if isinstance(p, InUseDrift):
        return json.dumps(p.state.to_dict()).encode()
    return _repair_state(p)


def _restore_part(p: Chain | Repair | InUseDrift, s: bytes) -> None:
    if isinstance(p, Chain):
        p.restore(s)
    elif isinstance(p, InUseDrift):
        try:
            state = InUseState.from_dict(json_loads(s), p.layout.n_elements)
        except (ParameterError, TypeError, KeyError) as e:
            raise ValueError(f"the in-use drift state: {e}") from None
        p.set_state(state)
    else:
        _restore_repair(p, s)


def _repair_state(r: Repair) -> bytes:
    """A harmonic repair's state: its last value and its previous frame, per element."""
    return np.concatenate([r._last, r._prev]).astype("<f8").tobytes()


def _restore_repair(r: Repair, s: bytes) -> None:
    n = r.layout.n_elements
    if len(s) != 16 * n:
        raise ValueError(f"a harmonic repair's state needs {16 * n} bytes, got {len(s)}")
    a = np.frombuffer(s, "<f8").astype(np.float64)
    r._last, r._prev = a[:n].copy(), a[n:].copy()


def _read_state(state: bytes) -> tuple[dict[str, Any], list[bytes]]:
    """The header and the sections of a pipeline's state; anything else is one
    ParameterError saying what."""
    k = len(STATE_MAGIC)
    if state[:k] != STATE_MAGIC or len(state) < k + 8:
        raise ParameterError("not a texsense pipeline state")
    version, size = struct.unpack_from("<II", state, k)
    if version != STATE_VERSION:
        raise ParameterError(
            f"a pipeline state of version {version}; this build reads version {STATE_VERSION}"
        )
    try:
        head = json_loads(state[k + 8 : k + 8 + size])
        lengths = [int(x) for x in head["sections"]]
    except (ValueError, KeyError, TypeError):
        raise ParameterError("the pipeline state's header is damaged") from None
    pos, sections = k + 8 + size, []
    for length in lengths:
        sections.append(state[pos : pos + length])
        pos += length
    if pos != len(state) or any(x < 0 for x in lengths):
        raise ParameterError("the pipeline state is cut short or has bytes left over")
    return head, sections
