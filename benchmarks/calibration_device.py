"""A new mat from the serial line to calibrated pressure, as a person does it with the CLI
(docs/calibration.md): the virtual device (``texsense simulate device``) serves a virtual
seat on a pseudo-terminal; ``texsense record`` records nothing on the mat and a uniform
1.0 N/cm² through the serial line; ``texsense calibrate mat --material textile-3mm`` fits the
chain; then a uniform 2.0 N/cm² and a person sitting are recorded and processed with
``texsense process``, and compared with the device's true pressure (``--truth``).

The truth is the simulator's (texsense.sim), which knows nothing of the compensation's
models. Beside the full chain the no-model baseline: a linear calibration from the same two
recordings (pressure = 1.0 N/cm² x (C - C_zero) / (C_uniform - C_zero) per element).

Targets (issue 25): uniform 2.0 N/cm² -> 2.0 ± 0.2 (median of working elements); the person's
load within 10 % of the truth.

Run:  .venv/bin/python benchmarks/calibration_device.py [--seeds 0 1 2] [--speed 20]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from texsense.io import load

ROOT = Path(__file__).resolve().parent.parent
TEXSENSE = [sys.executable, "-m", "texsense"]


class Device:
    """``texsense simulate device`` in the background; :meth:`load` types a load."""

    def __init__(self, folder: Path, seed: int, speed: float) -> None:
        self.link = folder / "port"
        self.proc = subprocess.Popen(
            [*TEXSENSE, "simulate", "device", "--mat", "seat", "--link", str(self.link),
             "--seed", str(seed), "--speed", str(speed), "--truth", str(folder / "truth.h5")],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        deadline = time.monotonic() + 30
        while not self.link.exists():
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the device did not start: {self.proc.communicate()[0]}")
            time.sleep(0.05)

    def load(self, text: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(text + "\n")
        self.proc.stdin.flush()
        time.sleep(0.5)  # a few frames of the new load pass before recording starts

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(timeout=20)


def cli(*args: str) -> str:
    done = subprocess.run([*TEXSENSE, *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"texsense {' '.join(args)}: {done.stderr.strip()}")
    return done.stdout


def median_pressure(path: Path) -> float:
    rec = load(path)
    x = np.where(rec.valid, rec.frames, np.nan)
    return float(np.nanmedian(np.nanmedian(x, axis=0)))


def load_error(processed: Path, truth: Path) -> tuple[float, float]:
    """Relative error of the mat's total load, frame by frame against the true pressure at
    the same times: (median, 95th percentile of |error|) over frames with a load."""
    rec, tru = load(processed), load(truth)
    idx = np.searchsorted(tru.times, rec.times - 1e-6)
    idx = np.clip(idx, 0, tru.n_frames - 1)
    measured = np.nansum(np.where(rec.valid, rec.frames, 0.0), axis=1)
    true = tru.frames[idx].sum(axis=1)
    on = true > 0.05 * true.max()
    err = measured[on] / true[on] - 1
    return float(np.median(err)), float(np.percentile(np.abs(err), 95))


def linear_baseline(zero: Path, one: Path, recording: Path, out: Path) -> None:
    """The no-model baseline: per element (C - C_zero) / (C_one - C_zero) x 1.0 N/cm²."""
    from texsense.data.recording import Recording
    from texsense.io import save

    def typical(p: Path) -> np.ndarray:
        r = load(p)
        return np.nanmedian(np.where(r.valid, r.frames, np.nan), axis=0)

    c0, c1 = typical(zero), typical(one)
    rec = load(recording)
    gain = np.where(np.abs(c1 - c0) > 1e-6, c1 - c0, np.nan)
    p = (rec.frames - c0) / gain
    ok = rec.valid & np.isfinite(p)
    save(Recording(np.where(ok, p, 0.0), rec.times, rec.layout, "pressure", "N/cm2",
                   valid=ok), out)  # fmt: skip


def run(seed: int, speed: float, folder: Path) -> dict[str, float]:
    dev = Device(folder, seed, speed)
    port = f"serial:{dev.link}"
    t0 = time.monotonic()
    try:
        cli("record", "--source", port, "-o", str(folder / "zero.h5"), "--frames", "10")
        dev.load("uniform:1.0")
        cli("record", "--source", port, "-o", str(folder / "one.h5"), "--frames", "10")
        dev.load("uniform:2.0")
        cli("record", "--source", port, "-o", str(folder / "two.h5"), "--frames", "10")
        dev.load("empty")
        # the person sits down while the recorder runs, so that the recording holds the
        # same sitting whatever the recorder's start-up takes (the device at 20 x real time)
        rec = subprocess.Popen(
            [*TEXSENSE, "record", "--source", port, "-o", str(folder / "person.h5"),
             "--frames", "100"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        assert rec.stderr is not None
        rec.stderr.readline()  # "... Ctrl-C stops": recording
        time.sleep(0.5)
        dev.load("person")
        if rec.wait(timeout=120) != 0:
            raise RuntimeError(f"texsense record: {rec.stderr.read()}")
    finally:
        dev.stop()
    cli("calibrate", "mat", "--material", "textile-3mm", "--baseline", str(folder / "zero.h5"),
        "--uniform", str(folder / "one.h5"), "--pressure", "1.0",
        "-o", str(folder / "mat.json"))  # fmt: skip
    row: dict[str, float] = {"seed": seed, "wall_s": time.monotonic() - t0}
    for name in ("two", "person"):
        cli("process", str(folder / f"{name}.h5"), "--calibration", str(folder / "mat.json"),
            "-o", str(folder / f"{name}-p.h5"))  # fmt: skip
        linear_baseline(folder / "zero.h5", folder / "one.h5", folder / f"{name}.h5",
                        folder / f"{name}-lin.h5")  # fmt: skip
    row["two"] = median_pressure(folder / "two-p.h5")
    row["two_lin"] = median_pressure(folder / "two-lin.h5")
    row["person"], row["person95"] = load_error(folder / "person-p.h5", folder / "truth.h5")
    row["person_lin"], row["person_lin95"] = load_error(folder / "person-lin.h5",
                                                       folder / "truth.h5")  # fmt: skip
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--speed", type=float, default=20.0)
    args = ap.parse_args()
    rows = []
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            rows.append(run(seed, args.speed, Path(tmp)))
        print(f"seed {seed} done", file=sys.stderr, flush=True)
    print(
        "| mat seed | uniform 2.0 N/cm², median (chain) | (linear, no model) | person's load "
        "error, median (chain) | p95 |abs| (chain) | median (linear) | p95 (linear) | wall s |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['seed']:.0f} | {r['two']:.3f} | {r['two_lin']:.3f} | "
              f"{100 * r['person']:+.1f} % | {100 * r['person95']:.1f} % | "
              f"{100 * r['person_lin']:+.1f} % | {100 * r['person_lin95']:.1f} % | "
              f"{r['wall_s']:.0f} |")  # fmt: skip
    ok2 = all(abs(r["two"] - 2.0) <= 0.2 for r in rows)
    okp = all(abs(r["person"]) <= 0.10 for r in rows)
    print(
        f"\ntargets: uniform 2.0 ± 0.2 N/cm² {'met' if ok2 else 'MISSED'}; person's load "
        f"within 10 % (median over frames) {'met' if okp else 'MISSED'}"
    )


if __name__ == "__main__":
    main()
