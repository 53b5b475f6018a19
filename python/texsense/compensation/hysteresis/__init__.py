"""Preisach hysteresis compensation (thesis chapter 4).

:class:`HysteresisModel` identifies the Everett function of a spacer (or any hysteretic
input -> output relation) from a calibration record — by the thesis's method (rising curve +
falling curves, §4.4.2) or by least squares on any cyclic record — and evaluates the
numerical Preisach model of §4.4.1 (eq. 4.15-4.22) in the Rust core for many elements at once,
streaming (:class:`PreisachState`) or batch (:meth:`HysteresisModel.predict`). Models are
saved as versioned JSON.
"""

from texsense.compensation.hysteresis._model import (
    DEFAULT_CAPACITY,
    MODEL_FORMAT,
    MODEL_VERSION,
    HysteresisModel,
    PreisachState,
    scale_hysteresis,
)

__all__ = [
    "DEFAULT_CAPACITY",
    "MODEL_FORMAT",
    "MODEL_VERSION",
    "HysteresisModel",
    "PreisachState",
    "scale_hysteresis",
]
