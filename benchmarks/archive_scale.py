"""Memory and throughput of `texsense process` on long recordings and on archives.

Run:  .venv/bin/python benchmarks/archive_scale.py [--quick]

1. Peak memory (RSS) against the recording's length: a 1024-element capacitance recording of
   2,500 / 10,000 / 40,000 frames (HDF5), processed by `texsense process` (block by block)
   and, as the baseline, by loading it whole and calling `Pipeline.run` (what the command
   did before), each in a fresh process that reports its own peak RSS.
2. Archive throughput: 100 recordings (1024 elements x 400 frames each) on a Dask
   `LocalCluster` of 1 and of 2 worker processes (one thread each), files per second, in
   the same run.
3. Peak memory with a text input: the same recordings of 10,000 / 40,000 frames as a wide
   CSV (``time_s,e0,...``; every reader streams blocks of frames, not only HDF5's).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pipeline_speed import mat_chain
from texsense.calibration.workflows import seat_calibration
from texsense.compensation.stages import StageChain
from texsense.data.layout import Layout
from texsense.io.hdf5 import RecordingWriter

PY = sys.executable


def big_calibration(n: int, path: Path) -> StageChain:
    """The seat's spacer model and material curve with per-element offsets and gains for a
    mat of n elements."""
    cal = mat_chain(seat_calibration(mat_seed=5), n, np.random.default_rng(0))
    cal.save(path)
    return cal


def write_recording(cal: StageChain, layout: Layout, frames: int, path: Path, seed: int):
    """A capacitance recording written block by block (moving loads, 2 % failed readings)."""
    rng = np.random.default_rng(seed)
    n = layout.n_elements
    with RecordingWriter(path, layout, "capacitance", "pF", compress=False) as w:
        for a in range(0, frames, 2000):
            t = np.arange(a, min(frames, a + 2000)) * 0.1
            e = 1.2 + 0.8 * np.sin(t[:, None] / 3 + np.arange(n)[None, :] / 50)
            e += rng.normal(0, 0.01, e.shape)
            conv = cal["convert"]
            ref = np.interp(e, conv.curve_compression_mm_, conv.curve_capacitance_pF_)
            cap = conv.offset_pF_ + conv.gain_ * ref
            cap[rng.random(cap.shape) < 0.02] = 0.0
            w.append(cap, t)


CHUNKED = """
import resource, sys
from texsense.cli import main
main(["process", sys.argv[1], "--calibration", sys.argv[2], "-o", sys.argv[3],
      "--repair", "neighbour-mean"])
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""

WHOLE = """
import resource, sys
from texsense.io import load, save
from texsense.compensation.pipeline import Pipeline
from texsense.compensation.stages import load_chain
rec = load(sys.argv[1])
out = Pipeline(load_chain(sys.argv[2]), rec.layout, repair="neighbour-mean").run(rec)
save(out, sys.argv[3])
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def peak_rss_mib(script: str, *args: str) -> tuple[float, float]:
    start = time.perf_counter()
    out = subprocess.run(
        [PY, "-c", script, *args], capture_output=True, text=True, check=True
    ).stdout.split()
    return int(out[-1]) / 1024, time.perf_counter() - start


def write_wide_csv_input(src: Path, dst: Path) -> None:
    """The HDF5 recording ``src`` as a wide CSV (a foreign-style file: quantity and unit
    lines, the header, one line per frame), written block by block."""
    from texsense.io import open_reader

    with open_reader(src) as reader, dst.open("w") as out:
        n = reader.header.layout.n_elements
        out.write("# quantity: capacitance\n# unit: pF\n")
        out.write("time_s," + ",".join(f"e{k}" for k in range(n)) + "\n")
        for block in reader.blocks(2000):
            data = np.column_stack([block.times, block.frames.astype(np.float64)])
            np.savetxt(out, data, fmt="%.9g", delimiter=",")


def memory(tmp: Path, quick: bool, text: bool = False) -> None:
    n = 1024
    lay = Layout.grid(32, 32, pitch_cm=1.0)
    cal = big_calibration(n, tmp / "cal.json")
    if text:
        lengths = (500, 2000) if quick else (10_000, 40_000)
        print("| frames (1024 elements), wide CSV input | input size | `texsense process`: peak "
              "RSS | time | whole recording in memory: peak RSS | time |")  # fmt: skip
    else:
        lengths = (500, 2000) if quick else (2500, 10_000, 40_000)
        print("| frames (1024 elements) | input size | `texsense process`: peak RSS | time | "
              "whole recording in memory (before): peak RSS | time |")  # fmt: skip
    print("|---:|---:|---:|---:|---:|---:|")
    for frames in lengths:
        src = tmp / f"long-{frames}.h5"
        write_recording(cal, lay, frames, src, seed=frames)
        if text:
            write_wide_csv_input(src, tmp / f"long-{frames}.csv")
            src.unlink()
            src = tmp / f"long-{frames}.csv"
        rss_c, t_c = peak_rss_mib(CHUNKED, str(src), str(tmp / "cal.json"), str(tmp / "c.h5"))
        rss_w, t_w = peak_rss_mib(WHOLE, str(src), str(tmp / "cal.json"), str(tmp / "w.h5"))
        size = src.stat().st_size / 2**20
        print(f"| {frames:,} | {size:.0f} MiB | {rss_c:.0f} MiB | {t_c:.1f} s | "
              f"{rss_w:.0f} MiB | {t_w:.1f} s |")  # fmt: skip
        src.unlink()


def throughput(tmp: Path, quick: bool) -> None:
    from dask.distributed import LocalCluster

    from texsense.compensation.archive import ProcessOptions, archive_jobs, process_archive

    n_files = 20 if quick else 100
    lay = Layout.grid(32, 32, pitch_cm=1.0)
    cal = big_calibration(1024, tmp / "cal.json")
    folder = tmp / "archive"
    folder.mkdir()
    for k in range(n_files):
        write_recording(cal, lay, 400, folder / f"r{k:03d}.h5", seed=k)
    rates = {}
    for workers in (1, 2):
        out = tmp / f"out{workers}"
        jobs, _ = archive_jobs([folder], out)
        env = dict.fromkeys(("RAYON_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"), "1")
        with LocalCluster(
            n_workers=workers, threads_per_worker=1, dashboard_address=":0", env=env
        ) as cluster:
            start = time.perf_counter()
            reports = process_archive(
                jobs, tmp / "cal.json", ProcessOptions(repair="neighbour-mean"),
                scheduler=cluster.scheduler_address,
            )  # fmt: skip
            elapsed = time.perf_counter() - start
        assert all(r.status == "done" for r in reports), reports
        rates[workers] = n_files / elapsed
    print(f"| workers | {n_files} recordings of 1024 x 400: files/s | M element-samples/s |")
    print("|---:|---:|---:|")
    for w, r in rates.items():
        print(f"| {w} | {r:.2f} | {r * 1024 * 400 / 1e6:.1f} |")
    print(f"| **2 workers / 1 worker** | **{rates[2] / rates[1]:.2f} x** | |")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", choices=("hdf5", "throughput", "csv"), help="one part only")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        if args.only in (None, "hdf5"):
            memory(Path(d), args.quick)
            print()
        if args.only in (None, "throughput"):
            throughput(Path(d), args.quick)
            print()
        if args.only in (None, "csv"):
            memory(Path(d), args.quick, text=True)


if __name__ == "__main__":
    main()
