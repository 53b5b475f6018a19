"""``texsense drift fit STEPS.csv``: γ (or a Prony kernel) from step-and-hold records."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from texsense.drift import DriftModel, split_steps
from texsense.exceptions import ParameterError
from texsense.io.columns_csv import read_columns_csv


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``drift`` command group."""
    p = sub.add_parser(
        "drift",
        help="identify drift from step-and-hold records",
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
    f.add_argument("steps", type=Path, help="CSV, e.g. from 'texsense simulate steps --csv'")
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
        help="with --history: write the hysteresis model with the fitted drift stage here",
    )
    f.add_argument("--json", action="store_true", help="print JSON")
    f.set_defaults(run=run_fit)


def load_steps(path: Path) -> list:
    """Steps of a CSV with time_s, compression_mm and pressure_ncm2 columns."""
    cols = _columns(path)
    return split_steps(cols["time_s"], cols["pressure_ncm2"], cols["compression_mm"])


def _columns(path: Path) -> dict:
    return read_columns_csv(path, required=("time_s", "compression_mm", "pressure_ncm2"))


def run_fit_history(args: argparse.Namespace) -> int:
    """``texsense drift fit REC.csv --history MODEL.json``: γ over a whole load history."""
    from texsense.hysteresis import HysteresisModel

    model = HysteresisModel.load(args.history)
    cols = _columns(args.steps)
    h = model.predict(cols["compression_mm"])
    drift, rms = DriftModel.fit_history(h, cols["pressure_ncm2"], cols["time_s"])
    summary = {"gamma": drift.gamma, "rms_residual_ncm2": rms, "samples": int(h.size)}
    if args.output:
        model.with_drift(drift)
        model.provenance_["drift_history"] = str(args.steps)
        summary["model"] = str(model.save(args.output))
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(
        f"γ {drift.gamma:.5f} over {h.size} samples of {args.steps.name} "
        f"(RMS residual {rms:.4g} N/cm² in 0.5-3.5 N/cm²)"
    )
    if args.output:
        print(f"wrote {args.output}")
    return 0


def run_fit(args: argparse.Namespace) -> int:
    """Run ``texsense drift fit``."""
    if args.history is not None:
        return run_fit_history(args)
    if args.output is not None:
        raise ParameterError("drift fit: -o/--output needs --history MODEL.json")
    steps = load_steps(args.steps)
    model, fit = DriftModel.fit(steps, kind=args.kind)
    summary = {
        "steps": [round(s, 6) for _, _, s in steps],
        "gamma_common": fit.gamma_common,
        "gamma_per_step": fit.gamma_single,
        "max_fit_error_one_step": fit.max_error_single,
        "max_fit_error_common": fit.max_error_common,
        "proportionality_spread": fit.proportionality_spread,
        "proportional": fit.proportional,
        "kind": model.kind,
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
    verdict = "proportional" if fit.proportional else "NOT proportional (eq. 5.1 fails)"
    print(f"  spread between steps {fit.proportionality_spread:.2%}: {verdict}")
    return 0
