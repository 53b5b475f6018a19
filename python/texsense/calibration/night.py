"""The virtual night's bed mat calibrated as a user would, before the night (issue 37):
zeroing (the mat empty), equilibration under a uniform 1 N/cm² and the material preset of
the mat's own spacer (:class:`~texsense.calibration.session.CalibrationSession`, the steps of
``texsense calibrate mat --material PRESET``; the preset brings its laboratory drift stage, γ
from an hour of cycles). The scans load a fresh mat of the same seed (the same physical mat,
rested by the night), without failures (a failed element cannot be calibrated).
"""

from __future__ import annotations

import numpy as np

from texsense.calibration.session import CalibrationSession
from texsense.compensation.stages import StageChain
from texsense.sim.night import NIGHT_MAT_SEED, night_mat

__all__ = ["night_calibration"]


def night_calibration(spacer: str = "textile-3mm", mat_seed: int = NIGHT_MAT_SEED) -> StageChain:
    """The calibration of :func:`texsense.sim.night.night_mat` (``spacer``, ``mat_seed``) by the
    documented user steps: 10 frames empty, 10 frames at 1 N/cm², the spacer's preset."""
    mat = night_mat(spacer, mat_seed, failures=False)
    n = mat.layout.n_elements
    ft = mat.cdc.frame_time_s(n, mat.converters)
    zero = mat.scan(np.arange(10) * ft, np.zeros((10, n))).capacitance
    uniform = mat.scan((11 + np.arange(10)) * ft, np.full((10, n), 1.0)).capacitance
    return CalibrationSession(spacer, pressure=1.0).fit(zero, uniform)
