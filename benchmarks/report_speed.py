"""How long ``texsense report`` takes (docs/report.md; target of issue 26: < 10 s for a PMD
subject and for a virtual bed night).

Rows: a real PhysioNet PMD subject (17 posture files, raw counts), a real Tekscan F-Scan
export, and simulated nights on the virtual bed (8 h, through the textile mat with its
failing elements and the compensation pipeline, saved as HDF5 the way the monitor records;
the simulation is not timed). Each time is the best of 3 runs of the whole report from the
file: reading it, the statistics and recomputed events, the figures, the PDF. The baseline
of the same run is reading the file alone (``texsense.load``): the report costs that plus
the ratio's remainder.

    .venv/bin/python benchmarks/report_speed.py [--long]

``--long`` adds a night at the mat's own frame rate (a frame every 1.06 s, 27,000 frames of
2048 elements; about 5 minutes more to simulate).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _realdata import DATA
from _timing import best_of
from texsense import load
from texsense.apps.report import write_report
from texsense.io import save


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--long", action="store_true", help="also a night at 1.06 s per frame")
    args = ap.parse_args()
    from texsense.calibration.workflows import processed_bed_night

    work = Path(tempfile.mkdtemp(prefix="texsense-report-"))
    cases = [
        ("PMD subject S1 (real, raw counts)", DATA / "pmd" / "experiment-i" / "S1"),
        ("PMD subject S7 (real, raw counts)", DATA / "pmd" / "experiment-i" / "S7"),
        ("Tekscan F-Scan export (real)", DATA / "vendor-formats" / "fscan_testL.asf"),
    ]
    nights = [(8.0, 10.0)] + ([(8.0, 1.06)] if args.long else [])
    for hours, frame_s in nights:
        path = work / f"night-{frame_s:g}s.h5"
        print(f"simulating a {hours:g} h night, a frame every {frame_s:g} s ...", flush=True)
        save(processed_bed_night(hours=hours, frame_s=frame_s, seed=3), path)
        cases.append((f"virtual bed night, {hours:g} h, a frame every {frame_s:g} s", path))
    print("\n| recording | frames x elements | read the file (baseline) | report (PDF) | "
          "report / read | pages |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|")
    for name, path in cases:
        t_load, rec = best_of(load, path)
        out = work / "report.pdf"
        t_report, _ = best_of(write_report, path, out)
        pages = out.read_bytes().count(b"/Type /Page\n") or out.read_bytes().count(b"/Type /Page")
        print(f"| {name} | {rec.n_frames} x {rec.n_elements} | {t_load:.2f} s | "
              f"{t_report:.2f} s | {t_report / t_load:.1f} | {pages} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
