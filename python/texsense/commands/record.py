"""``texsense record``: raw frames from any source into a crash-safe HDF5 recording, with no
calibration (docs/calibration.md)."""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any

from texsense.commands import HELP
from texsense.commands.monitor import add_source_options, open_source
from texsense.data.files import check_new, check_not_input
from texsense.exceptions import ParameterError
from texsense.monitor.record import SILENT_S, record

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``record`` command."""
    p = sub.add_parser(
        "record",
        help=HELP["record"],
        description="Record what a source sends, as it is (capacitance in pF for a mat), to a "
        "new HDF5 file that survives a crash (flushed every 0.5 s). Stops after --duration "
        "seconds of frames, after --frames frames, or at Ctrl-C. A progress line shows frames, "
        "rate and frames dropped. Examples: "
        "texsense record --source serial:/dev/ttyACM0 -o empty.h5 --duration 30",
    )
    add_source_options(p)
    p.add_argument("-o", "--output", type=Path, required=True, help="the new HDF5 recording")
    p.add_argument("--duration", type=float, metavar="S", help="seconds of frames to record")
    p.add_argument("--frames", type=int, metavar="N", help="number of frames to record")
    p.set_defaults(run=run_record)


class _Progress:
    """One line on stderr: rewritten in place on a terminal, every 5 s otherwise."""

    def __init__(self) -> None:
        self.tty = sys.stderr.isatty() and not os.environ.get("TEXSENSE_NO_PROGRESS")
        self.last = 0.0
        self.said_silent = False

    def __call__(self, stats: Any) -> None:
        if stats.silent and not self.said_silent:
            print(f"\rtexsense record: no frames for {SILENT_S:g} s", file=sys.stderr, flush=True)
        self.said_silent = stats.silent
        now = time.monotonic()
        if self.tty:
            print(f"\rtexsense record: {stats.line()}   ", end="", file=sys.stderr, flush=True)
        elif now - self.last >= 5.0 and not os.environ.get("TEXSENSE_NO_PROGRESS"):
            print(f"texsense record: {stats.line()}", file=sys.stderr, flush=True)
            self.last = now

    def end(self) -> None:
        if self.tty:
            print(file=sys.stderr)


def run_record(args: argparse.Namespace) -> int:
    """Run ``texsense record``."""

    kind, _, rest = args.source.partition(":")
    if kind == "replay":
        check_not_input(args.output, [rest], what="recording")
    check_new(args.output)
    if not args.output.parent.is_dir():
        raise ParameterError(f"the folder {args.output.parent} does not exist")
    source = open_source(args, loop=False)
    print(
        f"texsense record: {source.name} ({source.layout.n_elements} elements, "
        f"{source.quantity} in {source.unit}) -> {args.output}; Ctrl-C stops",
        file=sys.stderr,
        flush=True,
    )
    progress = _Progress()

    async def main() -> Any:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        return await record(
            source,
            args.output,
            duration_s=args.duration,
            max_frames=args.frames,
            on_progress=progress,
            stop=stop,
        )

    stats = asyncio.run(main())
    progress.end()
    print(f"texsense record: {stats.line()} -> {args.output}", flush=True)
    if stats.frames == 0:
        args.output.unlink(missing_ok=True)  # nothing recorded: no empty file left behind
        print(f"texsense record: error: no frames came from {source.name}", file=sys.stderr)
        return 1
    return 0
