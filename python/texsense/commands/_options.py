"""Options that several commands share."""

from __future__ import annotations

import argparse
from pathlib import Path

from texsense.exceptions import ParameterError

__all__ = ["add_accept_truncated", "refuse_replacing"]

ACCEPT_TRUNCATED_HELP = (
    "read a recording that holds less than it declares (an export cut short or closed early, "
    "a last frame cut mid-line, an HDF5 file whose datasets differ in length) up to its last "
    "complete frame, with one warning line saying how much is missing, instead of refusing it"
)


def add_accept_truncated(p: argparse.ArgumentParser) -> None:
    """Add ``--accept-truncated`` (``args.accept_truncated``) to a command that reads
    recordings."""
    p.add_argument("--accept-truncated", action="store_true", help=ACCEPT_TRUNCATED_HELP)


def refuse_replacing(path: Path, replace: bool) -> None:
    """A calibration file is not written over without ``--replace`` (a monitor may be using
    it; the mat's readings would change without a word)."""
    if path.exists() and not replace:
        raise ParameterError(
            f"{path} exists: a calibration is not replaced without --replace "
            "(or write it to another name)"
        )
