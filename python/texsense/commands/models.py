"""``texsense rehash FILE...``: accept a deliberate edit of a model file (docs/pipeline.md,
"The one file format")."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from texsense.commands import HELP
from texsense.compensation.stages import chain_from_dict
from texsense.data.modelfile import rehash


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``rehash`` command."""
    p = sub.add_parser(
        "rehash",
        help=HELP["rehash"],
        description="A model file (calibration chain, stage, hysteresis or drift model) whose "
        "content does not match its sha256 was edited after texsense wrote it and is "
        "refused. If the edit is deliberate, this writes the hash of the content as it is "
        "now (the content itself is unchanged and must still read as its format).",
    )
    p.add_argument("files", type=Path, nargs="+", help="model files (JSON)")
    p.set_defaults(run=run_rehash)


def run_rehash(args: argparse.Namespace) -> int:
    """Run ``texsense rehash``."""

    for path in args.files:

        def check(d: dict[str, Any], path: Path = path) -> None:
            chain_from_dict(d, path)  # what it now says must still read as its format

        fmt, digest = rehash(path, check=check)
        print(f"{path}: {fmt}, content accepted as it is (sha256 {digest[:16]}...)")
    return 0
