"""A small dense convex quadratic program with linear inequality constraints.

``minimise ½ xᵀH x - gᵀx  subject to  C x >= 0`` with ``H`` symmetric positive definite
(n up to about a thousand) and ``C`` sparse, solved by a primal-dual interior-point method
(Mehrotra predictor-corrector) that starts from a *strictly feasible* point and keeps every
iterate strictly feasible: the slack ``s = C x`` is recomputed from ``x`` each iteration and
the step never lets it reach zero. For the Everett tables of the hysteresis identification
this means the returned table satisfies its monotonicity constraints by construction, at any
iteration — nothing is clipped afterwards.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError

if TYPE_CHECKING:
    from scipy.sparse import csr_matrix

__all__ = ["solve_monotone_qp"]


def _step_to_boundary(v: np.ndarray, dv: np.ndarray) -> float:
    neg = dv < 0
    if not neg.any():
        return np.inf
    return float(np.min(-v[neg] / dv[neg]))


def solve_monotone_qp(
    H: npt.NDArray[np.float64],
    g: npt.NDArray[np.float64],
    C: csr_matrix,
    x0: npt.NDArray[np.float64],
    tol: float = 1e-7,
    max_iter: int = 80,
) -> tuple[np.ndarray, int]:
    """Solve ``min ½ xᵀHx - gᵀx`` s.t. ``Cx >= 0`` from the strictly feasible ``x0``.

    Converged when the complementarity gap and the dual residual are below ``tol`` relative
    to the size of the gradient (the slacks of active constraints cannot shrink below the
    rounding of ``C x``, so much tighter tolerances only stall). Returns the solution
    (strictly feasible: ``C x > 0``) and the iterations used. Raises
    :class:`ParameterError` when ``x0`` is not strictly feasible or ``H`` is not positive
    definite.
    """
    from scipy.linalg import (  # heavy: imported where a fit needs it
        LinAlgError,
        cho_factor,
        cho_solve,
    )

    x = np.array(x0, dtype=np.float64)
    s = C @ x
    if not np.all(s > 0):
        raise ParameterError("the starting point must satisfy C x > 0 strictly")
    m = s.size
    Ct = C.T.tocsr()
    scale = max(float(np.abs(g).max()), float(np.abs(H @ x).max()), 1e-300)
    y = scale * float(np.mean(s)) / m / s  # centred: every y_i s_i equal
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (the count is returned)
        r_dual = H @ x - g - Ct @ y
        mu = float(s @ y) / m
        if mu * m < tol * scale and np.abs(r_dual).max() < tol * scale:
            break
        d = y / s
        M = H + (Ct.multiply(d) @ C).toarray()
        try:
            factor = cho_factor(M, check_finite=False)
        except LinAlgError:
            raise ParameterError(
                "the quadratic program's matrix is not positive definite"
            ) from None
        # predictor (affine scaling)
        dx = cho_solve(factor, g - H @ x, check_finite=False)
        ds = C @ dx
        dy = -y - d * ds
        a_p, a_d = _step_to_boundary(s, ds), _step_to_boundary(y, dy)
        mu_aff = float((s + min(1.0, a_p) * ds) @ (y + min(1.0, a_d) * dy)) / m
        sigma = (mu_aff / mu) ** 3
        # corrector with Mehrotra's second-order term
        target = sigma * mu - ds * dy
        dx = cho_solve(factor, -r_dual + Ct @ (target / s - y), check_finite=False)
        ds = C @ dx
        dy = target / s - y - d * ds
        step = min(1.0, 0.99 * min(_step_to_boundary(s, ds), _step_to_boundary(y, dy)))
        x_new = x + step * dx
        s_new = C @ x_new
        while not np.all(s_new > 0):  # rounding at the boundary: shorten, never cross
            step *= 0.5
            x_new = x + step * dx
            s_new = C @ x_new
        x, s, y = x_new, s_new, y + step * dy
    return x, it
