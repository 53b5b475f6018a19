"""Drift corrected in use (issue 37, docs/drift.md "Drift corrected in use").

The laboratory cannot identify the drift a mat will show in use (docs/drift.md: the γ of held
steps or of cycles does not transfer to a person lying still), but use itself tells two
things the laboratory cannot:

- **stillness**: while a person lies (or sits) still, the load on every part of the mat stays
  what it is — a change of the reading is drift (the thesis's "shift of the hysteresis during
  longer pressure", §5);
- **an empty mat** reads zero — what it reads instead is an offset.

:class:`InUseDrift` follows both, frame by frame, on the hysteresis stage's output (eq.
4.15-4.22; it replaces the laboratory drift stage of eq. 5.8 when it runs). Its model of the
drift is the spacer's creep: under a held load the spacer keeps compressing, so an element
reads more than it carries; the creep stays in the spacer after the load changes (a set).
Each element keeps a *creep* ``du`` in the units of the hysteresis stage's input (mm of
compression) and reads ``F(F⁻¹(h) - du)``, ``F`` the calibration's first-loading curve (the
compression that the reading ``h`` means, less the creep). While the mat is still, the creep
of the loaded elements of each region grows by what keeps the region's load constant
(smoothed over ``smooth_s``); it is never changed while anything moves. When the mat has been
empty for ``settle_s`` its readings become the elements' zero offsets.

Stillness and emptiness are read from the frames: the map's change between frames summed
over small blocks of elements (so that breathing, a common factor, is not movement and a
turn, a shift of load, is), relative to the load; a frame is still when it changes by less
than ``motion`` of the load, and the mat is still from ``settle_s`` after the last movement.
A turn, getting up, a second load put on the mat are movements: the creep is not touched by
them (a load change is never taken for drift; tests/test_inuse.py). A change of a still
region's load faster than ``max_rate`` per hour is not drift either: that still period starts
again.

Everything it knows is a small object (:class:`InUseState`, ``to_dict``/``from_dict``), shown
on the dashboard, kept in recordings' metadata and in the report.

Examples
--------
>>> import numpy as np
>>> from texsense import Layout
>>> lay = Layout.grid(4, 4)
>>> est = InUseDrift(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 4.0]), lay, settle_s=20)
>>> for t in range(0, 200, 10):  # a still load whose reading creeps by 0.1 % per 10 s
...     out = est.step(np.full(16, 1.0 + 0.001 * t / 10), np.ones(16, bool), float(t))
>>> round(float(out[0]), 3), est.state.status(180.0)["state"]
(1.003, 'correcting')
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import nnls

from texsense.data.layout import Layout
from texsense.exceptions import ParameterError

__all__ = ["REGIONS", "InUseDrift", "InUseState", "motion_blocks"]

#: How the creep is shared: one region for the mat, or blocks of K x K elements.
REGIONS = ("elements", "blocks", "mat")
#: Size (elements) of the blocks whose load change tells movement from stillness.
MOTION_BLOCK = 4


def motion_blocks(layout: Layout, size: int = 4) -> np.ndarray:
    """A block index per element: ``size`` x ``size`` cells of a grid, one block per element
    of a points layout."""
    if layout.cells is None or layout.shape is None:
        return np.arange(layout.n_elements)
    rows, cols = np.divmod(np.asarray(layout.cells), layout.shape[1])
    per_row = (layout.shape[1] + size - 1) // size
    blocks = (rows // size) * per_row + cols // size
    _, index = np.unique(blocks, return_inverse=True)
    return np.asarray(index, dtype=np.intp)


@dataclass
class InUseState:
    """What the in-use estimator knows: the creep and zero offset of every element and how it
    came to them (small: two numbers per element; ``to_dict``/``from_dict`` for checkpoints)."""

    creep: np.ndarray  # (N,) in the hysteresis stage's input unit (mm)
    offset: np.ndarray  # (N,) N/cm², the readings of the empty mat
    still_s: float = 0.0  # still time the creep was read from (s)
    first_t: float | None = None  # when the creep was first changed
    last_t: float | None = None  # when the creep was last changed
    zeroed_t: float | None = None  # when the offsets were last taken
    zeroed: int = 0  # how many empty periods gave offsets
    refused: int = 0  # still periods refused (their load changed faster than drift can)
    load_correction: float = 0.0  # the correction of the present load (share, -0.12: 12 % less)
    exposure: np.ndarray | None = None  # (N,) ∫ pressure dt, N/cm² s: the creep law's clock
    read: np.ndarray | None = None  # (N,) bool: the element's creep was read in stillness
    law: tuple[float, ...] | None = None  # creep = a · exposure^b fitted on the read ones
    path: np.ndarray | None = None  # (N,) Σ|Δ pressure|, N/cm²: the load path travelled
    at_read: np.ndarray | None = None  # (2, N) exposure and path when the creep was last set

    def __post_init__(self) -> None:
        n = self.creep.size
        self.exposure = np.zeros(n) if self.exposure is None else self.exposure
        self.read = np.zeros(n, bool) if self.read is None else self.read
        self.path = np.zeros(n) if self.path is None else self.path
        self.at_read = np.zeros((2, n)) if self.at_read is None else self.at_read

    def status(self, t: float | None = None) -> dict[str, Any]:
        """The state in words and numbers (dashboard, metadata, report)."""
        state = "waiting for stillness" if self.first_t is None else "correcting"
        return {
            "state": state,
            "load_correction": round(float(self.load_correction), 4),
            "since_t": self.first_t,
            "last_t": self.last_t,
            "still_s": round(float(self.still_s), 1),
            "zeroed": self.zeroed,
            "zeroed_t": self.zeroed_t,
            "refused": self.refused,
            "max_creep_mm": round(float(np.max(np.abs(self.creep), initial=0.0)), 4),
            "read_elements": int(np.count_nonzero(self.read)),
            "creep_law": None if self.law is None else [round(v, 5) for v in self.law],
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-able."""
        return {
            "creep": np.asarray(self.creep, float).tolist(),
            "offset": np.asarray(self.offset, float).tolist(),
            "still_s": self.still_s,
            "first_t": self.first_t,
            "last_t": self.last_t,
            "zeroed_t": self.zeroed_t,
            "zeroed": self.zeroed,
            "refused": self.refused,
            "load_correction": self.load_correction,
            "exposure": np.asarray(self.exposure, float).tolist(),
            "read": np.asarray(self.read, bool).tolist(),
            "law": None if self.law is None else list(self.law),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], n_elements: int | None = None) -> InUseState:
        """Inverse of :meth:`to_dict`; ``n_elements`` checks the size."""
        try:
            creep = np.asarray(d["creep"], dtype=np.float64)
            offset = np.asarray(d["offset"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as e:
            raise ParameterError(f"in-use drift state: {e}") from None
        if creep.ndim != 1 or creep.shape != offset.shape:
            raise ParameterError("in-use drift state: creep and offset must be equal 1-D lists")
        if n_elements is not None and creep.size != n_elements:
            raise ParameterError(
                f"in-use drift state of {creep.size} elements, the mat has {n_elements}"
            )
        if not (np.all(np.isfinite(creep)) and np.all(np.isfinite(offset))):
            raise ParameterError("in-use drift state: creep and offset must be numbers")
        opt = {k: d.get(k) for k in ("first_t", "last_t", "zeroed_t")}
        exposure = np.asarray(d.get("exposure", np.zeros(creep.size)), dtype=np.float64)
        read = np.asarray(d.get("read", np.zeros(creep.size, bool)), dtype=bool)
        law = d.get("law")
        if exposure.shape != creep.shape or read.shape != creep.shape:
            raise ParameterError("in-use drift state: exposure and read need one value per element")
        return cls(
            creep,
            offset,
            float(d.get("still_s", 0.0)),
            zeroed=int(d.get("zeroed", 0)),
            refused=int(d.get("refused", 0)),
            load_correction=float(d.get("load_correction", 0.0)),
            exposure=exposure,
            read=read,
            law=None if law is None else (float(law[0]), float(law[1])),
            **{k: None if v is None else float(v) for k, v in opt.items()},
        )


class InUseDrift:
    """The in-use drift estimator of one mat (see the module documentation).

    Parameters
    ----------
    curve_input, curve_output : array_like
        The first-loading curve of the calibration (hysteresis stage input -> pressure,
        N/cm², non-decreasing): ``F`` of the module documentation.
    layout : Layout
        The mat's elements (areas; blocks for movement and regions).
    settle_s : float
        Still (or empty) this long before the drift (or the zero) is read (default 60 s).
    motion : float
        A frame moves when the map changes by more than this share of the load (0.05).
    loaded_ncm2 : float
        An element is loaded above this (0.05 N/cm², about 4 mmHg).
    empty_ncm2 : float
        The mat is empty when at most 0.2 % of its elements (at least 2) read above this
        (0.1 N/cm², about 7.5 mmHg).
    smooth_s : float
        Region loads are smoothed over this time (60 s).
    regions : {"mat", "blocks"}
        One creep rate for the whole mat, or per block of ``block`` x ``block`` elements.
    block : int
        Block size (elements) of ``regions="blocks"`` and of the movement test.
    max_rate : float
        Largest drift a still region may show, share of its load per hour (0.5); faster is a
        load change, not drift.
    max_creep_mm : float
        Largest creep of an element (the correction stops there and says so).
    predict : bool
        Give loaded elements whose creep was never read the creep law's (see
        :meth:`_predict_unread`).
    """

    def __init__(
        self,
        curve_input: npt.ArrayLike,
        curve_output: npt.ArrayLike,
        layout: Layout,
        *,
        settle_s: float = 60.0,
        motion: float = 0.05,
        loaded_ncm2: float = 0.05,
        empty_ncm2: float = 0.1,
        smooth_s: float = 60.0,
        regions: str = "elements",
        block: int = 4,
        max_rate: float = 0.5,
        max_creep_mm: float = 1.5,
        predict: bool = True,
        zero: bool = True,
        path_law: bool = False,
    ) -> None:
        u = np.asarray(curve_input, dtype=np.float64)
        p = np.asarray(curve_output, dtype=np.float64)
        if u.ndim != 1 or u.shape != p.shape or u.size < 2:
            raise ParameterError("the loading curve needs >= 2 points (input, pressure)")
        keep = np.concatenate([[True], np.diff(p) > 1e-12])  # strictly increasing for F⁻¹
        self._u, self._p = u[keep], p[keep]
        if self._u.size < 2:
            raise ParameterError("the loading curve does not rise")
        if regions not in REGIONS:
            raise ParameterError(f"regions must be one of {', '.join(REGIONS)}, got {regions!r}")
        for name, v in (("settle_s", settle_s), ("motion", motion), ("smooth_s", smooth_s),
                        ("max_rate", max_rate), ("max_creep_mm", max_creep_mm)):  # fmt: skip
            if not (np.isfinite(v) and v > 0):
                raise ParameterError(f"{name} must be > 0, got {v}")
        if not 0 <= loaded_ncm2 < empty_ncm2:
            raise ParameterError("need 0 <= loaded_ncm2 < empty_ncm2")
        self.layout = layout
        self.settle_s, self.motion, self.smooth_s = float(settle_s), float(motion), float(smooth_s)
        self.loaded_ncm2, self.empty_ncm2 = float(loaded_ncm2), float(empty_ncm2)
        self.max_rate, self.max_creep_mm = float(max_rate) / 3600.0, float(max_creep_mm)
        self.regions_kind = regions
        self.predict, self.zero, self.path_law = bool(predict), bool(zero), bool(path_law)
        n = layout.n_elements
        self.area = np.asarray(layout.area_cm2, dtype=np.float64)
        self._moving_blocks = motion_blocks(layout, MOTION_BLOCK)
        self._n_moving = int(self._moving_blocks.max()) + 1
        self._elements = np.arange(n)
        self._region = (
            np.zeros(n, np.intp)
            if regions == "mat"
            else self._elements
            if regions == "elements"
            else motion_blocks(layout, block)
        )
        self._n_regions = int(self._region.max()) + 1
        self._empty_count = max(2, int(0.002 * n))
        # the smallest load movement is judged against: 20 elements at the empty threshold
        self._floor_n = 20.0 * float(np.mean(self.area)) * self.empty_ncm2
        self.forget()

    # ------------------------------------------------------------------ the stream
    def reset(self) -> InUseDrift:
        """Start a new stream (the state — creep and offsets — stays)."""
        self._last_t: float | None = None
        self._prev: tuple[np.ndarray, np.ndarray] | None = None
        self._still_since: float | None = None
        self._period: dict[str, Any] | None = None  # the present still period
        self._empty_since: float | None = None
        self._zeroing = False
        return self

    def forget(self) -> InUseDrift:
        """A new mat state (no creep, no offsets) and a new stream."""
        n = self.layout.n_elements
        self.state = InUseState(np.zeros(n), np.zeros(n))
        return self.reset()

    def set_state(self, state: InUseState) -> InUseDrift:
        """Continue from a saved state (a checkpoint)."""
        if state.creep.shape != (self.layout.n_elements,):
            raise ParameterError("the state is of another mat (element count)")
        self.state = state
        return self.reset()

    def _corrected(self, x0: np.ndarray) -> np.ndarray:
        """``F(F⁻¹(x0) - creep)`` where an element is loaded and has creep; else ``x0``."""
        out = x0.copy()
        sel = (x0 > 0) & (self.state.creep != 0)
        if sel.any():
            u = np.interp(x0[sel], self._p, self._u) - self.state.creep[sel]
            out[sel] = np.interp(np.maximum(u, self._u[0]), self._u, self._p)
        return out

    def _slope(self, c: np.ndarray) -> np.ndarray:
        """dF/du at the readings ``c`` (N/cm² per input unit)."""
        u = np.interp(c, self._p, self._u)
        du = 1e-3 * (self._u[-1] - self._u[0])
        hi = np.interp(u + du, self._u, self._p)
        lo = np.interp(u - du, self._u, self._p)
        span = np.minimum(u + du, self._u[-1]) - np.maximum(u - du, self._u[0])
        return np.maximum((hi - lo) / np.maximum(span, 1e-12), 1e-9)

    def step(self, values: npt.ArrayLike, valid: npt.ArrayLike, t: float) -> np.ndarray:
        """One frame of hysteresis outputs (N/cm²) with the mask of measured elements at ``t``
        (s) -> the corrected frame."""
        x = np.asarray(values, dtype=np.float64)
        ok = np.asarray(valid, dtype=bool) & np.isfinite(x)
        x0 = np.where(ok, x - self.state.offset, np.nan_to_num(x))
        dt = 0.0 if self._last_t is None else float(t) - self._last_t
        if dt < 0:
            raise ParameterError("frame times must not decrease")
        self._last_t = float(t)
        c = self._corrected(x0)
        t = float(t)
        if int(np.count_nonzero(ok & (c > self.empty_ncm2))) <= self._empty_count:
            # an empty mat: nothing to move; settled, its readings are the zero offsets
            self._still_since, self._period, self._prev = None, None, None
            self._empty_since = t if self._empty_since is None else self._empty_since
            if self.zero and t - self._empty_since >= self.settle_s:
                self._zero(x0, ok, dt, t)
                c = self._corrected(np.where(ok, x - self.state.offset, x0))
            return c
        self._empty_since, self._zeroing = None, False
        if dt > 0:  # the creep law's clock: how long and how hard each element was loaded
            self.state.exposure += np.clip(c, 0.0, None) * dt
        if self._moved(c, ok):
            self._still_since, self._period = None, None
            return c
        self._still_since = t if self._still_since is None else self._still_since
        if t - self._still_since >= self.settle_s:
            c = self._still(x0, c, ok, dt, t)
        return c

    def _predict_unread(self, x0: np.ndarray, ok: np.ndarray) -> bool:
        """At the start of a still period: the creep gathered where it could not be read —
        under loads too light to show it (its pressure change is below the noise there, its
        compression is not) and while the load moved (a spacer's loops shift with the path
        travelled) — from the creep law ``a · exposure^b + c · path`` fitted on the elements
        whose creep was read. Read elements gain the law's growth since their last reading,
        the others the law's value. True when a creep changed."""
        st = self.state
        fit = st.read & (st.creep > 1e-4)
        if np.count_nonzero(fit) < 20:
            return False
        e_r, p_r = st.at_read[0, fit], st.at_read[1, fit]
        best = None
        for b in (0.25, 0.5, 0.75, 1.0):
            design = np.column_stack([e_r**b, p_r]) if self.path_law else (e_r**b)[:, None]
            coef, res = nnls(design, st.creep[fit])
            coef = np.append(coef, 0.0) if not self.path_law else coef
            if best is None or res < best[0]:
                best = (res, b, coef)
        assert best is not None
        _, b, (a, cpath) = best
        st.law = (float(a), float(b), float(cpath))

        def law(e: np.ndarray, path: np.ndarray) -> np.ndarray:
            return a * e**b + cpath * path

        now = law(st.exposure, st.path)
        grow = st.read & ok
        st.creep[grow] += np.maximum(now[grow] - law(st.at_read[0, grow], st.at_read[1, grow]), 0)
        new = ok & ~st.read & (x0 > self.loaded_ncm2)
        st.creep[new] = now[new]
        changed = grow | new
        np.clip(st.creep, -self.max_creep_mm, self.max_creep_mm, out=st.creep)
        st.at_read[0, changed], st.at_read[1, changed] = st.exposure[changed], st.path[changed]
        return bool(changed.any())

    def _moved(self, c: np.ndarray, ok: np.ndarray) -> bool:
        """Whether the map changed since the previous frame by more than ``motion`` of the
        load, summed over small blocks (elements measured in both frames)."""
        moved = True
        if self._prev is not None:
            prev, prev_ok = self._prev
            both = ok & prev_ok
            self.state.path[both] += np.abs(c[both] - prev[both])
            change = np.where(both, self.area * (c - prev), 0.0)
            blocks = np.bincount(self._moving_blocks, weights=change, minlength=self._n_moving)
            scale = max(float(self.area[both] @ np.abs(c[both])), self._floor_n)
            moved = float(np.abs(blocks).sum()) > self.motion * scale
        self._prev = (c, ok)
        return moved

    def _zero(self, x0: np.ndarray, ok: np.ndarray, dt: float, t: float) -> None:
        """An empty, settled mat: its readings are the elements' offsets (smoothed)."""
        if not self._zeroing:
            self._zeroing = True
            self.state.zeroed += 1
        a = 1.0 - np.exp(-dt / self.smooth_s) if dt > 0 else 0.0
        self.state.offset[ok] += a * x0[ok]
        self.state.zeroed_t = t

    def _still(
        self, x0: np.ndarray, c: np.ndarray, ok: np.ndarray, dt: float, t: float
    ) -> np.ndarray:
        """A settled still frame: the creep of each region's loaded elements grows by what
        keeps the region's smoothed load at the period's first value."""
        if self._period is None:  # the period's reference: the loaded elements and their values
            if self.predict and self._predict_unread(x0, ok):
                c = self._corrected(x0)
            loaded = ok & (c > self.loaded_ncm2)
            self._period = {"loaded": loaded, "ref": np.where(loaded, c, 0.0), "q": None, "t": t,
                            "moved": 0.0, "cum": np.zeros(c.size)}  # fmt: skip
            return c
        per = self._period
        mask = per["loaded"] & ok
        reg = self._region
        total = np.bincount(
            reg, weights=np.where(mask, self.area * c, 0.0), minlength=self._n_regions
        )
        ref = np.bincount(reg, weights=np.where(mask, self.area * per["ref"], 0.0),
                          minlength=self._n_regions)  # fmt: skip
        has = ref > 0
        ratio = np.where(has, total / np.where(has, ref, 1.0), 1.0)
        q = (
            ratio
            if per["q"] is None
            else per["q"] + (1.0 - np.exp(-dt / self.smooth_s)) * (ratio - per["q"])
        )
        per["q"] = q
        per["moved"] += abs(float(np.sum(q * ref) / max(float(ref.sum()), 1e-12)) - 1.0)
        if per["moved"] > self.max_rate * (t - per["t"]) + 0.03:
            self.state.refused += 1  # faster than drift: a load change; start the period again
            self._period = None
            return c
        if self._region is self._elements:  # an element changing faster than drift: not drift
            per["cum"] += q - 1.0
            fast = np.abs(per["cum"]) > self.max_rate * (t - per["t"]) + 0.05
            per["loaded"] &= ~fast
            mask &= ~fast
            q = np.where(fast, 1.0, q)
        slope = self._slope(c)
        stiff = np.bincount(
            reg, weights=np.where(mask, self.area * slope, 0.0), minlength=self._n_regions
        )
        shift = np.where(stiff > 0, (q - 1.0) * ref / np.where(stiff > 0, stiff, 1.0), 0.0)
        creep = self.state.creep
        self.state.read[mask] = True
        self.state.at_read[0, mask] = self.state.exposure[mask]
        self.state.at_read[1, mask] = self.state.path[mask]
        creep[mask] = np.clip(creep[mask] + shift[reg[mask]], -self.max_creep_mm, self.max_creep_mm)
        per["q"] = np.ones_like(q)
        self.state.still_s += dt
        self.state.first_t = t if self.state.first_t is None else self.state.first_t
        self.state.last_t = t
        out = self._corrected(x0)
        before = float(self.area[ok] @ np.clip(x0[ok], 0, None))
        if before > 0:
            self.state.load_correction = (
                float(self.area[ok] @ np.clip(out[ok], 0, None)) / before - 1
            )
        return out

    def run(self, frames: npt.ArrayLike, valid: npt.ArrayLike, times: npt.ArrayLike) -> np.ndarray:
        """Frames (T, N) with their validity at ``times`` -> corrected frames (continues the
        stream)."""
        x = np.asarray(frames, dtype=np.float64)
        ok = np.asarray(valid, dtype=bool)
        t = np.asarray(times, dtype=np.float64)
        out = np.empty_like(x)
        #: the load correction after every frame of the last run (NaN: not correcting yet)
        self.corrections_ = np.full(x.shape[0], np.nan)
        for k in range(x.shape[0]):
            out[k] = self.step(x[k], ok[k], float(t[k]))
            if self.state.first_t is not None:
                self.corrections_[k] = self.state.load_correction
        return out
