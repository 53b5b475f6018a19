"""The spacer's stages: compression -> pressure by the Preisach model (``hysteresis``,
eq. 4.15-4.22) and the drift of eq. 5.8 after it (``drift``). Both run the compiled banks
(``PreisachBank``, ``DriftBank``) that the pipeline's chain runs in one pass
(``Compensation``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from texsense._core import Curve, DriftBank, PreisachBank
from texsense.compensation.drift import RANGES as DRIFT_RANGES
from texsense.compensation.drift import DriftModel, StepFit
from texsense.compensation.hysteresis import DEFAULT_CAPACITY, HysteresisModel
from texsense.compensation.hysteresis._model import RANGES as MODEL_RANGES
from texsense.compensation.stage import Stage
from texsense.data.modelfile import Fields
from texsense.data.ranges import Kind
from texsense.exceptions import ParameterError

__all__ = ["Drift", "Hysteresis"]


class Hysteresis(Stage):
    """Compression -> pressure by the Preisach model (eq. 4.15-4.22,
    :class:`texsense.compensation.hysteresis.HysteresisModel`), one state per element.

    Parameters
    ----------
    method, grid, cells, smoothing, folds
        How :meth:`fit` identifies the Everett function (see
        :class:`~texsense.compensation.hysteresis.HysteresisModel`).
    """

    name = "hysteresis"
    _reads = ("compression", "mm")
    _gives = ("pressure", "N/cm2")

    #: the range of every parameter (the model's, :mod:`texsense.data.ranges`)
    ranges: ClassVar[Mapping[str, Kind]] = {
        k: MODEL_RANGES[k] for k in ("method", "grid", "cells", "smoothing", "folds")
    }

    #: learned: the Preisach model (its Everett function)
    model_: HysteresisModel

    def __init__(
        self,
        method: str = "auto",
        grid: int = 100,
        cells: int | None = None,
        smoothing: float | None = None,
        folds: int = 4,
    ) -> None:
        self.method = method
        self.grid = grid
        self.cells = cells
        self.smoothing = smoothing
        self.folds = folds

    @classmethod
    def of(cls, model: HysteresisModel) -> Hysteresis:
        """The stage of a fitted model (its parameters the model's)."""
        model._check_fitted()
        stage = cls(**{name: getattr(model, name) for name in cls._param_names()})
        return stage.set_fitted(model=model)

    def fit(self, compression_mm: npt.ArrayLike, pressure_ncm2: npt.ArrayLike) -> Hysteresis:
        """Identify the Everett function from a test-machine record. The same record and
        parameters give the same model: made once per version of the code
        (``HysteresisModel.fit(..., remember=True)``)."""
        model = HysteresisModel(**self.get_params())  # the stage's parameters are the model's
        model.fit(compression_mm, pressure_ncm2, remember=True)
        return self.set_fitted(model=model)

    def _prepare(self) -> None:
        if not isinstance(self.model_, HysteresisModel):
            raise ParameterError("the hysteresis stage needs a HysteresisModel")
        self.model_._check_fitted()

    def _reset_stream(self) -> None:
        self._bank: PreisachBank | None = None

    def bank(self, n_elements: int, capacity: int = DEFAULT_CAPACITY) -> PreisachBank:
        """A fresh compiled Preisach bank of ``n_elements`` (lower saturation), each element
        keeping at most ``capacity`` turning points."""
        self._check_fitted()
        return self.model_.bank(n_elements, capacity)

    def loading_points(self, points: int = 400) -> tuple[np.ndarray, np.ndarray]:
        """The first-loading curve as arrays (compression, pressure): the model's output on a
        rise from lower saturation, made non-decreasing."""
        m = self.model_
        e = np.linspace(m.u_min_, m.u_max_, points)
        p = np.maximum.accumulate(m.predict(e))
        return np.ascontiguousarray(e), np.ascontiguousarray(p, dtype=np.float64)

    def loading_curve(self) -> Curve:
        """The first-loading curve compression -> pressure (what an uncompensated system
        does), :meth:`loading_points` as the core's curve."""
        return Curve(*self.loading_points())

    @property
    def clamped(self) -> np.ndarray:
        """Inputs clamped into the identified range, per element, in this stream."""
        return np.zeros(0, np.uint64) if self._bank is None else self._bank.clamped()

    def _block(
        self, values: np.ndarray, valid: np.ndarray, dt: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        if self._bank is None or self._bank.n_elements != values.shape[1]:
            self._bank = self.bank(values.shape[1])
        out = self._bank.run(values, valid)
        return out, valid & np.isfinite(out)

    def _fitted_json(self) -> dict[str, Any]:
        return {"model": self.model_.to_content()}

    @classmethod
    def _fitted_from_json(cls, fields: Fields, params: Mapping[str, Any]) -> dict[str, Any]:
        return {"model": HysteresisModel.from_content(fields.sub("model"))}


class Drift(Stage):
    """The drift of eq. 5.8 added to the hysteresis output
    (:class:`texsense.compensation.drift.DriftModel`), one state per element.

    Parameters
    ----------
    kind : {"log", "thesis", "prony"}
        The kernel :meth:`fit` identifies (see :meth:`texsense.compensation.drift.DriftModel.fit`).
    rest_rate : float
        > 0: the kernel runs on the rest clock (N/cm² per s that halves it).
    """

    name = "drift"
    _reads = ("pressure", "N/cm2")
    _gives = ("pressure", "N/cm2")

    #: the range of every parameter (the model's, :mod:`texsense.data.ranges`)
    ranges: ClassVar[Mapping[str, Kind]] = {k: DRIFT_RANGES[k] for k in ("kind", "rest_rate")}

    #: learned: γ and the kernel; how well γ fitted the held steps (after fit only)
    model_: DriftModel
    step_fit_: StepFit | None

    def __init__(self, kind: str = "log", rest_rate: float = 0.0) -> None:
        self.kind = kind
        self.rest_rate = rest_rate

    @classmethod
    def of(cls, model: DriftModel) -> Drift:
        """The stage of a fitted drift model (its parameters the model's)."""
        return cls(model.kind, model.rest_rate).set_fitted(model=model)

    def fit(self, steps: Sequence[Any]) -> Drift:
        """γ (and the kernel) from held steps (:func:`texsense.compensation.drift.split_steps`)."""
        model = DriftModel.fit_steps(list(steps), kind=self.kind, rest_rate=float(self.rest_rate))
        self.step_fit_ = model.step_fit_
        return self.set_fitted(model=model)

    def _prepare(self) -> None:
        if not isinstance(self.model_, DriftModel):
            raise ParameterError("the drift stage needs a DriftModel")

    def _reset_stream(self) -> None:
        self._bank: DriftBank | None = None

    def bank(self, n_elements: int) -> DriftBank:
        """A fresh compiled drift bank of ``n_elements``."""
        self._check_fitted()
        return self.model_.state(n_elements)

    @property
    def needs_inputs(self) -> bool:
        """True for QLV (``level="backbone"``): the stage needs the hysteresis stage's inputs
        (:meth:`block_on`), which a chain gives it."""
        return self.model_.level == "backbone"

    def _block(
        self, values: np.ndarray, valid: np.ndarray, dt: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        if self.needs_inputs:
            raise ParameterError(
                "this drift stage relaxes the elastic response of the input (QLV): run it in "
                "a chain right after its hysteresis stage"
            )
        if self._bank is None or self._bank.n_elements != values.shape[1]:
            self._bank = self.bank(values.shape[1])
        out = self._bank.run(dt, values, valid)
        return out, valid & np.isfinite(out)

    def block_on(
        self, values: np.ndarray, valid: np.ndarray, dt: np.ndarray, inputs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_block` given also the hysteresis stage's inputs (QLV)."""
        if not self.needs_inputs:
            return self._block(values, valid, dt)
        if self._bank is None or self._bank.n_elements != values.shape[1]:
            self._bank = self.bank(values.shape[1])
        out = self.model_.add_backbone_drift(self._bank, dt, values, valid, inputs)
        return out, valid & np.isfinite(out)

    def _fitted_json(self) -> dict[str, Any]:
        return {"model": self.model_.to_dict()}

    @classmethod
    def _fitted_from_json(cls, fields: Fields, params: Mapping[str, Any]) -> dict[str, Any]:
        return {"model": DriftModel.from_content(fields.sub("model"))}
