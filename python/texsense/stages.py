"""Stages as peers: one contract for every stage of the capacitance-to-pressure chain.

Every stage

- stores its parameters in the constructor (nothing is learned there);
- learns in ``fit(...)``, which returns the stage; everything it learned ends in ``_``;
- maps readings to readings: ``step(values (N,), valid (N,), t)`` for one frame and
  ``run(recording)`` for many return values and validity the same way (``run`` gives a
  recording), the same numbers either way (tested for every stage);
- leaves an element's state untouched by a reading that is invalid or not a number (only time
  passes for it; the detector's stuck counter restarts after a reading that is not a number),
  and marks that reading invalid in its output;
- forgets its stream with ``reset()``;
- saves and loads itself in one versioned envelope
  ``{"format": "texsense.stage", "version": 1, "stage": NAME, "params": {...}, "fitted": {...}}``.

=============  ================================  =========================================
stage          maps                              learns in ``fit``
=============  ================================  =========================================
``detect``     capacitance -> capacitance,       unloaded level and largest expected
               validity &= healthy (§6.5.2.5)    reading per element
``convert``    capacitance -> compression        material curve, per-element offset and
               (eq. 2.1)                         gain (zeroing, equilibration)
``hysteresis`` compression -> pressure           the Everett function
               (eq. 4.15-4.22)
``drift``      pressure -> pressure (eq. 5.8)    γ and the kernel, from held steps
``repair``     fills failed readings (eq. 6.14   nothing (parameters only)
               and better methods)
=============  ================================  =========================================

:class:`StageChain` holds the fitted stages of a mat in order and saves them as one file
(``"format": "texsense.chain"``); :func:`load_chain` also reads the mat calibration files of
the first round. ``chain.calibration()`` gives what :class:`texsense.pipeline.Pipeline`
compiles: the whole chain then runs as one pass of the Rust core.

Examples
--------
>>> import numpy as np
>>> from texsense import Layout
>>> from texsense.stages import Repair
>>> stage = Repair(Layout.grid(3, 3), method="neighbour-mean").fit()
>>> x = np.arange(9.0); ok = np.ones(9, bool); ok[4] = False
>>> values, valid = stage.step(x, ok, t=0.0)
>>> float(values[4]), bool(valid[4])
(4.0, False)
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from texsense.exceptions import FormatError, NotFittedError, ParameterError
from texsense.layout import Layout
from texsense.recording import Recording

__all__ = [
    "CHAIN_FORMAT",
    "STAGE_FORMAT",
    "Convert",
    "Detect",
    "Drift",
    "Hysteresis",
    "Repair",
    "Stage",
    "StageChain",
    "load_chain",
    "stage_from_dict",
]

STAGE_FORMAT = "texsense.stage"
CHAIN_FORMAT = "texsense.chain"
FORMAT_VERSION = 1


class Stage:
    """The contract every stage follows (see the module documentation)."""

    #: Name in files and in the chain.
    name: ClassVar[str] = ""
    #: (quantity, unit) read and given.
    reads: ClassVar[tuple[str, str]] = ("", "")
    gives: ClassVar[tuple[str, str]] = ("", "")

    # -- what a stage implements
    def _params(self) -> dict[str, Any]:
        raise NotImplementedError

    def _fitted(self) -> dict[str, Any]:
        raise NotImplementedError

    def _load_fitted(self, fitted: Mapping[str, Any]) -> None:
        raise NotImplementedError

    def _block(
        self, values: np.ndarray, valid: np.ndarray, dt: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(T, N) values and validity with the time steps (T,) -> the same, continuing the
        stream."""
        raise NotImplementedError

    def _reset_stream(self) -> None:
        raise NotImplementedError

    # -- the contract, shared
    def is_fitted(self) -> bool:
        """True once :meth:`fit` (or :meth:`from_dict`) has given the stage its state."""
        return any(k.endswith("_") and not k.startswith("_") for k in vars(self))

    def _check_fitted(self) -> None:
        if not self.is_fitted():
            raise NotFittedError(f"the {self.name} stage is not fitted yet: call fit()")

    def reset(self) -> Stage:
        """Forget the stream (the start of a new recording); the fitted state stays."""
        self._last_t: float | None = None
        if self.is_fitted():
            self._reset_stream()
        return self

    def _dt(self, times: np.ndarray) -> np.ndarray:
        last = getattr(self, "_last_t", None)
        dt = np.diff(times, prepend=times[0] if last is None else last)
        if np.any(dt < 0) or not np.all(np.isfinite(dt)):
            raise ParameterError("frame times must be numbers that do not decrease")
        self._last_t = float(times[-1])
        return dt

    def step(
        self, values: npt.ArrayLike, valid: npt.ArrayLike | None = None, t: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """One frame: values (N,), validity (N,) at time ``t`` (s) -> values and validity."""
        self._check_fitted()
        x = np.asarray(values, dtype=np.float64).reshape(1, -1)
        ok = np.ones(x.shape, bool) if valid is None else np.asarray(valid, bool).reshape(1, -1)
        if ok.shape != x.shape:
            raise ParameterError(f"valid has shape {ok.shape[1:]}, values {x.shape[1:]}")
        ok = ok & np.isfinite(x)
        out, out_ok = self._block(x, ok, self._dt(np.array([float(t)])))
        return out[0], out_ok[0]

    def run(self, rec: Recording) -> Recording:
        """A recording of what the stage reads -> a recording of what it gives, with the
        validity of every reading; continues the stream."""
        self._check_fitted()
        quantity, unit = self.reads
        if quantity and rec.quantity != quantity:
            raise ParameterError(f"the {self.name} stage reads {quantity}, not {rec.quantity}")
        frames = rec.to_unit(unit).frames if unit and rec.unit != unit else rec.frames
        x = np.asarray(frames, dtype=np.float64)
        ok = rec.valid & np.isfinite(x)
        if rec.n_frames == 0:
            return rec._with(quantity=self.gives[0] or rec.quantity, unit=self.gives[1] or rec.unit)
        out, out_ok = self._block(x, ok, self._dt(np.asarray(rec.times, np.float64)))
        return rec._with(
            frames=out,
            valid=out_ok,
            quantity=self.gives[0] or rec.quantity,
            unit=self.gives[1] or rec.unit,
        )

    # -- files
    def to_dict(self) -> dict[str, Any]:
        """The versioned envelope (JSON-able)."""
        return {
            "format": STAGE_FORMAT,
            "version": FORMAT_VERSION,
            "stage": self.name,
            "params": self._params(),
            "fitted": self._fitted() if self.is_fitted() else None,
        }

    def save(self, path: str | Path) -> Path:
        """Write the stage file (JSON)."""
        path = Path(path)
        path.write_text(json.dumps(self.to_dict()), encoding="utf-8")
        return path

    @classmethod
    def load(cls, path: str | Path) -> Stage:
        """Read a stage file (any stage)."""
        return stage_from_dict(read_json(path), path)

    def __repr__(self) -> str:
        state = "fitted" if self.is_fitted() else "not fitted"
        return f"{type(self).__name__}({self._params()}, {state})"


# ---------------------------------------------------------------------------------- detect
class Detect(Stage):
    """Failure detection on raw capacitance (thesis §6.5.2.5, :mod:`texsense.health`): a
    reading that fails is marked invalid (its value passes unchanged); the codes of the last
    frames are in ``codes_`` after each call."""

    name = "detect"
    reads = ("capacitance", "pF")
    gives = ("capacitance", "pF")

    def __init__(self, layout: Layout, **thresholds: float) -> None:
        from texsense.health import FailureDetector

        known = set(FailureDetector.__dataclass_fields__) - {"layout", "baseline_pF", "max_pF"}
        unknown = set(thresholds) - known
        if unknown:
            raise ParameterError(f"unknown detector thresholds {sorted(unknown)}")
        self.layout = layout
        self.thresholds = dict(thresholds)
        self._last_t = None

    def fit(self, baseline: Recording | None = None, max_pF: npt.ArrayLike | None = None) -> Detect:
        """Learn each element's unloaded level from an unloaded recording (mean of its valid
        readings) and take the largest reading to expect (e.g. from a :class:`Convert`
        stage: :meth:`Convert.expected_range_pF`)."""
        from texsense.calibration import _mean_reading

        n = self.layout.n_elements
        self.baseline_pF_ = None if baseline is None else _mean_reading(baseline, "baseline")
        self.max_pF_ = None if max_pF is None else np.asarray(max_pF, np.float64).reshape(n)
        self._build()
        return self

    def _build(self) -> None:
        from texsense.health import FailureDetector

        self._detector = FailureDetector(
            self.layout, baseline_pF=self.baseline_pF_, max_pF=self.max_pF_, **self.thresholds
        )

    def is_fitted(self) -> bool:
        return hasattr(self, "baseline_pF_")

    def _reset_stream(self) -> None:
        self._detector.reset()

    def _block(self, values, valid, dt):  # noqa: ANN001
        self.codes_ = self._detector.detect(values, valid)
        return values, valid & (self.codes_ == 0)

    def _params(self) -> dict[str, Any]:
        return {"layout": self.layout.to_dict(), "thresholds": self.thresholds}

    def _fitted(self) -> dict[str, Any]:
        as_list = lambda a: None if a is None else a.tolist()  # noqa: E731
        return {"baseline_pF": as_list(self.baseline_pF_), "max_pF": as_list(self.max_pF_)}

    def _load_fitted(self, fitted: Mapping[str, Any]) -> None:
        as_array = lambda a: None if a is None else np.asarray(a, np.float64)  # noqa: E731
        self.baseline_pF_ = as_array(fitted["baseline_pF"])
        self.max_pF_ = as_array(fitted["max_pF"])
        self._build()

    @classmethod
    def _create(cls, params: Mapping[str, Any]) -> Detect:
        return cls(Layout.from_dict(params["layout"]), **params.get("thresholds", {}))


# --------------------------------------------------------------------------------- convert
class Convert(Stage):
    """Capacitance -> compression per element (eq. 2.1): ``C_i = a_i + b_i C_ref(e)``
    (:class:`texsense.calibration.MatCalibration` without its spacer model)."""

    name = "convert"
    reads = ("capacitance", "pF")
    gives = ("compression", "mm")

    def __init__(self, thickness_mm: float, uniform_pressure_ncm2: float = 1.0) -> None:
        self.thickness_mm = float(thickness_mm)
        self.uniform_pressure_ncm2 = float(uniform_pressure_ncm2)
        self._last_t = None

    def fit(
        self, material: Mapping[str, np.ndarray], baseline: Recording, uniform: Recording
    ) -> Convert:
        """Zeroing (``baseline``, unloaded) and equilibration (``uniform``, under
        ``uniform_pressure_ncm2``) against the material curve of a test-machine record
        (``compression_mm``, ``capacitance_pF``, ``pressure_ncm2``)."""
        from texsense.calibration import MatCalibration, fit_conversion

        ce, cc, offset, gain = fit_conversion(
            dict(material), baseline, uniform, self.uniform_pressure_ncm2
        )
        self._take(MatCalibration.from_parts(ce, cc, offset, gain, None, self.thickness_mm))
        return self

    def _take(self, cal: Any) -> None:
        self.curve_compression_mm_ = cal.curve_compression_mm
        self.curve_capacitance_pF_ = cal.curve_capacitance_pF
        self.offset_pF_ = cal.offset_pF
        self.gain_ = cal.gain

    def expected_range_pF(self) -> tuple[np.ndarray, np.ndarray]:
        """Per element: capacitance unloaded and at the end of the material curve."""
        self._check_fitted()
        c = self.curve_capacitance_pF_
        return self.offset_pF_ + self.gain_ * c[0], self.offset_pF_ + self.gain_ * c[-1]

    def _reset_stream(self) -> None:
        pass  # no stream state

    def _block(self, values, valid, dt):  # noqa: ANN001
        ref = (values - self.offset_pF_) / self.gain_
        e = np.interp(ref, self.curve_capacitance_pF_, self.curve_compression_mm_)
        return np.where(valid, e, np.nan), valid.copy()

    def _params(self) -> dict[str, Any]:
        return {
            "thickness_mm": self.thickness_mm,
            "uniform_pressure_ncm2": self.uniform_pressure_ncm2,
        }

    def _fitted(self) -> dict[str, Any]:
        return {
            "curve": {
                "compression_mm": self.curve_compression_mm_.tolist(),
                "capacitance_pF": self.curve_capacitance_pF_.tolist(),
            },
            "elements": {"offset_pF": self.offset_pF_.tolist(), "gain": self.gain_.tolist()},
        }

    def _load_fitted(self, fitted: Mapping[str, Any]) -> None:
        from texsense.calibration import MatCalibration

        cal = MatCalibration.from_parts(
            fitted["curve"]["compression_mm"], fitted["curve"]["capacitance_pF"],
            fitted["elements"]["offset_pF"], fitted["elements"]["gain"], None, self.thickness_mm,
        )  # fmt: skip
        self._take(cal)

    @classmethod
    def _create(cls, params: Mapping[str, Any]) -> Convert:
        return cls(params["thickness_mm"], params.get("uniform_pressure_ncm2", 1.0))


# ------------------------------------------------------------------------------ hysteresis
class Hysteresis(Stage):
    """Compression -> pressure by the Preisach model (eq. 4.15-4.22,
    :class:`texsense.hysteresis.HysteresisModel`), one state per element."""

    name = "hysteresis"
    reads = ("compression", "mm")
    gives = ("pressure", "N/cm2")

    def __init__(self, method: str = "auto", grid: int = 100) -> None:
        self.method = method
        self.grid = int(grid)
        self._last_t = None

    def fit(self, compression_mm: npt.ArrayLike, pressure_ncm2: npt.ArrayLike) -> Hysteresis:
        """Identify the Everett function from a test-machine record."""
        from texsense.hysteresis import HysteresisModel

        self.model_ = HysteresisModel(method=self.method, grid=self.grid).fit(
            compression_mm, pressure_ncm2
        )
        self._state = None
        return self

    def _reset_stream(self) -> None:
        self._state = None

    def _block(self, values, valid, dt):  # noqa: ANN001
        if self._state is None or self._state.n_elements != values.shape[1]:
            self._state = self.model_.state(values.shape[1])
        out = self._state.run(values, valid)
        return out, valid & np.isfinite(out)

    def _params(self) -> dict[str, Any]:
        return {"method": self.method, "grid": self.grid}

    def _fitted(self) -> dict[str, Any]:
        d = self.model_.to_dict()
        d["drift"] = None  # drift is its own stage
        return {"model": d}

    def _load_fitted(self, fitted: Mapping[str, Any]) -> None:
        from texsense.hysteresis import HysteresisModel

        self.model_ = HysteresisModel.from_dict(fitted["model"])
        self.model_.drift_ = None
        self._state = None

    @classmethod
    def _create(cls, params: Mapping[str, Any]) -> Hysteresis:
        return cls(params.get("method", "auto"), params.get("grid", 100))


# ----------------------------------------------------------------------------------- drift
class Drift(Stage):
    """The drift of eq. 5.8 added to the hysteresis output
    (:class:`texsense.drift.DriftModel`), one state per element."""

    name = "drift"
    reads = ("pressure", "N/cm2")
    gives = ("pressure", "N/cm2")

    def __init__(self, kind: str = "log", rest_rate: float = 0.0) -> None:
        self.kind = kind
        self.rest_rate = float(rest_rate)
        self._last_t = None

    def fit(self, steps: Sequence[Any]) -> Drift:
        """γ (and the kernel) from held steps (:func:`texsense.drift.split_steps`)."""
        from texsense.drift import DriftModel

        self.model_, self.step_fit_ = DriftModel.fit(
            list(steps), kind=self.kind, rest_rate=self.rest_rate
        )
        self._bank = None
        return self

    def _reset_stream(self) -> None:
        self._bank = None

    def _block(self, values, valid, dt):  # noqa: ANN001
        if self._bank is None or self._bank_n != values.shape[1]:
            self._bank, self._bank_n = self.model_.state(values.shape[1]), values.shape[1]
        out = self._bank.run(np.ascontiguousarray(dt), np.ascontiguousarray(values), valid)
        return out, valid & np.isfinite(out)

    def is_fitted(self) -> bool:
        return hasattr(self, "model_")

    def _params(self) -> dict[str, Any]:
        return {"kind": self.kind, "rest_rate": self.rest_rate}

    def _fitted(self) -> dict[str, Any]:
        return {"model": self.model_.to_dict()}

    def _load_fitted(self, fitted: Mapping[str, Any]) -> None:
        from texsense.drift import DriftModel

        self.model_ = DriftModel.from_dict(fitted["model"])
        self._bank = None

    @classmethod
    def _create(cls, params: Mapping[str, Any]) -> Drift:
        return cls(params.get("kind", "log"), params.get("rest_rate", 0.0))


# ---------------------------------------------------------------------------------- repair
class Repair(Stage):
    """Failed readings filled (thesis §6.5.2.5, :class:`texsense.repair.Repair`); they stay
    marked invalid in the output, so a repaired value is never mistaken for a measured one."""

    name = "repair"
    reads = ("", "")
    gives = ("", "")

    def __init__(self, layout: Layout, method: str = "harmonic") -> None:
        from texsense.repair import METHODS

        if method not in METHODS:
            raise ParameterError(f"unknown repair method {method!r}; known: {', '.join(METHODS)}")
        self.layout = layout
        self.method = method
        self._last_t = None

    def fit(self) -> Repair:
        """Nothing to learn: prepares the method for the layout."""
        from texsense.repair import Repair as _Repair

        self.ready_ = True
        self._repair = _Repair(self.layout, self.method)
        return self

    def _reset_stream(self) -> None:
        self._repair.reset()

    def _block(self, values, valid, dt):  # noqa: ANN001
        out = np.empty_like(values)
        for k in range(values.shape[0]):
            out[k], _ = self._repair.step(values[k], valid[k])
        return out, valid.copy()

    def _params(self) -> dict[str, Any]:
        return {"layout": self.layout.to_dict(), "method": self.method}

    def _fitted(self) -> dict[str, Any]:
        return {}

    def _load_fitted(self, fitted: Mapping[str, Any]) -> None:
        self.fit()

    @classmethod
    def _create(cls, params: Mapping[str, Any]) -> Repair:
        return cls(Layout.from_dict(params["layout"]), params.get("method", "harmonic"))


STAGES: dict[str, type[Stage]] = {s.name: s for s in (Detect, Convert, Hysteresis, Drift, Repair)}


def read_json(path: str | Path) -> Any:
    """A JSON file's content; an unreadable, binary or malformed file raises
    :class:`FormatError` naming it (and the line)."""
    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise FormatError(path, f"cannot read: {e.strerror}") from None
    except UnicodeDecodeError:
        raise FormatError(path, "not JSON: a binary file") from None
    except json.JSONDecodeError as e:
        raise FormatError(path, f"not JSON: {e.msg}", line=e.lineno) from None


def stage_from_dict(d: Any, source: str | Path = "<dict>") -> Stage:
    """A stage from its envelope; every problem raises :class:`FormatError` naming it."""
    if not isinstance(d, dict) or d.get("format") != STAGE_FORMAT:
        raise FormatError(source, f"not a {STAGE_FORMAT} description")
    if d.get("version") != FORMAT_VERSION:
        raise FormatError(source, f"stage version {d.get('version')!r}; this texsense reads 1")
    cls = STAGES.get(d.get("stage"))
    if cls is None:
        raise FormatError(source, f"unknown stage {d.get('stage')!r}; known: {sorted(STAGES)}")
    try:
        stage = cls._create(d.get("params", {}))  # type: ignore[attr-defined]
        if d.get("fitted") is not None:
            stage._load_fitted(d["fitted"])
    except (KeyError, TypeError, ValueError) as e:
        if isinstance(e, FormatError):
            raise
        raise FormatError(source, f"{cls.name} stage: bad or missing field ({e})") from None
    return stage.reset()


# ----------------------------------------------------------------------------------- chain
class StageChain:
    """The fitted stages of a mat, in order: detect, convert, hysteresis, [drift]; saved
    as one file. A repair stage is chosen when processing (``texsense process --repair``),
    not stored with the calibration."""

    def __init__(self, stages: Sequence[Stage]) -> None:
        names = [s.name for s in stages]
        order = [n for n in ("detect", "convert", "hysteresis", "drift") if n in names]
        if names != order or "convert" not in names or "hysteresis" not in names:
            raise ParameterError(
                f"a mat chain is detect?, convert, hysteresis, drift? in this order; got {names}"
            )
        for s in stages:
            s._check_fitted()
        self.stages = list(stages)

    def __getitem__(self, name: str) -> Stage:
        for s in self.stages:
            if s.name == name:
                return s
        raise KeyError(name)

    def __contains__(self, name: str) -> bool:
        return any(s.name == name for s in self.stages)

    @property
    def id(self) -> str:
        """Content hash of every stage's parameters and fitted state."""
        import hashlib

        body = json.dumps(self.to_dict()["stages"], sort_keys=True).encode()
        return hashlib.sha256(body).hexdigest()[:16]

    @property
    def n_elements(self) -> int:
        """Number of elements of the mat."""
        return int(self["convert"].gain_.size)  # type: ignore[attr-defined]

    def detector(self) -> Any:
        """The failure detector of the detect stage (None without one)."""
        return self["detect"]._detector if "detect" in self else None  # type: ignore[attr-defined]

    @classmethod
    def fit_mat(
        cls,
        material: Mapping[str, np.ndarray],
        baseline: Recording,
        uniform: Recording,
        uniform_pressure_ncm2: float,
        thickness_mm: float,
        *,
        steps: Sequence[Any] | None = None,
    ) -> StageChain:
        """The mat calibration as a chain: convert (zeroing, equilibration), hysteresis from
        the material record, drift from held steps if given, detection with the expected
        range of every element."""
        convert = Convert(thickness_mm, uniform_pressure_ncm2).fit(material, baseline, uniform)
        hyst = Hysteresis().fit(material["compression_mm"], material["pressure_ncm2"])
        lo, hi = convert.expected_range_pF()
        detect = Detect(baseline.layout)
        detect.baseline_pF_, detect.max_pF_ = lo, hi
        detect._build()
        stages: list[Stage] = [detect, convert, hyst]
        if steps is not None:
            stages.append(Drift().fit(steps))
        return cls(stages)

    @classmethod
    def from_calibration(cls, cal: Any, layout: Layout | None = None) -> StageChain:
        """The chain of a first-round :class:`~texsense.calibration.MatCalibration` (the
        detect stage needs the mat's layout; without one the chain has no detect stage)."""
        from texsense.drift import DriftModel

        convert = Convert(cal.thickness_mm, cal.uniform_pressure_ncm2 or 1.0)
        convert._take(cal)
        hyst = Hysteresis(method=cal.model.method_, grid=int(cal.model.everett_.shape[0]))
        hyst._load_fitted({"model": cal.model.to_dict()})
        stages: list[Stage] = [convert, hyst]
        if layout is not None:
            detect = Detect(layout)
            detect.baseline_pF_, detect.max_pF_ = cal.expected_range_pF()
            detect._build()
            stages.insert(0, detect)
        drift = getattr(cal.model, "drift_", None)
        if drift is not None:
            d = Drift(drift.kind if drift.kind in ("log", "thesis") else "log", drift.rest_rate)
            d.model_ = DriftModel.from_dict(drift.to_dict())
            d._bank = None
            stages.append(d)
        return cls([s.reset() for s in stages])

    def calibration(self) -> Any:
        """The :class:`~texsense.calibration.MatCalibration` that the compiled pipeline runs
        (the same numbers as the stages, one pass of the Rust core)."""
        from texsense.calibration import MatCalibration
        from texsense.hysteresis import HysteresisModel

        c = self["convert"]
        model = HysteresisModel.from_dict(self["hysteresis"].model_.to_dict())  # type: ignore[attr-defined]
        model.drift_ = self["drift"].model_ if "drift" in self else None  # type: ignore[attr-defined]
        return MatCalibration.from_parts(
            c.curve_compression_mm_, c.curve_capacitance_pF_, c.offset_pF_, c.gain_,  # type: ignore[attr-defined]
            model, c.thickness_mm, c.uniform_pressure_ncm2,  # type: ignore[attr-defined]
        )  # fmt: skip

    def reset(self) -> StageChain:
        """Every stage's stream forgotten."""
        for s in self.stages:
            s.reset()
        return self

    def run(self, rec: Recording) -> Recording:
        """The stages one after the other in Python (the reference for the compiled
        pipeline; use :class:`~texsense.pipeline.Pipeline` for speed)."""
        for s in self.stages:
            rec = s.run(rec)
        return rec

    def to_dict(self) -> dict[str, Any]:
        """One versioned file: the envelopes of the stages in order."""
        return {
            "format": CHAIN_FORMAT,
            "version": FORMAT_VERSION,
            "stages": [s.to_dict() for s in self.stages],
        }

    def save(self, path: str | Path) -> Path:
        """Write the chain file (JSON)."""
        path = Path(path)
        path.write_text(json.dumps(self.to_dict()), encoding="utf-8")
        return path

    @classmethod
    def from_dict(cls, d: Any, source: str | Path = "<dict>") -> StageChain:
        """Inverse of :meth:`to_dict`."""
        if not isinstance(d, dict) or d.get("format") != CHAIN_FORMAT:
            raise FormatError(source, f"not a {CHAIN_FORMAT} file")
        if d.get("version") != FORMAT_VERSION:
            raise FormatError(source, f"chain version {d.get('version')!r}; this texsense reads 1")
        stages = [stage_from_dict(s, source) for s in d.get("stages", [])]
        try:
            return cls(stages)
        except (ParameterError, NotFittedError) as e:
            raise FormatError(source, str(e)) from None


def load_chain(path: str | Path, layout: Layout | None = None) -> StageChain:
    """Read a chain file, or a mat calibration file of the first round (``layout`` adds the
    detect stage to the latter)."""
    d = read_json(path)
    if isinstance(d, dict) and d.get("format") == CHAIN_FORMAT:
        return StageChain.from_dict(d, path)
    from texsense.calibration import MatCalibration, calibration_from_dict

    cal = calibration_from_dict(d, path)
    if not isinstance(cal, MatCalibration):
        raise FormatError(path, "a linear calibration has no stage chain (no spacer model)")
    return StageChain.from_calibration(cal, layout)
