"""``texsense stocking``: compression stockings read by a textile sensor strip
(docs/stocking.md)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from texsense.apps.stocking import POINTS, report
from texsense.calibration.workflows import strip_calibration
from texsense.commands import HELP
from texsense.commands._options import add_accept_truncated
from texsense.data.files import make_folder
from texsense.sim.stocking import LEGS, wear


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``stocking`` command."""
    p = sub.add_parser(
        "stocking",
        help=HELP["stocking"],
        description="Read a sensor strip under a compression stocking (elements named B, B1, "
        "C, D): the pressure at each point in mmHg hour by hour, the gradient from the ankle "
        "up and the compression class of RAL-GZ 387, drift compensated with the uncompensated "
        "value beside it; or simulate a day's wear on a virtual leg.",
    )
    ps = p.add_subparsers(dest="stocking_command", metavar="WHAT")
    ps.required = True
    r = ps.add_parser("report", help="pressure, gradient and class hour by hour")
    r.add_argument("recording", type=Path, help="the strip: capacitance, or pressure")
    r.add_argument("--calibration", type=Path, help="the strip's calibration (for capacitance)")
    r.add_argument("--every", type=float, default=1.0, help="hours between rows (default 1)")
    r.add_argument("--json", action="store_true")
    add_accept_truncated(r)
    r.set_defaults(run=run_report)
    s = ps.add_parser("simulate", help="a day's wear on a virtual leg, read by the strip")
    s.add_argument("--class", dest="cls", choices=("I", "II", "III", "IV"), default="II")
    s.add_argument("--leg", choices=("small", "medium", "large"), default="medium")
    s.add_argument("--hours", type=float, default=8.0)
    s.add_argument("-o", "--output", type=Path, required=True, help="folder to write")
    s.set_defaults(run=run_simulate)


def run_simulate(args: argparse.Namespace) -> int:
    """Run ``texsense stocking simulate``: strip.h5 (capacitance, true pressure as labels) and
    calibration.json (the strip's stage chain)."""
    from texsense.io import save

    make_folder(args.output)
    _, truth, scan = wear(args.cls, LEGS[args.leg], hours=args.hours)
    labels = {f"true_{p}_ncm2": truth[:, k] for k, p in enumerate(POINTS)}
    rec = scan.capacitance.with_labels(labels)
    save(rec, args.output / "strip.h5")
    strip_calibration().save(args.output / "calibration.json")
    print(f"wrote {args.output}/strip.h5 ({rec.n_frames} frames, class {args.cls} stocking, "
          f"{args.leg} leg, {args.hours:g} h) and calibration.json")  # fmt: skip
    return 0


def run_report(args: argparse.Namespace) -> int:
    """Run ``texsense stocking report``."""
    from texsense.commands.pipeline import to_pressure
    from texsense.io import load

    rec = load(args.recording, accept_truncated=args.accept_truncated)
    pressure = to_pressure(rec, args.calibration)
    unc = None
    if rec.quantity == "capacitance":  # the uncompensated reading beside it
        unc = to_pressure(rec, args.calibration, hysteresis=False, drift=False)
    rep = report(pressure, unc, every_h=args.every)
    if args.json:
        print(json.dumps(rep.to_dict(), indent=1))
        return 0
    head = " | ".join(POINTS)
    extra = " | uncompensated B | class uncompensated" if unc is not None else ""
    print(f"| hours | {head} (mmHg) | B1/B, C/B, D/B | class (RAL-GZ 387){extra} |")
    print("|---:|" + "---:|" * len(POINTS) + "---|---|" + ("---:|---|" if unc is not None else ""))
    classes = rep.classes()
    unc_classes = rep.classes(uncompensated=True) if unc is not None else None
    for k, h in enumerate(rep.hours):
        vals = " | ".join(f"{v:.1f}" for v in rep.mmhg[k])
        grad = ", ".join(f"{v:.2f}" for v in rep.gradient[k])
        row = f"| {h:g} | {vals} | {grad} | {classes[k]}"
        if unc_classes is not None and rep.uncompensated_mmhg is not None:
            row += f" | {rep.uncompensated_mmhg[k, 0]:.1f} | {unc_classes[k]}"
        print(row + " |")
    return 0
