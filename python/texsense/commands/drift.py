"""``texsense drift fit STEPS.csv``: γ (or a Prony kernel) from step-and-hold records."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from texsense.commands import HELP
from texsense.commands._applies import Rule, only_where
from texsense.compensation.drift import DriftModel, read_steps
from texsense.compensation.drift_structure import (
    LEVEL_EXPONENTS,
    STRUCTURES,
    StructureChoice,
    candidate_name,
    choose_structure,
)
from texsense.compensation.hysteresis import HysteresisModel
from texsense.compensation.stages import Drift, Hysteresis, StageChain, load_chain
from texsense.exceptions import FormatError, ParameterError
from texsense.io.columns import read_columns


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``drift`` command group."""
    p = sub.add_parser(
        "drift",
        help=HELP["drift"],
        description="Drift compensation (thesis chapter 5).",
    )
    ds = p.add_subparsers(dest="drift_command", metavar="ACTION")
    ds.required = True
    f = ds.add_parser(
        "fit",
        help="fit γ of p(t) = s γ ln(t + 1) (eq. 5.2) to held steps",
        description="Cut a step-and-hold CSV (time_s, compression_mm, "
        "pressure_ncm2) into steps and fit γ per step and common to all; flags "
        "data whose change is not proportional to the step size.",
    )
    f.add_argument(
        "steps",
        type=Path,
        nargs="+",
        help="CSV, e.g. from 'texsense simulate steps --csv'; with --history one or more "
        "records (--clock rest+time: e.g. held steps and an hour of cycles)",
    )
    f.add_argument(
        "--kind",
        choices=("log", "prony"),
        default="log",
        help="logarithmic kernel (thesis) or a fitted Prony series",
    )
    f.add_argument(
        "--history",
        type=Path,
        metavar="MODEL.json",
        help="fit γ by least squares over the whole record (any load history, e.g. cycles) "
        "after this hysteresis model, instead of cutting it into steps",
    )
    f.add_argument(
        "-o",
        "--output",
        type=Path,
        help="with --history: write the hysteresis model and the fitted drift stage here (a "
        "chain of the two)",
    )
    add_clock_arguments(f)
    f.add_argument("--json", action="store_true", help="print JSON")
    f.set_defaults(run=run_fit)
    only_where(f, [
        Rule("--kind", lambda a: a.history is None, "held steps (without --history: over a "
             "load history the kernel is the logarithm of eq. 5.2)"),
        Rule("--output", lambda a: a.history is not None, "--history MODEL.json (the chain of "
             "the model and the drift fitted over it)"),
    ])  # fmt: skip


#: Default rest rate of the rest clock (N/cm² per s; the velocity is averaged over 0.5 s).
REST_RATE = 0.02


def add_clock_arguments(parser: argparse.ArgumentParser, prefix: str = "") -> None:
    """``--clock rest|time`` and ``--rest-rate`` (with ``prefix``, e.g. ``drift-``)."""
    parser.add_argument(
        f"--{prefix}clock",
        choices=("rest", "thesis", "time") if prefix else ("rest", "thesis", "time", "rest+time"),
        default="rest" if prefix else None,
        help="rest (default): the kernel's clock runs while the element's reading holds "
        "still, so γ from held steps also serves cycles; thesis (or time): eq. 5.8 as printed"
        + (
            ""
            if prefix
            else "; rest+time (with --history): both, fitted together; not given with "
            "--history: chosen by validation on the records' held-out later halves"
        )
        + " (docs/drift.md)",
    )
    parser.add_argument(
        f"--{prefix}rest-rate",
        type=float,
        default=REST_RATE,
        help=f"rest clock: reading velocity (N/cm² per s) that halves the clock ({REST_RATE})",
    )
    key = prefix.replace("-", "_")
    only_where(parser, [Rule(f"--{prefix}rest-rate",
                             lambda a: getattr(a, f"{key}clock") not in ("thesis", "time"),
                             f"the rest clock (not --{prefix}clock thesis or time)")])  # fmt: skip


def rest_rate_of(args: argparse.Namespace, prefix: str = "") -> float:
    """The rest rate the arguments ask for (0 for the time clock)."""
    key = prefix.replace("-", "_")
    if getattr(args, f"{key}clock") in ("thesis", "time"):  # None (not given): rest
        return 0.0
    rate = float(getattr(args, f"{key}rest_rate"))
    if not rate > 0:
        raise ParameterError(f"--{prefix}rest-rate must be > 0 N/cm² per s, got {rate}")
    return rate


def _columns(path: Path) -> dict:
    return read_columns(path, required=("time_s", "compression_mm", "pressure_ncm2"))


def load_model(path: Path) -> tuple[HysteresisModel, DriftModel | None]:
    """The hysteresis model of a model file (a hysteresis model, or a chain of hysteresis
    and drift) and its drift stage, if any."""
    chain = load_chain(path)
    hyst, drift = chain.find(Hysteresis), chain.find(Drift)
    if hyst is None:
        raise FormatError(path, f"holds the stages {', '.join(chain.names)}: no hysteresis model")
    return hyst.model_, None if drift is None else drift.model_


def run_fit_history(args: argparse.Namespace) -> int:
    """``texsense drift fit REC.csv --history MODEL.json``: γ over a whole load history."""
    model, _ = load_model(args.history)
    records = []
    backbones = []
    for path in args.steps:
        cols = _columns(path)
        records.append(
            (model.predict(cols["compression_mm"]), cols["pressure_ncm2"], cols["time_s"])
        )
        backbones.append(model.backbone(cols["compression_mm"]))
    if args.clock is None:
        return _choose_and_report(args, model, records, backbones)
    if args.clock == "rest+time":
        drift = DriftModel.fit_joint(records, rest_rate=rest_rate_of(args))
        rms = drift.rms_ncm2_
    elif len(records) == 1:
        h, p, t = records[0]
        drift = DriftModel.fit_history(h, p, t, rest_rate=rest_rate_of(args))
        rms = drift.rms_ncm2_
    else:
        raise ParameterError("several records need --clock rest+time (one record otherwise)")
    h = np.concatenate([r[0] for r in records])
    summary = {
        "gamma": drift.gamma,
        "gamma_time": drift.gamma_time,
        "clock": drift.clock,
        "rms_residual_ncm2": rms,
        "samples": int(h.size),
    }
    if args.output:
        chain = StageChain([Hysteresis.of(model), Drift.of(drift)])
        summary["model"] = str(chain.save(args.output))
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(
        f"γ {drift.gamma:.5f}"
        + (f", γ_time {drift.gamma_time:.5f}" if drift.gamma_time else "")
        + f" ({drift.clock} clock) over {h.size} samples of "
        + ", ".join(p.name for p in args.steps)
        + " "
        f"(RMS residual {rms:.4g} N/cm² in 0.5-3.5 N/cm²)"
    )
    if args.output:
        print(f"wrote {args.output}")
    return 0


def _choose_and_report(
    args: argparse.Namespace,
    model: HysteresisModel,
    records: list,
    backbones: list,
) -> int:
    """``drift fit RECORD... --history MODEL`` without ``--clock``: the structure chosen by
    validation on the held-out later half of every record (:func:`choose_structure`)."""
    choice = choose_structure(
        [(h, e, p, t) for (h, p, t), e in zip(records, backbones, strict=True)],
        rest_rate=rest_rate_of(args),
        backbone=model.backbone_curve(),
    )
    summary: dict[str, Any] = {
        "chosen": choice.chosen,
        "held_out_rmse_ncm2": choice.held_out_rmse,
        "hysteresis_only_rmse_ncm2": choice.baseline_rmse,
        "deployable": choice.deployable,
    }
    if choice.model is not None:
        summary.update(
            gamma=choice.model.gamma, clock=choice.model.clock, exponent=choice.model.exponent
        )
        if args.output:
            chain = StageChain([Hysteresis.of(model), Drift.of(choice.model)])
            summary["model"] = str(chain.save(args.output))
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print_held_out(choice)
    if choice.model is None:
        best = min(choice.held_out_rmse.values())
        raise ParameterError(
            f"no drift structure beats hysteresis only on the held-out halves (best "
            f"{best:.4g} vs {choice.baseline_rmse:.4g} N/cm²): keep the hysteresis model alone, "
            "or name a structure with --clock"
        )
    if not args.json:
        print(f"chose {choice.chosen} ({choice.model.describe()}; refitted on all samples)")
        if args.output:
            print(f"wrote {args.output}")
    return 0


def print_held_out(choice: StructureChoice) -> None:
    """The held-out RMSE of every candidate as a table: structures by level power."""
    print("held-out RMSE (later half of every record, 0.5-3.5 N/cm²), N/cm²:")
    print(f"  {'hysteresis only':<16}{choice.baseline_rmse:.4g}")
    powers = sorted({1.0, *LEVEL_EXPONENTS})
    head = "".join(f"{'h' if q == 1 else f'h^{q:g}':<10}" for q in powers)
    print(f"  {'':<16}{head}".rstrip())
    for structure in STRUCTURES:
        cells = [choice.held_out_rmse.get(candidate_name(structure, q)) for q in powers]
        row = "".join(f"{c:<10.4g}" for c in cells if c is not None)
        label = "qlv (backbone)" if structure == "qlv" else structure
        print(f"  {label:<16}{row}".rstrip())


def run_fit(args: argparse.Namespace) -> int:
    """Run ``texsense drift fit``."""
    if args.history is not None:
        return run_fit_history(args)
    if len(args.steps) != 1:
        raise ParameterError("drift fit: one step-and-hold CSV (several need --history)")
    if args.clock == "rest+time":
        raise ParameterError(
            "drift fit: --clock rest+time needs --history MODEL.json and records with cycles "
            "(held steps alone cannot tell the two clocks apart)"
        )
    steps = read_steps(args.steps[0])
    model = DriftModel.fit_steps(steps, kind=args.kind, rest_rate=rest_rate_of(args))
    fit = model.step_fit_
    assert fit is not None  # fit_steps sets it
    summary: dict[str, Any] = {
        "steps": [round(s, 6) for _, _, s in steps],
        "gamma_common": fit.gamma_common,
        "gamma_per_step": fit.gamma_single,
        "max_fit_error_one_step": fit.max_error_single,
        "max_fit_error_common": fit.max_error_common,
        "proportionality_spread": fit.proportionality_spread,
        "proportional": fit.proportional,
        "kind": model.kind,
        "clock": model.clock,
        "kernel_terms": int(model.kernel.weights.size),
        "kernel_max_error": model.kernel.max_error,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f"{len(steps)} steps of {', '.join(f'{s:+.3g}' for s in summary['steps'])} N/cm²")
    print(
        f"  γ common {fit.gamma_common:.4f}; per step "
        + ", ".join(f"{g:.4f}" for g in fit.gamma_single)
    )
    print(
        f"  fit error (share of the step): one step {fit.max_error_single:.2%}, common "
        f"{fit.max_error_common:.2%}"
    )
    print(
        f"  kernel: {model.kind}, as {summary['kernel_terms']} exponential terms "
        f"(largest deviation {model.kernel.max_error:.2g} in units of ln(1 + t))"
    )
    verdict = "proportional" if fit.proportional else "NOT proportional (eq. 5.1 fails)"
    print(f"  spread between steps {fit.proportionality_spread:.2%}: {verdict}")
    print(
        f"  clock: {model.clock}"
        + (
            f" (rest rate {model.rest_rate:g} N/cm² per s): transfers to cycles. For a mat "
            "in use (sitting, lying: held loads) fit held loads plus cycles instead: drift fit "
            "LOADS.csv CYCLES.csv --history MODEL.json --clock rest+time (docs/drift.md)"
            if model.clock == "rest"
            else " (eq. 5.8 as printed)"
        )
    )
    return 0
