"""``texsense muscle``: contractions from a sensor sleeve (docs/muscle.md)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from texsense.calibration.workflows import sleeve_calibration
from texsense.commands import HELP
from texsense.commands._options import add_accept_truncated
from texsense.data.files import check_not_input, make_folder, pyplot, save_figure, write_text
from texsense.sim.muscle import session

if TYPE_CHECKING:
    from texsense.apps.muscle import Contractions


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``muscle`` command."""
    p = sub.add_parser(
        "muscle",
        help=HELP["muscle"],
        description="Find contractions in a recording of a sensor sleeve (1-4 elements at a "
        "high rate): onsets, count and relative intensity, compensated (Preisach + drift: the "
        "sleeve sits preloaded), with a plot; or simulate a session on a virtual forearm.",
    )
    ps = p.add_subparsers(dest="muscle_command", metavar="WHAT")
    ps.required = True
    d = ps.add_parser("detect", help="contractions in a recording")
    d.add_argument("recording", type=Path, help="the sleeve: capacitance, or pressure")
    d.add_argument("--calibration", type=Path, help="the sleeve's calibration (capacitance)")
    d.add_argument("--threshold", type=float, default=0.06, help="onset, N/cm² (default 0.06)")
    d.add_argument("--plot", type=Path, help="a figure of the activation and the onsets")
    d.add_argument("--json", action="store_true")
    add_accept_truncated(d)
    d.set_defaults(run=run_detect)
    s = ps.add_parser("simulate", help="a session on a virtual forearm")
    s.add_argument("--minutes", type=float, default=10.0)
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("-o", "--output", type=Path, required=True, help="folder to write")
    s.set_defaults(run=run_simulate)


def run_simulate(args: argparse.Namespace) -> int:
    """Run ``texsense muscle simulate``: sleeve.h5, calibration.json and truth.json."""
    from texsense.io import save

    make_folder(args.output)
    s = session(args.minutes, seed=args.seed)
    save(s.scan.capacitance, args.output / "sleeve.h5")
    sleeve_calibration(seed=args.seed).save(args.output / "calibration.json")
    truth = {"onsets_s": s.onsets_s.round(3).tolist(), "ends_s": s.ends_s.round(3).tolist(),
             "intensity": s.intensity.round(3).tolist(), "rest_s": s.rest}  # fmt: skip
    write_text(args.output / "truth.json", json.dumps(truth, indent=1))
    every = f"a frame every {1e3 * s.frame_s:.0f} ms"
    print(f"wrote {args.output}/sleeve.h5 ({s.times.size} frames, {len(s.onsets_s)} "
          f"contractions, {every}), calibration.json, truth.json")  # fmt: skip
    return 0


def run_detect(args: argparse.Namespace) -> int:
    """Run ``texsense muscle detect``."""
    from texsense.apps.muscle import activation, detect
    from texsense.commands.pipeline import to_pressure
    from texsense.io import load

    if args.plot:
        check_not_input(args.plot, [args.recording])
    rec = to_pressure(load(args.recording, accept_truncated=args.accept_truncated),
                      args.calibration)  # fmt: skip
    act = activation(rec)
    found = detect(rec.times, act, on_ncm2=args.threshold)
    if args.plot:
        _plot(rec.times, act, found, args.threshold, args.plot)
    if args.json:
        print(json.dumps(found.to_dict(), indent=1))
        return 0
    minutes = (rec.times[-1] - rec.times[0]) / 60
    rate = rec.n_frames / max(rec.times[-1] - rec.times[0], 1e-9)
    print(f"{found.count} contractions in {minutes:.1f} min ({rec.n_elements} elements, "
          f"{rate:.1f} frames/s)")  # fmt: skip
    for o, e, k in zip(found.onsets_s, found.ends_s, found.intensity, strict=True):
        print(f"  {o:9.2f} s  {e - o:5.2f} s  intensity {k:4.2f}")
    return 0


def _plot(
    times: np.ndarray, act: np.ndarray, found: Contractions, threshold: float, path: Path
) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 3.2))
    ax.plot(times, act, lw=0.8, label="activation")
    ax.axhline(threshold, color="tab:orange", ls=":", lw=1, label="onset threshold")
    for o in found.onsets_s:
        ax.axvline(o, color="tab:green", ls="--", lw=0.8)
    ax.set_xlabel("time, s")
    ax.set_ylabel("N/cm²")
    ax.set_title(f"{found.count} contractions")
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    try:
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
