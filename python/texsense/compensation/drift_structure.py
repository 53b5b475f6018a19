"""Choosing the drift structure from the user's own records (``texsense drift fit RECORD...
--history MODEL`` without ``--clock``; docs/drift.md, "Which structure?"): every candidate —
the time clock (eq. 5.8 as printed), the rest clock, both, a Prony series and a quasi-linear
viscoelastic one acting on the backbone — is fitted on the first half of every record and
scored on the second; the best one that beats hysteresis only is refitted on everything.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from texsense.compensation.drift import DriftModel, unit_drift
from texsense.compensation.drift_kernels import DriftKernel, log_kernel
from texsense.exceptions import ParameterError

__all__ = [
    "LEVEL_EXPONENTS",
    "PRONY_TAUS_S",
    "STRUCTURES",
    "StructureChoice",
    "candidate_name",
    "choose_structure",
]


#: Time constants of the Prony candidate of :func:`choose_structure` (s).
PRONY_TAUS_S = (1.0, 10.0, 100.0, 1000.0, 1e4, 1e5)

#: Powers q of the level whose steps the nonlinear candidates superpose (1: eq. 5.8).
LEVEL_EXPONENTS = (1.0, 2.0, 3.0)

#: The structures tried, each with every level power: four on the Preisach output, and
#: quasi-linear viscoelasticity (``qlv``: the time clock on the elastic response).
STRUCTURES = ("time", "rest", "rest+time", "prony", "qlv")


@dataclass
class StructureChoice:
    """What :func:`choose_structure` found: the chosen candidate (None: none beats
    hysteresis only), its model refitted on the whole records (None for a candidate that
    the drift stage cannot run, see ``deployable``), and every candidate's held-out RMSE."""

    chosen: str | None
    model: DriftModel | None
    held_out_rmse: dict[str, float]
    baseline_rmse: float
    deployable: dict[str, bool]


def candidate_name(structure: str, exponent: float) -> str:
    """``prony`` for eq. 5.8's linear superposition, ``prony h^2`` for the level's square."""
    return structure if exponent == 1.0 else f"{structure} h^{exponent:g}"


def choose_structure(
    records: Sequence[tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike, npt.ArrayLike]],
    rest_rate: float = 0.02,
    band: tuple[float, float] = (0.5, 3.5),
    train_share: float = 0.5,
    margin: float = 0.05,
    exponents: Sequence[float] = LEVEL_EXPONENTS,
    nonlinear_margin: float = 0.10,
    backbone: tuple[np.ndarray, np.ndarray] | None = None,
) -> StructureChoice:
    """Choose the drift structure from the user's records by validation on held-out parts.

    ``records`` are ``(h, backbone, pressure, times_s)``: the Preisach output, the elastic
    (single-valued backbone) response of the same input, the measured pressure and the
    times. Every candidate is fitted on the first ``train_share`` of every record and scored
    on the rest (a forecast: drift is about what comes later), every record weighted equally,
    over the samples whose measured pressure lies in ``band``:

    - ``time``: eq. 5.8 as printed (logarithmic kernel on time);
    - ``rest``: the same kernel on the rest clock;
    - ``rest+time``: both clocks (:meth:`DriftModel.fit_joint`);
    - ``prony``: a non-negative Prony series (time constants 1 s .. 1 day, one sign) on time;
    - each of them also on the steps of ``h^q`` for every q in ``exponents`` (named e.g.
      ``prony h^2``): Schapery's nonlinear superposition, where a step's drift grows as a
      power of its level (Schapery 1969, the standard extension of linear viscoelasticity
      to soft polymers; a spacer whose creep is faster under larger loads);
    - ``qlv``: quasi-linear viscoelasticity — the logarithmic relaxation acts on the elastic
      (backbone) response of the input instead of the Preisach output (the standard model
      of soft tissue and elastomers, Fung), its drift added to the Preisach output. It is
      deployable (``level="backbone"`` of :class:`DriftModel`) when ``backbone``, the
      curve of the elastic response (:meth:`HysteresisModel.backbone_curve`), is given;
      otherwise reported only (``deployable``).

    The choice: the linear superposition (eq. 5.8's) is the prior. The best linear
    deployable candidate is chosen if it beats hysteresis only (γ = 0) by more than
    ``margin`` (relative: a drift fitted to noise wins by chance by a little); a nonlinear
    one replaces it only if it beats both the best linear candidate and hysteresis only by
    more than ``nonlinear_margin``. None beats hysteresis only: ``chosen`` is None.
    """
    if not records:
        raise ParameterError("choose_structure needs at least one record")
    powers = [1.0] + [float(q) for q in exponents if float(q) != 1.0]
    designs = _designs(records, powers, rest_rate, band, train_share)
    scores = {name: _held_out(_fit(name, parts, "train"), parts) for name, parts in designs.items()}
    baseline = _held_out(None, designs["time"])
    deployable = {name: backbone is not None or not name.startswith("qlv") for name in designs}
    exponent_of = {candidate_name(s, q): q for q in powers for s in STRUCTURES}
    usable = [n for n in exponent_of if deployable[n] and scores[n] < (1 - margin) * baseline]
    linear = [n for n in usable if exponent_of[n] == 1.0]
    best_linear = min(linear, key=lambda n: scores[n]) if linear else None
    bar = (1 - nonlinear_margin) * min(baseline, scores[best_linear] if best_linear else np.inf)
    nonlinear = [n for n in usable if exponent_of[n] != 1.0 and scores[n] < bar]
    chosen = min(nonlinear, key=lambda n: scores[n]) if nonlinear else best_linear
    if chosen is None:
        return StructureChoice(None, None, scores, baseline, deployable)
    coef = _fit(chosen, designs[chosen], "all")
    model = _model_of(chosen.split(" ")[0], coef, exponent_of[chosen], rest_rate, backbone)
    return StructureChoice(chosen, model, scores, baseline, deployable)


#: One record's part of a candidate's least-squares problem: its design columns, the target
#: (measured - Preisach output) and which samples are the training share.
_Part = tuple[np.ndarray, np.ndarray, np.ndarray]


def _designs(
    records: Sequence[tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike, npt.ArrayLike]],
    powers: Sequence[float],
    rest_rate: float,
    band: tuple[float, float],
    train_share: float,
) -> dict[str, list[_Part]]:
    """Every candidate's design, built from the unit responses of every record (the drift of
    γ = 1) over the samples in ``band``, by candidate name."""
    prony_k = [DriftKernel(np.ones(1), np.array([tau]), 0.0, (0.0, 1e6)) for tau in PRONY_TAUS_S]
    designs: dict[str, list[_Part]] = {candidate_name(s, q): [] for q in powers for s in STRUCTURES}
    for n, (h, e, p, t) in enumerate(records):
        x = np.asarray(h, dtype=np.float64)
        el = np.asarray(e, dtype=np.float64)
        y = np.asarray(p, dtype=np.float64)
        tt = np.asarray(t, dtype=np.float64)
        if not (x.shape == el.shape == y.shape == tt.shape) or x.ndim != 1:
            raise ParameterError(f"record {n}: h, backbone, pressure and times differ in shape")
        sel = np.isfinite(x) & np.isfinite(y) & (y >= band[0]) & (y < band[1])
        if sel.sum() < 4:
            raise ParameterError(f"record {n} has fewer than 4 samples in {band[0]}-{band[1]}")
        target = (y - x)[sel]
        idx = np.nonzero(sel)[0]
        train = idx < idx[int(train_share * idx.size)]
        for q in powers:
            d_time = unit_drift(x, tt, 0.0, exponent=q)
            d_rest = unit_drift(x, tt, rest_rate, exponent=q)
            prony = np.column_stack([unit_drift(x, tt, 0.0, k, q) for k in prony_k])
            d_qlv = unit_drift(el, tt, 0.0, exponent=q)
            for structure, cols in (
                ("time", d_time[sel, None]),
                ("rest", d_rest[sel, None]),
                ("rest+time", np.column_stack([d_rest, d_time])[sel]),
                ("prony", prony[sel]),
                ("qlv", d_qlv[sel, None]),
            ):
                designs[candidate_name(structure, q)].append((cols, target, train))
    return designs


def _fit(name: str, parts: list[_Part], use: str) -> np.ndarray:
    """A candidate's coefficients on the training shares (``use="train"``) or on all samples,
    every record weighted equally; a Prony series is non-negative of one sign."""
    rows, rhs = [], []
    for cols, target, train in parts:
        m = train if use == "train" else np.ones(train.size, bool)
        w = 1.0 / np.sqrt(max(int(m.sum()), 1))
        rows.append(w * cols[m])
        rhs.append(w * target[m])
    A, b = np.vstack(rows), np.concatenate(rhs)
    if name.startswith("prony"):  # one sign, non-negative weights: the better of the two
        best = None
        for sign in (1.0, -1.0):
            from scipy.optimize import nnls  # heavy: only fits need it

            c, r = nnls(sign * A, b, maxiter=50 * A.shape[1])
            if best is None or r < best[1]:
                best = (sign * c, r)
        assert best is not None
        return best[0]
    coef, *_ = np.linalg.lstsq(A, b, rcond=None)
    return coef


def _held_out(coef: np.ndarray | None, parts: list[_Part]) -> float:
    """RMSE over the held-out shares (records weighted equally); None: hysteresis only."""
    per = []
    for cols, target, train in parts:
        r = target[~train] - (0.0 if coef is None else cols[~train] @ coef)
        per.append(float(np.mean(r**2)) if r.size else 0.0)
    return float(np.sqrt(np.mean(per)))


def _model_of(
    structure: str,
    coef: np.ndarray,
    q: float,
    rest_rate: float,
    backbone: tuple[np.ndarray, np.ndarray] | None,
) -> DriftModel:
    """The drift stage of a chosen candidate from its coefficients."""
    log_k = log_kernel()
    if structure == "time":
        return DriftModel(float(coef[0]), log_k, "log", exponent=q)
    if structure == "rest":
        return DriftModel(float(coef[0]), log_k, "log", rest_rate, exponent=q)
    if structure == "rest+time":
        return DriftModel(float(coef[0]), log_k, "log", rest_rate, 0.5, float(coef[1]), q)
    if structure == "qlv":
        return DriftModel(float(coef[0]), log_k, "log", exponent=q, level="backbone",
                          backbone=backbone)  # fmt: skip
    sign = -1.0 if coef.sum() < 0 else 1.0  # prony: one sign, the weights as the kernel
    w = np.abs(coef)
    keep = w > 0
    kernel = DriftKernel(w[keep], np.asarray(PRONY_TAUS_S)[keep], 0.0, (0.0, 1e6))
    return DriftModel(sign, kernel, "prony", exponent=q)
