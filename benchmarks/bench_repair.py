"""Speed of the eq. 6.14 neighbour-mean repair: Rust core versus a NumPy baseline.

Run:  .venv/bin/python benchmarks/bench_repair.py [--quick]

Both implementations are run in the same process on the same frames, so the ratio is
meaningful even on a shared, noisy machine; absolute numbers are not.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import best_of
from texsense import Layout, Recording
from texsense.compensation.repair import Repair


def numpy_repair(frames: np.ndarray, valid: np.ndarray, layout: Layout) -> np.ndarray:
    """Eq. 6.14 in plain NumPy, vectorised over elements, frame by frame (the baseline)."""
    indptr, indices = layout.neighbours
    owner = np.repeat(np.arange(layout.n_elements), np.diff(indptr))
    last = np.full(layout.n_elements, np.nan, np.float32)
    out = np.empty_like(frames)
    for t in range(frames.shape[0]):
        f = frames[t]
        ok = valid[t] & np.isfinite(f)
        contrib = np.where(ok[indices], f[indices], 0.0)
        sums = np.bincount(owner, weights=contrib, minlength=layout.n_elements)
        counts = np.bincount(owner, weights=ok[indices], minlength=layout.n_elements)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = (sums / counts).astype(np.float32)
        row = np.where(ok, f, np.where(counts > 0, mean, last))
        last = np.where(ok | (counts > 0), row, last)
        out[t] = row
    return out


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="50 times fewer frames (a smoke test)")
    quick = 50 if ap.parse_args().quick else 1
    rng = np.random.default_rng(0)
    print("| elements | frames | failed | numpy [Melem/s] | rust [Melem/s] | rust / numpy |")
    print("|---:|---:|---:|---:|---:|---:|")
    for rows, cols, frames in ((8, 12, 20000), (32, 32, 5000), (64, 64, 1000)):
        n_frames = frames // quick
        lay = Layout.grid(rows, cols)
        frames = rng.random((n_frames, lay.n_elements)).astype(np.float32)
        valid = rng.random(frames.shape) > 0.25
        rec = Recording(frames, np.arange(n_frames, dtype=float), lay, valid=valid)
        expected = numpy_repair(frames, valid, lay)
        got = Repair(lay, "neighbour-mean").fit().run(rec).frames
        np.testing.assert_allclose(got, expected, rtol=1e-6)  # same algorithm, same answer
        t_np, _ = best_of(numpy_repair, frames, valid, lay)
        t_rs, _ = best_of(lambda r, lay=lay: Repair(lay, "neighbour-mean").fit().run(r), rec)
        n = frames.size / 1e6
        print(
            f"| {lay.n_elements} | {n_frames} | 25 % | {n / t_np:.1f} | {n / t_rs:.1f} "
            f"| {t_np / t_rs:.1f} |"
        )


if __name__ == "__main__":
    main()
