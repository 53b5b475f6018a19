"""Element failures of a textile sensor (thesis §6.5.2.5).

Conductive lint and imperfect connections short or break elements; a shorted or broken
element reads 0 pF. The thesis's seat had 12 of 96 elements failing permanently, and others
failing now and then — more often where the layers are pressed together — so that 50-57 % of
the elements failed at least once during a session.

:class:`FailureModel` draws permanent failures, and intermittent failure episodes for a
susceptible share of the elements with an onset rate that grows with the local pressure and
exponentially distributed durations. A :class:`FailureState` carries the failed elements and
the open episodes from one call to the next, so that a mat scanned frame by frame (a live
virtual source) keeps its broken elements broken, and an episode runs on across frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError

__all__ = ["FailureModel", "FailureState"]


@dataclass
class FailureState:
    """What a mat's failures remember between scans: the mat's element count, the permanently
    failed elements, the
    susceptible ones, when each susceptible element's current episode ends (s; -inf: none)
    and the time of the last frame simulated (None before the first)."""

    n_elements: int
    permanent: npt.NDArray[np.intp]
    susceptible: npt.NDArray[np.intp]
    until: npt.NDArray[np.float64] = field(repr=False)
    last_t: float | None = None


@dataclass(frozen=True)
class FailureModel:
    """Permanent and pressure-correlated intermittent failures.

    Parameters
    ----------
    permanent_fraction : float
        Share of elements failed for the whole recording (thesis: 12 / 96).
    susceptible_fraction : float
        Share of the other elements that can fail intermittently.
    onset_per_hour : float
        Failure onsets per hour of a susceptible element loaded at ``p_ref_ncm2``.
    pressure_exponent : float
        The onset rate scales with (pressure / p_ref) ** exponent; an unloaded element still
        fails at ``unloaded_share`` of the loaded rate.
    p_ref_ncm2 : float
        Reference pressure.
    unloaded_share : float
        Onset rate of an unloaded element relative to one at p_ref.
    mean_duration_s : float
        Mean duration of an intermittent failure episode.
    """

    permanent_fraction: float = 12 / 96
    susceptible_fraction: float = 0.55
    onset_per_hour: float = 4.0
    pressure_exponent: float = 1.5
    p_ref_ncm2: float = 1.0
    unloaded_share: float = 0.05
    mean_duration_s: float = 20.0

    def __post_init__(self) -> None:
        for name in ("permanent_fraction", "susceptible_fraction", "unloaded_share"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ParameterError(f"{name} must lie in [0, 1], got {v}")
        if self.onset_per_hour < 0 or self.mean_duration_s <= 0 or self.p_ref_ncm2 <= 0:
            raise ParameterError("onset_per_hour >= 0, mean_duration_s > 0, p_ref > 0 required")

    @classmethod
    def none(cls) -> FailureModel:
        """No failures at all."""
        return cls(permanent_fraction=0.0, susceptible_fraction=0.0, onset_per_hour=0.0)

    def start(self, n_elements: int, rng: np.random.Generator) -> FailureState:
        """Draw which of ``n_elements`` fail for good and which can fail now and then."""
        order = rng.permutation(n_elements)
        n_perm = round(self.permanent_fraction * n_elements)
        rest = order[n_perm:]
        susceptible = rest[rng.random(rest.size) < self.susceptible_fraction]
        return FailureState(
            n_elements, order[:n_perm], susceptible, np.full(susceptible.size, -np.inf)
        )

    def simulate(
        self,
        times_s: npt.ArrayLike,
        pressure_ncm2: npt.ArrayLike,
        rng: np.random.Generator,
        state: FailureState | None = None,
    ) -> npt.NDArray[np.bool_]:
        """Failed (True) per frame and element for a pressure history (T, N).

        Without ``state`` the failed elements are drawn anew (one whole session); with it, the
        history continues that state (which is updated): the same elements stay broken and an
        open episode goes on. Frame times must continue the state's clock."""
        t = np.asarray(times_s, dtype=np.float64)
        p = np.asarray(pressure_ncm2, dtype=np.float64)
        if p.ndim != 2 or p.shape[0] != t.size:
            raise ParameterError(f"pressure must be (T, N) with T = {t.size}, got {p.shape}")
        n_t, n = p.shape
        if state is None:
            state = self.start(n, rng)
        elif state.n_elements != n:
            raise ParameterError(
                f"the failure state is of a mat of {state.n_elements} elements, not {n}"
            )
        failed = np.zeros((n_t, n), dtype=bool)
        failed[:, state.permanent] = True
        susceptible = state.susceptible
        if susceptible.size == 0 or self.onset_per_hour == 0 or n_t == 0:
            state.last_t = float(t[-1]) if n_t else state.last_t
            return failed
        dt = np.diff(t, prepend=t[0] if state.last_t is None else state.last_t)
        load = np.clip(p[:, susceptible] / self.p_ref_ncm2, 0.0, None) ** self.pressure_exponent
        rate = (
            self.onset_per_hour / 3600.0 * (self.unloaded_share + (1 - self.unloaded_share) * load)
        )
        until = state.until
        for k in range(n_t):
            active = t[k] < until
            start = ~active & (rng.random(susceptible.size) < -np.expm1(-rate[k] * dt[k]))
            until[start] = t[k] + rng.exponential(self.mean_duration_s, int(start.sum()))
            failed[k, susceptible] = active | start
        state.last_t = float(t[-1])
        return failed
