"""Spacer materials of the virtual sensor driven: specimen variation, the laws' states
(banks) and driving them. The materials' parameters and presets are
:mod:`texsense.sensor.materials`.

The mechanics are in the Rust core (``crates/core/src/spacer.rs``, documented there): a
foam/pile backbone, friction elements whose stress follows the backbone (rate-independent
hysteresis with non-congruent minor loops), creep of stuck contacts (logarithmic relaxation
under held compression), fast viscoelastic branches (0.1-10 s), cyclic softening driven by the
path travelled (loops shift towards higher compression over many cycles) and slow structural
creep with slower recovery (10²-10⁴ s). None of it is a Preisach model or a logarithmic
step-response superposition — the two models the compensation uses — so accuracy tests do not
grade themselves.

Examples
--------
>>> import numpy as np
>>> from texsense.sim.spacer import Spacer
>>> spacer = Spacer.preset("textile-6mm", seed=0)
>>> t = np.linspace(0, 60, 601)
>>> result = spacer.drive_pressure(t, np.minimum(t / 10, 2.3))
>>> round(float(result.compression_mm[-1, 0]), 1)   # about half of the 6 mm
3.0
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense._core import SpacerBank
from texsense.exceptions import ParameterError
from texsense.sensor.materials import (
    PRESETS,
    BoucWenMaterial,
    IwanMaterial,
    Material,
    SpacerMaterial,
)
from texsense.sim.iwan import IwanBank

__all__ = ["DriveResult", "Spacer", "bank_of"]


def bank_of(material: Material, scale: npt.NDArray[np.float64]) -> SpacerBank | IwanBank:
    """The state of elements of ``material`` whose stresses are multiplied by ``scale``: the
    core's bank of its law (``spacer.rs``, ``bouc_wen.rs``) or the Iwan bank."""
    if isinstance(material, IwanMaterial):
        return IwanBank(material, np.asarray(scale, dtype=np.float64))
    if isinstance(material, BoucWenMaterial):
        return _bouc_wen_bank(material, scale)
    return _spacer_bank(material, scale)


def _spacer_bank(m: SpacerMaterial, scale: npt.NDArray[np.float64]) -> SpacerBank:
    """The first law's bank (``spacer.rs``)."""
    amplitude, linear = m.backbone_amplitude()

    def table(rows: tuple[tuple[float, float], ...]) -> np.ndarray:
        return np.asarray(rows, dtype=np.float64).reshape(-1, 2)

    return SpacerBank(
        amplitude,
        m.backbone_m,
        m.densification,
        linear,
        table(m.friction),
        m.creep_a,
        m.creep_tc,
        m.rest_rate,
        m.clutch[0],
        m.clutch[1],
        table(m.viscous),
        table(m.kelvin),
        m.recovery_factor,
        m.p50_ncm2,
        table(m.softening),
        m.softening_recovery_s,
        np.ascontiguousarray(scale, dtype=np.float64),
    )


def _bouc_wen_bank(m: BoucWenMaterial, scale: npt.NDArray[np.float64]) -> SpacerBank:
    """The second law's bank (``bouc_wen.rs``)."""
    try:
        return SpacerBank.bouc_wen(
            m.stiffness(),
            m.exponent,
            m.densification,
            m.friction,
            m.slip,
            m.bw_n,
            m.bw_beta,
            m.creep_share,
            m.creep_rate,
            m.creep_exponent,
            np.ascontiguousarray(scale, dtype=np.float64),
        )
    except ValueError as e:
        raise ParameterError(f"{m.name}: {e}") from None


@dataclass
class DriveResult:
    """What a spacer did under a drive: arrays (T,) or (T, N) for N specimens."""

    times_s: npt.NDArray[np.float64]
    compression_mm: npt.NDArray[np.float64]
    pressure_ncm2: npt.NDArray[np.float64]
    meta: dict[str, Any] = field(default_factory=dict)


class Spacer:
    """One or more specimens of a spacer material, with their mechanical state.

    Parameters
    ----------
    material : SpacerMaterial
        The material.
    n_specimens : int
        How many independent specimens (elements) to simulate side by side.
    seed : int, optional
        Seed of the specimen-to-specimen variation (stiffness and friction spread of
        ``material.variation``); None gives the nominal material for every specimen.
    """

    def __init__(
        self,
        material: Material,
        n_specimens: int = 1,
        seed: int | None = None,
    ):
        material.validate()
        if n_specimens < 1:
            raise ParameterError(f"n_specimens must be >= 1, got {n_specimens}")
        self.material = material
        self.n_specimens = int(n_specimens)
        self.seed = seed
        if seed is None:
            scale = np.ones(n_specimens)
            mat = material
        else:
            rng = np.random.default_rng(seed)
            scale = np.exp(rng.normal(0.0, material.variation, n_specimens))
            mat = material.varied(rng)  # one friction and creep variation per call (a batch)
        self._effective = mat
        self.scale = scale
        self._bank = self._new_bank()

    @classmethod
    def preset(cls, name: str, n_specimens: int = 1, seed: int | None = None) -> Spacer:
        """A spacer from :data:`PRESETS` (``textile-3mm``, ``textile-6mm``, ``foam-7mm``,
        ``foam-9mm``, ``foam-13mm``)."""
        if name not in PRESETS:
            raise ParameterError(f"unknown spacer preset {name!r}; known: {', '.join(PRESETS)}")
        return cls(PRESETS[name], n_specimens, seed)

    def _new_bank(self) -> SpacerBank | IwanBank:
        return bank_of(self._effective, self.scale)

    @property
    def thickness_mm(self) -> float:
        """Unloaded thickness in mm."""
        return self.material.thickness_mm

    @property
    def max_compression_mm(self) -> float:
        """The compression at which the spacer is fully densified (cannot be reached)."""
        return self.material.densification * self.material.thickness_mm

    def reset(self) -> Spacer:
        """Back to the unloaded, fully recovered state."""
        self._bank = self._new_bank()
        return self

    def creep_set_mm(self) -> npt.NDArray[np.float64]:
        """Permanent set per specimen (mm): how far the free surface sits below unloaded."""
        return self._bank.creep_strain() * self.thickness_mm

    def _columns(self, values: npt.ArrayLike, t: int, what: str) -> np.ndarray:
        v = np.asarray(values, dtype=np.float64)
        if v.ndim == 1:
            v = np.repeat(v[:, None], self.n_specimens, axis=1)
        if v.shape != (t, self.n_specimens):
            raise ParameterError(
                f"{what}: expected shape ({t},) or ({t}, {self.n_specimens}), got {v.shape}"
            )
        if not np.all(np.isfinite(v)):
            raise ParameterError(f"{what}: values must be finite")
        return np.ascontiguousarray(v)

    @staticmethod
    def _steps(times: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(times, dtype=np.float64)
        if t.ndim != 1 or t.size == 0:
            raise ParameterError("times: expected a non-empty 1-D array of seconds")
        dt = np.diff(t, prepend=t[0])
        if np.any(dt < 0) or not np.all(np.isfinite(t)):
            raise ParameterError("times must be finite and non-decreasing")
        return t, dt

    def drive_displacement(
        self, times: npt.ArrayLike, compression_mm: npt.ArrayLike
    ) -> DriveResult:
        """Displacement control: move the platen through ``compression_mm`` (T,) or (T, N).

        The state continues from the previous drive. Raises :class:`ParameterError` for a
        compression outside [0, densification) of the thickness.
        """
        t, dt = self._steps(times)
        e = self._columns(compression_mm, t.size, "compression_mm") / self.thickness_mm
        bad = (e < 0) | (e >= self.material.densification)
        if bad.any():
            k = int(np.argwhere(bad)[0][0])
            raise ParameterError(
                f"compression {e.flat[np.argmax(bad)] * self.thickness_mm:.4g} mm at sample {k} "
                f"is outside 0 .. {self.max_compression_mm:.4g} mm (the {self.thickness_mm} mm "
                "spacer densifies there)"
            )
        pressure, spacer_e = self._bank.run_displacement(dt, e)
        return DriveResult(t, spacer_e * self.thickness_mm, pressure, {"control": "displacement"})

    def drive_pressure(self, times: npt.ArrayLike, pressure_ncm2: npt.ArrayLike) -> DriveResult:
        """Pressure control: find the compression that carries ``pressure_ncm2`` (T,) or (T, N)
        at every sample (the state continues from the previous drive). The result holds the
        pressure reached, which equals the target except at turning points where the contacts
        creep during the instant of rest (within about 0.3 % of the target)."""
        t, dt = self._steps(times)
        p = self._columns(pressure_ncm2, t.size, "pressure_ncm2")
        if np.any(p < 0):
            raise ParameterError("pressure_ncm2 must be >= 0 (a spacer cannot be pulled)")
        try:
            e, reached = self._bank.run_pressure(dt, p)
        except ValueError as err:
            raise ParameterError(str(err)) from None
        return DriveResult(t, e * self.thickness_mm, reached, {"control": "pressure"})

    def backbone_ncm2(self, compression_mm: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The elastic backbone stress (no friction, no creep) at the given compressions."""
        e = np.ascontiguousarray(np.asarray(compression_mm, float).ravel() / self.thickness_mm)
        return self._bank.backbone(e)
