"""Spacer materials of the virtual sensor: presets, specimen variation, and driving them.

The mechanics are in the Rust core (``crates/core/src/spacer.rs``, documented there): a
foam/pile backbone, friction elements whose stress follows the backbone (rate-independent
hysteresis with non-congruent minor loops), creep of stuck contacts (logarithmic relaxation
under held compression), fast viscoelastic branches (0.1-10 s), cyclic softening driven by the
path travelled (loops shift towards higher compression over many cycles) and slow structural
creep with slower recovery (10²-10⁴ s). None of it is a Preisach model or a logarithmic
step-response superposition — the two models the compensation uses — so accuracy tests do not
grade themselves.

Presets follow thesis §2.3.3 (compression at which the loading curve reaches the quoted
pressure is 50 %): textile spacers of 3 mm (1.8 N/cm²) and 6 mm (2.3 N/cm²), PU foams of 7 mm
and 13 mm (2.0 N/cm²) and a 9 mm foam (1.7 N/cm²) that keeps a permanent set of 0.6-0.8 mm
after a compression and recovers over hours.

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

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense._core import SpacerBank
from texsense.exceptions import ParameterError
from texsense.sim.iwan import IwanBank, IwanMaterial

__all__ = ["PRESETS", "BoucWenMaterial", "DriveResult", "Spacer", "SpacerMaterial"]


def _check_material(m: SpacerMaterial | BoucWenMaterial) -> None:
    """The checks every spacer material shares (its law's own are in the core)."""
    if not m.thickness_mm > 0:
        raise ParameterError(f"{m.name}: thickness must be > 0 mm, got {m.thickness_mm}")
    if not m.p50_ncm2 > 0:
        raise ParameterError(f"{m.name}: p50 must be > 0 N/cm², got {m.p50_ncm2}")
    if not 0.5 < m.densification < 1.0:
        raise ParameterError(f"{m.name}: densification must lie in (0.5, 1), got {m.densification}")
    if not 0 <= m.variation < 0.5:
        raise ParameterError(f"{m.name}: variation must lie in [0, 0.5)")


@dataclass(frozen=True)
class SpacerMaterial:
    """Parameters of a spacer material (see the module docstring and spacer.rs).

    Stresses are in N/cm², compressions in fractions of the thickness, times in s.
    """

    name: str
    thickness_mm: float
    p50_ncm2: float
    densification: float = 0.86
    backbone_m: float = 1.25
    linear_share: float = 0.15
    friction: tuple[tuple[float, float], ...] = ((0.09, 0.004), (0.14, 0.012), (0.14, 0.024))
    creep_a: float = 0.0
    creep_tc: float = 1.0
    rest_rate: float = 1e-7
    clutch: tuple[float, float] = (0.3, 0.108)
    viscous: tuple[tuple[float, float], ...] = ((0.01, 0.1), (0.01, 1.0), (0.005, 10.0))
    kelvin: tuple[tuple[float, float], ...] = ()
    recovery_factor: float = 3.0
    softening: tuple[tuple[float, float], ...] = ((0.03, 0.01), (0.05, 0.001))
    softening_recovery_s: float = 3.0 * 3600.0
    description: str = ""
    variation: float = 0.05  # relative specimen-to-specimen spread (1 sigma)

    @property
    def friction_share(self) -> float:
        """Share φ of the backbone stress carried by friction when fully dragged."""
        return float(sum(w for w, _ in self.friction))

    def backbone_amplitude(self) -> tuple[float, float]:
        """Backbone amplitude A and linear stiffness E_lin so that the loading curve (friction
        fully dragged) passes through p50 at 50 % compression."""
        e = 0.5
        shape = (e / (self.densification - e)) ** self.backbone_m
        total = self.p50_ncm2 / ((1.0 + self.friction_share) * (1.0 + self.clutch[0]))
        linear = self.linear_share * total / e
        amplitude = (1.0 - self.linear_share) * total / shape
        return amplitude, linear

    def validate(self) -> None:
        """Raise :class:`ParameterError` on a bad value (before the core sees it)."""
        _check_material(self)

    def varied(self, rng: np.random.Generator) -> SpacerMaterial:
        """One batch of the material: friction and creep varied by ``variation`` (1 sigma)."""
        f = float(np.exp(rng.normal(0.0, self.variation)))
        return replace(
            self,
            friction=tuple((w * f, r) for w, r in self.friction),
            creep_a=self.creep_a * float(np.exp(rng.normal(0.0, self.variation))),
            clutch=(
                self.clutch[0],
                self.clutch[1] * float(np.exp(rng.normal(0.0, self.variation))),
            ),
        )

    def bank(self, scale: npt.NDArray[np.float64]) -> SpacerBank:
        """The core's state for elements whose stresses are multiplied by ``scale``."""
        amplitude, linear = self.backbone_amplitude()

        def table(rows: tuple[tuple[float, float], ...]) -> np.ndarray:
            return np.asarray(rows, dtype=np.float64).reshape(-1, 2)

        return SpacerBank(
            amplitude,
            self.backbone_m,
            self.densification,
            linear,
            table(self.friction),
            self.creep_a,
            self.creep_tc,
            self.rest_rate,
            self.clutch[0],
            self.clutch[1],
            table(self.viscous),
            table(self.kelvin),
            self.recovery_factor,
            self.p50_ncm2,
            table(self.softening),
            self.softening_recovery_s,
            np.ascontiguousarray(scale, dtype=np.float64),
        )


@dataclass(frozen=True)
class BoucWenMaterial:
    """A spacer of the second law (``crates/core/src/bouc_wen.rs``): exponential backbone,
    Bouc–Wen friction, Norton (power-law) creep that runs on time, moving or not. Another
    family than the first law and than the compensation's models; used to check that results
    do not depend on one simulator.

    Stresses in N/cm², compressions in fractions of the thickness, times in s.
    """

    name: str
    thickness_mm: float
    p50_ncm2: float
    densification: float = 0.85
    exponent: float = 6.0
    friction: float = 0.35
    slip: float = 0.015
    bw_n: float = 1.5
    bw_beta: float = 0.6
    creep_share: float = 0.3
    creep_rate: float = 1e-3
    creep_exponent: float = 2.0
    description: str = ""
    variation: float = 0.05

    def stiffness(self) -> float:
        """Backbone stiffness E so that the loading curve passes through p50 at 50 %."""
        return self.p50_ncm2 / (
            (1.0 + self.friction) * (1.0 + self.creep_share) * (np.exp(0.5 * self.exponent) - 1)
        )

    def validate(self) -> None:
        """Raise :class:`ParameterError` on a bad value (before the core sees it)."""
        _check_material(self)

    def varied(self, rng: np.random.Generator) -> BoucWenMaterial:
        """One batch of the material: friction and creep rate varied by ``variation``."""
        return replace(
            self,
            friction=self.friction * float(np.exp(rng.normal(0.0, self.variation))),
            creep_rate=self.creep_rate * float(np.exp(rng.normal(0.0, self.variation))),
        )

    def bank(self, scale: npt.NDArray[np.float64]) -> SpacerBank:
        """The core's state for elements whose stresses are multiplied by ``scale``."""
        try:
            return SpacerBank.bouc_wen(
                self.stiffness(),
                self.exponent,
                self.densification,
                self.friction,
                self.slip,
                self.bw_n,
                self.bw_beta,
                self.creep_share,
                self.creep_rate,
                self.creep_exponent,
                np.ascontiguousarray(scale, dtype=np.float64),
            )
        except ValueError as e:
            raise ParameterError(f"{self.name}: {e}") from None


PRESETS: dict[str, SpacerMaterial | BoucWenMaterial | IwanMaterial] = {
    m.name: m
    for m in (
        SpacerMaterial(
            "textile-3mm",
            3.0,
            1.8,
            description="3D knit polyester spacer fabric, 3 mm (Müller Textil), 50 % at 1.8 N/cm²",
        ),
        SpacerMaterial(
            "textile-6mm",
            6.0,
            2.3,
            description="3D knit polyester spacer fabric, 6 mm (Müller Textil), 50 % at 2.3 N/cm²",
        ),
        SpacerMaterial(
            "foam-7mm",
            7.0,
            2.0,
            friction=((0.04, 0.008), (0.05, 0.02), (0.05, 0.05)),
            creep_a=0.12,
            kelvin=((0.004, 300.0), (0.006, 3000.0)),
            description="soft open-cell PU foam, 7 mm, 50 % at 2.0 N/cm², small hysteresis",
        ),
        SpacerMaterial(
            "foam-13mm",
            13.0,
            2.0,
            friction=((0.08, 0.006), (0.11, 0.02), (0.11, 0.05)),
            creep_a=0.12,
            kelvin=((0.004, 300.0), (0.006, 3000.0)),
            description="soft PU foam, 13 mm, 50 % at 2.0 N/cm², large hysteresis",
        ),
        SpacerMaterial(
            "foam-9mm",
            9.0,
            1.7,
            friction=((0.02, 0.006), (0.03, 0.02), (0.03, 0.05)),
            creep_a=0.12,
            kelvin=((0.16, 4.0),),
            recovery_factor=720.0,
            description="open-cell foam, 9 mm, 50 % at 1.7 N/cm²; after a compression it "
            "recovers only to 8.2-8.4 mm, and to > 8.9 mm after hours",
        ),
        BoucWenMaterial(
            "bouc-wen-6mm",
            6.0,
            2.3,
            description="second law (Bouc–Wen friction, Norton creep on time), 6 mm, 50 % at "
            "2.3 N/cm²: a spacer of another family for generalisation checks",
        ),
        IwanMaterial(
            "iwan-6mm",
            6.0,
            2.3,
            description="third law (Iwan bank of Jenkins elements with stiffening springs on a "
            "stiffening backbone, viscoplastic relaxation), 6 mm, 50 % at 2.3 N/cm²: a spacer "
            "of neither the textile nor the Bouc–Wen family, for generalisation checks",
        ),
    )
}


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
        material: SpacerMaterial | BoucWenMaterial | IwanMaterial,
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
        return self._effective.bank(self.scale)

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
