"""Speed of the drift stage: Preisach + recursive drift for 240 elements over 4 h at 10 Hz,
and the exact windowed model against the recursive form as the history grows.

Run:  .venv/bin/python benchmarks/drift_speed.py [--quick]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import best_of
from texsense._core import Compensation
from texsense.compensation.drift import DriftModel, drift_exact
from texsense.compensation.drift_kernels import log_kernel
from texsense.compensation.hysteresis import HysteresisModel
from texsense.compensation.stage import time_steps
from texsense.sim.protocols import run_protocol


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="6 min instead of 4 h (a smoke test)")
    hours = 0.1 if ap.parse_args().quick else 4.0
    cal = run_protocol("calibration", "textile-6mm", seed=0, sample_hz=None)
    model = HysteresisModel().fit(cal.labels["compression_mm"], cal.labels["pressure_ncm2"])
    drift = DriftModel(-0.025, log_kernel())
    rng = np.random.default_rng(0)
    n_t, n = round(hours * 3600 * 10), 240
    t = np.arange(n_t) / 10.0
    # every element cycles slowly with its own phase and amplitude (a person on a seat)
    u = model.u_max_ * (
        0.45 + 0.4 * np.sin(2 * np.pi * t[:, None] / 60.0 + rng.uniform(0, 6.3, n)[None, :])
    )

    t_h, h = best_of(lambda: model.state(n).run(u))
    t_d, separate = best_of(lambda: drift.apply(h, t))
    ok, dt = np.ones(u.shape, bool), time_steps(t)
    t_c, combined = best_of(lambda: Compensation(model.bank(n), drift.state(n)).run(dt, u, ok))
    np.testing.assert_array_equal(combined, separate)
    print("| what | time (best of 3) |")
    print("|---|---:|")
    print(
        f"| Preisach alone, 240 elements x {hours:g} h at 10 Hz ({n_t * n / 1e6:.1f} M "
        f"element-samples) | {t_h:.2f} s |"
    )
    print(f"| recursive drift alone (K = {log_kernel().weights.size}), same | {t_d:.2f} s |")
    print(f"| **Preisach + drift in one pass (`Compensation`)** | **{t_c:.2f} s** |")
    print()
    print(
        "| history | exact windowed: steps kept | exact: µs per sample | recursive: µs per "
        "sample | recursive memory per element |"
    )
    print("|---|---:|---:|---:|---:|")
    k = log_kernel().weights.size
    for minutes in (10, 60, 240) if hours == 4.0 else (1, 6):
        m = minutes * 60 * 10
        tt, hh = t[:m], h[:m, 0]
        e0 = time.perf_counter()
        _, kept = drift_exact(tt, hh, -0.025)
        e1 = time.perf_counter()
        DriftModel(-0.025, log_kernel()).apply(hh, tt)
        e2 = time.perf_counter()
        print(
            f"| {minutes} min | {kept} (memory grows with it) | {(e1 - e0) / m * 1e6:.1f} | "
            f"{(e2 - e1) / m * 1e6:.2f} | {k + 2} numbers, constant |"
        )


if __name__ == "__main__":
    main()
