"""``texsense report``: a PDF or HTML report of one recording (docs/report.md)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from texsense.apps.posture.model import PostureModel
from texsense.apps.report import write_report
from texsense.apps.roi import parse_rois
from texsense.commands import HELP
from texsense.commands._applies import Rule, only_where
from texsense.data.files import json_loads, read_regular
from texsense.exceptions import FormatError, ParameterError


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``report`` command."""
    p = sub.add_parser(
        "report",
        help=HELP["report"],
        description="Write a report of any recording texsense reads: identity, peak and mean "
        "maps on a fixed scale with the threshold, load/peak/contact area/centre of force over "
        "time, statistics per region, events and alerts, sensor health and, for a bed, the "
        "time per side and the turns.",
    )
    p.add_argument("recording", type=Path, help="a file or folder texsense reads")
    p.add_argument("-o", "--output", type=Path, required=True, help="report.pdf or report.html")
    p.add_argument("--mode", choices=("seat", "bed", "foot", "generic"), help="default: guessed")
    p.add_argument("--unit", help="pressure unit shown (default: the mode's, mmHg on seats, beds)")
    p.add_argument("--scale", metavar="LO,HI", help="colour scale in that unit (default: fixed)")
    p.add_argument("--threshold", type=float, metavar="MMHG", help="exposure threshold (mmHg)")
    p.add_argument("--reposition-min", type=float, help="reposition alert after (min)")
    p.add_argument("--turn-every", type=float, metavar="MIN", help="bed: turning schedule (min)")
    p.add_argument("--model", type=Path, help="bed: a posture model of sides for the time per side")
    p.add_argument("--rois", type=Path, help="regions of interest (default: RECORDING.rois.json)")
    p.set_defaults(run=run_report)
    # (a mode guessed from the recording: the same refused once it is read, apps.review)
    only_where(p, [
        *(Rule(flag, lambda a: a.mode in (None, "bed"), "a bed (--mode bed)")
          for flag in ("--model", "--turn-every")),
        *(Rule(flag, lambda a: a.mode != "foot", "exposure alerts (not --mode foot)")
          for flag in ("--threshold", "--reposition-min")),
    ])  # fmt: skip


def _scale(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise ParameterError(f"--scale: expected LO,HI (two numbers), got {text!r}") from None
    if not hi > lo:
        raise ParameterError(f"--scale: HI must be above LO, got {text!r}")
    return lo, hi


def run_report(args: argparse.Namespace) -> int:
    """Run ``texsense report``."""

    start = time.perf_counter()
    rois = None
    if args.rois is not None:
        try:
            data = json_loads(read_regular(args.rois, "a regions file").decode("utf-8"))
        except FormatError:
            raise  # (names the file and what it is instead)
        except (OSError, ValueError) as e:
            raise ParameterError(f"{args.rois}: cannot read the regions ({e})") from None
        try:
            rois = parse_rois(data.get("regions") if isinstance(data, dict) else data)
        except ParameterError as e:
            raise ParameterError(f"{args.rois}: {e}") from None
    model = None
    if args.model is not None:
        model = PostureModel.load(args.model)
    out = write_report(
        args.recording, args.output, rois=rois, mode=args.mode, unit=args.unit,
        scale=_scale(args.scale), threshold_mmhg=args.threshold,
        reposition_min=args.reposition_min, turn_every_min=args.turn_every, model=model,
    )  # fmt: skip
    print(f"wrote {out} ({time.perf_counter() - start:.1f} s)")
    return 0
