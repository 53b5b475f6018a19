"""The in-use drift estimator's state (:mod:`texsense.compensation.inuse`): what it knows of
one mat — the creep of every element and how it came to them, the weight of a still person and
when the correction was last checked — small, shown on the dashboard, kept in recordings'
metadata and checkpoints (``to_dict``/``from_dict``).

Examples
--------
>>> import numpy as np
>>> st = InUseState(np.zeros(4))
>>> st.status()["state"], InUseState.from_dict(st.to_dict(), 4).creep.size
('waiting for stillness', 4)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from texsense.exceptions import ParameterError

__all__ = ["InUseState"]


@dataclass
class InUseState:
    """What the in-use estimator knows: the creep of every element and how it
    came to them (small: two numbers per element; ``to_dict``/``from_dict`` for checkpoints)."""

    creep: np.ndarray  # (N,) in the hysteresis stage's input unit (mm)
    still_s: float = 0.0  # still time the creep was read from (s)
    first_t: float | None = None  # when the creep was first changed
    last_t: float | None = None  # when the creep was last changed
    zeroed_t: float | None = None  # when an empty mat last gave the creep
    zeroed: int = 0  # how many empty periods gave the creep
    refused: int = 0  # still periods refused (their load changed faster than drift can)
    load_correction: float = 0.0  # the correction of the present load (share, -0.12: 12 % less)
    exposure: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (N,) ∫ p dt, N/cm² s
    read: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))  # (N,) creep was read
    law: tuple[float, ...] | None = None  # creep = a · exposure^b fitted on the read ones
    at_read: np.ndarray = field(default_factory=lambda: np.zeros(0))  # exposure when last set
    weight: float | None = None  # the still load the mat carries (N), from the first still period
    weight_t: float | None = None  # when it was taken
    weighed: int = 0  # still periods whose load was brought back to it
    checked_t: float | None = None  # when a still load last agreed with the weight

    def __post_init__(self) -> None:
        n = self.creep.size
        if self.exposure.size != n:
            self.exposure = np.zeros(n)
        if self.read.size != n:
            self.read = np.zeros(n, bool)
        if self.at_read.size != n:
            self.at_read = np.zeros(n)

    def age_h(self, t: float) -> float:
        """Hours at ``t`` since the correction was last checked: a still load agreed with the
        weight (or the weight was taken), else since the first correction (0 before it)."""
        since = self.checked_t if self.checked_t is not None else self.first_t
        return 0.0 if since is None else max(t - since, 0.0) / 3600.0

    def status(self, t: float | None = None) -> dict[str, Any]:
        """The state in words and numbers (dashboard, metadata, report); at ``t`` (the last
        frame's time) also ``checked_age_s``, the age the bounds are widened by (:meth:`age_h`)."""
        state = "waiting for stillness" if self.first_t is None else "correcting"
        age = None if t is None or self.first_t is None else round(3600.0 * self.age_h(t), 1)
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
            "weight_n": None if self.weight is None else round(float(self.weight), 1),
            "weighed": self.weighed,
            "checked_t": self.checked_t,
            "checked_age_s": age,
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-able."""
        return {
            "creep": np.asarray(self.creep, float).tolist(),
            "still_s": self.still_s,
            "first_t": self.first_t,
            "last_t": self.last_t,
            "zeroed_t": self.zeroed_t,
            "zeroed": self.zeroed,
            "refused": self.refused,
            "load_correction": self.load_correction,
            "exposure": np.asarray(self.exposure, float).tolist(),
            "read": np.asarray(self.read, bool).tolist(),
            "at_read": np.asarray(self.at_read, float).tolist(),
            "law": None if self.law is None else list(self.law),
            "weight": self.weight,
            "weight_t": self.weight_t,
            "weighed": self.weighed,
            "checked_t": self.checked_t,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], n_elements: int | None = None) -> InUseState:
        """Inverse of :meth:`to_dict`; ``n_elements`` checks the size."""
        try:
            creep = np.asarray(d["creep"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as e:
            raise ParameterError(f"in-use drift state: the creep: {e}") from None
        if creep.ndim != 1:
            raise ParameterError("in-use drift state: creep must be a list of numbers")
        if n_elements is not None and creep.size != n_elements:
            raise ParameterError(
                f"in-use drift state of {creep.size} elements, the mat has {n_elements}"
            )
        if not np.all(np.isfinite(creep)):
            raise ParameterError("in-use drift state: creep must be numbers")
        times = ("first_t", "last_t", "zeroed_t", "weight", "weight_t", "checked_t")
        opt = {k: d.get(k) for k in times}
        exposure = np.asarray(d.get("exposure", np.zeros(creep.size)), dtype=np.float64)
        read = np.asarray(d.get("read", np.zeros(creep.size, bool)), dtype=bool)
        at_read = np.asarray(d.get("at_read", np.zeros(creep.size)), dtype=np.float64)
        law = d.get("law")
        if not exposure.shape == read.shape == at_read.shape == creep.shape:
            raise ParameterError("in-use drift state: exposure and read need one value per element")
        return cls(
            creep,
            float(d.get("still_s", 0.0)),
            zeroed=int(d.get("zeroed", 0)),
            refused=int(d.get("refused", 0)),
            weighed=int(d.get("weighed", 0)),
            load_correction=float(d.get("load_correction", 0.0)),
            exposure=exposure,
            read=read,
            at_read=at_read,
            law=None if law is None else (float(law[0]), float(law[1])),
            **{k: None if v is None else float(v) for k, v in opt.items()},
        )
