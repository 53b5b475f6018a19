"""Playback of recordings longer than the memory budget (docs/monitor.md "Recordings longer
than the memory budget"): texsense HDF5 recordings of 32 x 32 float64 frames, written chunk
by chunk, opened by the monitor's playback under ``TEXSENSE_MAX_MEMORY=16M`` in a child
process each (after a warm-up on a 200-frame file), then seeks to the start, the middle and
the end. Prints, per file: its size, frames, the time to open it (the streaming passes), the
mean time of a seek, and how far the child's peak resident memory grew over its warm-up; and,
as the baseline, the same file read whole under an 8 GiB budget (``texsense.load`` then the
same review), which the 16 MiB budget refuses.

    .venv/bin/python benchmarks/playback_memory.py [FRAMES ...]
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from faults.test_playback_demand import _long_recording  # noqa: E402

_CHILD = r"""
import json, sys, time
from pathlib import Path
from texsense.monitor.playback import _Reviews, _frame, _summary

def kib(key):
    for line in open("/proc/self/status"):
        if line.startswith(key + ":"):
            return int(line.split()[1])

reviews = _Reviews()
warm = Path(sys.argv[2])
_frame(reviews.get(warm), 0)
base = kib("VmHWM")
path = Path(sys.argv[1])
t = time.perf_counter()
if sys.argv[3] == "whole":
    from texsense.apps.review import open_review
    from texsense.io import load
    review = open_review(load(path), unit="N/cm2", name=path.name)
else:
    review = reviews.get(path)
opened = time.perf_counter() - t
n = review.rec.n_frames
t = time.perf_counter()
for i in (0, n // 2, n - 1, 1, n // 2 + 1, n - 2):
    _frame(review, i)
seek = (time.perf_counter() - t) / 6
print(json.dumps({"frames": n, "open_s": opened, "seek_ms": seek * 1e3,
                  "grown_mib": (kib("VmHWM") - base) / 1024}))
"""


def _play(path: Path, warm: Path, how: str, budget: str) -> dict[str, float]:
    env = dict(os.environ, TEXSENSE_MAX_MEMORY=budget, TEXSENSE_NO_PROGRESS="1")
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(path), str(warm), how],
                          capture_output=True, text=True, env=env, check=False)  # fmt: skip
    if proc.returncode:
        return {"error": proc.stderr.strip().splitlines()[-1]}  # type: ignore[dict-item]
    return json.loads(proc.stdout)


def main() -> int:
    counts = [int(a) for a in sys.argv[1:]] or [4800, 9600, 19200]
    print("| file | frames | how | open (s) | seek (ms) | peak memory over warm-up |")
    print("|---:|---:|---|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        warm = _long_recording(Path(tmp) / "warm.h5", 200)
        for frames in counts:
            path = _long_recording(Path(tmp) / f"long-{frames}.h5", frames)
            size = f"{path.stat().st_size / 2**20:.0f} MiB"
            for how, budget in (("on demand", "16M"), ("whole", "8G")):
                r = _play(path, warm, how, budget)
                label = f"{how}, budget {budget}iB"
                if "error" in r:
                    print(f"| {size} | {frames} | {label} | refused: {r['error'][:60]} | | |")
                    continue
                print(f"| {size} | {r['frames']} | {label} | {r['open_s']:.1f} | "
                      f"{r['seek_ms']:.1f} | {r['grown_mib']:.0f} MiB |")  # fmt: skip
            path.unlink()
    return 0


if __name__ == "__main__":
    sys.exit(main())
