"""The Preisach hysteresis model: identification, evaluation in the Rust core, model files.

A model file is the ``texsense.compensation.hysteresis`` envelope of :mod:`texsense.data.modelfile`
(content hash checked on load); the files of the first round, with a drift stage attached, read as a
chain of hysteresis and drift (:mod:`texsense.data.legacy`)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from texsense._core import PreisachBank
from texsense.compensation.hysteresis._identify import (
    Identified,
    _beats,
    find_thesis_curves,
    fold_mse,
    held_out_of_table,
    identify_lsq,
    identify_relay,
    identify_thesis,
)
from texsense.compensation.hysteresis._lsq import branch_folds
from texsense.compensation.hysteresis._relay import loop_orientation
from texsense.compensation.hysteresis._segments import split_branches
from texsense.compensation.intervals import HeldOut
from texsense.data import modelfile, units
from texsense.data.fitcache import remembered
from texsense.data.modelfile import Fields
from texsense.data.ranges import Checked, Kind, Maybe, OneOf, RangeError, Real, Text, UnitOf, Whole
from texsense.exceptions import FormatError, NotFittedError, ParameterError, UnitError

__all__ = ["MODEL_FORMAT", "MODEL_VERSION", "HysteresisModel", "PreisachState", "scale_hysteresis"]

MODEL_FORMAT = "texsense.hysteresis"
#: A record with at most this many monotone branches and the thesis's curves is the thesis
#: protocol (its calibration has 6; a 65 s random sawtooth 38-54).
FEW_BRANCHES = 16
#: The relative RMSE gain on held-out folds that lets one candidate replace another (with
#: the one-standard-error rule).
CLEAR_GAIN = 0.2

#: The range of every parameter of a model (:mod:`texsense.data.ranges`; the hysteresis
#: stage's are these), checked by the constructor.
RANGES = {
    "method": OneOf(("auto", "lsq", "thesis", "relay")),
    "grid": Whole(2, 2000),
    "cells": Maybe(Whole(1, 2000), "chosen by cross-validation"),
    "smoothing": Maybe(Real(0.0, 1e12), "chosen by cross-validation"),
    "folds": Whole(2, 100),
    "input_name": Text(),
    "output_name": Text(),
    "input_unit": UnitOf(),
    "output_unit": UnitOf(),
}
#: The bounds of a file's Everett table and output offset (output units), its input range.
_OUTPUT = Real(-1e12, 1e12)
_INPUT = Real(-1e9, 1e9)


def _clearly_beats(challenger: Any, incumbent: Any) -> bool:
    """One standard error over folds and at least :data:`CLEAR_GAIN` lower pooled RMSE."""
    c, i = np.asarray(challenger, float), np.asarray(incumbent, float)
    return _beats(c, i) and np.sqrt(c.mean()) <= (1 - CLEAR_GAIN) * np.sqrt(i.mean())


#: The quantile of the absolute held-out error that stands for a candidate's tail.
TAIL_QUANTILE = 95.0


def _tails(pred: np.ndarray, p: np.ndarray, fold: np.ndarray) -> tuple[np.ndarray, float]:
    """The :data:`TAIL_QUANTILE` percentile of the absolute held-out error in every fold, and
    over all held-out samples."""
    err = np.abs(pred - p)
    per_fold = np.asarray(
        [np.percentile(err[fold == f], TAIL_QUANTILE) for f in range(int(fold.max()) + 1)]
    )
    return per_fold, float(np.percentile(err[fold >= 0], TAIL_QUANTILE))


def _clearly_smaller_tail(
    challenger: tuple[np.ndarray, float], incumbent: tuple[np.ndarray, float]
) -> bool:
    """The tail (:func:`_tails`) smaller by more than one standard error over the folds and
    by at least :data:`CLEAR_GAIN` over all held-out samples."""
    return _beats(challenger[0], incumbent[0]) and challenger[1] <= (1 - CLEAR_GAIN) * incumbent[1]


def _orientation(ident: Identified) -> float:
    """Orientation of an identified model's major loop (positive: counter-clockwise, as
    magnetisation against field; negative: clockwise, as a spacer)."""
    bank = PreisachBank(
        ident.u_min, ident.u_max, np.ascontiguousarray(ident.everett), 1, 256, ident.offset, 1.0
    )
    x = np.linspace(ident.u_min, ident.u_max, 201)
    path = np.concatenate([x, x[::-1]])
    y = bank.run(np.ascontiguousarray(path[:, None]), np.ones((path.size, 1), bool))[:, 0]
    return loop_orientation(path, y)


MODEL_VERSION = modelfile.FORMATS[MODEL_FORMAT]
DEFAULT_CAPACITY = 256


class PreisachState:
    """Streaming evaluation for N elements (the Rust ``PreisachBank``).

    Parameters
    ----------
    model : HysteresisModel
        A fitted model.
    n_elements : int
        Elements evaluated side by side.
    capacity : int
        Extrema kept per element (see the stack policy in ``crates/core/src/preisach.rs``).
    """

    def __init__(
        self, model: HysteresisModel, n_elements: int = 1, capacity: int = DEFAULT_CAPACITY
    ) -> None:
        model._check_fitted()
        if n_elements < 1:
            raise ParameterError(f"n_elements must be >= 1, got {n_elements}")
        self.model = model
        self.n_elements = int(n_elements)
        self._bank = model.bank(self.n_elements, capacity)

    def reset(self) -> PreisachState:
        """Back to lower saturation (input u_min, output = the model's offset)."""
        self._bank.reset()
        return self

    def run(self, inputs: npt.ArrayLike, valid: npt.ArrayLike | None = None) -> np.ndarray:
        """Outputs (T, N) for inputs (T, N) (or (T,) for one element), continuing the state.
        Invalid or NaN inputs give NaN and leave the element's state untouched."""
        u = np.asarray(inputs, dtype=np.float64)
        one = u.ndim == 1
        u2 = np.ascontiguousarray(u[:, None] if one else u)
        v = np.ones(u2.shape, bool) if valid is None else np.asarray(valid, bool).reshape(u2.shape)
        out = self._bank.run(u2, np.ascontiguousarray(v))
        return out[:, 0] if one else out

    def step(self, frame: npt.ArrayLike, valid: npt.ArrayLike | None = None) -> np.ndarray:
        """Outputs (N,) for one frame of inputs (N,)."""
        u = np.asarray(frame, dtype=np.float64).reshape(1, -1)
        v = None if valid is None else np.asarray(valid, bool).reshape(1, -1)
        return self.run(u, v)[0]

    def set_state(self, inputs: npt.ArrayLike, outputs: npt.ArrayLike) -> np.ndarray:
        """Start every element at an input with a known output (§6.4.4); outputs outside the
        model's major loop are clamped to it. Returns the outputs set."""
        u = np.broadcast_to(np.asarray(inputs, np.float64), (self.n_elements,))
        h = np.broadcast_to(np.asarray(outputs, np.float64), (self.n_elements,))
        return self._bank.set_state(np.ascontiguousarray(u), np.ascontiguousarray(h))

    @property
    def clamped(self) -> np.ndarray:
        """Samples per element whose input was clamped into the identified range."""
        return self._bank.clamped()

    @property
    def forgotten(self) -> np.ndarray:
        """Minor loops per element forgotten because the stack was full."""
        return self._bank.forgotten()


class HysteresisModel(Checked):
    """A Preisach model from an input (compression, displacement, field, ...) to an output
    (pressure, force, magnetisation, ...), identified from a calibration record.

    Parameters
    ----------
    method : {"auto", "lsq", "thesis", "relay"}
        ``lsq``: constrained least squares on any record (every turning point; monotone table
        by construction; grid and smoothing chosen by cross-validation on held-out reversal
        curves unless given). ``thesis``: the thesis's rising curve + falling curves
        (§4.4.2). ``relay``: a non-negative Preisach density on a relay grid whose nodes
        follow the record (:mod:`._relay`; magnetic and other counter-clockwise loops,
        sharp switching). ``auto`` (default): on the thesis protocol the thesis table, least
        squares with the thesis prior, or their average (:meth:`_auto`); on other records
        least squares, or the relay grid where it is clearly better on held-out curves.
        The generalisation benchmark in docs/hysteresis.md chose these rules.
    grid : int
        Size K of the evaluated Everett table (K x K).
    cells : int, optional
        Coarse cells of least squares, in α and in the distance fallen α - β alike (None:
        chosen by cross-validation).
    smoothing : float, optional
        Curvature penalty of least squares (None: chosen by cross-validation).
    folds : int
        Folds of held-out reversal curves for the cross-validation.
    input_name, output_name, input_unit, output_unit : str
        What the model maps (stored in the model file and checked when applied).

    Examples
    --------
    >>> from texsense.sim.protocols import run_protocol
    >>> cal = run_protocol("calibration", "textile-6mm", seed=1, sample_hz=None)
    >>> model = HysteresisModel().fit(cal.labels["compression_mm"], cal.labels["pressure_ncm2"])
    >>> model.method_
    'thesis/lsq average'
    """

    #: the range of every parameter (:data:`RANGES`), checked when made and when set
    ranges: ClassVar[Mapping[str, Kind]] = RANGES

    def __init__(
        self,
        method: str = "auto",
        grid: int = 100,
        cells: int | None = None,
        smoothing: float | None = None,
        folds: int = 4,
        input_name: str = "compression_mm",
        output_name: str = "pressure_ncm2",
        input_unit: str = "mm",
        output_unit: str = "N/cm2",
    ) -> None:
        self.method = method
        self.grid = grid
        self.cells = cells
        self.smoothing = smoothing
        self.folds = folds
        self.input_name = input_name
        self.output_name = output_name
        self.input_unit = input_unit
        self.output_unit = output_unit
        self.check_all()  # and each parameter set after (ranges.Checked)

    def _what(self) -> str:
        return "the hysteresis model"

    # ------------------------------------------------------------------ fitting
    def fit(
        self,
        inputs: npt.ArrayLike,
        outputs: npt.ArrayLike,
        provenance: dict[str, Any] | None = None,
        *,
        remember: bool = False,
    ) -> HysteresisModel:
        """Identify the Everett function from a record of inputs and outputs (T,).

        With ``remember``, the model is identified once per record, parameters and version of
        the code, and read back after that (:func:`texsense.data.fitcache.remembered`): the
        same model to the bit, in milliseconds instead of seconds (a spacer preset's record
        is fitted in every calibration made from it)."""
        if remember:
            return self._fit_remembered(inputs, outputs, provenance)
        if self.method not in ("auto", "thesis", "lsq", "relay"):
            raise ParameterError(f"method must be auto, lsq, relay or thesis, got {self.method!r}")
        units.canonical(self.input_unit)
        units.canonical(self.output_unit)
        u = np.asarray(inputs, dtype=np.float64).ravel()
        p = np.asarray(outputs, dtype=np.float64).ravel()
        if u.shape != p.shape:
            raise ParameterError(f"inputs and outputs differ in length: {u.size} vs {p.size}")
        ok = np.isfinite(u) & np.isfinite(p)
        if ok.sum() < 10:
            raise ParameterError("need at least 10 finite samples to identify a model")
        u, p = u[ok], p[ok]
        if np.ptp(u) <= 0:
            raise ParameterError("the input does not vary: nothing to identify")
        # the Preisach part needs an output that rises with the input: flip it otherwise
        sign = 1.0 if np.corrcoef(u, p)[0, 1] >= 0 else -1.0
        if self.method == "thesis":
            ident: Identified = identify_thesis(u, sign * p, self.grid)
        elif self.method == "relay":
            ident = identify_relay(
                u, sign * p, self.grid, nodes=self.cells, ridge=self.smoothing,
                folds=self.folds, signed=None,
            )  # fmt: skip
        elif self.method == "lsq":
            ident = identify_lsq(
                u, sign * p, grid=self.grid, cells=self.cells, smoothing=self.smoothing,
                folds=self.folds,
            )  # fmt: skip
        else:
            ident = self._auto(u, sign * p)
        self.everett_ = ident.everett
        self.u_min_ = ident.u_min
        self.u_max_ = ident.u_max
        self.offset_ = ident.offset
        self.sign_ = sign
        self.method_ = ident.method
        self.details_ = ident.details
        self.held_out_: HeldOut | None = None  # residuals on a record not fitted on (bounds)
        self.provenance_ = dict(provenance or {})
        return self

    def _params(self) -> dict[str, Any]:
        """The constructor's arguments by name (what :meth:`check_all` checks)."""
        names = "method grid cells smoothing folds input_name output_name input_unit output_unit"
        return {name: getattr(self, name) for name in names.split()}

    def _fit_remembered(
        self, inputs: npt.ArrayLike, outputs: npt.ArrayLike, provenance: dict[str, Any] | None
    ) -> HysteresisModel:
        params = self._params()
        u = np.asarray(inputs, dtype=np.float64).ravel()
        p = np.asarray(outputs, dtype=np.float64).ravel()
        fitted = remembered(
            "hysteresis",
            [params, dict(provenance or {}), u, p],
            lambda: HysteresisModel(**params).fit(u, p, provenance).to_content(),
            lambda content: HysteresisModel.from_content(Fields(content, "the fit cache")),
        )
        vars(self).update(vars(fitted))  # this model, fitted
        return self

    def _auto(self, u: np.ndarray, p: np.ndarray) -> Identified:
        """The default. Cross-validation compares candidates on held-out reversal curves of
        the record; a more flexible candidate replaces a structured one only when it is
        better on the folds by more than one standard error (:func:`_beats`) *and* by at
        least :data:`CLEAR_GAIN` in RMSE.

        - **The thesis protocol** (the thesis's curves, at most :data:`FEW_BRANCHES`
          monotone branches): the thesis method (§4.4.2) and least squares with the thesis
          table as a prior are compared; without a clear winner in RMSE the default is their
          average (the two tables' mean: a model average, monotone like both), unless one of
          them has a clearly smaller *tail* on the held-out curves than the average (the 95th
          percentile of the absolute error, :func:`_clearly_smaller_tail`): a few falling
          curves give two or three folds, whose RMSE may not tell the two apart while one of
          them errs far more often — and averaging with it costs the tail of the other
          (:meth:`_thesis_protocol`). When least squares cannot hold any curve out, nothing
          speaks against the structured prior: the thesis method.
        - **Any other record**: least squares (with the thesis prior where the record holds
          the thesis's curves), against the non-negative relay grid on nodes placed by the
          record — only for counter-clockwise loops (least squares' own major loop says
          which), never for a spacer; a signed density only where the non-negative grid
          already wins and the folds ask for it (interacting magnetic systems).
        """
        tol = 0.01 * float(np.ptp(u))
        thesis_found = find_thesis_curves(u, tol, outputs=p) is not None
        lsq = identify_lsq(
            u, p, grid=self.grid, cells=self.cells, smoothing=self.smoothing,
            folds=self.folds, thesis_prior=thesis_found,
        )  # fmt: skip
        lsq_err = lsq.details.get("fold_mse")
        fold = branch_folds(u, self.folds, tol)
        if thesis_found and len(split_branches(u, tol)) <= FEW_BRANCHES:
            return self._thesis_protocol(u, p, lsq, fold)
        if lsq_err is None or _orientation(lsq) <= 0:
            return lsq
        relay = identify_relay(u, p, self.grid, nodes=self.cells, folds=self.folds, signed=None)
        relay_plain = relay.details.get("plain_fold_mse")
        if relay_plain is None or not _clearly_beats(relay_plain, lsq_err):
            lsq.details.update(relay_fold_mse=relay_plain, chosen_over="relay")
            return lsq
        relay.details.update(lsq_fold_mse=lsq_err, chosen_over="lsq")
        return relay

    def _thesis_protocol(
        self, u: np.ndarray, p: np.ndarray, lsq: Identified, fold: np.ndarray
    ) -> Identified:
        """Thesis method, least squares with the thesis prior, or their average."""
        thesis = identify_thesis(u, p, self.grid)

        def thesis_fold(held: np.ndarray) -> tuple[np.ndarray, float] | None:
            try:
                t = identify_thesis(u, p, self.grid, exclude=held)
            except ParameterError:  # the fold holds out a curve the method needs
                return None
            return t.everett, t.offset

        thesis_pred = held_out_of_table(u, fold, thesis_fold) if fold.max() >= 1 else None
        thesis.held_out = thesis_pred
        thesis_err = None if thesis_pred is None else fold_mse(thesis_pred, p, fold)
        lsq_err = lsq.details.get("fold_mse")
        comparison: dict[str, Any] = {
            "thesis_fold_mse": None if thesis_err is None else thesis_err.tolist(),
            "lsq_fold_mse": lsq_err,
        }
        if lsq_err is None:  # nothing held out: no evidence against the structured prior
            thesis.details.update(comparison, chosen_over=lsq.method)
            return thesis
        average = Identified(
            0.5 * (thesis.everett + lsq.everett),
            thesis.u_min,
            thesis.u_max,
            0.5 * (thesis.offset + lsq.offset),
            "thesis/lsq average",
            {"grid": self.grid, "members": {"thesis": thesis.details, lsq.method: lsq.details}},
        )
        if thesis_err is None or thesis_pred is None or lsq.held_out is None:
            average.details.update(comparison, validation_rmse=None)
            return average
        # the model's output is linear in (table, offset): the average's held-out prediction
        # is the mean of its members'
        average.held_out = 0.5 * (thesis_pred + lsq.held_out)
        tails = {
            name: _tails(ident.held_out, p, fold)
            for name, ident in (("thesis", thesis), ("lsq", lsq), ("average", average))
            if ident.held_out is not None
        }
        comparison["held_out_p95"] = {k: v[1] for k, v in tails.items()}
        if _clearly_beats(lsq_err, thesis_err):
            lsq.details.update(comparison, chosen_over="thesis", chosen_by="rmse")
            return lsq
        if _clearly_beats(thesis_err, lsq_err):
            return self._thesis_chosen(thesis, thesis_err, comparison, lsq.method, "rmse")
        smaller = [
            k for k in ("thesis", "lsq") if _clearly_smaller_tail(tails[k], tails["average"])
        ]
        if smaller:  # the average would cost this member's tail
            best = min(smaller, key=lambda k: tails[k][1])
            if best == "thesis":
                return self._thesis_chosen(
                    thesis, thesis_err, comparison, "thesis/lsq average", "tail"
                )
            lsq.details.update(comparison, chosen_over="thesis/lsq average", chosen_by="tail")
            return lsq
        average.details.update(comparison, validation_rmse=None)
        return average

    @staticmethod
    def _thesis_chosen(
        thesis: Identified,
        err: np.ndarray,
        comparison: dict[str, Any],
        over: str,
        by: str,
    ) -> Identified:
        """The thesis method, with what it was chosen over and by which criterion."""
        thesis.details.update(comparison, chosen_over=over, chosen_by=by)
        thesis.details["validation_rmse"] = float(np.sqrt(np.mean(err)))
        thesis.details["validation_folds"] = int(err.size)
        return thesis

    @property
    def validation_rmse_(self) -> float | None:
        """RMSE on held-out reversal curves of the setting least squares chose (None for the
        thesis method, or when the record has too few reversal curves to hold any out)."""
        self._check_fitted()
        return self.details_.get("validation_rmse")

    def fit_diagnosis(self, inputs: npt.ArrayLike, outputs: npt.ArrayLike) -> dict[str, Any]:
        """Training error, held-out validation error and the record's noise side by side.

        The noise is estimated from the output's second differences along the record
        (median absolute value / 0.6745 / √6: white noise, robust to the branches' curvature
        and to turning points). ``underfit`` is True when the training RMSE is more than
        three times the noise and above 1 % of the output range: the model cannot follow
        the record it was identified on (more nodes, another method), which no amount of
        cross-validation will reveal from the validation error alone."""
        self._check_fitted()
        u = np.asarray(inputs, dtype=np.float64).ravel()
        y = np.asarray(outputs, dtype=np.float64).ravel()
        ok = np.isfinite(u) & np.isfinite(y)
        u, y = u[ok], y[ok]
        train = float(np.sqrt(np.mean((self.predict(u) - y) ** 2)))
        d2 = np.diff(y, 2)
        noise = float(np.median(np.abs(d2)) / 0.6745 / np.sqrt(6.0)) if d2.size else 0.0
        span = float(np.ptp(y)) if y.size else 0.0
        return {
            "training_rmse": train,
            "validation_rmse": self.details_.get("validation_rmse"),
            "noise_rmse": noise,
            "output_range": span,
            "underfit": bool(train > 3.0 * noise and train > 0.01 * span),
        }

    def _check_fitted(self) -> None:
        if not hasattr(self, "everett_"):
            raise NotFittedError("this HysteresisModel is not fitted yet: call fit() or load()")

    # ------------------------------------------------------------------ evaluation
    def state(self, n_elements: int = 1, capacity: int = DEFAULT_CAPACITY) -> PreisachState:
        """A streaming evaluator for ``n_elements`` starting at lower saturation."""
        return PreisachState(self, n_elements, capacity)

    def predict(self, inputs: npt.ArrayLike, valid: npt.ArrayLike | None = None) -> np.ndarray:
        """Outputs for a whole input history (T,) or (T, N), from lower saturation (the drift
        of eq. 5.8 is a stage of its own: :class:`texsense.compensation.stages.Drift`)."""
        u = np.asarray(inputs, dtype=np.float64)
        return self.state(1 if u.ndim == 1 else u.shape[1]).run(u, valid)

    def bank(self, n_elements: int = 1, capacity: int = DEFAULT_CAPACITY) -> PreisachBank:
        """The compiled Preisach bank of ``n_elements`` at lower saturation, with the model's
        output offset and sign (eq. 4.15-4.22)."""
        self._check_fitted()
        return PreisachBank(
            self.u_min_,
            self.u_max_,
            np.ascontiguousarray(self.everett_, dtype=np.float64),
            int(n_elements),
            int(capacity),
            self.offset_,
            self.sign_,
        )

    def backbone(self, inputs: npt.ArrayLike) -> np.ndarray:
        """The elastic (single-valued) response: the mean of the major loop's rising and
        falling branches at each input (what quasi-linear viscoelasticity relaxes)."""
        grid, response = self.backbone_curve()
        return np.interp(np.asarray(inputs, dtype=np.float64), grid, response)

    def backbone_curve(self, points: int = 401) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`backbone` as (inputs, responses) on ``points`` inputs over the range."""
        self._check_fitted()
        grid = np.linspace(self.u_min_, self.u_max_, points)
        rising = self.predict(grid)
        falling = self.predict(np.concatenate([grid, grid[::-1]]))[grid.size :][::-1]
        return grid, 0.5 * (rising + falling)

    def everett(self, alpha: npt.ArrayLike, beta: npt.ArrayLike) -> np.ndarray:
        """The (interpolated) Everett function F(α, β) in the model's internal output units."""
        st = self.state(1)
        a = np.ascontiguousarray(np.asarray(alpha, np.float64).ravel())
        b = np.ascontiguousarray(np.broadcast_to(np.asarray(beta, np.float64), a.shape).ravel())
        return st._bank.everett(a, b)

    def hold_out(self, inputs: npt.ArrayLike, outputs: npt.ArrayLike, source: str = "") -> HeldOut:
        """Keep the residuals of a record the model was not fitted on (by band of the
        predicted output), the scale of its bounds (:mod:`texsense.compensation.intervals`)."""
        self._check_fitted()
        self.held_out_ = HeldOut.from_residuals(self.predict(inputs), outputs, source=source)
        return self.held_out_

    # ------------------------------------------------------------------ files
    def to_content(self) -> dict[str, Any]:
        """The content of the model file (JSON-able)."""
        self._check_fitted()
        held: HeldOut | None = getattr(self, "held_out_", None)
        return {
            "method": self.method_,
            "params": {
                "method": self.method,
                "grid": self.grid,
                "cells": self.cells,
                "smoothing": self.smoothing,
                "folds": self.folds,
            },
            "input": {
                "name": self.input_name,
                "unit": units.canonical(self.input_unit),
                "min": self.u_min_,
                "max": self.u_max_,
            },
            "output": {
                "name": self.output_name,
                "unit": units.canonical(self.output_unit),
                "offset": self.offset_,
                "sign": self.sign_,
            },
            "grid": int(self.everett_.shape[0]),
            "everett": self.everett_.tolist(),
            "details": self.details_,
            "provenance": dict(self.provenance_),
            **({} if held is None else {"held_out": held.to_dict()}),
        }

    def save(self, path: str | Path) -> Path:
        """Write the model file (atomically; a failed write keeps the previous file)."""
        return modelfile.write(path, MODEL_FORMAT, self.to_content())

    @classmethod
    def from_content(cls, f: Fields) -> HysteresisModel:
        """A model from the content of its file; every problem raises :class:`FormatError`
        naming the file and the field."""
        method = f.text("method")
        params = f.get("params", None)
        if params is None:  # files of the first round: the fitted method only
            params = {"method": method if method in ("lsq", "thesis") else "auto"}
        if not isinstance(params, dict):
            raise f.error("params", "expected an object")
        try:
            model = cls(
                **params,
                input_name=f.text("input.name"),
                output_name=f.text("output.name"),
                input_unit=units.canonical(f.text("input.unit")),
                output_unit=units.canonical(f.text("output.unit")),
            )
        except RangeError as e:
            raise f.error(f"params.{e.key}", str(e)) from None
        except TypeError as e:
            raise f.error("params", str(e)) from None
        except UnitError as e:
            raise FormatError(f.source, str(e)) from None
        table = f.array("everett", ndim=2, within=_OUTPUT)
        if table.shape[0] != table.shape[1] or table.shape[0] != f.number("grid"):
            raise f.error("everett", f"must be grid x grid, got {table.shape}")
        model.everett_ = table
        model.u_min_ = f.number("input.min", within=_INPUT)
        model.u_max_ = f.number("input.max", within=_INPUT)
        model.offset_, model.sign_ = (
            f.number("output.offset", within=_OUTPUT),
            f.number("output.sign"),
        )
        if not model.u_max_ > model.u_min_:
            raise f.error("input", "max must exceed min")
        with np.errstate(over="ignore", divide="ignore"):  # the kernel runs on 1 / step
            if not np.isfinite((table.shape[0] - 1) / (model.u_max_ - model.u_min_)):
                raise f.error(
                    "input",
                    f"max and min are {model.u_max_ - model.u_min_:g} apart: too close for a "
                    f"grid of {table.shape[0]} (the reciprocal of its step overflows)",
                )
        if model.sign_ not in (1.0, -1.0):
            raise f.error("output.sign", f"must be 1 or -1, got {model.sign_}")
        model.method_ = method
        details, provenance = f.get("details", {}), f.get("provenance", {})
        if not isinstance(details, dict) or not isinstance(provenance, dict):
            raise FormatError(f.source, "fields 'details' and 'provenance' must be objects")
        model.details_, model.provenance_ = dict(details), dict(provenance)
        model.held_out_ = None  # files before issue 37: no held-out residuals, no bounds
        if f.get("held_out", None) is not None:
            try:
                model.held_out_ = HeldOut.from_dict(f.get("held_out"))
            except ParameterError as e:
                raise f.error("held_out", str(e)) from None
        return model

    @classmethod
    def load(cls, path: str | Path) -> HysteresisModel:
        """Read a model file (of this or the first round's version). A file with a drift
        stage is a chain: read it with :func:`texsense.compensation.stages.load_chain`."""
        _, content = modelfile.load(path, (MODEL_FORMAT,))
        return cls.from_content(Fields(content, path))

    def check_units(self, input_unit: str, output_unit: str | None = None) -> None:
        """Raise :class:`UnitError` if data come in other units than the model's."""
        if units.canonical(input_unit) != units.canonical(self.input_unit):
            raise UnitError(
                f"the model takes {self.input_name} in {self.input_unit}, got {input_unit}"
            )
        if output_unit is not None and units.canonical(output_unit) != units.canonical(
            self.output_unit
        ):
            raise UnitError(
                f"the model gives {self.output_name} in {self.output_unit}, "
                f"data are in {output_unit}"
            )


def scale_hysteresis(
    model: HysteresisModel, start: npt.ArrayLike, end: npt.ArrayLike, f_h: float
) -> np.ndarray:
    """Thesis eq. 6.12 as its text defines it: ``p_t2 = p_r2 + f_h (h(p_r2) - p_r2)``.

    For a model from pressure to pressure: every element starts at ``start`` (p_r1) with
    output = input (§6.4.4) and moves to ``end`` (p_r2); the model's output ``h(p_r2)``
    departs from ``p_r2`` by its hysteresis, and ``f_h`` scales that departure (f_h = 0: the
    test pattern is the reference pattern r2, as §6.4.4 says for d_h = 0; 1: the model's own
    hysteresis; 2: doubled). The equation as printed, ``p_r1 + f_h (h(p_r2) - p_r1)``, would
    give the *start* pattern for f_h = 0 and cannot be meant: with it no posture would be
    recognised at small f_h, where fig. 6.10 shows 100 %.
    """
    p1 = np.asarray(start, dtype=np.float64).ravel()
    p2 = np.asarray(end, dtype=np.float64).ravel()
    if p1.shape != p2.shape:
        raise ParameterError("start and end must have the same shape")
    st = model.state(p1.size)
    st.set_state(p1, p1)
    h = st.step(p2)
    return p2 + f_h * (h - p2)
