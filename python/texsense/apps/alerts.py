"""Pressure-exposure and reposition alerts (thesis §1.1: tissue pressure above 32 mmHg held
for 5-20 min obstructs the blood flow; decubitus prevention).

:class:`ExposureTracker` follows, per element (or per region), how long the pressure has been
above a threshold. Time above the threshold accumulates while the element stays loaded; short
reliefs do not reset it (the tissue does not recover in a few seconds); an element below the
threshold for ``offload_s`` without interruption starts again from zero. When the exposure of
any element reaches ``reposition_s``, a *reposition* alert opens. It stays open until every
exposed element has been offloaded (then it is *cleared*); acknowledging it silences it but
does not clear it, and no second reposition alert opens while one is open.

A tracker's state (:meth:`ExposureTracker.state`: the exposure and relief of every exposed
element, whether the mat is loaded, the open alert) is JSON-ready and small: what a recording
started on a live mat stores, so that its review goes on from where the monitor was, and what a
station of a group hands over when it takes over a mat (docs/station.md, "A group of
stations"); another tracker of the same layout goes on from it (:meth:`ExposureTracker.restore`);
a turn on a bed hands the exposure to new skin (:meth:`ExposureTracker.turned`); a mat that still
carries its calibration load is not a person (:meth:`ExposureTracker.wait_for_empty`).

Examples
--------
>>> import numpy as np
>>> from texsense import Layout
>>> tr = ExposureTracker(Layout.grid(1, 2), threshold=32, unit="mmHg", reposition_min=5)
>>> events = []
>>> for t in range(0, 301, 10):  # 5 min at 1 N/cm² (75 mmHg) on element 0
...     events += tr.step(np.array([1.0, 0.0]), float(t))
>>> [(e.kind, e.t) for e in events], tr.exposure_s.tolist()
([('seated', 0.0), ('reposition', 300.0)], [300.0, 0.0])
"""

from __future__ import annotations

import base64
import copy
import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense._core import exposure_advance as _exposure_advance
from texsense.data import stored, units
from texsense.data.layout import Layout
from texsense.exceptions import ParameterError

__all__ = ["REPOSITION_RANGE_MIN", "Alert", "Event", "ExposureTracker", "frame_time"]

#: Allowed reposition intervals, minutes (§1.1: 5-20 min obstruct the blood flow; bed-care
#: turning schedules reach 2 h).
REPOSITION_RANGE_MIN = (5.0, 120.0)
#: What an alert says of its places with bounds (:attr:`Alert.certainty`).
CERTAINTIES = ("confident", "possible")


def frame_time(t: object) -> float:
    """The time argument of a tracker's ``step(..., t)``, checked: a number (a value in its
    place means the call has the arguments of before, time first)."""
    if isinstance(t, bool) or not isinstance(t, int | float | np.floating | np.integer):
        raise TypeError(
            f"step(..., t): the time comes last and is a number, got {type(t).__name__}"
        )
    return float(t)


@dataclass
class Event:
    """Something the monitor reports: ``kind`` is ``reposition`` (an alert opened),
    ``cleared`` (it ended: the exposed skin was offloaded), ``acknowledged``, or the load
    appearing / disappearing in the mode's words (``seated`` / ``left`` on a seat, ``in-bed``
    / ``out-of-bed`` on a bed, ``loaded`` / ``unloaded`` otherwise)."""

    kind: str
    t: float
    alert_id: int | None = None
    detail: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"kind": self.kind, "t": self.t, "alert_id": self.alert_id, "detail": self.detail}


@dataclass
class Alert:
    """An open or closed reposition alert."""

    id: int
    opened_t: float
    elements: list[int]  # element (or region) indices over the limit when it opened
    peak_exposure_s: float
    acknowledged_t: float | None = None
    cleared_t: float | None = None
    #: where, in words: the anatomical regions (or seat zones) the mode knows; empty when it
    #: knows none (a mat whose orientation is unknown)
    where: list[str] = field(default_factory=list)
    #: the places no region names, as rows and columns (the alert's details line)
    details: list[str] = field(default_factory=list)
    #: wall clock (Unix s) when it opened, when the monitor knows it
    opened_wall: float | None = None
    #: why it cleared: ``offloaded`` or ``turned``
    cleared_by: str | None = None
    #: with bounds: "confident" (above the threshold with the bounds' confidence: the lower
    #: bound is above it) or "possible" (only the upper bound is; counted only when the user
    #: chose so); None without bounds
    certainty: str | None = None

    @property
    def active(self) -> bool:
        """Open and not acknowledged: the banner shows."""
        return self.cleared_t is None and self.acknowledged_t is None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "id": self.id,
            "opened_t": self.opened_t,
            "elements": self.elements,
            "peak_exposure_s": self.peak_exposure_s,
            "acknowledged_t": self.acknowledged_t,
            "cleared_t": self.cleared_t,
            "active": self.active,
            "where": self.where,
            "details": self.details,
            "opened_wall": self.opened_wall,
            "cleared_by": self.cleared_by,
            "certainty": self.certainty,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], places: int | None = None) -> Alert:
        """The alert of :meth:`to_dict` (a recording's or a checkpoint's stored state; each
        value of the type it must have, its elements within ``places``, or a
        :class:`ParameterError` naming it)."""
        what = "alert"
        return cls(
            stored.whole(d, "id", what, lo=1),
            stored.number(d, "opened_t", what),
            stored.wholes(d, "elements", what, hi=places),
            stored.number(d, "peak_exposure_s", what, lo=0),
            stored.optional_number(d, "acknowledged_t", what),
            None,
            stored.texts(d, "where", what, default=[]),
            stored.texts(d, "details", what, default=[]),
            stored.optional_number(d, "opened_wall", what),
            certainty=stored.optional_text(d, "certainty", what, choices=CERTAINTIES),
        )


class ExposureTracker:
    """Per-element (or per-region) pressure exposure and the reposition alert.

    Parameters
    ----------
    layout : Layout
        The sensor's elements.
    threshold : float
        Pressure above which tissue counts as exposed, in ``unit`` (default 32 mmHg).
    unit : str
        Any pressure unit of :mod:`texsense.data.units`.
    reposition_min : float
        Exposure after which the reposition alert opens, minutes (5-120, default 20).
    offload_min : float
        Time below the threshold that resets an element's exposure, minutes (default 1).
    regions : dict of name -> element indices, optional
        Track the mean pressure of each region instead of single elements (e.g.
        ``layout.equal_areas(16)``); the exposure map then repeats a region's value on its
        elements.
    occupancy : (str, str) or None
        Event kinds when the mat becomes loaded / unloaded (default ``seated`` / ``left``);
        None: no such events (a foot sensor, loaded at every step).
    occupancy_hold_s : float
        A change of occupancy is reported once it has held this long (default 0: at once).
    count_possible : bool
        With bounds (:meth:`step` ``lower``/``upper``): count an element that is only
        *possibly* above the threshold (its upper bound is, its lower bound is not) toward the
        reposition alert too (default: only those above it with the bounds' confidence).
    """

    #: A step of single elements (no regions) in one compiled pass
    #: (``texsense._core.exposure_advance``; False: the numpy reference, the same bits, tested).
    compiled = True

    def __init__(
        self,
        layout: Layout,
        *,
        threshold: float = 32.0,
        unit: str = "mmHg",
        reposition_min: float = 20.0,
        offload_min: float = 1.0,
        regions: dict[str, npt.ArrayLike] | None = None,
        occupancy: tuple[str, str] | None = ("seated", "left"),
        occupancy_hold_s: float = 0.0,
        count_possible: bool = False,
    ) -> None:
        if not units.is_pressure_unit(unit):
            raise ParameterError(f"threshold unit {unit!r} is not a pressure unit")
        if not np.isfinite(threshold) or threshold <= 0:
            raise ParameterError(f"threshold must be > 0, got {threshold}")
        lo, hi = REPOSITION_RANGE_MIN
        if not lo <= reposition_min <= hi:
            raise ParameterError(
                f"reposition interval must lie in {lo:g}-{hi:g} min, got {reposition_min}"
            )
        if not np.isfinite(offload_min) or offload_min < 0:
            raise ParameterError(f"offload time must be >= 0 min, got {offload_min}")
        self.layout = layout
        self.threshold_ncm2 = float(units.convert(threshold, unit, "N/cm2"))
        self.threshold, self.unit = float(threshold), units.canonical(unit)
        self.reposition_s = 60.0 * float(reposition_min)
        self.offload_s = 60.0 * float(offload_min)
        if regions is None:
            self._groups: list[np.ndarray] | None = None
            self.names = [str(i) for i in range(layout.n_elements)]
        else:
            self._groups = [np.asarray(v, dtype=np.int64) for v in regions.values()]
            for name, g in zip(regions, self._groups, strict=True):
                if g.size == 0 or g.min() < 0 or g.max() >= layout.n_elements:
                    raise ParameterError(f"region {name!r} has no elements or bad indices")
            self.names = [str(k) for k in regions]
        n = len(self.names)
        self.exposure_s = np.zeros(n)
        self._relief_s = np.zeros(n)
        self._loaded_last = np.zeros(n, bool)  # the state of the last step
        self._last_t: float | None = None
        self._ids = itertools.count(1)
        self.alerts: list[Alert] = []
        self.seated = False
        self.occupancy = occupancy
        self.occupancy_hold_s = float(occupancy_hold_s)
        self._occupancy_since: float | None = None  # when the load last changed state
        self.count_possible = bool(count_possible)
        #: with bounds, per element (or region) of the last frame: above the threshold with
        #: the bounds' confidence, and only possibly above it
        self.confident = np.zeros(n, bool)
        self.possible = np.zeros(n, bool)
        self.waiting_empty = False  # a calibration load on the mat: nothing counts yet
        self.hold = False  # no new alert this frame (a bed's turn is being confirmed)

    @property
    def open_alert(self) -> Alert | None:
        """The alert not yet cleared, if any."""
        return next((a for a in self.alerts if a.cleared_t is None), None)

    @property
    def by_region(self) -> bool:
        """True when the tracker follows regions (its indices and names are the regions')."""
        return self._groups is not None

    def exposure_map(self) -> np.ndarray:
        """Exposure in seconds per element (a region's value on each of its elements)."""
        if self._groups is None:
            return self.exposure_s.copy()
        out = np.zeros(self.layout.n_elements)
        for g, v in zip(self._groups, self.exposure_s, strict=True):
            out[g] = np.maximum(out[g], v)
        return out

    def _values(self, pressure: np.ndarray) -> np.ndarray:
        p = np.where(np.isnan(pressure), 0.0, pressure)  # (what it is compared with:
        if self._groups is None:  # an infinity needs no nan_to_num's largest float)
            return p
        return np.array([p[g].mean() for g in self._groups])

    def step(
        self,
        pressure_ncm2: npt.ArrayLike,
        t: float,
        lower: npt.ArrayLike | None = None,
        upper: npt.ArrayLike | None = None,
        *,
        skipped: bool = False,
    ) -> list[Event]:
        """Advance to time ``t`` (s) with the pressure (N/cm²) of every element; returns the
        events this frame caused. A missing (NaN) reading counts as unloaded. (Time after the
        values, as a stage's ``step(values, valid, t)``.) With the bounds ``lower`` and
        ``upper`` (issue 37) an element is above the threshold when its lower bound is,
        *possibly* above when only its upper bound is (counted with ``count_possible``).
        ``skipped``: frames since the last step were not read (a station behind skims them, a
        takeover, frames lost on the way), so what happened between the two frames read is not
        known: that time counts as loaded for an element loaded at either of them, never as
        relief (otherwise the time since the last step counts in this frame's state, as
        between two frames in a row). So an element's exposure is never below that of reading
        every frame, unless a load came and went wholly inside the frames not read, and an
        alert is never later but for the frames not read (docs/station.md, "What is lost at
        worst")."""
        t = frame_time(t)
        p = np.asarray(pressure_ncm2, dtype=np.float64)
        if p.shape != (self.layout.n_elements,):
            raise ParameterError(
                f"expected {self.layout.n_elements} pressures, got shape {p.shape}"
            )
        if self._last_t is not None and t < self._last_t:
            raise ParameterError(f"time went backwards: {t} after {self._last_t}")
        dt = 0.0 if self._last_t is None else t - self._last_t
        self._last_t = t
        events: list[Event] = []
        if self.compiled and self._groups is None and not self.waiting_empty:
            any_load, n_over, top = self._advance_compiled(p, lower, upper, dt, skipped)
        else:
            if self.waiting_empty:  # the calibration load: no person, no exposure, no events
                if (self._values(p) > self.threshold_ncm2).any():
                    return events
                self.waiting_empty, self.seated = False, False
            any_load = self._loaded_step(p, lower, upper, dt, skipped)
            n_over, top = -1, float(self.exposure_s.max())
        events += self._occupancy(t, any_load)
        alert = self.open_alert
        if alert is None:
            over = np.flatnonzero(self.exposure_s >= self.reposition_s) if n_over else None
            if over is not None and over.size and not self.hold:
                alert = Alert(next(self._ids), t, over.tolist(), float(self.exposure_s.max()))
                detail: dict[str, Any] = {"where": [self.names[i] for i in over]}
                if lower is not None and upper is not None:
                    alert.certainty = "confident" if self.confident[over].any() else "possible"
                    detail["certainty"] = alert.certainty
                self.alerts.append(alert)
                events.append(Event("reposition", t, alert.id, detail))
        else:
            alert.peak_exposure_s = max(alert.peak_exposure_s, top)
            if not np.any(self.exposure_s[alert.elements] > 0):
                alert.cleared_t, alert.cleared_by = t, "offloaded"
                events.append(Event("cleared", t, alert.id, {"by": "offloaded"}))
        return events

    def _loaded_step(
        self,
        p: np.ndarray,
        lower: npt.ArrayLike | None,
        upper: npt.ArrayLike | None,
        dt: float,
        skipped: bool,
    ) -> bool:
        """Which places are loaded and their exposure advanced over ``dt`` (numpy: the
        reference of the compiled step); True when any is loaded."""
        loaded = self._values(p) > self.threshold_ncm2
        if lower is not None and upper is not None:
            self.confident = self._values(np.asarray(lower, np.float64)) > self.threshold_ncm2
            self.possible = (
                self._values(np.asarray(upper, np.float64)) > self.threshold_ncm2
            ) & ~self.confident
            loaded = self.confident | (self.possible & self.count_possible)
        # frames not read: the time between is loaded where either frame read is, never relief
        self._advance(loaded | self._loaded_last if skipped else loaded, dt)
        self._loaded_last = loaded
        return bool(loaded.any())

    def _advance_compiled(
        self,
        p: np.ndarray,
        lower: npt.ArrayLike | None,
        upper: npt.ArrayLike | None,
        dt: float,
        skipped: bool,
    ) -> tuple[bool, int, float]:
        """:meth:`_loaded_step` of single elements in one compiled pass, in place
        (``texsense._core.exposure_advance``: the same bits); also how many elements have
        reached the reposition time and the largest exposure."""
        bounded = lower is not None and upper is not None
        lo = np.ascontiguousarray(lower, np.float64) if bounded else None
        hi = np.ascontiguousarray(upper, np.float64) if bounded else None
        for name in ("confident", "possible", "_loaded_last"):  # owned, as the core writes them
            a = getattr(self, name)
            if not (a.flags.c_contiguous and a.flags.writeable and a.dtype == bool):
                setattr(self, name, np.array(a, dtype=bool))
        return _exposure_advance(np.ascontiguousarray(p), lo, hi, self.threshold_ncm2,
                                 self.count_possible, self.offload_s, self.reposition_s, dt,
                                 bool(skipped), self.exposure_s, self._relief_s,
                                 self._loaded_last, self.confident, self.possible)  # fmt: skip

    def _advance(self, loaded: np.ndarray, dt: float | np.ndarray) -> None:
        """``dt`` (s, per element or one for all) in the state ``loaded``: exposure grows
        while loaded, relief time while not; a relief of ``offload_s`` resets the exposure
        (masked ufuncs: the same sums as masked assignments, without gathering)."""
        np.add(self.exposure_s, dt, out=self.exposure_s, where=loaded)
        np.copyto(self._relief_s, 0.0, where=loaded)
        np.add(self._relief_s, dt, out=self._relief_s, where=~loaded)
        np.copyto(self.exposure_s, 0.0, where=self._relief_s >= self.offload_s)

    def turned(self, t: float, since_t: float) -> list[Event]:
        """A bed's turn that began at ``since_t`` is confirmed at ``t``: other skin now lies on
        the mat, so no element has been exposed longer than ``t - since_t``, and an open alert
        clears (by the turn)."""
        np.minimum(self.exposure_s, max(t - since_t, 0.0), out=self.exposure_s)
        alert = self.open_alert
        if alert is None:
            return []
        alert.cleared_t, alert.cleared_by = t, "turned"
        return [Event("cleared", t, alert.id, {"by": "turned"})]

    def wait_for_empty(self) -> None:
        """Count nothing until the mat has been seen empty: what lies on it now is the load a
        calibration was made with, not a person (no *seated*, no exposure)."""
        self.waiting_empty = True
        self.exposure_s[:] = 0.0

    def state(self) -> dict[str, Any]:
        """What the tracker knows now, JSON-ready and compact: the time of the last frame,
        per exposed element (or region) ``[index, exposure s, relief s]``, whether the mat
        is loaded, and the open alert (see :meth:`restore`)."""
        exposed = np.flatnonzero(self.exposure_s > 0)
        relief = np.minimum(self._relief_s, self.offload_s)
        return self._state_with([
            [int(i), round(float(self.exposure_s[i]), 3), round(float(relief[i]), 3)]
            for i in exposed
        ])  # fmt: skip

    def state_packed(self) -> dict[str, Any]:
        """:meth:`state` with the exposed places as arrays' bytes, exact and cheap to make: a
        station checkpoints hundreds of mats of 1024 elements a second, and :meth:`state`'s
        rows (a Python float per element, then their JSON) took most of its event loop.
        ``exposed`` is ``{"index": ..., "exposure_s": ..., "relief_s": ...}``, base64 of
        little-endian int32, float64, float64 (:meth:`restore` reads both forms)."""
        exposed = np.flatnonzero(self.exposure_s > 0)
        relief = np.minimum(self._relief_s[exposed], self.offload_s)
        head = copy.deepcopy(self._state_with(None))
        head["exposed"] = {
            "index": _b64(exposed.astype("<i4")),
            "exposure_s": _b64(self.exposure_s[exposed].astype("<f8")),
            "relief_s": _b64(relief.astype("<f8")),
        }
        return head

    def _state_with(self, exposed: list[list[Any]] | None) -> dict[str, Any]:
        alert = self.open_alert
        return {
            "t": self._last_t,
            "by": "region" if self._groups is not None else "element",
            "size": len(self.names),
            "exposed": exposed,
            "loaded": self.seated,
            "waiting_empty": self.waiting_empty,
            "alert": None if alert is None else alert.to_dict(),
            "next_id": max((a.id for a in self.alerts), default=0) + 1,
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Go on from a :meth:`state` (of a tracker of the same layout and regions); a state
        that does not fit raises :class:`ParameterError` naming what."""
        what = "exposure state"
        size = stored.whole(state, "size", what)
        if size != len(self.names):
            raise ParameterError(
                f"the stored exposure state is of {size} places, the tracker has {len(self.names)}"
            )
        try:
            index, exposure, relief = _exposed_arrays(state["exposed"])
        except (KeyError, TypeError, ValueError, OverflowError) as e:
            raise ParameterError(f"the stored exposure state lacks or mangles {e}") from None
        if np.any((index < 0) | (index >= size)):
            raise ParameterError(f"the stored exposure state names places beyond its {size}")
        times = np.concatenate([exposure, relief])
        if not np.all(np.isfinite(times) & (times >= 0)):
            raise ParameterError("the stored exposure state has a time that is not finite or < 0")
        t = stored.optional_number(state, "t", what)
        next_id = stored.whole(state, "next_id", what, lo=1, default=1)
        seated = stored.flag(state, "loaded", what, default=False)
        waiting_empty = stored.flag(state, "waiting_empty", what, default=False)
        alert = state.get("alert")
        if alert is not None:
            alert = Alert.from_dict(stored.mapping(state, "alert", what), places=size)
        self.exposure_s[:] = 0.0
        self._relief_s[:] = self.offload_s
        self.exposure_s[index], self._relief_s[index] = exposure, relief
        self._loaded_last = self._relief_s == 0.0  # (loaded at its last step: no relief)
        self._last_t = t
        self.seated = seated
        self._occupancy_since = None
        self.waiting_empty = waiting_empty
        self.alerts = []
        if alert is not None:
            self.alerts.append(alert)
            next_id = max(next_id, alert.id + 1)
        self._ids = itertools.count(next_id)

    def adopt(self, alert: Alert) -> None:
        """Take ``alert`` as this tracker's own open alert (one raised by another holder of
        the mat, read back from the event store after a takeover): the next alert's id comes
        after it, so no id is given twice."""
        self.alerts.append(alert)
        self._ids = itertools.count(max(next(self._ids), alert.id + 1))

    def _occupancy(self, t: float, any_load: bool) -> list[Event]:
        """The load appearing or disappearing, once the change has held ``occupancy_hold_s``."""
        if any_load == self.seated:
            self._occupancy_since = None
            return []
        if self._occupancy_since is None:
            self._occupancy_since = t
        if t - self._occupancy_since < self.occupancy_hold_s:
            return []
        self.seated, self._occupancy_since = any_load, None
        if self.occupancy is None:
            return []
        return [Event(self.occupancy[0] if any_load else self.occupancy[1], t)]

    def acknowledge(self, alert_id: int, t: float) -> Event:
        """Silence an alert (it stays open until the skin is offloaded)."""
        for a in self.alerts:
            if a.id == alert_id:
                if a.acknowledged_t is None:
                    a.acknowledged_t = float(t)
                return Event("acknowledged", float(t), a.id)
        raise ParameterError(f"no alert with id {alert_id}")


def _b64(a: np.ndarray) -> str:
    return base64.b64encode(a.tobytes()).decode("ascii")


def _exposed_arrays(exposed: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The exposed places of a stored state (rows ``[index, exposure s, relief s]`` or
    :meth:`ExposureTracker.state_packed`'s arrays) as three arrays of one length."""
    if isinstance(exposed, dict):
        arrays = [np.frombuffer(base64.b64decode(exposed[k], validate=True), dtype)
                  for k, dtype in (("index", "<i4"), ("exposure_s", "<f8"),
                                   ("relief_s", "<f8"))]  # fmt: skip
        if len({a.size for a in arrays}) != 1:
            raise ValueError("exposed arrays of different lengths")
        index, exposure, relief = arrays
        return index.astype(np.intp), exposure.astype(np.float64), relief.astype(np.float64)
    rows = np.asarray([(int(i), float(e), float(r)) for i, e, r in exposed], np.float64)
    rows = rows.reshape(-1, 3)
    return rows[:, 0].astype(np.intp), rows[:, 1], rows[:, 2]
