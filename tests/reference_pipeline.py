"""The pipeline as it was before it moved into one compiled pass (commit 99671fd), kept in
the tests only, as the oracle of the equality tests: a numpy failure detector (neighbour
median from a padded table), the conversion by ``np.interp``, the Rust ``Compensation`` kernel,
the local repairs in numpy and the harmonic ones by the repair stage, frame by frame.

One deliberate difference: eq. 6.14 is evaluated here in float64 (numpy), where the old path
went through a float32 repair kernel and rounded every value of the frame to float32 on the
way; the compiled chain computes in float64, and a 1e-9 comparison needs an oracle that does
too.
"""

from __future__ import annotations

import numpy as np

from texsense._core import Compensation
from texsense.compensation.repair import Repair, idw_weights
from texsense.compensation.stages import StageChain
from texsense.data.layout import Layout


class ReferenceDetector:
    """The numpy detector of texsense.compensation.health before the move (same thresholds)."""

    def __init__(self, layout: Layout, baseline_pF, max_pF, **kw) -> None:
        self.min_pF = kw.get("min_pF", 0.05)
        self.low_share = kw.get("low_share", 0.5)
        self.high_share = kw.get("high_share", 1.2)
        self.stuck_frames = kw.get("stuck_frames", 20)
        self.stuck_pF = kw.get("stuck_pF", 1e-4)
        self.neighbour_change_pF = kw.get("neighbour_change_pF", 0.05)
        jump_share, jump_pF = kw.get("jump_share", 0.6), kw.get("jump_pF", 2.0)
        n = layout.n_elements
        self._base = None if baseline_pF is None else np.asarray(baseline_pF, float)
        self._max = None if max_pF is None else np.asarray(max_pF, float)
        if self._base is not None and self._max is not None:
            self._jump = jump_share * np.maximum(self._max - self._base, 1e-6)
        else:
            self._jump = np.full(n, jump_pF)
        indptr, indices = layout.neighbours
        counts = np.diff(indptr)
        self._has_nb = counts > 0
        width = int(counts.max()) if counts.size else 0
        self._nb_table = np.full((n, width), n, dtype=np.int64)
        rows = np.repeat(np.arange(n), counts)
        slots = np.arange(indices.size) - np.repeat(indptr[:-1], counts)
        self._nb_table[rows, slots] = indices
        self._nb_lo = np.maximum(counts - 1, 0) // 2
        self._nb_hi = counts // 2
        self.n = n
        self._last = np.full(n, np.nan)
        self._still = np.zeros(n, dtype=np.int64)
        self._moved = np.zeros(n)

    def neighbour_median(self, x: np.ndarray) -> np.ndarray:
        if self._nb_table.shape[1] == 0:
            return np.zeros(self.n)
        vals = np.append(x, np.inf)[self._nb_table]
        vals.sort(axis=1)
        rows = np.arange(self.n)
        out = 0.5 * (vals[rows, self._nb_lo] + vals[rows, self._nb_hi])
        out[~self._has_nb] = 0.0
        return out

    def step(self, c: np.ndarray, ok_in: np.ndarray) -> np.ndarray:
        code = np.zeros(self.n, dtype=np.uint8)
        delta = np.abs(c - self._last)
        first = np.isnan(delta)
        delta = np.where(first, 0.0, delta)
        nb_move = self.neighbour_median(delta)
        still = (delta <= self.stuck_pF) & ~first
        self._still = np.where(still, self._still + 1, 0)
        self._moved = np.where(still, self._moved + nb_move, 0.0)
        stuck = (
            (self._still >= self.stuck_frames)
            & (self._moved > self.neighbour_change_pF)
            & self._has_nb
        )
        code[stuck] = 3
        code[~first & (delta > self._jump)] = 4
        low = ~np.isfinite(c) | (c <= self.min_pF)
        if self._base is not None:
            low |= c < self.low_share * self._base
        high = ~ok_in
        if self._max is not None:
            high |= c > self.high_share * self._max
        code[high] = 2
        code[low] = 1
        self._last = np.where(np.isfinite(c), c, self._last)
        return code


class ReferencePipeline:
    """detect -> convert -> Compensation (or the loading curve) -> repair, frame by frame
    in Python around the kernels, as before."""

    def __init__(
        self,
        chain: StageChain,
        layout: Layout,
        *,
        detect: bool = True,
        hysteresis: bool = True,
        drift: bool = True,
        repair: str | None = "harmonic",
    ) -> None:
        conv = chain["convert"]
        model = chain["hysteresis"].model_
        self.layout, self.detect = layout, detect
        self.curve = (conv.curve_capacitance_pF_, conv.curve_compression_mm_)
        self.offset, self.gain = conv.offset_pF_, conv.gain_
        self.detector = ReferenceDetector(layout, *conv.expected_range_pF())
        self.repair = repair
        global_repair = repair in ("harmonic", "harmonic-temporal")
        self._repair = Repair(layout, repair).fit() if global_repair else None
        self._weights = idw_weights(layout) if repair == "idw8" else None
        self._last = np.full(layout.n_elements, np.nan)
        n = layout.n_elements
        d = chain["drift"].model_.state(n) if drift and "drift" in chain else None
        self._stage = Compensation(model.bank(n), d) if hysteresis else None
        e = np.linspace(model.u_min_, model.u_max_, 400)
        self._loading = (e, np.maximum.accumulate(model.predict(e)))
        self._last_t = None

    def _local(self, x: np.ndarray, ok: np.ndarray) -> np.ndarray:
        """The local repairs in float64 numpy: eq. 6.14 (the mean of the measured
        4-neighbours), idw8, zero, last value; else the last value."""
        out = np.where(ok, x, np.nan)
        if self.repair == "neighbour-mean":
            indptr, indices = self.layout.neighbours
            for i in np.flatnonzero(~ok):
                nb = indices[indptr[i] : indptr[i + 1]]
                nb = nb[ok[nb]]
                out[i] = x[nb].mean() if nb.size else np.nan
        elif self.repair == "idw8":
            num = self._weights @ np.where(ok, x, 0.0)
            den = self._weights @ ok.astype(np.float64)
            have = ~ok & (den > 0)
            out[have] = num[have] / den[have]
        elif self.repair == "zero":
            out[~ok] = 0.0
        left = ~ok & ~np.isfinite(out)
        out[left] = self._last[left]
        self._last = np.where(np.isfinite(out), out, self._last)
        return out

    def run(self, cap: np.ndarray, valid: np.ndarray, times: np.ndarray):
        n_t = cap.shape[0]
        if self.detect:
            codes = np.stack([self.detector.step(cap[k], valid[k]) for k in range(n_t)])
        else:
            codes = np.where(valid & np.isfinite(cap), 0, 2).astype(np.uint8)
        ok = codes == 0
        comp = np.interp((cap - self.offset) / self.gain, *self.curve)
        if self._stage is not None:
            t0 = times[0] if self._last_t is None else self._last_t
            dt = np.diff(times, prepend=t0)
            pressure = self._stage.run(
                np.ascontiguousarray(dt), np.ascontiguousarray(comp), np.ascontiguousarray(ok)
            )
        else:
            e, p = self._loading
            pressure = np.where(ok, np.interp(comp, e, p), np.nan)
        self._last_t = float(times[-1])
        for k in range(n_t):
            if self._repair is not None:
                pressure[k], _ = self._repair.step(pressure[k], ok[k], float(times[k]))
            elif self.repair is not None:
                pressure[k] = self._local(pressure[k], ok[k])
        return pressure, ok, codes
