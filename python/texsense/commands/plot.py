"""``texsense plot FILE -o PNG``: pressure map of a frame, load and centre of force over time."""

from __future__ import annotations

import argparse
from pathlib import Path

from texsense.apps.plotting import peak_frame, save_overview
from texsense.commands import HELP
from texsense.commands._options import add_accept_truncated
from texsense.data.files import check_not_input
from texsense.io import load


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``plot`` command."""
    p = sub.add_parser(
        "plot",
        help=HELP["plot"],
        description="Render a PNG: the map of one frame beside the total load (sum for raw "
        "data) and the centre of force over time.",
    )
    p.add_argument("file", type=Path, help="recording file or folder")
    p.add_argument("-o", "--output", type=Path, required=True, help="PNG file to write")
    p.add_argument("--frame", type=int, help="frame index to map (default: the peak frame)")
    p.add_argument("--unit", help="display pressure in this unit (N/cm2, kPa, mmHg, psi)")
    add_accept_truncated(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run ``texsense plot``."""
    check_not_input(args.output, [args.file])
    rec = load(args.file, accept_truncated=args.accept_truncated)
    if args.unit:
        rec = rec.to_unit(args.unit)
    frame = peak_frame(rec) if args.frame is None else args.frame
    save_overview(rec, args.output, frame, title=str(args.file))
    print(f"wrote {args.output} (frame {frame} of {rec.n_frames})")
    return 0
