"""Drift corrected in use (issue 37, docs/drift.md "Drift corrected in use").

The laboratory cannot identify the drift a mat will show in use (docs/drift.md: the γ of held
steps or of cycles does not transfer to a person lying still), but use itself tells two
things the laboratory cannot:

- **stillness**: while a person lies (or sits) still, the load on every part of the mat stays
  what it is — a change of the reading is drift (the thesis's "shift of the hysteresis during
  longer pressure", §5);
- **an empty mat** carries zero load — the compression it still reads is the spacer's set.

:class:`InUseDrift` follows both, frame by frame, on the hysteresis stage's output (eq.
4.15-4.22; it replaces the laboratory drift stage of eq. 5.8 when it runs). Its model of the
drift is the spacer's creep: under a held load the spacer keeps compressing, so an element
reads more than it carries; the creep stays in the spacer after the load changes (a set).
Each element keeps a *creep* ``du`` in the units of the hysteresis stage's input (mm of
compression) and reads ``F(F⁻¹(h) - du)``, ``F`` the calibration's first-loading curve (the
compression that the reading ``h`` means, less the creep). While the mat is still, every
loaded element's creep grows by what keeps its reading at the value it had when the stillness
began (read every ``update_s`` from the mean over that time); it is never changed while
anything moves. Creep also gathers where it cannot be read — under loads too light for the
reading to show it, and in elements loaded only after the stillness began — so at the start of
every still period the elements never read get the creep that a law fitted on the read ones
gives for their load history (``a · exposure^b``, exposure = ∫ pressure dt). When the mat has
been empty for ``settle_s``, the compression every element still reads (the conversion of
eq. 2.1 on its raw capacitance: a true zero load) is the set the spacer kept, which the
pressure cannot show (on a descending branch of the hysteresis every set reads about zero);
it becomes the creep of the elements whose creep was never read while loaded.

A still person also keeps their weight: the load on the mat (missing elements filled from
their measured neighbours) at the start of every still period is compared with the load of the
first one, and a difference no larger than drift can make since then (``weigh_rate`` per hour,
at most ``weigh_max``) checks the correction (the bounds widen with the time since the last
check). A heavier load is taken as creep the reading did not show — the creep of elements
loaded only after the stillness began, and what crept before the period settled — and shared
over the loaded elements in proportion to their readings; a lighter one is not (creep only
makes a reading heavier; ``weigh_up`` takes it too). A larger difference is a load change
(a second load, a person sitting on the edge) and is left alone; after an empty mat it is
another occupant, weighed anew. A second load lighter than that window, put down while the
person moves, is taken for drift (docs/drift.md says where the line is).

Stillness and emptiness are read from the frames: the map's change between frames summed
over small blocks of elements (so that breathing, a common factor, is not movement and a
turn, a shift of load, is), relative to the load; a frame is still when it changes by less
than ``motion`` of the load, and the mat is still from ``settle_s`` after the last movement.
A turn, getting up, a second load put on the mat are movements: the creep is not touched by
them (a load change is never taken for drift; tests/test_inuse.py). A still mat whose load
changes faster than ``max_rate`` per hour is not drifting either (a slow load change): that
still period starts again; an element whose own reading changes that fast (a person slowly
sliding shifts load between elements, the total stays) is left out of the period.

Everything it knows is a small object (:class:`InUseState`, ``to_dict``/``from_dict``), shown
on the dashboard, kept in recordings' metadata and in the report.

Examples
--------
>>> import numpy as np
>>> from texsense import Layout
>>> lay = Layout.grid(4, 4)
>>> est = InUseDrift(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 4.0]), lay)
>>> for t in range(0, 1200, 10):  # a still load whose reading creeps by 0.1 % per 10 s
...     out = est.step(np.full(16, 1.0 + 0.001 * t / 10), np.ones(16, bool), float(t))
>>> float(out[0]) < 1.02 < 1.0 + 0.001 * 119, est.state.status()["state"]
(True, 'correcting')
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from texsense._core import MotionTest
from texsense.compensation.inuse_state import InUseState
from texsense.data.layout import Layout
from texsense.exceptions import ParameterError

__all__ = ["MOTION_BLOCK", "InUseDrift", "InUseState", "motion_blocks"]

#: Size (elements) of the blocks whose load change tells movement from stillness.
MOTION_BLOCK = 4
#: What a still mat's load (an element's reading) may change by in a still period beyond
#: ``max_rate`` per hour before it counts as a load change, not drift. Chosen on the textile
#: nights of seed 0: wider (0.08, 0.15) also takes the first minutes' fast creep after a load
#: is taken (up to 8 %), which the spacer gives back, and over-corrected by 3-9 points.
LOAD_SLACK, ELEMENT_SLACK = 0.03, 0.05


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


class InUseDrift:
    """The in-use drift estimator of one mat (see the module documentation).

    Parameters
    ----------
    curve_input, curve_output : array_like
        The first-loading curve of the calibration (hysteresis stage input -> pressure,
        N/cm², non-decreasing): ``F`` of the module documentation.
    layout : Layout
        The mat's elements (areas; blocks for the movement test).
    settle_s : float
        Still (or empty) this long before the drift (or the zero) is read (default 60 s).
    motion : float
        A frame moves when the map changes by more than this share of the load (0.05),
        summed over blocks of :data:`MOTION_BLOCK` x :data:`MOTION_BLOCK` elements.
    loaded_ncm2 : float
        An element's creep is read above this (0.05 N/cm², about 4 mmHg).
    empty_ncm2 : float
        The mat is empty when at most 0.2 % of its elements (at least 2) read above this
        (0.1 N/cm², about 7.5 mmHg).
    update_s : float
        The creep is read from the mean over this much still time (30 s).
    max_rate : float
        Largest drift a still mat (or element) may show, share of its load per hour (0.5);
        faster is a load change.
    max_creep_mm : float
        Largest creep of an element, in the hysteresis stage's input unit (1.5).
    predict : bool
        Give elements whose creep was never read the creep law's (module documentation).
    zero : bool
        Take the compression an empty mat reads as the creep (needs ``converter``).
    converter : Converter, optional
        The calibration's conversion (capacitance -> compression, eq. 2.1,
        ``Convert.kernel()``): with it, :meth:`run` given the raw frames reads the set of an
        empty mat.
    rest_input : float, optional
        What ``converter`` gives for a rested, unloaded element (its lowest compression; default
        the loading curve's first input).
    weigh : bool
        Keep a still person's weight (module documentation; default on).
    weigh_rate, weigh_max : float
        How much the load of a still person may differ from their weight and still be taken
        for drift: 1 % + ``weigh_rate`` (0.03) per hour since the weight was taken, at most
        ``weigh_max`` (0.15). Chosen on the textile and Iwan nights of seeds 0 and 1 (0.02 /
        0.10 and 0.05 / 0.25 were worse there: docs/drift.md).
    weigh_up : bool
        Also bring a still load lighter than the weight up to it (off: creep only makes a
        reading heavier, so a lighter load is not creep the reading missed; with it the
        Bouc–Wen nights and one foam night were worse per element: docs/drift.md).
    """

    #: The empty count and the movement test of a frame in one compiled pass
    #: (``texsense._core.MotionTest``; False: the numpy reference, the same bits, tested).
    compiled = True

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
        update_s: float = 30.0,
        max_rate: float = 0.5,
        max_creep_mm: float = 1.5,
        predict: bool = True,
        zero: bool = True,
        converter: Any = None,
        rest_input: float | None = None,
        weigh: bool = True,
        weigh_rate: float = 0.03,
        weigh_max: float = 0.15,
        weigh_up: bool = False,
    ) -> None:
        u = np.asarray(curve_input, dtype=np.float64)
        p = np.asarray(curve_output, dtype=np.float64)
        if u.ndim != 1 or u.shape != p.shape or u.size < 2:
            raise ParameterError("the loading curve needs >= 2 points (input, pressure)")
        keep = np.concatenate([[True], np.diff(p) > 1e-12])  # strictly increasing for F⁻¹
        self._u, self._p = u[keep], p[keep]
        if self._u.size < 2:
            raise ParameterError("the loading curve does not rise")
        # the compression an unloaded, rested spacer reads (the conversion's floor): an empty
        # mat's set is what it reads beyond this
        self._u_rest = float(self._u[0]) if rest_input is None else float(rest_input)
        for name, v in (("settle_s", settle_s), ("motion", motion), ("update_s", update_s),
                        ("max_rate", max_rate), ("max_creep_mm", max_creep_mm)):  # fmt: skip
            if not (np.isfinite(v) and v > 0):
                raise ParameterError(f"{name} must be > 0, got {v}")
        if not 0 <= loaded_ncm2 < empty_ncm2:
            raise ParameterError("need 0 <= loaded_ncm2 < empty_ncm2")
        self.layout = layout
        self.settle_s, self.motion, self.update_s = float(settle_s), float(motion), float(update_s)
        self.loaded_ncm2, self.empty_ncm2 = float(loaded_ncm2), float(empty_ncm2)
        self.max_rate, self.max_creep_mm = float(max_rate) / 3600.0, float(max_creep_mm)
        self.predict, self.zero, self.converter = bool(predict), bool(zero), converter
        if not (0 <= weigh_rate < 1 and 0 <= weigh_max < 0.5):
            raise ParameterError("need 0 <= weigh_rate < 1 and 0 <= weigh_max < 0.5")
        self.weigh, self.weigh_rate, self.weigh_max = bool(weigh), weigh_rate / 3600, weigh_max
        self.weigh_up = bool(weigh_up)
        indptr, indices = layout.neighbours
        self._nb_owner = np.repeat(np.arange(layout.n_elements), np.diff(indptr))
        self._nb_index = np.asarray(indices, dtype=np.intp)
        n = layout.n_elements
        self.area = np.asarray(layout.area_cm2, dtype=np.float64)
        self._blocks = motion_blocks(layout, MOTION_BLOCK)
        self._n_blocks = int(self._blocks.max()) + 1
        self._empty_count = max(2, int(0.002 * n))
        # the smallest load a movement is judged against: 20 elements at the empty threshold
        self._floor_n = 20.0 * float(np.mean(self.area)) * self.empty_ncm2
        self._test = MotionTest(self._blocks.astype(np.int64), np.ascontiguousarray(self.area))
        self.forget()

    # ------------------------------------------------------------------ the stream
    def reset(self) -> InUseDrift:
        """Start a new stream (the state — the creep — stays)."""
        n = self.layout.n_elements
        self._last_t: float | None = None
        self._prev: tuple[np.ndarray, np.ndarray] | None = None  # last map, block loads
        self._test.forget()  # (the compiled test's last map)
        self._still_since: float | None = None
        self._period: dict[str, Any] | None = None  # the present still period
        self._empty_since: float | None = None
        self._zeroing = False
        self._gain = np.ones(n)  # c = x * gain: the creep at the last refresh
        self._set: np.ndarray | None = None  # an empty mat's compression, smoothed
        self._returned = False  # the mat was empty since the last still period began
        return self

    def forget(self) -> InUseDrift:
        """A new mat state (no creep) and a new stream."""
        n = self.layout.n_elements
        self.state = InUseState(np.zeros(n))
        return self.reset()

    def set_state(self, state: InUseState) -> InUseDrift:
        """Continue from a saved state (a checkpoint)."""
        if state.creep.shape != (self.layout.n_elements,):
            raise ParameterError("the state is of another mat (element count)")
        self.state = state
        return self.reset()

    @property
    def last_t(self) -> float | None:
        """The time of the last frame of the stream (s), None before the first."""
        return self._last_t

    def corrected(self, x0: np.ndarray) -> np.ndarray:
        """``F(F⁻¹(x0) - creep)`` where an element reads above zero and has creep; else
        ``x0`` (exact: what the per-frame gain approximates between refreshes)."""
        out = np.array(x0, dtype=np.float64)
        sel = (out > 0) & (self.state.creep != 0)
        if sel.any():
            u = np.interp(out[sel], self._p, self._u) - self.state.creep[sel]
            out[sel] = np.interp(np.maximum(u, self._u[0]), self._u, self._p)
        return out

    def _refresh(self, x0: np.ndarray) -> np.ndarray:
        """The gain of every element at the readings ``x0`` (the creep changed, or the load
        did); returns the corrected frame."""
        c = self.corrected(x0)
        # a gain only where the element is loaded (where its creep is read), and never below 0:
        # a ratio over a reading near zero is no gain, and times a later load it was one
        # (-82 N/cm² at a sit-down, docs/drift.md)
        big = x0 > self.loaded_ncm2
        self._gain = np.where(big, np.maximum(c / np.where(big, x0, 1.0), 0.0), 1.0)
        return c

    def _slope(self, c: np.ndarray) -> np.ndarray:
        """dF/du at the readings ``c`` (N/cm² per input unit)."""
        u = np.interp(c, self._p, self._u)
        du = 1e-3 * (self._u[-1] - self._u[0])
        hi = np.interp(u + du, self._u, self._p)
        lo = np.interp(u - du, self._u, self._p)
        span = np.minimum(u + du, self._u[-1]) - np.maximum(u - du, self._u[0])
        return np.maximum((hi - lo) / np.maximum(span, 1e-12), 1e-9)

    def step(
        self,
        values: npt.ArrayLike,
        valid: npt.ArrayLike,
        t: float,
        raw: npt.ArrayLike | None = None,
    ) -> np.ndarray:
        """One frame of hysteresis outputs (N/cm²) with the mask of measured elements at ``t``
        (s) -> the corrected frame (elements not measured keep their value, corrected);
        ``raw``: the frame's raw readings, for the zero of an empty mat (with ``converter``)."""
        x = np.ascontiguousarray(values, dtype=np.float64)  # (read, never written to)
        if not np.isfinite(x).all():
            x = np.nan_to_num(x)
        ok = np.ascontiguousarray(valid, dtype=bool)
        t = float(t)
        dt = 0.0 if self._last_t is None else t - self._last_t
        if dt < 0:
            raise ParameterError("frame times must not decrease")
        self._last_t = t
        if self.compiled:  # the empty count and the movement test in one compiled pass
            c, verdict = self._test.step(x, self._gain, ok, self.empty_ncm2, self._empty_count,
                                         self._floor_n, self.motion)  # fmt: skip
        else:
            c = x * self._gain
            empty = np.count_nonzero((c > self.empty_ncm2) & ok) <= self._empty_count
            verdict = "empty" if empty else ""  # "": the movement test below
        if verdict == "empty":
            self._empty(ok, dt, t, raw)
            return c
        if self._zeroing:  # the mat was empty and is loaded again: the set read is the creep
            self._take_zero()
        self._empty_since, self._zeroing = None, False
        if verdict == "moved" or (verdict == "" and self._moved(c, ok)):
            self._still_since, self._period = None, None
            return c
        if self._still_since is None:  # the first still frame: the gains at this load
            self._still_since = t
            c = self._refresh(x)
        if t - self._still_since >= self.settle_s:
            c = self._still(x, c, ok, t)
        return c

    def _empty(self, ok: np.ndarray, dt: float, t: float, raw: npt.ArrayLike | None) -> None:
        """An empty mat: nothing moves; settled, the compression it reads (its set) is
        smoothed over ``update_s``."""
        self._still_since, self._period, self._prev = None, None, None
        self._test.forget()
        if self._empty_since is None:  # it just became empty
            self._empty_since = t
            self._gain[:] = 1.0  # the gains were of a load that is gone
        self._returned = True
        if not (self.zero and self.converter is not None and raw is not None):
            return
        if t - self._empty_since < self.settle_s:
            return
        r = np.ascontiguousarray(np.asarray(raw, dtype=np.float64).reshape(1, -1))
        u = self.converter.run(r, np.ascontiguousarray(ok.reshape(1, -1)))[0] - self._u_rest
        good = ok & np.isfinite(u)
        if self._set is None or not self._zeroing:
            self._set = np.where(good, u, np.nan)
            self._zeroing = True
        else:
            a = 1.0 - np.exp(-dt / self.update_s) if dt > 0 else 0.0
            fresh = good & np.isnan(self._set)
            self._set[fresh] = u[fresh]
            keep = good & ~fresh
            self._set[keep] += a * (u[keep] - self._set[keep])
        self.state.zeroed_t = t

    def _take_zero(self) -> None:
        """The set an empty mat showed becomes every measured element's creep."""
        st = self.state
        got = np.isfinite(self._set) if self._set is not None else None
        if got is None or not got.any():
            return
        # an element whose creep was read while loaded keeps it: the set an unloaded spacer
        # keeps is not the creep it shows loaded again (on the textile law taking it made
        # hours 5-8 of a night worse by 10-20 points, docs/drift.md)
        got &= ~st.read
        assert self._set is not None
        st.creep[got] = np.clip(self._set[got], -self.max_creep_mm, self.max_creep_mm)
        st.read[got] = True
        st.at_read[got] = st.exposure[got]
        st.zeroed += 1
        self._set = None
        self._gain[:] = 1.0
        self._still_since = None

    def _moved(self, c: np.ndarray, ok: np.ndarray) -> bool:
        """Whether the load moved since the previous frame by more than ``motion`` of it,
        summed over small blocks (an element not measured keeps its last value)."""
        if self._prev is not None:
            c = np.where(ok, c, self._prev[0])
        blocks = np.bincount(self._blocks, weights=self.area * c, minlength=self._n_blocks)
        moved = True
        if self._prev is not None:
            scale = max(float(np.abs(blocks).sum()), self._floor_n)
            moved = float(np.abs(blocks - self._prev[1]).sum()) > self.motion * scale
        self._prev = (c, blocks)
        return moved

    def _still(self, x0: np.ndarray, c: np.ndarray, ok: np.ndarray, t: float) -> np.ndarray:
        """A settled still frame: sum it up; every ``update_s`` read the creep."""
        per = self._period
        if per is None:  # the period's reference: the loaded elements and their values
            if self.predict and self._predict_unread(x0, ok):
                c = self._refresh(x0)
            if self.weigh and self._weigh(x0, c, ok, t):
                c = self._refresh(x0)
            loaded = ok & (c > self.loaded_ncm2)
            self._period = {
                "loaded": loaded,
                "ref": np.where(loaded, c, 0.0),
                "t": t,
                "last": t,
                "sum": np.zeros(c.size),
                "n": np.zeros(c.size),
                "moved": 0.0,
                "cum": np.zeros(c.size),
                "creep0": self.state.creep.copy(),
                "still0": self.state.still_s,
            }
            return c
        per["sum"] += np.where(ok, c, 0.0)
        per["n"] += ok
        if t - per["last"] < self.update_s:
            return c
        return self._read_creep(x0, c, ok, t)

    def _read_creep(self, x0: np.ndarray, c: np.ndarray, ok: np.ndarray, t: float) -> np.ndarray:
        """The creep of the period's loaded elements from the mean since the last reading."""
        per = self._period
        assert per is not None
        seen = per["n"] > 0
        mean = np.where(seen, per["sum"] / np.where(seen, per["n"], 1), 0.0)
        mask = per["loaded"] & seen
        ref = per["ref"]
        elapsed = t - per["last"]
        self.state.exposure += np.clip(mean, 0.0, None) * elapsed
        total_ref = float(self.area[mask] @ ref[mask])
        change = float(self.area[mask] @ (mean[mask] - ref[mask])) / max(total_ref, 1e-12)
        per["moved"] += change
        per["last"], per["sum"][:], per["n"][:] = t, 0.0, 0
        if abs(per["moved"]) > self.max_rate * (t - per["t"]) + LOAD_SLACK:
            # faster than drift: a load change, also what was read of it; start again
            self.state.refused += 1
            self.state.creep[:] = per["creep0"]
            self.state.still_s = per["still0"]
            self._period = None
            return self._refresh(x0)
        rel = np.where(mask, mean / np.where(mask, ref, 1.0) - 1.0, 0.0)
        per["cum"] += rel  # an element changing faster than drift is not drifting
        fast = np.abs(per["cum"]) > self.max_rate * (t - per["t"]) + ELEMENT_SLACK
        per["loaded"] &= ~fast
        mask &= ~fast
        st = self.state
        shift = rel[mask] * ref[mask] / self._slope(mean[mask])
        st.creep[mask] = np.clip(st.creep[mask] + shift, -self.max_creep_mm, self.max_creep_mm)
        st.read[mask] = True
        st.at_read[mask] = st.exposure[mask]
        st.still_s += elapsed
        st.first_t = t if st.first_t is None else st.first_t
        st.last_t = t
        out = self._refresh(x0)
        pos = ok & (x0 > 0)
        before = float(self.area[pos] @ x0[pos])
        if before > 0:
            st.load_correction = float(self.area[pos] @ out[pos]) / before - 1.0
        return out

    def total(self, c: np.ndarray, ok: np.ndarray) -> float:
        """The load on the mat (N): measured elements as read, every other element the mean of
        its measured neighbours (a frame misses 15-20 % of its elements on the virtual bed)."""
        v = np.where(ok, c, 0.0)
        s = np.bincount(self._nb_owner, weights=v[self._nb_index], minlength=v.size)
        n = np.bincount(self._nb_owner, weights=ok[self._nb_index], minlength=v.size)
        fill = np.where(n > 0, s / np.maximum(n, 1), 0.0)
        return float(self.area @ np.where(ok, v, fill))

    def _weigh(self, x0: np.ndarray, c: np.ndarray, ok: np.ndarray, t: float) -> bool:
        """At the start of a still period: a still person weighs what they weighed in the
        first still period (the weight). A load off by no more than drift can make since then
        (``weigh_rate`` per hour, at most ``weigh_max``) checks the correction; a heavier one is
        brought back to it by creep shared in proportion to the loaded elements' readings (a
        lighter one too with ``weigh_up``); a larger change is a load change (after an empty
        mat: another occupant, weighed anew). True when a creep changed."""
        st = self.state
        load = self.total(c, ok)
        if load <= self._floor_n:
            return False
        returned, self._returned = self._returned, False
        if st.weight is None or st.weight_t is None:
            st.weight, st.weight_t = load, t
            st.checked_t = t
            return False
        r = load / st.weight - 1.0
        window = min(self.weigh_max, LOAD_SLACK / 3 + self.weigh_rate * (t - st.weight_t))
        if returned and r > 0:
            # back on a mat that was empty, a person's spacer shows at once the creep it
            # gathered since the weight was taken (the set kept through the empty minutes),
            # not the drift of a still load since then: heavier by up to weigh_max is creep
            window = self.weigh_max
        if abs(r) > window:
            if returned:
                st.weight, st.weight_t = load, t
                st.checked_t = t
            return False
        st.checked_t = t
        if abs(r) < 0.005 or (r < 0 and not self.weigh_up):
            return False
        sel = ok & (c > self.loaded_ncm2)
        u_now = np.interp(c[sel], self._p, self._u)
        u_new = np.interp(c[sel] / (1.0 + r), self._p, self._u)
        st.creep[sel] = np.clip(
            st.creep[sel] + u_now - u_new, -self.max_creep_mm, self.max_creep_mm
        )
        st.weighed += 1
        return True

    def _predict_unread(self, x0: np.ndarray, ok: np.ndarray) -> bool:
        """At the start of a still period: the creep of elements never read (module
        documentation), from ``creep = a · exposure^b`` fitted on the read ones (b from 0.25,
        0.5, 0.75, 1 by least squares, a >= 0); read elements gain the law's growth since
        their last reading. True when a creep changed."""
        st = self.state
        fit = st.read & (st.creep > 1e-4)
        if np.count_nonzero(fit) < 20:
            return False
        e_r, y = st.at_read[fit], st.creep[fit]
        best: tuple[float, float, float] | None = None
        for b in (0.25, 0.5, 0.75, 1.0):
            xb = e_r**b
            a = max(float(xb @ y) / max(float(xb @ xb), 1e-300), 0.0)
            res = float(np.sum((y - a * xb) ** 2))
            if best is None or res < best[0]:
                best = (res, a, b)
        assert best is not None
        _, a, b = best
        st.law = (a, b)
        now = a * st.exposure**b
        grow = st.read & ok
        st.creep[grow] += np.maximum(now[grow] - a * st.at_read[grow] ** b, 0.0)
        new = ok & ~st.read & (x0 > self.loaded_ncm2)
        st.creep[new] = now[new]
        changed = grow | new
        np.clip(st.creep, -self.max_creep_mm, self.max_creep_mm, out=st.creep)
        st.at_read[changed] = st.exposure[changed]
        return bool(changed.any())

    def run(
        self,
        frames: npt.ArrayLike,
        valid: npt.ArrayLike,
        times: npt.ArrayLike,
        raw: np.ndarray | None = None,
    ) -> np.ndarray:
        """Frames (T, N) with their validity at ``times`` (and the raw readings, for the zero
        of an empty mat) -> corrected frames (continues the stream); ``corrections_`` holds the
        load correction after every frame."""
        x = np.asarray(frames, dtype=np.float64)
        ok = np.asarray(valid, dtype=bool)
        t = np.asarray(times, dtype=np.float64)
        if x.shape[0] == 1:  # a frame of a stream (Pipeline.step): no per-frame loop
            t0 = float(t[0])
            out = self.step(x[0], ok[0], t0, None if raw is None else raw[0])[None, :]
            on = self.state.first_t is not None
            self.corrections_ = np.array([self.state.load_correction if on else np.nan])
            self.ages_ = np.array([self.state.age_h(t0) if on else np.nan])
            return out
        out = np.empty_like(x)
        #: the load correction after every frame of the last run (NaN: not correcting yet)
        self.corrections_ = np.full(x.shape[0], np.nan)
        #: hours since the correction was last checked against the weight after every frame
        self.ages_ = np.full(x.shape[0], np.nan)
        for k in range(x.shape[0]):
            out[k] = self.step(x[k], ok[k], float(t[k]), None if raw is None else raw[k])
            if self.state.first_t is not None:
                self.corrections_[k] = self.state.load_correction
                self.ages_[k] = self.state.age_h(float(t[k]))
        return out
