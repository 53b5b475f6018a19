"""``texsense calibrate wizard``: a new mat calibrated on the terminal, step by step
(docs/calibration.md).

1. nothing on the mat: zeroing frames are recorded once the readings are steady;
2. a uniform load P on the whole mat: recorded once the readings have risen (at least half the
   change the material's reference element shows at P) and are steady;
3. the material (a preset, by default the spacer the device announces, or a record): the
   calibration is fitted after every check of :mod:`texsense.calibration.checks` (refused
   with every reason, or warned);
4. a check with another known load (``--check``, default 2 x P): every element's reading
   through the new calibration, the elements off by more than 10 % named.

Between steps 1 and 2 the wizard learns how the mat lies (written into the calibration, so
that the monitor names left and right): what the device announces, else ``--orientation``,
else it asks which edge is the head (a bed), the front (a seat) or the toes (a foot) — typed,
or found where a hand presses on the mat; with ``--yes`` and neither, none is declared (the
maps then say "orientation unknown" and no left or right is named).

Each step waits for Enter first; with ``--yes`` it starts at once and waits for the load by
itself (what a script or a test rig needs). The step recordings are written next to the
calibration (``mat-zero.h5``, ``mat-uniform.h5``, ``mat-check.h5``; never over a file).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import sys
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np

from texsense.calibration.checks import edge_of_press, parse_pressure, typical_reading
from texsense.calibration.session import CalibrationSession
from texsense.commands._applies import Rule, only_where
from texsense.commands._options import refuse_replacing
from texsense.commands.monitor import add_source_options, open_source
from texsense.data.files import unused_name
from texsense.data.layout import ORIENTATIONS, orientation_toward
from texsense.data.protocol import Frame
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError
from texsense.io import save
from texsense.monitor.clock import FrameClock, Quiet
from texsense.monitor.sources import Source

__all__ = ["register_wizard", "run_wizard"]

#: Frames in a row whose median moves by less than :data:`STEADY_SHARE` of the expected
#: load response: the load is steady.
STEADY_FRAMES = 3
STEADY_SHARE = 0.02
#: The readings have risen once the median change reaches this share of the expected one.
RISEN_SHARE = 0.5


def register_wizard(cs: argparse._SubParsersAction) -> None:
    """Add ``calibrate wizard``."""
    w = cs.add_parser(
        "wizard",
        help="calibrate a new mat step by step from its live source",
        description="Calibrate a new mat on the terminal: nothing on the mat -> record; a "
        "uniform load P -> record; the spacer material; a check with a known load -> a "
        "report per element. Each step waits for Enter (--yes: for the load itself). "
        "Example: texsense calibrate wizard --source serial:/dev/ttyACM0 -o mat.json",
    )
    add_source_options(w)
    w.add_argument("-o", "--output", type=Path, required=True, help="calibration file (JSON)")
    w.add_argument(
        "--material",
        metavar="PRESET|RECORD.csv",
        help="the spacer (default: the one the device announces)",
    )
    w.add_argument("--thickness-mm", type=float, help="spacer thickness (with a record)")
    w.add_argument("--pressure", default="1", help="the uniform load (N/cm², or 10kPa, 75mmHg)")
    w.add_argument(
        "--check", default=None, help="the known load of the check (default 2 x --pressure)"
    )
    w.add_argument("--no-check", action="store_true", help="skip the check step")
    w.add_argument("--frames", type=int, default=10, help="frames recorded per step")
    w.add_argument("--wait-s", type=float, default=300.0, help="longest wait for a load, s")
    w.add_argument("--yes", action="store_true", help="no questions: for scripts")
    w.add_argument("--replace", action="store_true", help="write over an existing calibration file")
    w.set_defaults(run=run_wizard)
    only_where(w, [Rule("--check", lambda a: not a.no_check, "the check step (not with "
                        "--no-check)")])  # fmt: skip


class _Feed:
    """Every frame of a source, read in the background (so that no stale frame waits in a
    buffer while the person reads a prompt); a frame with a time no clock has is refused at
    the door of every live frame (:meth:`~texsense.monitor.clock.FrameClock.place_frame`),
    counted with the source's errors and said once."""

    def __init__(self, source: Source) -> None:
        self.source = source
        self.recent: deque[Frame] = deque(maxlen=256)
        self.count = 0
        self.arrived = asyncio.Event()
        self.clock = FrameClock(rate=source.rate)
        self.quiet = Quiet(logging.getLogger("texsense.monitor"))
        self.task = asyncio.ensure_future(self._run())

    async def _run(self) -> None:
        async for frame in self.source.frames():
            if self.clock.place_frame(frame)[0] == "unclocked":  # the steps take the rest
                self.source.errors += 1
                self.quiet.warn(self.source.name, "unclocked",
                                f"refused frame {frame.seq}: {self.clock.fault}")  # fmt: skip
                continue
            self.recent.append(frame)
            self.count += 1
            self.arrived.set()

    async def next_frame(self, deadline: float) -> Frame:
        """The next frame to arrive (a ParameterError at the deadline)."""
        seen = self.count
        while self.count == seen:
            self.arrived.clear()
            left = deadline - time.monotonic()
            if left <= 0:
                raise ParameterError(f"{self.source.name} sent no frame in time")
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.arrived.wait(), timeout=left)
            if self.task.done() and self.count == seen:
                raise ParameterError(f"{self.source.name} ended")
        return self.recent[-1]

    async def close(self) -> None:
        self.task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await self.task
        self.source.close()


def _as_recording(frames: list[Frame], source: Source, step: str) -> Recording:
    values = np.array([f.values for f in frames], dtype=np.float64)
    valid = np.isfinite(values)
    meta = {"source": source.name, "recorded_by": f"texsense calibrate wizard ({step})"}
    meta.update(getattr(source, "announced", {}) or {})
    return Recording(
        np.where(valid, values, 0.0),
        np.array([f.t for f in frames]),
        source.layout,
        source.quantity,
        source.unit,
        valid=valid,
        element_times=np.array([f.element_times for f in frames]),
        meta=meta,
    )


def _median(frame: Frame, reference: np.ndarray) -> float:
    change = np.asarray(frame.values, dtype=np.float64) - reference
    return float(np.nanmedian(change)) if np.isfinite(change).any() else float("nan")


async def _steady_frames(
    feed: _Feed,
    n: int,
    wait_s: float,
    reference: np.ndarray | None,
    expected_pF: float,
    say: Any,
) -> list[Frame]:
    """Wait until the readings have moved by half ``expected_pF`` from ``reference`` (if
    given) and are steady, then collect ``n`` frames."""
    deadline = time.monotonic() + wait_s
    base = reference
    history: deque[float] = deque(maxlen=STEADY_FRAMES + 1)
    risen = reference is None
    last_said = 0.0
    while True:
        frame = await feed.next_frame(deadline)
        if base is None:
            base = np.asarray(frame.values, dtype=np.float64)
        level = _median(frame, base)
        if not risen and np.isfinite(level) and level / expected_pF >= RISEN_SHARE:
            risen = True
            say(f"  the load is on ({level:+.3f} pF); waiting until the readings are steady")
        history.append(level)
        moves = np.abs(np.diff(np.array(history)))
        steady = len(history) > STEADY_FRAMES and bool(
            np.all(moves < STEADY_SHARE * abs(expected_pF))
        )
        if risen and steady:
            break
        if time.monotonic() - last_said > 5:
            last_said = time.monotonic()
            what = "steady readings" if risen else f"the load ({expected_pF:+.3f} pF expected)"
            say(f"  waiting for {what}: median change {level:+.3f} pF")
        if time.monotonic() > deadline:
            raise ParameterError(
                f"no steady load within --wait-s {wait_s:g} s (median change {level:+.3f} pF, "
                f"{expected_pF:+.3g} pF expected)"
            )
    frames: list[Frame] = []
    while len(frames) < n:
        frames.append(await feed.next_frame(deadline + 60))
    return frames


async def _ask(question: str, yes: bool) -> str:
    if yes:
        print(question.replace("press Enter", "going on (--yes)"), flush=True)
        return ""
    print(question, end=" ", flush=True)
    answer = await asyncio.to_thread(sys.stdin.readline)
    if answer == "":
        raise ParameterError("standard input closed: run with --yes for no questions")
    return answer.strip()


_ASK_EDGE = (
    "which edge is the head (a bed), the front (a seat) or the toes (a foot)? Type the kind "
    "and the edge of the map: top (the first row), bottom, left (the first column) or right, "
    "e.g. 'bed top'; or the kind alone, then press on that edge of the mat; or 'none':"
)


async def _orientation(
    args: argparse.Namespace, source: Any, feed: _Feed, zero: Recording, say: Any
) -> dict[str, str]:
    """How the mat lies: announced, given, typed or pressed (see the module)."""
    declared = source.layout.orientation
    if declared:
        how = "--orientation" if args.orientation is not None else "announced by the device"
        say(f"  orientation: {_edges(declared)} ({how})")
        return dict(declared)
    if args.orientation is not None or args.yes:  # --orientation none, or no questions
        say("  orientation: not declared (--orientation bed|seat|foot[:EDGE] declares it): "
            "the maps will name no left or right")  # fmt: skip
        return {}
    answer = (await _ask(_ASK_EDGE, False)).lower().split()
    if not answer or answer[0] == "none":
        return {}
    if answer[0] not in ORIENTATIONS:
        raise ParameterError(
            f"the kind must be one of {', '.join(ORIENTATIONS)}, got {answer[0]!r}"
        )
    if len(answer) > 1:
        edge = answer[1]
    else:
        await _ask(f"press firmly on the mat at its {ORIENTATIONS[answer[0]]['top']} end and "
                   "hold, then press Enter", False)  # fmt: skip
        frame = await feed.next_frame(time.monotonic() + args.wait_s)
        edge = edge_of_press(frame.values, typical_reading(zero), source.layout)
        say(f"  the press is nearest the {edge} edge")
    found = orientation_toward(answer[0], edge)
    say(f"  orientation: {_edges(found)}")
    return found


def _edges(o: dict[str, str]) -> str:
    return ", ".join(f"{k}: {v}" for k, v in o.items())


async def _wizard(args: argparse.Namespace, source: Any) -> int:
    say = lambda text: print(text, flush=True)  # noqa: E731
    stem = args.output.with_suffix("")
    pressure = parse_pressure(args.pressure)
    check_p = None if args.no_check else parse_pressure(args.check or 2 * pressure)
    feed = _Feed(source)
    kept: list[Path] = []

    def keep(rec: Recording, step: str) -> Recording:
        path = unused_name(f"{stem}-{step}.h5")
        save(rec, path)
        kept.append(path)
        return rec

    try:
        say(f"texsense calibrate wizard: {source.name}, {source.layout.n_elements} elements")
        await _ask("step 1/4: take everything off the mat, then press Enter", args.yes)
        zero = keep(
            _as_recording(
                await _steady_frames(feed, args.frames, args.wait_s, None, 1.0, say),
                source,
                "zero",
            ),
            "zero",
        )
        say(f"  recorded {zero.n_frames} frames -> {kept[-1]}")
        orientation = await _orientation(args, source, feed, zero, say)
        material = args.material or (getattr(source, "announced", {}) or {}).get("spacer")
        if material is None:
            if args.yes:
                raise ParameterError("the device announces no spacer: give --material")
            material = await _ask("the spacer (a preset such as textile-3mm, or a CSV):", False)
        else:
            say(
                f"  material: {material}"
                + (" (announced by the device)" if args.material is None else "")
            )
        session = CalibrationSession(material, pressure, args.thickness_mm)
        expected = session.expected_change_pF(pressure)
        await _ask(
            f"step 2/4: put a uniform load of {pressure:g} N/cm² on the whole mat (a bladder "
            "or a plate), then press Enter",
            args.yes,
        )
        frames = await _steady_frames(
            feed, args.frames, args.wait_s, typical_reading(zero), expected, say
        )
        uniform = keep(_as_recording(frames, source, "uniform"), "uniform")
        say(f"  recorded {uniform.n_frames} frames -> {kept[-1]}")
        say(f"step 3/4: calibrating with {session.material_name}")
        chain = session.fit(zero, uniform, (str(kept[0]), str(kept[1])))
        chain.orientation = orientation
        for f in session.findings:
            say(f"  {f}")
        chain.save(args.output)
        say(f"  wrote {args.output} (id {chain.id})")
        if check_p is None:
            return 0
        await _ask(
            f"step 4/4: check: put a known load of {check_p:g} N/cm² on the mat, then press Enter",
            args.yes,
        )
        change = session.expected_change_pF(check_p) - expected
        frames = await _steady_frames(
            feed, args.frames, args.wait_s, typical_reading(uniform), change, say
        )
        check = keep(_as_recording(frames, source, "check"), "check")
        report = session.check(check, check_p, before=uniform)
        for line in report.lines():
            say(f"  {line}")
        say(
            "calibration done: "
            + ("every working element within 10 %" if report.passed else "see the elements above")
            + f"; use it with --calibration {args.output}"
        )
        return 0
    finally:
        await feed.close()


def run_wizard(args: argparse.Namespace) -> int:
    """Run ``texsense calibrate wizard``."""
    if args.frames < 3:
        raise ParameterError(f"--frames must be >= 3, got {args.frames}")
    if not args.output.parent.is_dir():
        raise ParameterError(f"the folder {args.output.parent} does not exist")
    refuse_replacing(args.output, args.replace)
    parse_pressure(args.pressure)
    source = open_source(args, loop=False)
    if source.quantity != "capacitance":
        source.close()
        raise ParameterError(f"{source.name} sends {source.quantity}: a calibration needs pF")
    try:
        return asyncio.run(_wizard(args, source))
    except KeyboardInterrupt:
        print("texsense calibrate wizard: stopped", file=sys.stderr)
        return 130
