"""Where the time of ``Pipeline.step`` goes: the latency of one frame of a 32 x 32 mat on a
real stream (every frame different) with stages switched off one after another.

Run:  .venv/bin/python benchmarks/step_stages.py [--frames N]

Columns: ``step`` is the public call (Python wrapper included), ``chain`` the compiled chain
alone (``Chain.step`` into arrays held). Medians over all frames after the first 100 (after
the first half of a run shorter than 200 frames: ``--frames 20`` is a smoke test).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pipeline_speed import mat_case
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.pipeline import Pipeline

CASES = [
    ("all stages", dict(repair="neighbour-mean")),
    ("no detection, no repair", dict(repair=None, detect=False)),
    ("... and no drift", dict(repair=None, detect=False, drift=False)),
    (
        "no detection, no repair, loading curve for Preisach, drift on",
        dict(repair=None, detect=False, hysteresis=False),
    ),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000)
    args = parser.parse_args()
    cal = seat_calibration(5)
    calibration, layout, rec = mat_case(cal, 32, 32, args.frames, seed=3)
    cap = np.ascontiguousarray(rec.frames, dtype=np.float64)
    n = cap.shape[1]
    dt = float(np.median(np.diff(rec.times)))
    warm = min(100, rec.n_frames // 2)
    print("| stages | step median µs | chain median µs |")
    print("|---|---:|---:|")
    for name, kw in CASES:
        pipe = Pipeline(calibration, layout, **kw)
        step, chain = [], []
        for k in range(rec.n_frames):
            t0 = time.perf_counter()
            pipe.step(cap[k], None, float(rec.times[k]))
            step.append(time.perf_counter() - t0)
        compiled = pipe.compiled()
        compiled.reset()
        held = np.empty(n), np.empty(n, np.uint8), np.empty(n, bool)
        for k in range(rec.n_frames):
            t0 = time.perf_counter()
            compiled.step(dt, cap[k], None, *held)
            chain.append(time.perf_counter() - t0)
        print(
            f"| {name} | {np.median(step[warm:]) * 1e6:.0f} | {np.median(chain[warm:]) * 1e6:.0f} |"
        )


if __name__ == "__main__":
    main()
