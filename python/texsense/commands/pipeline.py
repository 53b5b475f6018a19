"""``texsense calibrate mat|linear``, ``process``, ``repair`` and ``health``: raw capacitance
to pressure maps, one file or an archive (docs/pipeline.md)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from texsense.apps.views import checked_words, format_duration, times_words
from texsense.calibration.session import CalibrationSession
from texsense.commands import HELP
from texsense.commands._applies import Rule, no_effect, only_where, refuse_unless
from texsense.commands._options import add_accept_truncated, nonempty, refuse_replacing
from texsense.commands._tables import text_table
from texsense.commands.wizard import register_wizard
from texsense.compensation.archive import (
    ProcessOptions,
    archive_jobs,
    process_archive,
    process_file,
)
from texsense.compensation.health import FailureDetector, health_report
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.repair import METHODS, Repair
from texsense.compensation.stages import (
    Convert,
    Drift,
    Hysteresis,
    Linear,
    StageChain,
    load_chain,
)
from texsense.data.files import check_not_input
from texsense.data.layout import parse_orientation
from texsense.exceptions import FormatError, ParameterError
from texsense.io import load, save


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``calibrate``, ``process``, ``repair`` and ``health`` commands."""
    _register_calibrate(sub)
    _register_process(sub)
    _register_repair_and_health(sub)


def _register_calibrate(sub: argparse._SubParsersAction) -> None:
    """``calibrate mat`` and ``calibrate linear``."""
    c = sub.add_parser(
        "calibrate",
        help=HELP["calibrate"],
        description="Calibrate a mat from a test-machine record of its spacer and two mat "
        "recordings: unloaded and under a uniform known load.",
    )
    cs = c.add_subparsers(dest="calibrate_command", metavar="WHAT")
    cs.required = True
    m = cs.add_parser("mat", help="write a mat calibration file")
    m.add_argument(
        "--material",
        required=True,
        metavar="PRESET|RECORD.csv",
        help="the spacer: a preset name (textile-3mm, textile-6mm, foam-7mm, ...: the virtual "
        "sensor's materials, with their thickness and drift) or a test-machine record CSV with "
        "compression_mm, capacitance_pF, pressure_ncm2 (e.g. 'texsense simulate calibration "
        "--csv')",
    )
    m.add_argument("--baseline", type=Path, required=True, help="unloaded mat (capacitance)")
    m.add_argument("--uniform", type=Path, required=True, help="mat under a uniform load")
    m.add_argument(
        "--pressure",
        required=True,
        help="the uniform load: N/cm², or with a unit (10kPa, 75mmHg)",
    )
    m.add_argument("--thickness-mm", type=float, help="spacer thickness (a preset knows its own)")
    m.add_argument("--drift", type=Path, help="step-and-hold CSV: add a drift stage (eq. 5.8)")
    m.add_argument("-o", "--output", type=Path, required=True, help="calibration file (JSON)")
    m.add_argument(
        "--orientation",
        metavar="KIND[:EDGE]|EDGE=LABEL,...",
        help="how the mat lies (written into the calibration): bed, seat or foot with its "
        "head, front or toes at the map's first row, or e.g. bed:bottom; the monitor then "
        "names left and right",
    )
    m.add_argument("--replace", action="store_true", help="write over an existing file")
    add_accept_truncated(m)
    m.set_defaults(run=run_calibrate)

    lin = cs.add_parser(
        "linear",
        help="write a linear calibration (per-element offset and gain, no spacer model)",
        description="A calibration value = (reading - offset) / gain for mats whose readings "
        "are already linear in pressure (resistive mats, vendor-calibrated mats) or to "
        "reprocess an archive with failure detection and repair only (the defaults: offset 0, "
        "gain 1, values keep their unit).",
    )
    lin.add_argument("--like", type=Path, required=True, help="a recording of the mat")
    lin.add_argument("--offset", type=float, default=0.0, help="reading at zero load")
    lin.add_argument("--gain", type=float, default=1.0, help="reading units per output unit")
    lin.add_argument(
        "--to",
        default=None,
        metavar="QUANTITY:UNIT",
        help="what the values become (e.g. pressure:N/cm2); default: the reading's own",
    )
    lin.add_argument("--full-scale", type=float, help="readings beyond it are out of range")
    lin.add_argument("-o", "--output", type=Path, required=True, help="calibration file (JSON)")
    lin.add_argument("--replace", action="store_true", help="write over an existing file")
    add_accept_truncated(lin)
    lin.set_defaults(run=run_calibrate_linear)
    register_wizard(cs)


def _register_process(sub: argparse._SubParsersAction) -> None:
    """``process``."""
    p = sub.add_parser(
        "process",
        help=HELP["process"],
        description="Run the whole pipeline over recordings. One file: processed block by "
        "block (any input format, and an HDF5 output, keep the memory flat in the recording's "
        "length; the output may not be the input). "
        "Several files, a folder or a glob pattern: one task per file on Dask (local worker "
        "processes, or --scheduler ADDRESS), outputs mirrored into the -o folder; a second run "
        "skips files whose output has the same calibration and input; a failed file is "
        "reported at the end and the others go on.",
    )
    p.add_argument(
        "inputs", nargs="+", type=nonempty,
        help="recording(s), folder(s) or glob pattern(s) (quote them)",
    )  # fmt: skip
    p.add_argument("--calibration", type=Path, required=True, help="calibration file")
    p.add_argument(
        "-o", "--output", type=Path, required=True, help="output file, or folder for an archive"
    )
    p.add_argument("--repair", choices=(*METHODS, "none"), default="harmonic")
    p.add_argument("--no-hysteresis", action="store_true", help="first-loading curve only")
    p.add_argument("--no-drift", action="store_true", help="skip the drift stage")
    p.add_argument(
        "--in-use-drift",
        choices=("on", "off"),
        default="on",
        help="on (default): correct the drift from the mat in use (stillness, an empty mat) "
        "instead of with the calibration's drift stage, where the calibration has a spacer "
        "model; off: the laboratory drift stage only (docs/drift.md)",
    )
    p.add_argument(
        "--interval",
        type=float,
        metavar="LEVEL",
        help="give every value a bound at this level (e.g. 0.95): lower and upper maps beside "
        "the frames of an HDF5 output (docs/data-model.md, docs/drift.md)",
    )
    p.add_argument(
        "--chunk-frames",
        type=int,
        help="frames per block (default: about 2^18 element-samples, 256 frames of 1024)",
    )
    p.add_argument("--scheduler", help="dask.distributed scheduler address (archives)")
    p.add_argument(
        "--workers",
        type=int,
        help="local worker processes (default: one per core, at most one per file; an archive "
        "under 32 MB, or 1: in this process)",
    )
    add_accept_truncated(p)
    p.set_defaults(run=run_process)
    only_where(p, [
        Rule("--workers", lambda a: not _single(a) and a.scheduler is None,
             "an archive processed here (several inputs or a folder, without --scheduler)"),
        Rule("--chunk-frames", lambda a: not _single(a) or _hdf5(a.output),
             "a recording processed in blocks (an HDF5 output, or an archive): any other "
             "output is made in memory"),
        Rule("--interval", lambda a: not _single(a) or _hdf5(a.output),
             "an HDF5 output (.h5: the lower and upper maps are stored beside the frames)"),
    ])  # fmt: skip


def _register_repair_and_health(sub: argparse._SubParsersAction) -> None:
    """``repair`` and ``health``."""
    r = sub.add_parser(
        "repair",
        help=HELP["repair"],
        description="Repair every reading whose valid flag is False; repaired values stay "
        "marked invalid in the output.",
    )
    r.add_argument("input", type=Path)
    r.add_argument("-o", "--output", type=Path, required=True)
    r.add_argument("--method", choices=METHODS, default="neighbour-mean")
    add_accept_truncated(r)
    r.set_defaults(run=run_repair)

    h = sub.add_parser(
        "health",
        help=HELP["health"],
        description="Detect shorts/breaks, out-of-range, stuck readings and jumps; report "
        "per element: failure episodes, share of time failed, first/last seen.",
    )
    h.add_argument("raw", type=Path)
    h.add_argument("--calibration", type=Path, help="adds the expected range per element")
    h.add_argument("--all", action="store_true", help="list healthy elements too")
    h.add_argument("--json", action="store_true")
    add_accept_truncated(h)
    h.set_defaults(run=run_health)
    only_where(h, [Rule("--all", lambda a: not a.json, "the table (without --json: the JSON "
                        "lists every element)")])  # fmt: skip


def to_pressure(rec: Any, calibration: Path | None, **stages: Any) -> Any:
    """A recording as pressure: a capacitance recording through the pipeline of
    ``calibration`` (``stages``: e.g. ``hysteresis=False, drift=False``; no repair), a
    pressure recording as it is."""
    if rec.quantity != "capacitance":
        if calibration is not None:  # taken and ignored, the user would think it applied
            raise ParameterError(
                f"{no_effect('--calibration', 'a capacitance recording')}; this one holds "
                f"{rec.quantity} ({rec.unit})"
            )
        return rec
    if calibration is None:
        raise ParameterError("a capacitance recording needs --calibration")

    return Pipeline(load_chain(calibration), rec.layout, repair=None, **stages).run(rec)


def _capacitance(path: Path, accept_truncated: bool = False) -> Any:
    rec = load(path, accept_truncated=accept_truncated)
    if rec.quantity != "capacitance":
        raise FormatError(path, f"holds {rec.quantity}, the command needs capacitance")
    return rec


def run_calibrate(args: argparse.Namespace) -> int:
    """Run ``texsense calibrate mat``: check the inputs (:mod:`texsense.calibration.checks`),
    refuse with every reason or warn, then fit and write the chain."""
    inputs = [args.baseline, args.uniform] + ([args.drift] if args.drift else [])
    if Path(args.material).exists():
        inputs.append(Path(args.material))
    check_not_input(args.output, inputs)
    refuse_replacing(args.output, args.replace)
    try:
        orientation = parse_orientation(args.orientation)
    except ParameterError as e:
        raise ParameterError(f"--{e}") from None
    session = CalibrationSession(args.material, args.pressure, args.thickness_mm, args.drift)
    chain = session.fit(
        _capacitance(args.baseline, args.accept_truncated),
        _capacitance(args.uniform, args.accept_truncated),
        (str(args.baseline), str(args.uniform)),
    )
    chain.orientation = orientation
    for f in session.findings:
        print(f, file=sys.stderr)
    chain.save(args.output)
    convert = chain.find(Convert)
    assert convert is not None  # calibrate_mat always converts
    gain, offset = convert.gain_, convert.offset_pF_
    print(
        f"wrote {args.output}: stages {', '.join(chain.names)} for {convert.n_elements} "
        f"elements, {session.material_name} ({session.thickness_mm:g} mm) at "
        f"{session.pressure_ncm2:g} N/cm², id {chain.id}, gain {gain.min():.3f}..{gain.max():.3f}, "
        f"offset {offset.min():+.3f}..{offset.max():+.3f} pF"
    )
    return 0


def run_calibrate_linear(args: argparse.Namespace) -> int:
    """Run ``texsense calibrate linear``."""
    check_not_input(args.output, [args.like])
    refuse_replacing(args.output, args.replace)
    rec = load(args.like, accept_truncated=args.accept_truncated)
    quantity, unit = rec.quantity, rec.unit
    if args.to is not None:
        if ":" not in args.to:
            raise ParameterError(f"--to wants QUANTITY:UNIT (e.g. pressure:N/cm2), got {args.to}")
        quantity, unit = args.to.split(":", 1)
    n = rec.n_elements
    stage = Linear(rec.quantity, rec.unit, quantity, unit, args.full_scale)
    chain = StageChain([stage.fit(np.full(n, args.offset), np.full(n, args.gain))])
    chain.save(args.output)
    print(
        f"wrote {args.output}: linear calibration of {n} elements, {rec.quantity} "
        f"[{rec.unit}] -> {quantity} [{unit}], id {chain.id}"
    )
    return 0


def _options(args: argparse.Namespace) -> ProcessOptions:
    if args.chunk_frames is not None and args.chunk_frames < 1:
        raise ParameterError(f"--chunk-frames must be >= 1, got {args.chunk_frames}")
    return ProcessOptions(
        repair=None if args.repair == "none" else args.repair,
        hysteresis=not args.no_hysteresis,
        drift=not args.no_drift,
        chunk_frames=args.chunk_frames,
        accept_truncated=args.accept_truncated,
        in_use=args.in_use_drift == "on",
        interval=args.interval,
    )


def _single(args: argparse.Namespace) -> bool:
    """Whether ``process`` reads one file in blocks (not an archive)."""
    return (
        len(args.inputs) == 1
        and Path(args.inputs[0]).is_file()
        and not args.output.is_dir()
        and args.scheduler is None
    )


def _hdf5(path: Path) -> bool:
    return path.suffix.lower() in (".h5", ".hdf5")


def _stages_asked(args: argparse.Namespace, cal: StageChain) -> None:
    """Refuse a stage switched off that the calibration does not have (lin.json: no
    hysteresis, no drift, no spacer model for the in-use drift correction)."""
    held = f"{args.calibration} holds the stages {', '.join(cal.names)}"
    spacer = cal.find(Hysteresis) is not None and isinstance(cal.conversion, Convert)
    refuse_unless(args, "--no-hysteresis", cal.find(Hysteresis) is not None,
                  "a calibration with a hysteresis stage", held)  # fmt: skip
    refuse_unless(args, "--no-drift", cal.find(Drift) is not None,
                  "a calibration with a drift stage", held)  # fmt: skip
    refuse_unless(args, "--in-use-drift", spacer,
                  "a calibration with a spacer model (convert and hysteresis)", held)  # fmt: skip


def run_process(args: argparse.Namespace) -> int:
    """Run ``texsense process``: one file in blocks, or an archive on Dask."""
    options = _options(args)
    cal = load_chain(args.calibration)
    _stages_asked(args, cal)
    if _single(args):
        src = Path(args.inputs[0])
        if _hdf5(args.output):
            report = process_file(src, cal, args.output, options)
            if report.status == "skipped":
                print(f"{args.output} is up to date (same calibration {cal.id} and input)")
            else:
                print(
                    f"wrote {args.output}: {report.frames} frames; "
                    f"{report.failed_share:.1%} of readings failed"
                )
                if report.in_use is not None:
                    print(in_use_line(report.in_use))
            return 0
        return _process_in_memory(src, cal, args.output, options)
    jobs, ignored = archive_jobs(args.inputs, args.output)
    if ignored:
        names = ", ".join(str(p) for p in ignored[:5]) + (" ..." if len(ignored) > 5 else "")
        print(f"ignored {len(ignored)} file(s) that are not recordings: {names}")
    reports = process_archive(
        jobs, args.calibration, options, scheduler=args.scheduler, workers=args.workers
    )
    counts = {s: sum(r.status == s for r in reports) for s in ("done", "skipped", "failed")}
    print(
        f"{len(reports)} files -> {args.output}: {counts['done']} processed, "
        f"{counts['skipped']} up to date, {counts['failed']} failed"
    )
    for r in reports:
        if r.status == "failed":
            print(f"  failed: {r.source}: {r.error}", file=sys.stderr)
    return 1 if counts["failed"] else 0


def _process_in_memory(src: Path, cal: Any, output: Path, options: ProcessOptions) -> int:
    """Any output format other than HDF5: the whole recording in memory."""
    check_not_input(output, [src])
    raw = load(src, accept_truncated=options.accept_truncated)
    pipe = options.pipeline(cal, raw.layout)
    out = pipe.run(raw)
    save(out, output)
    failed = pipe.codes_ > 0
    print(
        f"wrote {output}: {out.n_frames} frames x {out.n_elements} elements, stages "
        f"{', '.join(out.meta['stages'])}; {failed.mean():.1%} of readings failed, "
        f"{int(failed.any(axis=0).sum())} elements failed at least once"
    )
    if options.in_use:
        print(in_use_line(pipe.in_use_status()))
    return 0


def in_use_line(status: dict[str, Any]) -> str:
    """The in-use drift correction in one line (``process``, the report)."""
    if status["state"] == "off":
        return f"in-use drift correction off: {status['why']}"
    if status["state"] != "correcting":
        return "in-use drift correction: no still period seen, nothing corrected"
    zeros = times_words(status["zeroed"])
    kept = status.get("weighed", 0)
    weight = (
        f"; reference load {status['weight_n']:.0f} N, held to it: {times_words(kept)}"
        if kept and status.get("weight_n") is not None
        else ""
    )
    return (
        f"in-use drift correction: load {100 * status['load_correction']:+.1f} % at the end, "
        f"correcting since t = {status['since_t']:.0f} s, from "
        f"{format_duration(status['still_s'])} still in all; "
        f"zero taken {zeros}{weight}; {checked_words(status, 'before the end')}"
    )


def run_repair(args: argparse.Namespace) -> int:
    """Run ``texsense repair``."""
    check_not_input(args.output, [args.input])
    rec = load(args.input, accept_truncated=args.accept_truncated)
    out = Repair(rec.layout, args.method).fit().run(rec)
    save(out, args.output)
    print(f"wrote {args.output}: {int((~rec.valid).sum())} readings repaired with {args.method}")
    return 0


def run_health(args: argparse.Namespace) -> int:
    """Run ``texsense health``."""
    raw = _capacitance(args.raw, args.accept_truncated)
    detector = FailureDetector(raw.layout).fit()
    if args.calibration:
        cal = load_chain(args.calibration)
        if cal.reads[0] != "capacitance":
            raise ParameterError("health reads capacitance: give a mat calibration")
        # the detector the pipeline would run with this calibration
        detector = Pipeline(cal, raw.layout, repair=None).detector or detector
    frames = raw.frames if raw.unit == "pF" else raw.to_unit("pF").frames
    codes = detector.detect(frames, raw.valid)
    report = health_report(codes, raw.times, raw.layout)
    if args.json:
        print(
            json.dumps(
                [
                    {
                        "element": e.element,
                        "name": e.name,
                        "status": e.status,
                        "episodes": e.episodes,
                        "failed_share": e.failed_share,
                        "first_failed_s": e.first_failed_s,
                        "last_failed_s": e.last_failed_s,
                        "kinds": e.kinds,
                    }
                    for e in report
                ],
                indent=1,
            )
        )
        return 0
    status = np.array([e.status for e in report])
    print(
        f"{raw.n_elements} elements over {raw.duration_s:.0f} s: {np.sum(status == 'ok')} ok, "
        f"{np.sum(status == 'intermittent')} intermittent, {np.sum(status == 'dead')} dead"
    )

    lay = raw.layout
    rc = None if lay.cells is None or lay.shape is None else np.divmod(lay.cells, lay.shape[1])
    rows = []
    for e in report:
        if e.status == "ok" and not args.all:
            continue
        where = ["-", "-"] if rc is None else [str(rc[0][e.element] + 1), str(rc[1][e.element] + 1)]
        first = "-" if e.first_failed_s is None else f"{e.first_failed_s:.1f}"
        last = "-" if e.last_failed_s is None else f"{e.last_failed_s:.1f}"
        kinds = ", ".join(f"{k} {v}" for k, v in e.kinds.items())
        rows.append(
            [e.name, *where, e.status, e.episodes, f"{e.failed_share:.1%}", first, last, kinds]
        )
    columns = [
        "element",
        "row",
        "column",
        "status",
        "episodes",
        "failed",
        "first s",
        "last s",
        "kinds",
    ]
    print("\n".join(text_table(columns, rows, "lrrrrrrrl")))
    if rc is not None:
        print("(rows and columns count from 1 at the top left of the map)")
    return 0
