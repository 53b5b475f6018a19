"""The kernels of drift (thesis chapter 5, eq. 5.8): what a drift model superposes over the
steps of its input, as a non-negative sum of exponentials ``k(t) = Σ c_j (1 - exp(-t / τ_j))``
that a :class:`~texsense._core.DriftBank` runs recursively (K states per element, O(K) per
sample whatever the length of the history).

- :func:`log_kernel`: ``ln(1 + t)`` of eq. 5.2 approximated once, with its largest error;
- :func:`prony_kernel`: a Prony series fitted to a measured step response where the logarithm
  does not hold.

:class:`~texsense.compensation.drift.DriftModel` holds one (its γ, clock and level beside).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from texsense._core import DriftBank
from texsense.exceptions import ParameterError

__all__ = ["DriftKernel", "log_kernel", "prony_kernel"]


@dataclass(frozen=True)
class DriftKernel:
    """``k(t) = Σ c_j (1 - exp(-t / τ_j))`` with its largest deviation from the target."""

    weights: npt.NDArray[np.float64]
    taus: npt.NDArray[np.float64]
    max_error: float
    span_s: tuple[float, float]

    def __call__(self, t: npt.ArrayLike) -> npt.NDArray[np.float64]:
        t = np.asarray(t, dtype=np.float64)[..., None]
        return np.sum(self.weights * (1.0 - np.exp(-t / self.taus)), axis=-1)

    def bank(
        self,
        gamma: float,
        n_elements: int = 1,
        rest_rate: float = 0.0,
        rest_window: float = 0.5,
        gamma_time: float = 0.0,
        exponent: float = 1.0,
    ) -> DriftBank:
        """A recursive evaluator for ``n_elements`` (on the rest clock when ``rest_rate`` >
        0, plus a time-clock part ``gamma_time``, superposing the steps of ``h**exponent``;
        see :class:`DriftModel`)."""
        return DriftBank(
            np.ascontiguousarray(self.weights),
            np.ascontiguousarray(self.taus),
            float(gamma),
            int(n_elements),
            float(rest_rate),
            float(rest_window),
            float(gamma_time),
            float(exponent),
        )


def _fit_exponentials(t: np.ndarray, target: np.ndarray, taus: np.ndarray) -> np.ndarray:
    basis = 1.0 - np.exp(-t[:, None] / taus[None, :])
    from scipy.optimize import nnls  # heavy: only fits need it

    weights, _ = nnls(basis, target, maxiter=50 * taus.size)
    return weights


def log_kernel(t_min_s: float = 0.1, t_max_s: float = 1e6, per_decade: int = 2) -> DriftKernel:
    """Approximate ``ln(1 + t)`` on ``[0, t_max_s]`` by a non-negative sum of exponentials
    with time constants log-spaced from ``t_min_s`` to ``t_max_s``.

    ``max_error`` is the largest absolute deviation on a dense logarithmic grid over the span,
    in the units of ``ln(1 + t)``; the drift error it causes is at most
    ``|γ| max_error Σ|Δh|`` over the steps of the history.
    """
    if not (0 < t_min_s < t_max_s) or per_decade < 1:
        raise ParameterError("need 0 < t_min_s < t_max_s and per_decade >= 1")
    n = int(np.ceil(np.log10(t_max_s / t_min_s) * per_decade)) + 1
    taus = np.geomspace(t_min_s, t_max_s, n)
    t = np.concatenate([[0.0], np.geomspace(t_min_s / 100, t_max_s, 4000)])
    target = np.log1p(t)
    weights = _fit_exponentials(t, target, taus)
    keep = weights > 0
    err = float(np.max(np.abs((1.0 - np.exp(-t[:, None] / taus[keep])) @ weights[keep] - target)))
    return DriftKernel(weights[keep], taus[keep], err, (0.0, t_max_s))


def prony_kernel(
    t_s: npt.ArrayLike,
    response: npt.ArrayLike,
    t_min_s: float = 0.1,
    t_max_s: float | None = None,
    per_decade: int = 3,
) -> DriftKernel:
    """Fit a non-negative Prony series to a measured step response normalised to ``γ k(t)``
    with ``k`` growing: ``response(t) ≈ -Σ c_j (1 - exp(-t/τ_j))`` for relaxation (negative
    response) or ``+Σ ...`` for creep; returns the kernel of the magnitude."""
    t = np.asarray(t_s, dtype=np.float64)
    y = np.asarray(response, dtype=np.float64)
    if t.shape != y.shape or t.size < 5:
        raise ParameterError("need matching t and response with at least 5 samples")
    t_max_s = float(t.max()) * 3 if t_max_s is None else t_max_s
    n = int(np.ceil(np.log10(t_max_s / t_min_s) * per_decade)) + 1
    taus = np.geomspace(t_min_s, t_max_s, n)
    sign = -1.0 if y[-1] < 0 else 1.0
    weights = _fit_exponentials(t - t[0], sign * y, taus)
    keep = weights > 0
    model = (1.0 - np.exp(-(t - t[0])[:, None] / taus[keep])) @ weights[keep]
    return DriftKernel(
        weights[keep],
        taus[keep],
        float(np.max(np.abs(model - sign * y))),
        (0.0, float(t.max() - t[0])),
    )
