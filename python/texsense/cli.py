"""The ``texsense`` command line: one sub-command per module in :mod:`texsense.commands`.

Exit codes: 0 ok, 1 failed (bad file, bad data), 2 bad usage.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from texsense import __version__
from texsense.commands import COMMANDS
from texsense.exceptions import FormatError, ParameterError, UnitError, WriteError

__all__ = ["main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="texsense",
        description=(
            "texsense: textile and soft pressure sensors, from raw capacitance to accurate "
            "pressure maps. Run 'texsense COMMAND --help' for the options of a command."
        ),
    )
    parser.add_argument("--version", action="version", version=f"texsense {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for module in COMMANDS:
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except (FormatError, ParameterError, UnitError, WriteError, FileNotFoundError) as e:
        print(f"texsense {args.command}: error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"texsense {args.command}: interrupted", file=sys.stderr)
        return 1
    except BrokenPipeError:  # the reader went away (`texsense ... | head`): not an error
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
