"""``texsense convert IN OUT``: any readable format to HDF5, wide CSV or Tekscan ASCII."""

from __future__ import annotations

import argparse
from pathlib import Path

from texsense.commands import HELP
from texsense.commands._options import add_accept_truncated
from texsense.data.files import check_not_input
from texsense.io import WRITERS, format_for_output, load, save


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``convert`` command."""
    p = sub.add_parser(
        "convert",
        help=HELP["convert"],
        description="Read any supported recording and write it in another format. The output "
        "format follows the extension of OUT unless --format is given. OUT is written under a "
        "temporary name and renamed when complete (a failed write keeps the previous OUT); "
        "OUT may not be IN.",
    )
    p.add_argument("input", type=Path, help="recording file or folder to read")
    p.add_argument("output", type=Path, help="file to write (.h5, .csv or .asf)")
    p.add_argument(
        "--format", choices=sorted(WRITERS), help="output format (default: by extension)"
    )
    p.add_argument("--unit", help="convert values to this unit first (e.g. kPa, mmHg)")
    add_accept_truncated(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run ``texsense convert``."""
    fmt = args.format or format_for_output(args.output)
    check_not_input(args.output, [args.input])
    rec = load(args.input, accept_truncated=args.accept_truncated)
    if args.unit:
        rec = rec.to_unit(args.unit)
    save(rec, args.output, format=fmt)
    print(
        f"wrote {args.output} ({fmt}): {rec.n_frames} frames x {rec.n_elements} elements, "
        f"{rec.quantity} in {rec.unit}"
    )
    return 0
