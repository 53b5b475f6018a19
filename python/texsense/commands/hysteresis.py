"""``texsense hysteresis fit|apply|plot``: identify and apply a Preisach model."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from texsense.commands import HELP
from texsense.commands._applies import Rule, only_where
from texsense.commands.drift import add_clock_arguments, load_model, rest_rate_of
from texsense.compensation.drift import DriftModel, read_steps
from texsense.compensation.hysteresis import HysteresisModel
from texsense.compensation.hysteresis.plots import model_figure, validation_report_figure
from texsense.compensation.hysteresis.sampling import check_sampling, is_row_count
from texsense.compensation.hysteresis.validation import validate
from texsense.compensation.intervals import bounds, drift_share
from texsense.compensation.stages import Drift, Hysteresis, StageChain
from texsense.exceptions import FormatError, ParameterError
from texsense.io.columns import read_columns, write_columns

#: Pressure bands of the error summary (thesis §4.5), in the output's unit.
DEFAULT_BANDS = ((0.5, 3.5), (3.5, 10.0))
_UNIT_BY_SUFFIX = {
    "_mm": "mm",
    "_ncm2": "N/cm2",
    "_kpa": "kPa",
    "_n": "N",
    "_pf": "pF",
    "_s": "s",
    "_mmhg": "mmHg",
}


def _unit_of(name: str) -> str:
    """Unit from a column name's suffix (compression_mm -> mm); '1' if there is none."""
    low = name.lower()
    for suffix, unit in _UNIT_BY_SUFFIX.items():
        if low.endswith(suffix):
            return unit
    return "1"


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``hysteresis`` command group."""
    p = sub.add_parser(
        "hysteresis",
        help=HELP["hysteresis"],
        description="Preisach hysteresis compensation (thesis chapter 4).",
    )
    hs = p.add_subparsers(dest="hysteresis_command", metavar="ACTION")
    hs.required = True
    f = hs.add_parser(
        "fit",
        help="identify a model from a calibration CSV",
        description="Identify the Everett function from a column CSV.",
    )
    f.add_argument("calibration", type=Path, help="CSV with the input and output columns")
    f.add_argument("-o", "--output-model", type=Path, required=True, help="model JSON to write")
    f.add_argument("--input", default="compression_mm", help="input column (compression_mm)")
    f.add_argument("--output", default="pressure_ncm2", help="output column (pressure_ncm2)")
    f.add_argument(
        "--method",
        default="auto",
        choices=("auto", "lsq", "thesis", "relay"),
        help="auto (default): the thesis method on a thesis record, least squares or the "
        "relay grid otherwise, a more flexible one only when cross-validation gains more than "
        "one standard error; lsq; thesis (§4.4.2); relay (non-negative density on nodes "
        "placed by the record)",
    )
    f.add_argument("--grid", type=int, default=100, help="evaluated Everett table K x K (100)")
    f.add_argument(
        "--cells", type=int, help="coarse α cells of least squares (default: cross-validated)"
    )
    f.add_argument(
        "--smoothing",
        type=float,
        help="curvature penalty of least squares (default: cross-validated)",
    )
    f.add_argument("--folds", type=int, default=4, help="folds of held-out reversal curves (4)")
    f.add_argument("--drift", type=Path, help="step-and-hold CSV: add a drift stage (eq. 5.8)")
    f.add_argument("--drift-kind", choices=("log", "prony"), default="log")
    f.add_argument(
        "--held-out",
        type=Path,
        metavar="RECORD.csv",
        help="a record the model is not fitted on (same columns): its residuals by band are "
        "the scale of the bounds of 'apply --interval' (docs/drift.md, Bounds)",
    )
    add_clock_arguments(f, "drift-")
    f.add_argument("--json", action="store_true", help="print a JSON summary")
    f.set_defaults(run=run_fit)
    only_where(f, FIT_RULES)
    a = hs.add_parser(
        "apply",
        help="apply a model to a CSV",
        description="Run a model over a CSV; OUT holds every input column plus "
        "<output>_model. With the output column present, prints the error.",
    )
    a.add_argument("model", type=Path, help="model JSON")
    a.add_argument("data", type=Path, help="CSV with the input column")
    a.add_argument("-o", "--out", type=Path, required=True, help="CSV to write")
    a.add_argument("--input", help="input column (default: the model's)")
    a.add_argument("--output", help="output column to compare with (default: the model's)")
    a.add_argument("--json", action="store_true", help="print the error summary as JSON")
    a.add_argument(
        "--interval",
        type=float,
        metavar="LEVEL",
        help="add <output>_lo and <output>_hi: the bound of every value at this level (e.g. "
        "0.95; needs a model fitted with --held-out)",
    )
    a.set_defaults(run=run_apply)
    v = hs.add_parser(
        "validate",
        help="where does a model fail on a record (bands, branches, worst places, plot)",
        description="Run a model through a record with the measured output and report the "
        "error overall, by output band, on rising and falling branches, and the worst places.",
    )
    v.add_argument("model", type=Path, help="model JSON")
    v.add_argument("data", type=Path, help="CSV with the input and the measured output")
    v.add_argument("--input", help="input column (default: the model's)")
    v.add_argument("--output", help="measured output column (default: the model's)")
    v.add_argument("--plot", type=Path, help="PNG: measured vs model and the error")
    v.add_argument("--json", action="store_true", help="print the report as JSON")
    v.set_defaults(run=run_validate)

    pl = hs.add_parser("plot", help="Everett surface and modelled loops as PNG")
    pl.add_argument("model", type=Path)
    pl.add_argument("-o", "--out", type=Path, required=True, help="PNG to write")
    pl.set_defaults(run=run_plot)


def _column(cols: dict[str, np.ndarray], name: str, path: Path) -> np.ndarray:
    if name not in cols:
        raise FormatError(path, f"no column {name!r}; columns are {', '.join(cols)}")
    return cols[name]


def error_summary(
    measured: np.ndarray,
    modelled: np.ndarray,
    bands: tuple[tuple[float, float], ...] = DEFAULT_BANDS,
) -> dict[str, Any]:
    """RMSE and mean/max relative error per output band."""
    ok = np.isfinite(measured) & np.isfinite(modelled)
    y, m = measured[ok], modelled[ok]
    out: dict[str, Any] = {
        "samples": int(ok.sum()),
        "rmse": float(np.sqrt(np.mean((m - y) ** 2))) if y.size else None,
    }
    for lo, hi in bands:
        sel = (y >= lo) & (y < hi)
        rel = np.abs(m[sel] - y[sel]) / y[sel]
        out[f"{lo:g}-{hi:g}"] = {
            "samples": int(sel.sum()),
            "mean_relative_error": float(rel.mean()) if sel.any() else None,
            "max_relative_error": float(rel.max()) if sel.any() else None,
        }
    return out


#: Where the options of ``hysteresis fit`` apply (:mod:`texsense.commands._applies`).
FIT_RULES = [
    *(Rule(flag, lambda a: a.drift is not None, "a drift stage (--drift STEPS.csv)")
      for flag in ("--drift-kind", "--drift-clock", "--drift-rest-rate")),
    *(Rule(flag, lambda a: a.method != "thesis", "--method auto, lsq or relay (the "
           "thesis method has none)") for flag in ("--cells", "--smoothing", "--folds")),
]  # fmt: skip


def run_fit(args: argparse.Namespace) -> int:
    """Run ``texsense hysteresis fit``."""
    cols = read_columns(args.calibration, required=(args.input, args.output))
    u = _column(cols, args.input, args.calibration)
    y = _column(cols, args.output, args.calibration)
    model = HysteresisModel(
        method=args.method,
        grid=args.grid,
        cells=args.cells,
        smoothing=args.smoothing,
        folds=args.folds,
        input_name=args.input,
        output_name=args.output,
        input_unit=_unit_of(args.input),
        output_unit=_unit_of(args.output),
    )
    model.fit(u, y, provenance={"calibration": str(args.calibration)}, remember=True)
    if args.held_out:
        held = read_columns(args.held_out)
        model.hold_out(
            _column(held, args.input, args.held_out),
            _column(held, args.output, args.held_out),
            str(args.held_out),
        )
    if args.drift:
        drift = DriftModel.fit_steps(
            read_steps(args.drift), kind=args.drift_kind, rest_rate=rest_rate_of(args, "drift-")
        )
        # hysteresis followed by drift: a chain of the two stages
        StageChain([Hysteresis.of(model), Drift.of(drift)]).save(args.output_model)
    else:
        model.save(args.output_model)
    fitted = model.predict(u)
    summary = {
        "model": str(args.output_model),
        "method": model.method_,
        "input_range": [model.u_min_, model.u_max_],
        "grid": model.everett_.shape[0],
        "fit": error_summary(y, fitted),
        "validation_rmse": model.validation_rmse_,
        "diagnosis": model.fit_diagnosis(u, y),
        "chosen": {
            k: model.details_.get(k) for k in ("alpha_cells", "d_cells", "spacing", "smoothing")
        },
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"wrote {args.output_model}: {model.method_} method, "
            f"{model.everett_.shape[0]} x {model.everett_.shape[0]} Everett grid, "
            f"{args.input} {model.u_min_:.4g}..{model.u_max_:.4g}; "
            f"fit RMSE {summary['fit']['rmse']:.4g}"
        )
        _print_choice(model)
        diag = summary["diagnosis"]
        held = diag["validation_rmse"]
        print(
            f"  training RMSE {diag['training_rmse']:.4g} | validation RMSE "
            + (
                f"{held:.4g}"
                if held is not None
                else ("of each member above" if "members" in model.details_ else "—")
            )
            + f" | noise {diag['noise_rmse']:.2g}"
        )
        if diag["underfit"]:
            print(
                "  underfit: the training error is far above the record's noise; the model "
                "cannot follow this record (try --method relay, or more --cells)"
            )
    return 0


def _print_choice(model: HysteresisModel) -> None:
    """What the identification chose and on what evidence (held-out reversal curves)."""
    if model.validation_rmse_ is not None:
        d = model.details_
        if "alpha_cells" in d:
            setting = f"{d['alpha_cells']} x {d['d_cells']} cells, smoothing {d['smoothing']:g}"
        elif "nodes" in d:
            setting = f"{len(d['nodes'])} nodes placed by the record, ridge {d['ridge']:g}"
        else:
            setting = "the thesis's interpolation"
        print(
            f"  chosen by {d['validation_folds']}-fold cross-validation on held-out reversal "
            f"curves: {setting}; validation RMSE {model.validation_rmse_:.4g}"
        )
        if d.get("chosen_by") == "tail":
            tails = d["held_out_p95"]
            mine = tails["thesis" if model.method_ == "thesis" else "lsq"]
            print(
                f"  over the thesis/lsq average, whose RMSE is not clearly different: its "
                f"95th-percentile held-out error {mine:.4g} against the average's "
                f"{tails['average']:.4g}"
            )
    elif "members" in model.details_:
        d = model.details_
        folds = [d.get("thesis_fold_mse"), d.get("lsq_fold_mse")]
        cv = ", ".join(
            f"{name} {np.sqrt(np.mean(f)):.4g}"
            for name, f in zip(("thesis", "least squares"), folds, strict=True)
            if f is not None
        )
        print(
            "  the mean of the thesis table and least squares: neither is clearly better "
            f"on held-out reversal curves (validation RMSE {cv})"
        )
    elif model.method_ == "thesis" and model.method == "auto":
        print("  the thesis method: too few reversal curves for least squares to show a gain")
    elif model.method_ != "thesis":
        print("  too few reversal curves to hold any out: settings not cross-validated")


def _model_and_record(
    args: argparse.Namespace, need_output: bool
) -> tuple[HysteresisModel, DriftModel | None, dict[str, np.ndarray], str, str, np.ndarray]:
    """The model and its drift stage, the record's columns, the input and output names (the
    model's unless given) and the input column, with its unit checked against the model's."""
    model, drift = load_model(args.model)
    in_name = args.input or model.input_name
    out_name = args.output or model.output_name
    # the columns named (validate needs the measured output too; apply compares when it is
    # there, and an --output named must be there: taken and ignored, the user would believe
    # it compared): a CSV whose header holds them is a column table
    named = (in_name, out_name) if need_output or args.output else (in_name,)
    cols = read_columns(args.data, required=named)
    u = _column(cols, in_name, args.data)
    if args.input and _unit_of(in_name) != "1":
        model.check_units(_unit_of(in_name))
    check_sampling(model, u, cols.get("time_s"), in_name)
    return model, drift, cols, in_name, out_name, u


def run_apply(args: argparse.Namespace) -> int:
    """Run ``texsense hysteresis apply``."""
    model, drift, cols, _, out_name, u = _model_and_record(args, False)
    st = model.state(1)
    modelled = st.run(u)
    clamped = int(st.clamped[0])
    if drift is not None:
        modelled = drift.apply(modelled, _column(cols, "time_s", args.data), inputs=u)
    cols[f"{out_name}_model"] = modelled
    if args.interval is not None:
        lo, hi = _apply_bounds(model, drift, u, modelled, cols.get("time_s"), args.interval)
        cols[f"{out_name}_lo"], cols[f"{out_name}_hi"] = lo, hi
    write_columns(args.out, cols, values=f"{out_name}_model", unit=model.output_unit)
    summary: dict[str, Any] = {
        "out": str(args.out),
        "samples": int(u.size),
        "clamped_inputs": clamped,
    }
    if out_name in cols and out_name != f"{out_name}_model":
        summary["error"] = error_summary(cols[out_name], modelled)
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    stages = "hysteresis + drift" if drift is not None else "hysteresis"
    print(
        f"wrote {args.out} ({stages}; {u.size} samples, {clamped} inputs clamped into "
        f"{model.u_min_:.4g}..{model.u_max_:.4g})"
    )
    if "error" in summary:
        e = summary["error"]
        if e["rmse"] is None:  # no sample measured and predicted (every value not a number)
            print("  RMSE: no finite sample to compare")
        else:
            print(f"  RMSE {e['rmse']:.4g} {model.output_unit}")
        for band in (k for k in e if "-" in k):
            b = e[band]
            if b["samples"]:
                print(
                    f"  {band} {model.output_unit}: mean relative error "
                    f"{b['mean_relative_error']:.2%}, max {b['max_relative_error']:.2%} "
                    f"({b['samples']} samples)"
                )
    return 0


def _apply_bounds(
    model: HysteresisModel,
    drift: DriftModel | None,
    u: np.ndarray,
    modelled: np.ndarray,
    times: np.ndarray | None,
    level: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The bounds of ``hysteresis apply --interval`` (:mod:`texsense.compensation.intervals`,
    context ``record``): the held-out scale by band, the drift share from the time since the
    record began (the model taken as made just before), an input beyond the identified range
    uncertain by how far it lies beyond."""
    held = getattr(model, "held_out_", None)
    if held is None:
        raise ParameterError(
            "--interval needs the model's held-out residuals: fit it with --held-out RECORD.csv "
            "(a record it is not fitted on)"
        )
    hours = np.zeros(u.size) if times is None else (times - times[0]) / 3600.0
    d = np.array([drift_share(h, None) for h in hours])
    lo, hi = bounds(modelled, level, held, drift=d, context="record")
    # beyond the identified range the input is clamped: the value is at least that of the
    # edge and may lie beyond by the slope at the edge times how far (twice, to be safe)
    span = model.u_max_ - model.u_min_
    ends = np.asarray(model.predict(np.array([model.u_max_ - 0.02 * span, model.u_max_])), float)
    slope = max(float(ends[1] - ends[0]) / (0.02 * span), 0.0)
    over = np.clip(u - model.u_max_, 0.0, None)
    return lo, hi + 2.0 * slope * over


def run_validate(args: argparse.Namespace) -> int:
    """Run ``texsense hysteresis validate``."""
    model, drift, cols, in_name, out_name, u = _model_and_record(args, True)
    y = _column(cols, out_name, args.data)
    times = cols.get("time_s")
    if times is not None and drift is None and is_row_count(times):
        times = None  # row numbers, not a clock: the worst places are named by sample alone
    report = validate(model, u, y, times_s=times, drift=drift)
    if args.plot:
        validation_report_figure(
            report,
            u,
            y,
            args.plot,
            in_name,
            out_name,
            title=f"{args.model.name} on {args.data.name}",
        )
    if args.json:
        print(json.dumps(report.to_dict(), indent=2))
        return 0
    unit = report.unit
    print(
        f"{args.model} on {args.data}: {report.samples} samples, RMSE {report.rmse:.4g} {unit} "
        f"(NRMSE {report.nrmse:.2%}), {report.clamped} inputs clamped"
    )

    def line(e: Any) -> str:
        if not e.samples:
            return f"  {e.name:>14}: no samples"
        rel = (
            ""
            if e.mean_relative is None
            else f", mean rel. {e.mean_relative:.2%}, max rel. {e.max_relative:.2%}"
        )
        return f"  {e.name:>14}: {e.samples:6d} samples, RMSE {e.rmse:.4g}{rel}"

    print(f"by measured {out_name} ({unit}):")
    for e in report.bands:
        print(line(e))
    print("by branch:")
    for e in report.branches:
        print(line(e))
    print("worst places (one per branch):")
    for n, p in enumerate(report.worst, 1):
        when = f"t = {p.time_s:.1f} s, " if p.time_s is not None else ""
        print(
            f"  {n}. sample {p.index} ({when}{p.branch}): {in_name} {p.input:.4g}, "
            f"measured {p.measured:.4g}, model {p.model:.4g} ({p.model - p.measured:+.3g})"
        )
    if args.plot:
        print(f"wrote {args.plot}")
    return 0


def run_plot(args: argparse.Namespace) -> int:
    """Run ``texsense hysteresis plot``."""
    model, _ = load_model(args.model)
    model_figure(model, args.out)
    print(f"wrote {args.out}")
    return 0


__all__ = ["error_summary", "register"]
