"""An experiment for issue 37, not the product: γ of the laboratory drift model (eq. 5.8)
re-estimated in use by least squares over the still periods seen so far.

The drift model is linear in γ: ``p = h + γ D`` with ``D`` the drift of γ = 1 over the history
of hysteresis outputs ``h`` (:func:`texsense.compensation.drift.unit_drift`, the logarithmic
kernel). While a person holds a position the true load is constant, so from 60 s into every
held position on, ``Δh = -γ ΔD`` for every loaded element; γ pooled over the mat is fitted on
the positions held *before* (causal) and applied to the next one (γ = 0 in the first).

The still periods here are the simulator's labels (``hold``), not read from the frames: this
is an oracle of stillness, a bound on what the method gives, not what the product would. Rows:
hysteresis only, γ by least squares, that output then through the in-use estimator
(:class:`~texsense.compensation.inuse.InUseDrift`, weight kept), and γ fitted again every 30 s
of a held position as well (a γ for the first position).

Run:  .venv/bin/python benchmarks/night_gamma.py textile-3mm:0 iwan-6mm:0 [--cache DIR]
(the nights of ``benchmarks/night_drift.py``, simulated into its cache when missing).
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import numpy as np

from night_drift import hourly, night_files
from texsense.compensation.drift import unit_drift
from texsense.compensation.pipeline import Pipeline


def held(labels: dict[str, np.ndarray], min_frames: int = 12) -> list[tuple[int, int]]:
    """(first, end) frames of every held position of at least ``min_frames`` frames."""
    hold, pos = labels["hold"], labels["position"]
    cut = np.flatnonzero((pos[1:] != pos[:-1]) | (hold[1:] != hold[:-1])) + 1
    edges = np.r_[0, cut, pos.size]
    return [
        (int(a), int(b))
        for a, b in itertools.pairwise(edges)
        if hold[a] and pos[a] != "out" and b - a > min_frames
    ]


def gamma_in_use(
    h: np.ndarray,
    ok: np.ndarray,
    times: np.ndarray,
    holds: list[tuple[int, int]],
    every: int | None = None,
) -> tuple[np.ndarray, list[float]]:
    """``h + γ D`` with γ fitted on the held positions before each one (and γ after each);
    with ``every``, γ is fitted again every ``every`` frames of a held position as well."""
    d = unit_drift(h, times)
    p, num, den, gamma, gammas = h.copy(), 0.0, 0.0, 0.0, []
    for a, b in holds:
        s = a + 6  # 60 s settled
        loaded = (h[s] > 0.05) & ok[s:b].all(axis=0)
        step = every or (b - a)
        p[a : s + 1] = h[a : s + 1] + gamma * d[a : s + 1]
        for k in range(s + 1, b, step):
            end = min(k + step, b)
            p[k:end] = h[k:end] + gamma * d[k:end]
            dh = h[k:end, loaded] - h[s, loaded]
            dd = d[k:end, loaded] - d[s, loaded]
            num, den = num + float(np.sum(dh * dd)), den + float(np.sum(dd * dd))
            gamma = -num / den if den > 0 else 0.0
        gammas.append(gamma)
    return p, gammas


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("nights", nargs="+", help="LAW:SEED")
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "texsense" / "nights")
    args = ap.parse_args()
    print("| night | method | " + " | ".join(f"hour {k + 1}" for k in range(8)) + " | max | load |")
    print("|---|---|" + "---:|" * 10)
    for spec in args.nights:
        law, seed = spec.rsplit(":", 1)
        raw, truth_rec, chain = night_files(law, int(seed), 8.0, args.cache)
        truth, t = truth_rec.frames.astype(np.float64), raw.times
        area = np.asarray(raw.layout.area_cm2)
        h, ok, _ = Pipeline(chain, raw.layout, drift=False).process(raw.frames, t, raw.valid)
        h = np.nan_to_num(h)
        holds = held(truth_rec.labels)
        p, gammas = gamma_in_use(h, ok, t, holds)
        p30, _ = gamma_in_use(h, ok, t, holds, every=3)
        est = Pipeline(chain, raw.layout, in_use=True).estimator
        assert est is not None
        q = est.run(p, ok, t, raw=raw.frames.astype(np.float64))
        rows = (
            ("hysteresis only", h),
            ("γ by least squares", p),
            ("γ, then in use", q),
            ("γ fitted every 30 s", p30),
        )
        for name, v in rows:
            err, lerr = hourly(v, ok, truth, t, area, 8)
            print(
                f"| {spec} | {name} | " + " | ".join(f"{100 * e:.1f}%" for e in err)
                + f" | {100 * max(err):.1f}% | {100 * max(lerr):.1f}% |"
            )  # fmt: skip
        print(f"| {spec} | γ after each held position | {', '.join(f'{g:.4f}' for g in gammas)} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
