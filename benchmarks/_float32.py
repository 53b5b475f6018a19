"""The ``--float32`` switch of the accuracy benchmarks (issue 34, seventh round): every
prediction of their tables through the experimental float32 banks of the core
(``texsense._core.PreisachBank32``, ``DriftBank32``: eight elements per AVX2 register), for
comparing the printed tables with those of the float64 kernels. Identification stays as it is.
"""

from __future__ import annotations

import sys

import numpy as np

from texsense import _core
from texsense.compensation.drift import DriftModel, time_steps
from texsense.compensation.hysteresis import HysteresisModel

FLOAT32 = "--float32" in sys.argv


def predict(m: HysteresisModel, u: np.ndarray) -> np.ndarray:
    """The model's outputs over the history ``u`` (T,): its float64 kernel, or with
    ``--float32`` the float32 bank."""
    if not FLOAT32:
        return m.predict(u)
    table = np.ascontiguousarray(m.everett_, dtype=np.float64)
    bank = _core.PreisachBank32(m.u_min_, m.u_max_, table, 1, m.offset_, m.sign_)
    x = np.ascontiguousarray(u, dtype=np.float64).reshape(-1, 1)
    return bank.run(x, np.ones(x.shape, bool))[:, 0]


def apply(d: DriftModel, h: np.ndarray, times_s: np.ndarray) -> np.ndarray:
    """``d.apply(h, times_s)`` for a history (T,): its float64 kernel, or with ``--float32``
    the float32 bank (eq. 5.8 on the time clock with the linear level only)."""
    if not FLOAT32:
        return d.apply(h, times_s)
    if d.rest_rate != 0 or d.gamma_time != 0 or d.exponent != 1 or d.level == "backbone":
        raise ValueError("the float32 drift bank runs eq. 5.8 on the time clock only")
    x = np.ascontiguousarray(h, dtype=np.float64).reshape(-1, 1)
    k = d.kernel
    bank = _core.DriftBank32(np.asarray(k.weights), np.asarray(k.taus), d.gamma, 1)
    dt = time_steps(times_s, x.shape[0])
    return bank.run(dt, x, np.ascontiguousarray(np.isfinite(x)))[:, 0]
