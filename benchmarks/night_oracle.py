"""How far a level correction could take the in-use drift correction (issue 37, a diagnostic).

**ORACLE — never the product.** The in-use estimator (:class:`InUseDrift`) sets the level of the
night at the first still period (the weight it keeps) and nothing read in use can tell whether
that level is right. This benchmark measures what the correction would reach if it were, by
giving the estimator the *true* total load from the truth recording of the virtual night
(``simulate night --truth``), which no mat in use has:

- ``in use + oracle first level``: at the first still period the load the measured elements
  read is brought to what they truly carry (both ways), and that is the weight kept from then
  on by today's rules (a heavier still load taken out, a lighter one left);
- ``... kept both ways``: the same, and later still loads lighter than the weight brought up
  to it too (``weigh_up=True``);
- ``in use + oracle every still period``: at the start of *every* still period the measured
  elements' load is brought to the true one (both ways, no window): the best any correction of
  the level at still periods could do;
- ``level exact every frame``: the in-use output of every frame scaled so that the measured
  elements' load is the true one (a pressure gain, no creep model): what is left is the scatter
  between elements alone;
- ``best gain every frame``: the in-use output of every frame times the one factor that makes
  that frame's per-element error at 10-150 mmHg smallest (the weighted median of truth /
  value): the floor of any correction that moves the whole mat's level, frame by frame;
  ``--regions``: the same per block of 16 x 16, 8 x 8 and 4 x 4 elements (a level per region).

``--body``: the oracle of the first and of every still period's level computed on the loaded
elements only (the body, the elements a level correction moves), not on every measured one.

``--weight-clip``: the body weight entered, and the same with readings below zero weighed as
zero (the unloaded part of a Bouc–Wen mat reads below zero: ``--bands``).

``--bands``: where the in-use output's total-load error sits, by band of the true pressure
(frames the simulator labels as held positions, hours 1, 4 and 8): each band's share of the
true load of the measured elements and its error as a share of that load.

Not an oracle (what a mat in use can know from outside its frames): ``body weight entered``,
the person's weight as entered at admission (the virtual sleeper's, rounded to 1 kg) times
:data:`LYING_SHARE` and the share of the mat's surface its elements cover (the layout's
element area over its pitch: 0.75 on the bed mat, 2.2 cm elements at 2.54 cm; the load the
estimator sums is pressure times element area), taken as the weight at the first still
period (both ways) and kept by today's rules, never weighed anew after an empty mat.

Beside them the baselines and today's product (``benchmarks/night_drift.py``'s three ways).
Worst hour 1-8 of the per-element mean relative error at 10-150 mmHg and of the total load,
scored as ``night_drift.py`` scores them (truth from the virtual sensor).

Run:  .venv/bin/python benchmarks/night_oracle.py [--nights textile-3mm:0 ...] --cache DIR
      .venv/bin/python benchmarks/night_oracle.py --regions [--nights ...] --cache DIR
      .venv/bin/python benchmarks/night_oracle.py --bands [--nights ...] --cache DIR
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from night_drift import BAND, METHODS, MMHG, hourly, night_files
from texsense.compensation.inuse import InUseDrift, motion_blocks
from texsense.compensation.pipeline import Pipeline
from texsense.sim.bed import Sleeper

#: The share of a lying (or sitting-up) person's weight a bed mat bears: all of it. The body
#: rests on the mattress alone and the mat covers the lying surface (162.6 x 81.3 cm); only
#: what lies beyond its edges (a tall person's heels, a head on a pillow past the head edge)
#: is lost, which the mat's size and the person's height bound, not modelled here.
LYING_SHARE = 1.0
G = 9.81
TUNING = {("textile-3mm", 0), ("textile-3mm", 1), ("iwan-6mm", 0), ("iwan-6mm", 1)}
NIGHTS = (
    [f"textile-3mm:{s}" for s in range(5)]
    + [f"iwan-6mm:{s}" for s in range(5)]
    + [f"bouc-wen-6mm:{s}" for s in range(3)]
    + [f"foam-9mm:{s}" for s in range(2)]
    + [f"foam-13mm:{s}" for s in range(2)]
)


class OracleDrift(InUseDrift):
    """ORACLE (benchmark only): the in-use estimator told the true load of the measured
    elements at the start of the first (``mode="first"``) or of every (``"every"``) still
    period. ``truth`` (T, N) are the true frames in the order :meth:`step` sees them."""

    truth: np.ndarray
    mode: str
    body: bool = False
    clip: bool = False  # weigh readings below zero as zero (``--weight-clip``)
    known_n: float
    _k: int

    def step(self, values: Any, valid: Any, t: float, raw: Any = None) -> np.ndarray:
        self._k += 1
        return super().step(values, valid, t, raw)

    def total(self, c: np.ndarray, ok: np.ndarray) -> float:
        return super().total(np.maximum(c, 0.0) if self.clip else c, ok)

    def _level(self, c: np.ndarray, ok: np.ndarray) -> float:
        """The measured elements' load over what they truly carry, less 1 (with ``body``: the
        loaded elements' only, those the shift moves)."""
        sel = ok & (c > self.loaded_ncm2) if self.body else ok
        true = float(self.area[sel] @ self.truth[self._k][sel])
        return float(self.area[sel] @ c[sel]) / max(true, 1e-12) - 1.0

    def _shift(self, c: np.ndarray, ok: np.ndarray, r: float) -> None:
        """Creep that divides every loaded element's reading by ``1 + r`` (as ``_weigh``)."""
        sel = ok & (c > self.loaded_ncm2)
        u_now = np.interp(c[sel], self._p, self._u)
        u_new = np.interp(c[sel] / (1.0 + r), self._p, self._u)
        st = self.state
        st.creep[sel] = np.clip(
            st.creep[sel] + u_now - u_new, -self.max_creep_mm, self.max_creep_mm
        )

    def _weigh(self, x0: np.ndarray, c: np.ndarray, ok: np.ndarray, t: float) -> bool:
        st = self.state
        if self.total(c, ok) <= self._floor_n:
            return False
        if self.mode == "weight":  # the entered weight: the first level, never weighed anew
            if st.weight is None:
                r = self.total(c, ok) / self.known_n - 1.0
                self._shift(c, ok, r)
                st.weight, st.weight_t, st.checked_t = self.known_n, t, t
                self._returned = False
                return True
            self._returned = False
            return super()._weigh(x0, c, ok, t)
        if self.mode == "every" or (self.mode == "first" and st.weight is None):
            r = self._level(c, ok)
            self._shift(c, ok, r)
            st.checked_t = t
            if st.weight is None:  # the weight kept: the true load (the body's: as corrected)
                load = self.total(self.corrected(x0), ok) if self.body else self.total(c, ok)
                st.weight, st.weight_t = load / (1.0 + (0.0 if self.body else r)), t
                self._returned = False
            return True
        return super()._weigh(x0, c, ok, t)


def oracle_run(
    chain: Any,
    raw: Any,
    truth: np.ndarray,
    mode: str,
    known_n: float = 0.0,
    body: bool = False,
    clip: bool = False,
    **options: Any,
) -> tuple[np.ndarray, np.ndarray]:
    """The pipeline in use with the estimator made an :class:`OracleDrift` of ``mode``."""
    pipe = Pipeline(chain, raw.layout, in_use=True, in_use_options=options or None)
    est = pipe.estimator
    assert est is not None
    est.__class__ = OracleDrift
    assert isinstance(est, OracleDrift)
    est.truth, est.mode, est.known_n, est.body, est._k = truth, mode, known_n, body, -1
    est.clip = clip
    values, ok, _ = pipe.process(raw.frames, raw.times, raw.valid)
    return values, ok


def level_exact(
    values: np.ndarray, ok: np.ndarray, truth: np.ndarray, area: np.ndarray
) -> np.ndarray:
    """Every frame scaled so that its measured elements carry their true load."""
    v = np.nan_to_num(values)
    read = (np.where(ok, v, 0.0) * area).sum(axis=1)
    true = (np.where(ok, truth, 0.0) * area).sum(axis=1)
    g = np.where(read > 1e-9, true / np.where(read > 1e-9, read, 1.0), 1.0)
    return v * g[:, None]


def best_gain(
    values: np.ndarray, ok: np.ndarray, truth: np.ndarray, band: tuple[float, float]
) -> np.ndarray:
    """Every frame times the factor g minimising the mean of |g v - y| / y over its measured
    elements in ``band``: the median of y / v weighted by v / y."""
    v = np.nan_to_num(values)
    out = v.copy()
    for k in range(v.shape[0]):
        m = ok[k] & (truth[k] >= band[0]) & (truth[k] <= band[1]) & (v[k] > 1e-9)
        if not m.any():
            continue
        ratio, w = truth[k][m] / v[k][m], v[k][m] / truth[k][m]
        order = np.argsort(ratio)
        cw = np.cumsum(w[order])
        out[k] *= ratio[order][np.searchsorted(cw, 0.5 * cw[-1])]
    return out


class Night(NamedTuple):
    """One night of the tables: the raw recording, its truth (N/cm², float64), the calibration
    chain, the elements' areas, and what the night is used for (tuning or judging)."""

    raw: Any
    truth: np.ndarray
    chain: Any
    area: np.ndarray
    seed: int
    used: str


def load_night(spec: str, hours: float, cache: Path) -> Night:
    """The night ``law:seed`` (simulated once, then read from ``cache``)."""
    law, seed_s = spec.split(":")
    seed = int(seed_s)
    raw, truth_rec, chain = night_files(law, seed, hours, cache)
    used = "tuning" if (law, seed) in TUNING else "judging"
    area = np.asarray(raw.layout.area_cm2, dtype=np.float64)
    return Night(raw, truth_rec.frames.astype(np.float64), chain, area, seed, used)


def regions_table(nights: list[str], hours: float, cache: Path) -> None:
    """ORACLE: the best gain per frame of every block of the in-use output (a level per region,
    fitted on the truth): the floor of a level correction at that scale."""
    sizes = (16, 8, 4)
    print("per element, worst hour at 10-150 mmHg: in use, and times the best gain per frame")
    print("(ORACLE: fitted on the truth) of the whole mat or of every block of elements\n")
    cols = " | ".join(f"{k} x {k} blocks" for k in sizes)
    print(f"| night | used for | in use (today) | whole mat | {cols} |")
    print("|---|---|" + "---:|" * (2 + len(sizes)))
    for spec in nights:
        raw, y, chain, area, _seed, used = load_night(spec, hours, cache)
        pipe = Pipeline(chain, raw.layout, in_use=True)
        v, ok, _ = pipe.process(raw.frames, raw.times, raw.valid)
        v = np.nan_to_num(v)
        outs = [v, best_gain(v, ok, y, BAND)]
        for k in sizes:
            blocks = motion_blocks(raw.layout, k)
            w = v.copy()
            for b in np.unique(blocks):
                m = blocks == b
                w[:, m] = best_gain(v[:, m], ok[:, m], y[:, m], BAND)
            outs.append(w)
        cells = [max(hourly(w, ok, y, raw.times, area, round(hours))[0]) for w in outs]
        print(f"| {spec} | {used} | " + " | ".join(f"{100 * c:.1f}%" for c in cells) + " |")


def bands_table(nights: list[str], hours: float, cache: Path) -> None:
    """Where the total-load error of the in-use output sits, by band of the true pressure."""
    edges = (0.0, 1.0, 10.0, 40.0, 150.0, np.inf)  # mmHg
    pairs = list(itertools.pairwise(edges))
    names = [f"{a:g}-{b:g} mmHg" if np.isfinite(b) else f"> {a:g} mmHg" for a, b in pairs]
    print("in use: share of the true load / error as a share of the true load (measured elements,")
    print("held positions), by band of the true pressure\n")
    print("| night | hour | " + " | ".join(names) + " | all |")
    print("|---|---:|" + "---:|" * (len(names) + 1))
    for spec in nights:
        raw, y, chain, area, _seed, _used = load_night(spec, hours, cache)
        v, ok, _ = Pipeline(chain, raw.layout, in_use=True).process(
            raw.frames, raw.times, raw.valid
        )
        v = np.nan_to_num(v)
        hour = ((raw.times - raw.times[0]) // 3600).astype(int)
        hold = np.asarray(raw.labels["hold"], dtype=bool)
        for h in (0, 3, 7):
            f = hold & (hour == h)
            if not f.any():
                continue
            yf, vf, of = y[f], v[f], ok[f]
            total = (yf * of) @ area
            cells = []
            for a, b in pairs:
                m = of & (yf * MMHG >= a) & (yf * MMHG < b)
                share = float(np.mean(((yf * m) @ area) / total))
                err = float(np.mean((((vf - yf) * m) @ area) / total))
                cells.append(f"{100 * share:.1f} / {100 * err:+.1f}%")
            err_all = float(np.mean((((vf - yf) * of) @ area) / total))
            print(f"| {spec} | {h + 1} | " + " | ".join(cells) + f" | {100 * err_all:+.1f}% |")


def _runs_table(
    nights: list[str],
    hours: float,
    cache: Path,
    names: list[str],
    more_runs: Callable[[Any, Any, np.ndarray, int], list[tuple[np.ndarray, np.ndarray]]],
) -> None:
    """One row per night: today's in-use output and the runs ``more_runs(chain, raw, truth,
    seed)`` adds, each as its worst hour per element / of the total load."""
    print("per element (worst hour at 10-150 mmHg) / total load (worst hour)\n")
    print("| night | used for | " + " | ".join(names) + " |")
    print("|---|---|" + "---:|" * len(names))
    for spec in nights:
        raw, y, chain, area, seed, used = load_night(spec, hours, cache)
        pipe = Pipeline(chain, raw.layout, in_use=True)
        runs = [pipe.process(raw.frames, raw.times, raw.valid)[:2]]
        runs += more_runs(chain, raw, y, seed)
        cells = []
        for v, ok in runs:
            err, lerr = hourly(v, ok, y, raw.times, area, round(hours))
            cells.append(f"{100 * max(err):.1f} / {100 * max(lerr):.1f}%")
        print(f"| {spec} | {used} | " + " | ".join(cells) + " |", flush=True)


def body_table(nights: list[str], hours: float, cache: Path) -> None:
    """ORACLE: the level of the body (the loaded elements, those a level correction moves)
    brought to the truth at the first or at every still period."""
    names = [
        "in use (today)",
        "oracle first level of the body",
        "oracle body level every still period",
    ]
    _runs_table(
        nights, hours, cache, names,
        lambda chain, raw, y, seed: [
            oracle_run(chain, raw, y, "first", body=True),
            oracle_run(chain, raw, y, "every", body=True),
        ],
    )  # fmt: skip


def entered_weight(raw: Any, seed: int) -> float:
    """The weight a nurse enters (the virtual sleeper's, rounded to 1 kg) as the load the mat's
    elements carry (N): times :data:`LYING_SHARE` and the elements' share of the surface."""
    kg = round(Sleeper.random(seed).weight_kg)
    py, px = raw.layout.pitch_cm
    cover = float(np.mean(raw.layout.area_cm2)) / (py * px)
    return kg * G * LYING_SHARE * cover


def clip_table(nights: list[str], hours: float, cache: Path) -> None:
    """The body weight entered, weighed as the readings are and with readings below zero
    weighed as zero (not an oracle)."""
    names = ["in use (today)", "body weight entered", "body weight entered, weighed clipped at 0"]

    def weighed(chain: Any, raw: Any, y: np.ndarray, seed: int) -> list:
        w = entered_weight(raw, seed)
        return [
            oracle_run(chain, raw, y, "weight", w),
            oracle_run(chain, raw, y, "weight", w, clip=True),
        ]

    _runs_table(nights, hours, cache, names, weighed)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--nights", nargs="+", default=list(NIGHTS), help="law:seed")
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "texsense" / "nights")
    ap.add_argument("--hours", type=float, default=8.0)
    ap.add_argument("--regions", action="store_true", help="the floor of a level per region")
    ap.add_argument("--bands", action="store_true", help="where the total load's error sits")
    ap.add_argument("--body", action="store_true", help="the oracle of the body's level")
    ap.add_argument("--weight-clip", action="store_true", help="the entered weight, clipped")
    args = ap.parse_args()
    tables = {
        "weight_clip": clip_table, "body": body_table, "bands": bands_table,
        "regions": regions_table,
    }  # fmt: skip
    for flag, table in tables.items():
        if getattr(args, flag):
            table(args.nights, args.hours, args.cache)
            return 0
    n_h = round(args.hours)
    names = [
        "hysteresis only", "laboratory drift", "in use (today)",
        "in use + oracle first level", "in use + oracle first level, kept both ways",
        "in use + oracle every still period", "level exact every frame",
        "best gain every frame (floor)", "in use + body weight entered (not an oracle)",
    ]  # fmt: skip
    print("per element (worst hour at 10-150 mmHg) / total load (worst hour), ORACLE rows marked\n")
    print("| night | used for | " + " | ".join(names) + " |")
    print("|---|---|" + "---:|" * len(names))
    hourly_rows = []
    for spec in args.nights:
        t0 = time.time()
        raw, truth, chain, area, seed, used = load_night(spec, args.hours, args.cache)
        outs: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for name, opts in METHODS.items():
            pipe = Pipeline(chain, raw.layout, **opts)
            v, ok, _ = pipe.process(raw.frames, raw.times, raw.valid)
            outs["in use (today)" if name == "in use" else name] = (v, ok)
        outs[names[3]] = oracle_run(chain, raw, truth, "first")
        outs[names[4]] = oracle_run(chain, raw, truth, "first", weigh_up=True)
        outs[names[5]] = oracle_run(chain, raw, truth, "every")
        v, ok = outs["in use (today)"]
        outs[names[6]] = (level_exact(v, ok, truth, area), ok)
        outs[names[7]] = (best_gain(v, ok, truth, BAND), ok)
        outs[names[8]] = oracle_run(chain, raw, truth, "weight", entered_weight(raw, seed))
        cells = []
        for name in names:
            v, ok = outs[name]
            err, lerr = hourly(v, ok, truth, raw.times, area, n_h)
            cells.append(f"{100 * max(err):.1f} / {100 * max(lerr):.1f}%")
            hourly_rows.append((spec, name, err, lerr))
        print(f"| {spec} | {used} | " + " | ".join(cells) + " |", flush=True)
        print(f"({spec}: {time.time() - t0:.0f} s)", file=sys.stderr, flush=True)
    print("\nper element by hour (10-150 mmHg) | total load by hour\n")
    print("| night | way | " + " | ".join(f"h{h + 1}" for h in range(n_h)) + " | load by hour |")
    print("|---|---|" + "---:|" * (n_h + 1))
    for spec, name, err, lerr in hourly_rows:
        print(
            f"| {spec} | {name} | "
            + " | ".join(f"{100 * e:.1f}" for e in err)
            + " | "
            + " ".join(f"{100 * e:.1f}" for e in lerr)
            + " |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
