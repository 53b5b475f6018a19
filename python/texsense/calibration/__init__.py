"""Calibration of a real mat: material presets, the calibration session and its checks, and
the workflows that calibrate the simulator's virtual mats as a user would.

- :mod:`~texsense.calibration.session`: zero, uniform load, material, check
  (``texsense calibrate mat|wizard`` and the monitor's calibration panel);
- :mod:`~texsense.calibration.checks`: what is refused or warned about, in words;
- :mod:`~texsense.calibration.workflows`: :func:`calibrate_mat` and the virtual mats'
  calibrations.

Layer rule: imports the data model, the compensation, the sensor physics
(:mod:`texsense.sensor`, whose :mod:`~texsense.sensor.materials` are the presets) and the
simulator (a preset's material record is the simulator's reference specimen); nothing from the
applications or the live products (tests/test_imports.py).

``texsense.calibration`` was the module of the eq. 2.1 fitting before the layered tree; its
names are still found here for one release, with a warning
(:mod:`texsense.compensation.conversion`).
"""

from __future__ import annotations

import importlib
import warnings
from typing import Any

#: The names of the eq. 2.1 module that was ``texsense.calibration`` (kept one release).
_CONVERSION_NAMES = {"material_curve", "fit_conversion", "rising_compression"}


def __getattr__(name: str) -> Any:
    if name in _CONVERSION_NAMES:
        warnings.warn(
            f"texsense.calibration.{name} moved to texsense.compensation.conversion.{name}; "
            "the old name goes in the next release",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(importlib.import_module("texsense.compensation.conversion"), name)
    raise AttributeError(f"module 'texsense.calibration' has no attribute {name!r}")
