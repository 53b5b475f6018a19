"""How often the live monitor names the virtual person's posture right.

`texsense monitor`'s default source is a simulated person on the 96-element seat (through the
virtual sensor: hysteresis, drift, failures) taking the 16 postures in random order; its
posture model is trained on *other* simulated people (texsense.apps.posture.training). This runs
the same source and model through `Monitor.process` as fast as possible and compares the
label on every seated frame with the simulated truth.

Run:  .venv/bin/python benchmarks/monitor_posture.py [--classifier linear-svm] [--seeds 0,1,2,3,4]
"""

from __future__ import annotations

import argparse
import asyncio
import time
from collections import Counter

import numpy as np

from texsense.apps.posture.training import train_virtual_seat_model
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.pipeline import Pipeline
from texsense.monitor import Monitor, VirtualSeatSource


async def collect(monitor: Monitor, frames: int) -> list[tuple]:
    """(truth, shown label (the 5 s vote), the frame's own label, frames since the posture
    changed) per frame."""
    out: list[tuple] = []
    since, last = 0, None
    async for frame in monitor.source.frames():
        snap = monitor.process(frame)
        truth = snap["source"]["true_posture"]
        since = since + 1 if truth == last else 0
        last = truth
        shown = snap["posture"]["label"] if snap["posture"] else None
        own = snap["posture"]["frame_label"] if snap["posture"] else None
        out.append((truth, shown, own, since))
        if len(out) >= frames:
            return out
    return out


def live_person(model, seed: int, sittings: float) -> tuple[list, int]:
    """(truth, label, frames since a change) per frame, and the frames in 10 s."""
    src = VirtualSeatSource(speed=0, seed=seed)
    n = int(sittings * (20 * 90 + 120) / src.frame_s)
    mon = Monitor(src, pipeline=Pipeline(seat_calibration(), src.layout), posture_model=model)
    return asyncio.run(collect(mon, n)), round(10 / src.frame_s)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sittings", type=float, default=1, help="20 postures + 2 min away each")
    ap.add_argument("--subjects", type=int, default=9, help="simulated people to train on")
    ap.add_argument("--classifier", default="linear-svm")
    ap.add_argument("--seeds", default="0,1,2,3,4", help="live people (seed 0: the monitor's)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    model = train_virtual_seat_model(subjects=args.subjects, classifier=args.classifier)
    train_s = time.perf_counter() - t0
    print(
        f"model: {args.classifier}, {args.subjects} training people ({train_s:.0f} s); "
        f"{args.sittings:g} sitting(s) of 20 postures per live person"
    )
    print(
        "\n| live person (seed) | frames | seated | right, all seated: per frame | "
        "vote over 5 s (shown) | right, ≥ 10 s after a change: per frame | vote over 5 s |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|")
    wrong: Counter[tuple[str, str]] = Counter()
    totals = []
    for seed in (int(v) for v in args.seeds.split(",")):
        rows, settle = live_person(model, seed, args.sittings)
        seated = [(t, v, p, s) for t, v, p, s in rows if t is not None]
        settled = [(t, v, p) for t, v, p, s in seated if s >= settle]
        acc = [
            100 * float(np.mean([t == (v if shown else p) for t, v, p, *_ in part]))
            for part in (seated, settled)
            for shown in (False, True)
        ]
        totals.append(acc)
        wrong.update((t, p) for t, _, p in settled if t != p)
        cells = " | ".join(f"{a:.1f} %" for a in acc)
        print(f"| {seed} | {len(rows)} | {len(seated)} | {cells} |")
    m = np.mean(totals, axis=0)
    print(f"| mean | | | {' | '.join(f'{a:.1f} %' for a in m)} |")
    print("\nmost frequent confusions (settled frames, all people, per frame): truth -> label")
    for (t, p), k in wrong.most_common(6):
        print(f"  {t} -> {p} ({k})")


if __name__ == "__main__":
    main()
