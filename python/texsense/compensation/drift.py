"""Drift compensation (thesis chapter 5): logarithmic step responses and their superposition.

After a step of size ``s`` at ``t0`` the pressure at constant compression changes as
``p(t) = p(t0) + s γ ln(t - t0 + 1)`` (eq. 5.2); γ follows from one point (eq. 5.3) or from
a least-squares fit over one or many steps. The drift of any history is the superposition of
the step responses of the Preisach output (eq. 5.8). texsense evaluates it recursively
(``texsense._core.DriftBank``): the kernel ``ln(1 + t)`` is approximated once by a
non-negative sum of exponentials (:func:`~texsense.compensation.drift_kernels.log_kernel`), so
each element keeps K states and each sample costs O(K) whatever the length of the history. The
same machinery runs any fitted non-negative Prony kernel
(:func:`~texsense.compensation.drift_kernels.prony_kernel`) where the logarithm does not hold;
the kernels are :mod:`texsense.compensation.drift_kernels`, this module the model that holds
one.

:class:`DriftModel` is what the drift stage (:class:`texsense.compensation.stages.Drift`) runs
after the Preisach model: fitted from step responses (:func:`split_steps` cuts a step-and-hold
record) or over a load history, saved in the ``texsense.compensation.drift`` model file (or in a
chain).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path

import numpy as np
import numpy.typing as npt

from texsense._core import Curve, DriftBank
from texsense.compensation.drift_kernels import DriftKernel, log_kernel, prony_kernel
from texsense.compensation.stage import time_steps as _time_steps
from texsense.data import modelfile
from texsense.data.modelfile import Fields
from texsense.data.ranges import OneOf, Real, check_params
from texsense.exceptions import FormatError, ParameterError

__all__ = [
    "LEVELS",
    "DriftModel",
    "StepFit",
    "drift_exact",
    "fit_gamma",
    "gamma_from_point",
    "read_steps",
    "split_steps",
    "time_steps",
    "unit_drift",
]


#: What the drift superposes: the Preisach output (eq. 5.8) or the elastic response of the
#: input (``backbone``: quasi-linear viscoelasticity).
LEVELS = ("output", "backbone")

#: The range of every parameter of a drift model (:mod:`texsense.data.ranges`; the drift
#: stage's ``kind`` and ``rest_rate`` are these), checked by the model and by its file's reader.
RANGES = {
    "gamma": Real(-1e3, 1e3),
    "kind": OneOf(("log", "thesis", "prony")),
    "rest_rate": Real(0.0, 1e12, unit="N/cm2 per s", note="0: the time clock of eq. 5.8"),
    "rest_window": Real(0.0, 1e6, lo_open=True, unit="s"),
    "gamma_time": Real(-1e3, 1e3),
    "exponent": Real(0.25, 8.0),
    "level": OneOf(LEVELS),
}
#: The bounds of a file's kernel: weights, time constants (s), its error and span (s), the
#: backbone's inputs and responses.
_WEIGHTS = Real(0.0, 1e6)
_TAUS = Real(0.0, 1e12, lo_open=True, unit="s")
_SPAN = Real(0.0, 1e12, unit="s")
_BACKBONE = Real(-1e12, 1e12)


def gamma_from_point(t0_s: float, p0: float, tc_s: float, pc: float, step: float) -> float:
    """Eq. 5.3: ``γ = (p(tc) - p(t0)) / (s ln(tc - t0 + 1))``."""
    if not tc_s > t0_s or step == 0:
        raise ParameterError("need tc > t0 and a non-zero step size")
    return (pc - p0) / (step * np.log(tc_s - t0_s + 1.0))


@dataclass(frozen=True)
class StepFit:
    """γ fitted to step responses (changes normalised to their step sizes)."""

    gamma_common: float
    gamma_single: list[float]
    max_error_common: float
    max_error_single: float
    proportionality_spread: float
    proportional: bool


def fit_gamma(
    steps: Sequence[tuple[npt.ArrayLike, npt.ArrayLike, float]],
    tolerance: float = 0.04,
) -> StepFit:
    """Least-squares γ of ``Δp / s = γ ln(t + 1)`` per step and common to all.

    Parameters
    ----------
    steps : sequence of (t_s, pressure, step_size)
        Time since the end of each step (s), the pressure held at constant compression (the
        first sample is p(t0)), and the step size s (negative for falling steps).
    tolerance : float
        Largest spread between the normalised responses at the end of the shortest record for
        them to count as proportional to the step size (thesis: 4 %). The thesis found Tekscan
        mats break this assumption; such data are flagged with ``proportional = False``.

    Errors are the largest deviations from the fitted curves as shares of the step size.
    """
    if not steps:
        raise ParameterError("no steps given")
    norm, times = [], []
    for t, p, s in steps:
        t = np.asarray(t, dtype=np.float64)
        p = np.asarray(p, dtype=np.float64)
        if s == 0 or t.shape != p.shape or t.size < 2:
            raise ParameterError("every step needs a non-zero size and matching t, p (>= 2)")
        times.append(t - t[0])
        norm.append((p - p[0]) / s)
    x_all = np.concatenate([np.log1p(t) for t in times])
    y_all = np.concatenate(norm)
    common = float(x_all @ y_all / (x_all @ x_all))
    singles = [
        float(np.log1p(t) @ y / (np.log1p(t) @ np.log1p(t)))
        for t, y in zip(times, norm, strict=True)
    ]
    err_single = max(
        float(np.max(np.abs(y - g * np.log1p(t))))
        for t, y, g in zip(times, norm, singles, strict=True)
    )
    err_common = max(
        float(np.max(np.abs(y - common * np.log1p(t)))) for t, y in zip(times, norm, strict=True)
    )
    horizon = min(float(t[-1]) for t in times)
    ends = [float(np.interp(horizon, t, y)) for t, y in zip(times, norm, strict=True)]
    spread = max(ends) - min(ends)
    return StepFit(common, singles, err_common, err_single, spread, spread <= tolerance)


def split_steps(
    times_s: npt.ArrayLike,
    pressure: npt.ArrayLike,
    compression: npt.ArrayLike,
    gap_s: float = 5.0,
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Cut a step-and-hold record into steps for :func:`fit_gamma`.

    Records are split where the time stamps jump by more than ``gap_s`` (separate specimens,
    as ``texsense simulate steps`` writes them). In each part the hold is the final stretch
    at constant compression; the step is the ramp just before it, and its size is the
    pressure at the start of the hold minus the pressure where that ramp began.
    """
    t = np.asarray(times_s, dtype=np.float64)
    p = np.asarray(pressure, dtype=np.float64)
    c = np.asarray(compression, dtype=np.float64)
    if not (t.shape == p.shape == c.shape) or t.size < 3:
        raise ParameterError("times, pressure and compression must be equal-length arrays (>= 3)")
    cuts = np.concatenate([[0], np.nonzero(np.diff(t) > gap_s)[0] + 1, [t.size]])
    steps = []
    for a, b in pairwise(cuts.tolist()):
        seg_c = c[a:b]
        moving = np.nonzero(np.abs(np.diff(seg_c)) > 1e-9)[0]
        if moving.size == 0:
            continue
        hold = a + int(moving[-1]) + 1
        if b - hold < 3:
            continue
        direction = np.sign(c[hold] - c[hold - 1])
        k = hold - 1
        while k > a and np.sign(c[k] - c[k - 1]) in (direction, 0):
            k -= 1
        size = p[hold] - p[k]
        if size == 0:
            continue
        steps.append((t[hold:b], p[hold:b], float(size)))
    if not steps:
        raise ParameterError("no step followed by a hold at constant compression was found")
    return steps


def read_steps(path: str | Path) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The held steps of a step-and-hold record (``time_s``, ``compression_mm``,
    ``pressure_ncm2``; a column CSV or a one-element recording), cut by
    :func:`split_steps`."""
    from texsense.io.columns import read_columns  # the file formats load h5py

    cols = read_columns(path, required=("time_s", "compression_mm", "pressure_ncm2"))
    return split_steps(cols["time_s"], cols["pressure_ncm2"], cols["compression_mm"])


def time_steps(times_s: npt.ArrayLike, n_frames: int) -> np.ndarray:
    """Time steps (s) between ``n_frames`` non-decreasing time stamps, the first one 0."""
    t = np.asarray(times_s, dtype=np.float64)
    if t.shape != (n_frames,):
        raise ParameterError(f"times_s must have {n_frames} entries, got {t.shape}")
    return _time_steps(t)


def _kernel_or_log(kernel: DriftKernel | None) -> tuple[DriftKernel, str]:
    """The given kernel (a fitted Prony series) or the logarithmic one."""
    return (log_kernel(), "log") if kernel is None else (kernel, "prony")


def unit_drift(
    h: npt.ArrayLike,
    times_s: npt.ArrayLike,
    rest_rate: float = 0.0,
    kernel: DriftKernel | None = None,
    exponent: float = 1.0,
) -> np.ndarray:
    """The drift of γ = 1 over a history of hysteresis outputs: ``D`` in ``p = h + γ D``
    (eq. 5.8 is linear in γ), with the logarithmic kernel unless a Prony ``kernel`` is given,
    on the rest clock when ``rest_rate`` > 0, over the steps of ``h**exponent``. What every
    least-squares fit of γ over a load history is built from."""
    x = np.asarray(h, dtype=np.float64)
    k, kind = _kernel_or_log(kernel)
    return DriftModel(1.0, k, kind, rest_rate, exponent=exponent).apply(x, times_s) - x


@dataclass(frozen=True)
class DriftModel:
    """γ and a kernel: the drift stage that follows the Preisach model (eq. 5.8).

    ``rest_rate`` > 0 runs the kernel on a *rest clock* instead of time: each element's clock
    advances by ``dt / (1 + |v| / rest_rate)``, ``v`` the velocity of its own hysteresis
    output (N/cm² per s for pressure) averaged exponentially over ``rest_window`` seconds (so
    reading noise does not stop the clock). At rest (a held step) it is time and eq. 5.8 is
    unchanged; while the load changes fast (cycles) the clock nearly stops. Why this transfers
    γ between held steps and cycles, and where it does not (load-controlled sitting):
    docs/drift.md. ``rest_rate = 0`` is eq. 5.8 as printed (``kind="thesis"`` in the CLI).

    ``exponent`` q ≠ 1 superposes the steps of ``max(h, 0)**q`` instead of ``h`` (Schapery's
    nonlinear superposition: a step's drift grows as the q-th power of its level, not in
    proportion; the drift is still added to ``h``). Eq. 5.8 is q = 1; a larger q is chosen
    only from the user's records (:func:`texsense.compensation.drift_structure.choose_structure`).

    ``level="backbone"`` is quasi-linear viscoelasticity (Fung): the kernel superposes the
    steps of the elastic response ``backbone(u)`` of the hysteresis stage's *input* (the
    curve ``backbone = (inputs, responses)``, the mean of the Preisach model's major-loop
    branches) instead of the Preisach output, and its drift is added to the Preisach output.
    It needs the inputs (:meth:`apply` ``inputs=``; in a chain it follows the hysteresis
    stage).
    """

    gamma: float
    kernel: DriftKernel
    kind: str = "log"
    rest_rate: float = 0.0
    rest_window: float = 0.5
    gamma_time: float = 0.0
    exponent: float = 1.0
    level: str = "output"
    backbone: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None
    #: how well the identification that made the model fitted its records (learned state, not
    #: parameters: not compared, not saved): the :class:`StepFit` of :meth:`fit_steps`, the RMS
    #: residual in N/cm² of :meth:`fit_history` and :meth:`fit_joint`; None otherwise
    step_fit_: StepFit | None = field(default=None, compare=False, repr=False)
    rms_ncm2_: float | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        check_params("the drift model", RANGES, {k: getattr(self, k) for k in RANGES})
        if (self.level == "backbone") != (self.backbone is not None):
            raise ParameterError("level 'backbone' (QLV) needs the backbone curve, and only it")

    def describe(self) -> str:
        """In a few words: kernel, clock, γ (or the Prony weights), level power and level."""
        if self.kind == "prony":
            what = (
                f"Prony kernel ({self.kernel.weights.size} terms), weights sum "
                f"{self.gamma * self.kernel.weights.sum():.4g}"
            )
        else:
            what = f"log kernel, γ {self.gamma:.5g}"
        what += f", {self.clock} clock"
        if self.gamma_time:
            what += f" (time γ {self.gamma_time:.5g})"
        if self.exponent != 1.0:
            what += f", on the steps of h^{self.exponent:g} (Schapery)"
        if self.level == "backbone":
            what += ", on the elastic response (QLV)"
        return what

    def level_curve(self) -> Curve | None:
        """The elastic response of the input as the core's curve (QLV), else None."""
        if self.backbone is None:
            return None
        x, y = self.backbone
        return Curve(np.ascontiguousarray(x, np.float64), np.ascontiguousarray(y, np.float64))

    @property
    def clock(self) -> str:
        """``"time"`` (eq. 5.8 as printed), ``"rest"``, or ``"rest+time"`` (both, the time
        part with factor ``gamma_time``; :meth:`fit_joint`)."""
        if self.rest_rate <= 0:
            return "time"
        return "rest+time" if self.gamma_time else "rest"

    def state(self, n_elements: int = 1) -> DriftBank:
        """A recursive evaluator for ``n_elements``."""
        return self.kernel.bank(
            self.gamma,
            n_elements,
            self.rest_rate,
            self.rest_window,
            self.gamma_time,
            self.exponent,
        )

    def apply(
        self, h: npt.ArrayLike, times_s: npt.ArrayLike, inputs: npt.ArrayLike | None = None
    ) -> np.ndarray:
        """Add the drift to a history of hysteresis outputs (T,) or (T, N) at ``times_s``
        (``inputs``: the hysteresis stage's inputs, for ``level="backbone"``)."""
        x = np.asarray(h, dtype=np.float64)
        one = x.ndim == 1
        x2 = np.ascontiguousarray(x[:, None] if one else x)
        dt = time_steps(times_s, x2.shape[0])
        if self.level == "backbone":
            if inputs is None:
                raise ParameterError(
                    "a QLV drift (level 'backbone') needs the hysteresis stage's inputs"
                )
            u = np.asarray(inputs, dtype=np.float64).reshape(x2.shape)
            out = self.add_backbone_drift(self.state(x2.shape[1]), dt, x2, np.isfinite(x2), u)
        else:
            out = self.state(x2.shape[1]).run(dt, x2, np.ascontiguousarray(np.isfinite(x2)))
        return out[:, 0] if one else out

    def add_backbone_drift(
        self, bank: DriftBank, dt: np.ndarray, h: np.ndarray, valid: np.ndarray, u: np.ndarray
    ) -> np.ndarray:
        """QLV on a batch: ``h`` plus the drift of the elastic response of the inputs ``u``
        (what the compiled ``Compensation`` with a level curve computes, to the bit)."""
        curve = self.level_curve()
        assert curve is not None
        ok_u = np.isfinite(u)
        b = np.full(u.shape, np.nan)
        b[ok_u] = curve.at(np.ascontiguousarray(u[ok_u]))
        ok = np.ascontiguousarray(valid & np.isfinite(h))
        return h + (bank.run(dt, np.ascontiguousarray(b), ok) - b)

    @classmethod
    def fit(
        cls,
        steps: Sequence[tuple[npt.ArrayLike, npt.ArrayLike, float]],
        kind: str = "log",
        rest_rate: float = 0.0,
    ) -> tuple[DriftModel, StepFit]:
        """Deprecated: :meth:`fit_steps` (the model, its :class:`StepFit` in ``step_fit_``)."""
        warnings.warn(
            "DriftModel.fit(steps) -> (model, fit) is now DriftModel.fit_steps(steps) -> model "
            "(the fit in model.step_fit_); the old name goes in the next release",
            DeprecationWarning,
            stacklevel=2,
        )
        model = cls.fit_steps(steps, kind, rest_rate)
        assert model.step_fit_ is not None
        return model, model.step_fit_

    @classmethod
    def fit_steps(
        cls,
        steps: Sequence[tuple[npt.ArrayLike, npt.ArrayLike, float]],
        kind: str = "log",
        rest_rate: float = 0.0,
    ) -> DriftModel:
        """The model of step responses: γ with the logarithmic kernel (``kind="log"``), or a
        non-negative Prony kernel of the common normalised response (``"prony"``);
        ``kind="thesis"`` is eq. 5.8 exactly as printed (``ln(1 + t)``, time clock). With
        ``rest_rate`` > 0 the model runs on the rest clock; γ is the same (a hold is at
        rest). How well γ fits the steps is the model's ``step_fit_`` (:class:`StepFit`)."""
        fit = fit_gamma(steps)
        if kind == "thesis":  # eq. 5.8 exactly as printed: ln(1 + t) on the time clock
            if rest_rate:
                raise ParameterError("kind='thesis' is eq. 5.8 as printed: no rest clock")
            return cls(fit.gamma_common, log_kernel(), "thesis", step_fit_=fit)
        if kind == "log":
            return cls(fit.gamma_common, log_kernel(), "log", rest_rate, step_fit_=fit)
        if kind == "prony":
            times = np.concatenate(
                [np.asarray(t, float) - float(np.asarray(t)[0]) for t, _, _ in steps]
            )
            norm = np.concatenate(
                [(np.asarray(p, float) - float(np.asarray(p)[0])) / s for _, p, s in steps]
            )
            order = np.argsort(times)
            k = prony_kernel(times[order], norm[order])
            sign = -1.0 if norm[order][-1] < 0 else 1.0
            return cls(sign, k, "prony", rest_rate, step_fit_=fit)
        raise ParameterError(f"kind must be 'thesis', 'log' or 'prony', got {kind!r}")

    @classmethod
    def fit_history(
        cls,
        h: npt.ArrayLike,
        pressure: npt.ArrayLike,
        times_s: npt.ArrayLike,
        band: tuple[float, float] = (0.5, 3.5),
        kernel: DriftKernel | None = None,
        rest_rate: float = 0.0,
    ) -> DriftModel:
        """γ by least squares over any load history, not only held steps.

        Eq. 5.8 is linear in γ: ``p(t) = h(t) + γ D(t)`` with ``D`` the superposition of the
        kernel over the steps of the Preisach output ``h``. ``D`` is computed once with γ = 1
        and γ solves the one-parameter least-squares problem over the samples whose true
        ``pressure`` lies in ``band`` (N/cm², the thesis's §4.5 range). Use it to identify γ on
        the kind of load the application sees (e.g. an hour of cycles) when γ from steps does
        not transfer (docs/drift.md). The RMS residual in N/cm² is the model's ``rms_ncm2_``.
        """
        x = np.asarray(h, dtype=np.float64)
        p = np.asarray(pressure, dtype=np.float64)
        if x.ndim != 1 or p.shape != x.shape:
            raise ParameterError(
                f"h and pressure must be 1-D and of equal length, got {x.shape} and {p.shape}"
            )
        k, kind = _kernel_or_log(kernel)
        unit = unit_drift(x, times_s, rest_rate, kernel)
        sel = np.isfinite(unit) & np.isfinite(p) & (p >= band[0]) & (p < band[1])
        denom = float(unit[sel] @ unit[sel])
        if sel.sum() < 2 or denom <= 0:
            raise ParameterError(
                f"the history has no drift to fit in {band[0]}-{band[1]} N/cm² "
                f"({int(sel.sum())} samples in the band)"
            )
        gamma = float(unit[sel] @ (p - x)[sel] / denom)
        rms = float(np.sqrt(np.mean((x + gamma * unit - p)[sel] ** 2)))
        return cls(gamma, k, kind, rest_rate, rms_ncm2_=rms)

    @classmethod
    def fit_joint(
        cls,
        records: Sequence[tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike]],
        rest_rate: float = 0.02,
        band: tuple[float, float] = (0.5, 3.5),
        kernel: DriftKernel | None = None,
    ) -> DriftModel:
        """Both clocks from records that hold both kinds of load (e.g. held steps and an
        hour of cycles): ``p = h + γ D_rest(h) + γ_time D_time(h)`` is linear in the two
        factors, which solve one least-squares problem over the samples in ``band`` with every
        record weighted equally. The data decide which clock the spacer's drift runs on: on
        the virtual textile spacer γ_time comes out near 0, on the second law (creep on time)
        the time part dominates (docs/drift.md). The RMS residual (N/cm²) is the model's
        ``rms_ncm2_``.
        """
        if not records:
            raise ParameterError("fit_joint needs at least one record")
        if not rest_rate > 0:
            raise ParameterError(f"rest_rate must be > 0, got {rest_rate}")
        k, kind = _kernel_or_log(kernel)
        rows, rhs, plain = [], [], []
        for n, (h, p, t) in enumerate(records):
            x = np.asarray(h, dtype=np.float64)
            y = np.asarray(p, dtype=np.float64)
            if x.ndim != 1 or y.shape != x.shape:
                raise ParameterError(f"record {n}: h and pressure must be equal-length 1-D")
            d_rest = unit_drift(x, t, rest_rate, kernel)
            d_time = unit_drift(x, t, 0.0, kernel)
            sel = np.isfinite(y) & np.isfinite(x) & (y >= band[0]) & (y < band[1])
            if sel.sum() < 2:
                raise ParameterError(f"record {n} has no samples in {band[0]}-{band[1]}")
            w = 1.0 / np.sqrt(sel.sum())
            design = np.column_stack([d_rest[sel], d_time[sel]])
            rows.append(w * design)
            rhs.append(w * (y - x)[sel])
            plain.append((design, (y - x)[sel]))
        (g_rest, g_time), *_ = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)
        resid = np.concatenate([d @ [g_rest, g_time] - r for d, r in plain])
        rms = float(np.sqrt(np.mean(resid**2)))
        return cls(float(g_rest), k, kind, rest_rate, 0.5, float(g_time), rms_ncm2_=rms)

    def to_dict(self) -> dict:
        """The content of the model file (JSON-able)."""
        return {
            "kind": self.kind,
            "gamma": self.gamma,
            "rest_rate": self.rest_rate,
            "rest_window_s": self.rest_window,
            "gamma_time": self.gamma_time,
            "exponent": self.exponent,
            "level": self.level,
            **(
                {}
                if self.backbone is None
                else {
                    "backbone": {
                        "inputs": np.asarray(self.backbone[0]).tolist(),
                        "responses": np.asarray(self.backbone[1]).tolist(),
                    }
                }
            ),
            "kernel": {
                "weights": self.kernel.weights.tolist(),
                "taus_s": self.kernel.taus.tolist(),
                "max_error": self.kernel.max_error,
                "span_s": list(self.kernel.span_s),
            },
        }

    @classmethod
    def from_dict(cls, d: dict) -> DriftModel:
        """Inverse of :meth:`to_dict`."""
        return cls.from_content(Fields(d, "<dict>"))

    @classmethod
    def from_content(cls, f: Fields) -> DriftModel:
        """A model from the content of its file; every problem raises
        :class:`~texsense.exceptions.FormatError` naming the file and the field."""
        span = f.array("kernel.span_s", ndim=1, within=_SPAN)
        if span.shape != (2,) or not span[1] > span[0]:
            raise f.error("kernel.span_s", "expected two increasing numbers")
        kernel = DriftKernel(
            f.array("kernel.weights", ndim=1, within=_WEIGHTS),
            f.array("kernel.taus_s", ndim=1, within=_TAUS),
            f.number("kernel.max_error", within=Real(0.0, 1e12)),
            (float(span[0]), float(span[1])),
        )
        if kernel.weights.shape != kernel.taus.shape:
            raise f.error("kernel", "needs one time constant per weight")
        rest_rate = f.number("rest_rate", 0.0, within=RANGES["rest_rate"])  # before: time
        window = f.number("rest_window_s", 0.5, within=RANGES["rest_window"])
        gamma_time = f.number("gamma_time", 0.0, within=RANGES["gamma_time"])
        if gamma_time and rest_rate <= 0:
            raise f.error("gamma_time", "needs the rest clock (rest_rate > 0)")
        kind = f.text("kind", "log")
        if not RANGES["kind"].holds(kind):
            raise f.error("kind", f"expected {RANGES['kind'].text()}, got {kind!r}")
        # files before the level power: eq. 5.8
        exponent = f.number("exponent", 1.0, within=RANGES["exponent"])
        level = f.text("level", "output")  # files before QLV: the Preisach output
        if not RANGES["level"].holds(level):
            raise f.error("level", f"expected {RANGES['level'].text()}, got {level!r}")
        backbone = None
        if level == "backbone":
            x = f.array("backbone.inputs", ndim=1, within=_BACKBONE)
            y = f.array("backbone.responses", ndim=1, within=_BACKBONE)
            if x.shape != y.shape or x.size < 2 or np.any(np.diff(x) <= 0):
                raise f.error("backbone", "needs >= 2 points with strictly increasing inputs")
            backbone = (x, y)
        return cls(
            f.number("gamma", within=RANGES["gamma"]),
            kernel,
            kind,
            rest_rate,
            window,
            gamma_time,
            exponent,
            level,
            backbone,
        )

    def save(self, path: str | Path) -> Path:
        """Write the drift model file (``texsense.compensation.drift``), atomically."""
        return modelfile.write(path, "texsense.drift", self.to_dict())

    @classmethod
    def load(cls, path: str | Path) -> DriftModel:
        """Read a drift model file."""
        _, content = modelfile.load(path, ("texsense.drift",))
        try:
            return cls.from_content(Fields(content, path))
        except ParameterError as e:
            raise FormatError(path, str(e)) from None


def drift_exact(
    times_s: npt.ArrayLike,
    h: npt.ArrayLike,
    gamma: float,
    window_s: float = 10.0,
    min_step: float = 0.01,
    delta: float = 0.0,
) -> tuple[np.ndarray, int]:
    """The thesis's exact drift model with its practical rules (§5.2-5.3, eq. 5.4-5.7).

    Every ``window_s`` the Preisach output is averaged over the window; when the average
    differs from the last stored level by at least ``min_step`` (relative), the difference is
    stored as a step at that time (smaller ones are omitted). With ``delta > 0`` a step whose
    present rate of drift is below ``delta`` times the largest one is deleted (eq. 5.5-5.7).
    The output is ``h(t) + γ Σ_i Δ_i ln(t - t_i + 1)`` (eq. 5.8). Cost and memory grow with
    the number of stored steps — the reference the recursive form is checked against.

    Returns the drift-corrected output (T,) and the number of steps kept at the end.
    """
    t = np.asarray(times_s, dtype=np.float64)
    x = np.asarray(h, dtype=np.float64)
    if t.shape != x.shape or t.ndim != 1:
        raise ParameterError("times and h must be equal-length 1-D arrays")
    if not window_s > 0 or min_step < 0 or not 0 <= delta < 1:
        raise ParameterError("need window_s > 0, min_step >= 0 and 0 <= delta < 1")
    out = np.empty_like(x)
    step_t: list[float] = []
    step_d: list[float] = []
    level = 0.0
    w_start, w_sum, w_n = (t[0] if t.size else 0.0), 0.0, 0
    for k in range(t.size):
        if t[k] - w_start >= window_s and w_n:
            avg = w_sum / w_n
            change = abs(avg - level)
            if change > 0 and change >= min_step * max(abs(level), 1e-12):
                step_t.append(float(t[k]))
                step_d.append(avg - level)
                level = avg
                if delta > 0 and len(step_t) > 1:
                    rate = np.abs(np.asarray(step_d)) / (t[k] - np.asarray(step_t) + 1.0)
                    keep = rate >= delta * rate.max()
                    kept_d = np.asarray(step_d)[keep]
                    # deleted steps stop drifting; the level they reached stays in h
                    step_t = list(np.asarray(step_t)[keep])
                    step_d = list(kept_d)
            w_start, w_sum, w_n = t[k], 0.0, 0
        w_sum += x[k]
        w_n += 1
        if step_t:
            st = np.asarray(step_t)
            done = st <= t[k]
            drift = gamma * np.sum(np.asarray(step_d)[done] * np.log1p(t[k] - st[done]))
        else:
            drift = 0.0
        out[k] = x[k] + drift
    return out, len(step_t)
