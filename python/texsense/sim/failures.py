"""Element failures of a textile sensor (thesis §6.5.2.5).

Conductive lint and imperfect connections short or break elements; a shorted or broken
element reads 0 pF. The thesis's seat had 12 of 96 elements failing permanently, and others
failing now and then — more often where the layers are pressed together — so that 50-57 % of
the elements failed at least once during a session.

:class:`FailureModel` draws permanent failures, and intermittent failure episodes for a
susceptible share of the elements with an onset rate that grows with the local pressure and
exponentially distributed durations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError

__all__ = ["FailureModel"]


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

    def simulate(
        self,
        times_s: npt.ArrayLike,
        pressure_ncm2: npt.ArrayLike,
        rng: np.random.Generator,
    ) -> npt.NDArray[np.bool_]:
        """Failed (True) per frame and element for a pressure history (T, N)."""
        t = np.asarray(times_s, dtype=np.float64)
        p = np.asarray(pressure_ncm2, dtype=np.float64)
        if p.ndim != 2 or p.shape[0] != t.size:
            raise ParameterError(f"pressure must be (T, N) with T = {t.size}, got {p.shape}")
        n_t, n = p.shape
        failed = np.zeros((n_t, n), dtype=bool)
        order = rng.permutation(n)
        n_perm = round(self.permanent_fraction * n)
        failed[:, order[:n_perm]] = True
        rest = order[n_perm:]
        susceptible = rest[rng.random(rest.size) < self.susceptible_fraction]
        if susceptible.size == 0 or self.onset_per_hour == 0 or n_t == 0:
            return failed
        dt = np.diff(t, prepend=t[0])
        load = np.clip(p[:, susceptible] / self.p_ref_ncm2, 0.0, None) ** self.pressure_exponent
        rate = (
            self.onset_per_hour / 3600.0 * (self.unloaded_share + (1 - self.unloaded_share) * load)
        )
        until = np.full(susceptible.size, -np.inf)
        for k in range(n_t):
            active = t[k] < until
            start = ~active & (rng.random(susceptible.size) < -np.expm1(-rate[k] * dt[k]))
            until[start] = t[k] + rng.exponential(self.mean_duration_s, int(start.sum()))
            failed[k, susceptible] = active | start
        return failed
