"""Speed of the Preisach evaluation (Rust core) against a plain-Python Everett sum, and of
the identification.

Run:  .venv/bin/python benchmarks/hysteresis_speed.py

Ratios are measured in the same run on the same inputs; absolute rates vary with the load of
this shared 2-core machine.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import best_of
from texsense.compensation.hysteresis import HysteresisModel
from texsense.compensation.hysteresis._identify import update_extrema
from texsense.sim.magnetic import forc_protocol
from texsense.sim.protocols import run_protocol


def python_everett_sum(model: HysteresisModel, u: np.ndarray) -> np.ndarray:
    """The textbook implementation (eq. 4.15/4.16): keep the dominant extrema with the
    wiping-out rule (the shared stack update) and sum the Everett terms anew at every sample,
    in plain Python with the same interpolation as the core."""
    k = model.everett_.shape[0]
    f = model.everett_.tolist()
    lo, step = model.u_min_, (model.u_max_ - model.u_min_) / (k - 1)

    def ev(a: float, b: float) -> float:
        x = min(max((a - lo) / step, 0.0), k - 1.0)
        y = min(max((b - lo) / step, 0.0), k - 1.0)
        if y >= x:
            return 0.0
        i, j = min(int(x), k - 2), min(int(y), k - 2)
        wa, wb = x - i, y - j
        if i == j:
            return (wa - wb) * f[i + 1][j]
        return (1 - wa) * ((1 - wb) * f[i][j] + wb * f[i][j + 1]) + wa * (
            (1 - wb) * f[i + 1][j] + wb * f[i + 1][j + 1]
        )

    out = []
    stack = [lo]
    prev = lo
    for x in u.tolist():
        x = min(max(x, lo), model.u_max_)
        update_extrema(stack, prev, x)
        prev = x
        h = 0.0
        for q in range(1, len(stack), 2):
            h += 2 * ev(stack[q], stack[q - 1])
            if q + 1 < len(stack):
                h -= 2 * ev(stack[q], stack[q + 1])
        h += 2 * ev(x, stack[-1]) if len(stack) % 2 == 1 else -2 * ev(stack[-1], x)
        out.append(model.sign_ * (h + model.offset_))
    return np.asarray(out)


def main() -> None:
    cal = run_protocol("calibration", "textile-6mm", seed=0, sample_hz=None)
    uc, pc = cal.labels["compression_mm"], cal.labels["pressure_ncm2"]
    t_thesis, model = best_of(lambda: HysteresisModel(method="thesis", grid=100).fit(uc, pc))
    t_default, default = best_of(lambda: HysteresisModel().fit(uc, pc), repeat=1)
    saw = run_protocol("sawtooth", "textile-6mm", seed=100, sample_hz=None)
    us, ps = saw.labels["compression_mm"][:20_000], saw.labels["pressure_ncm2"][:20_000]
    t_saw, _ = best_of(lambda: HysteresisModel().fit(us, ps), repeat=1)
    # the relay grid on 20,400 samples of sharp-switching FORCs (60 nodes, cross-validated)
    uf, mf, _ = forc_protocol(100, 0.005, noise=1e-3)
    kw = {"input_unit": "1", "output_unit": "1"}
    t_relay, relay = best_of(lambda: HysteresisModel("relay", **kw).fit(uf, mf), repeat=1)
    rng = np.random.default_rng(0)
    lo, hi = model.u_min_, model.u_max_
    # 1 element x 10^6 samples, every sample a reversal
    noisy = lo + (hi - lo) * (
        0.5 + 0.45 * rng.random(1_000_000) * np.where(np.arange(1_000_000) % 2 == 0, 1.0, -1.0)
    )
    t_one, out_one = best_of(lambda: model.predict(noisy))
    # 1024 elements x 10^4 frames, random walks
    walk = np.clip(
        np.cumsum(rng.normal(0, 0.02, (10_000, 1024)), axis=0) % (2 * (hi - lo)), 0, None
    )
    walk = lo + np.where(walk > hi - lo, 2 * (hi - lo) - walk, walk)
    t_many, _ = best_of(lambda: model.predict(walk))
    t_many_default, _ = best_of(lambda: default.predict(walk))
    span = relay.u_max_ - relay.u_min_
    walk_f = relay.u_min_ + span * (walk - lo) / (hi - lo)
    t_many_relay, _ = best_of(lambda: relay.predict(walk_f))
    # plain Python on a slice of the noisy input, checked against the core
    n_py = 20_000
    t_py, out_py = best_of(lambda: python_everett_sum(model, noisy[:n_py]), repeat=1)
    np.testing.assert_allclose(out_py, out_one[:n_py], rtol=1e-9, atol=1e-9)
    rust_rate = 1e6 / t_one
    py_rate = n_py / t_py
    print("| what | time | rate |")
    print("|---|---:|---:|")
    print(
        f"| Rust, 1 element x 10⁶ samples, every sample a reversal | {t_one:.3f} s | "
        f"{rust_rate / 1e6:.1f} M samples/s |"
    )
    print(
        f"| Rust, 1024 elements x 10⁴ frames (random walks) | {t_many:.3f} s | "
        f"{walk.size / t_many / 1e6:.1f} M element-samples/s |"
    )
    print(
        f"| Rust, same, the default model ({default.method_}) | {t_many_default:.3f} s | "
        f"{walk.size / t_many_default / 1e6:.1f} M element-samples/s |"
    )
    print(
        f"| Rust, same, a relay-grid model ({relay.everett_.shape[0]} x "
        f"{relay.everett_.shape[0]} table) | {t_many_relay:.3f} s | "
        f"{walk.size / t_many_relay / 1e6:.1f} M element-samples/s |"
    )
    print(
        f"| plain-Python Everett sum, 1 element x {n_py:,} samples | {t_py:.2f} s | "
        f"{py_rate / 1e3:.1f} k samples/s |"
    )
    print(f"| **Rust / Python** | | **{rust_rate / py_rate:,.0f} x** |")
    print(
        f"| identification, thesis method, 100 x 100 ({uc.size} samples) | "
        f"{t_thesis * 1000:.0f} ms | |"
    )
    print(
        f"| identification, default, cross-validated ({uc.size} samples, thesis record) | "
        f"{t_default:.2f} s | |"
    )
    print(
        f"| identification, default, cross-validated ({us.size} samples, random sawtooth) | "
        f"{t_saw:.2f} s | |"
    )
    print(
        f"| identification, relay grid, 60 nodes, cross-validated ({uf.size} samples, "
        f"sharp-switching FORCs) | {t_relay:.2f} s | |"
    )


if __name__ == "__main__":
    main()
