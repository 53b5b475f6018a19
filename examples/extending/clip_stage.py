"""A new compensation stage in one module: clip pressures to the range the calibration knows.

A stage follows the contract of :mod:`texsense.compensation.stage`: parameters in the
constructor, each with its declared range (``ranges``, checked when the stage is made),
``fit`` learns (here: the largest pressure of a calibration record) and returns the stage,
the batch path ``_block`` serves ``step`` and ``run``, and the learned state goes
to and from its file. Setting ``name`` registers it (``STAGES``): model files and chains find
it by that name; saved in ``texsense/compensation/stages/`` it is imported with the package.
``tests/test_extending.py`` runs the shared contract check on it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from texsense.compensation.stage import Stage
from texsense.data.modelfile import Fields
from texsense.data.ranges import Kind, Real


class Clip(Stage):
    """Pressure above ``margin`` times the largest calibrated pressure is marked invalid
    (an extrapolation the spacer model was not identified for)."""

    name = "example-clip"
    _reads = ("pressure", "N/cm2")
    _gives = ("pressure", "N/cm2")

    #: the range of every parameter, checked by the constructor (:mod:`texsense.data.ranges`)
    ranges: ClassVar[Mapping[str, Kind]] = {"margin": Real(1.0, 100.0)}

    #: learned: the largest pressure of the calibration record (N/cm²)
    top_: float

    def __init__(self, margin: float = 1.2) -> None:
        self.margin = margin

    def fit(self, calibration_ncm2: npt.ArrayLike) -> Clip:
        """Learn the calibrated range from a record of pressures."""
        return self.set_fitted(top=float(np.nanmax(np.asarray(calibration_ncm2, float))))

    def _block(
        self, values: np.ndarray, valid: np.ndarray, dt: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        return values.copy(), valid & ~(values > self.margin * self.top_)

    def _fitted_json(self) -> dict[str, Any]:
        return {"top": self.top_}

    @classmethod
    def _fitted_from_json(cls, fields: Fields, params: Mapping[str, Any]) -> dict[str, Any]:
        return {"top": fields.number("top")}
