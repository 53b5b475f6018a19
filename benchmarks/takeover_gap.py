"""How frames that nobody read (a takeover's gap, frames lost on the way) move a reposition
alert (docs/station.md, "What is lost at worst").

Virtual seats (the simulated people of ``texsense simulate mats``, read through the virtual
sensor and the seat's calibration, as a station reads them) are fed to a station's mat
(``MatEntry``) frame by frame: the *reference* reads every frame. A *taker* restores the
reference's checkpoint taken at frame j (``texsense.station.checkpoint``, as a member taking a
mat over does) and reads from frame j + 1 + g: g frames were read by nobody. For every j up to
the reference's first alert, the taker's first alert is compared with the reference's, under
two rules for the time not read:

- ``next frame``: the time since the last frame read counts in the state of the next frame
  read (what texsense did before: an element relieved inside the gap counts as loaded, one
  loaded inside it as relieved, and that relief can reset an exposure that is still there);
- ``loaded``: that time counts as loaded for an element loaded at either frame read, never as
  relief (``ExposureTracker.step``, ``skipped``): texsense now.

The ground truth is reading every frame through the same station code: what is measured is
only what the gap does.

Run:  .venv/bin/python benchmarks/takeover_gap.py [--people 3] [--stride 2]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from texsense.apps.alerts import ExposureTracker
from texsense.calibration.workflows import seat_calibration
from texsense.monitor.store import EventStore
from texsense.monitor.virtual import VirtualSeatSource
from texsense.station import checkpoint
from texsense.station.virtual import VirtualMats, frame_payload
from texsense.station.ward import MatConfig, MatEntry

#: the seat's frame period (s) and the alert after this much sitting (min)
FRAME_S, REPOSITION_MIN = 1.6, 5.0
#: frames nobody read in a takeover's gap: 1.6 ... 19.2 s (a killed member's mats are back
#: within 1-3 s, a vanished machine's within ~8 s, at up to 200 mats a member)
GAPS = (1, 3, 6, 12)
RULES = ("next frame", "loaded")


def payloads(seed: int, start: int, frames: int, every: int = 1) -> list[tuple[bytes, float]]:
    """A person's frames ``start`` ... (every ``every``-th: a mat that scans less often) as
    MQTT payloads numbered from 0, with their arrival (wall s) at real time."""
    source = VirtualSeatSource(speed=0, seed=seed)

    async def take() -> list:
        out = []
        async for f in source.frames():
            out.append(f)
            if len(out) == start + frames * every:
                break
        return out[start::every]

    taken = asyncio.run(take())
    t0 = taken[0].t
    out = []
    for k, f in enumerate(taken):
        d = json.loads(frame_payload(f))
        d["seq"] = k
        out.append((json.dumps(d).encode(), 1000.0 + f.t - t0))
    return out


def first_alert(entry: MatEntry) -> float | None:
    alerts = entry.monitor.tracker.alerts
    return alerts[0].opened_t if alerts else None


def reference(config: MatConfig, frames: list[tuple[bytes, float]], folder: Path):
    """Every frame read: the first alert and the checkpoint after each frame."""
    entry = MatEntry(config, EventStore(":memory:"), folder, 1.0)
    blobs, times = [], []
    for p, now in frames:
        entry.handle(p, now)
        times.append(entry.monitor.clock.last_t)
        blobs.append([checkpoint.save(entry, often=False), checkpoint.save(entry, often=True)])
    return first_alert(entry), blobs, np.array(times)


class _NextFrameRule(ExposureTracker):
    """The rule before: frames not read are not said to the tracker."""

    def step(self, *args, skipped: bool = False, **kw):  # type: ignore[override]
        return super().step(*args, skipped=False, **kw)


def taker(config, frames, blobs, j: int, g: int, rule: str, folder: Path) -> float | None:
    entry = MatEntry(config, EventStore(":memory:"), folder, 1.0)
    if rule == "next frame":
        entry.monitor.tracker.__class__ = _NextFrameRule
    checkpoint.restore(entry, blobs[j])
    for p, now in frames[j + 1 + g :]:
        entry.handle(p, now)
    return first_alert(entry)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--people", type=int, default=3, help="simulated people (seeds)")
    ap.add_argument("--stride", type=int, default=2, help="every n-th takeover position")
    ap.add_argument("--every", type=int, default=1,
                    help="every n-th frame of the seat (a mat that scans less often: the group "
                    "fault test's mats publish every 4th)")  # fmt: skip
    args = ap.parse_args()
    config = VirtualMats(1, None, speed=1.0).configs(seat_calibration(), None, REPOSITION_MIN)[0]
    folder = Path(tempfile.mkdtemp(prefix="texsense-gap-"))
    period = FRAME_S * args.every
    frames_n = int(REPOSITION_MIN * 60 / period) + 2 * max(GAPS) + 30
    diffs: dict[tuple[str, int], list[float]] = {}
    t_start = time.monotonic()
    for seed in range(args.people):
        for start in (0, 400):  # two stretches of each person's sitting
            frames = payloads(seed, start, frames_n, args.every)
            want, blobs, times = reference(config, frames, folder)
            if want is None:
                continue
            positions = range(0, int(np.searchsorted(times, want)) + 1, args.stride)
            last = int(np.searchsorted(times, want)) + max(GAPS) + 10  # (an alert is not later)
            frames = frames[: last + 1]
            for g in GAPS:
                for j in positions:
                    if j + 1 + g >= len(frames):
                        continue
                    for rule in RULES:
                        got = taker(config, frames, blobs, j, g, rule, folder)
                        d = np.inf if got is None else got - want
                        diffs.setdefault((rule, g), []).append(d)
            done = time.monotonic() - t_start
            print(f"  person {seed}, from frame {start}: {done:.0f} s", file=sys.stderr)
    print("| frames not read (s) | rule | takeovers | alert moved | later: most | earlier: most |")
    print("|---|---|---:|---:|---:|---:|")
    for g in GAPS:
        for rule in RULES:
            d = np.array(diffs[(rule, g)])
            moved = np.abs(d) > 0.01
            late, early = abs(max(d.max(), 0.0)), abs(max(-d.min(), 0.0))
            print(f"| {g} ({g * period:.1f} s) | {rule} | {d.size} | {moved.mean():.0%} | "
                  f"{late:.1f} s | {early:.1f} s |")  # fmt: skip


if __name__ == "__main__":
    main()
