"""A third spacer law: an Iwan (Masing) bank of Jenkins elements on a stiffening backbone.

Neither the textile law (friction that follows the backbone, crates/core/src/spacer.rs) nor
Bouc–Wen (bouc_wen.rs), and not built from the compensation's Preisach or logarithmic drift
models: pure numpy, its own mechanics.

- **Backbone**: ``σ_b(e) = E e (1 + c e²) / (1 - e / e_d)`` (stiffening towards the
  densification strain ``e_d``).
- **Jenkins elements** (a spring in series with a Coulomb slider) in parallel, the Iwan
  model: element ``i`` carries ``σ_i`` with ``|σ_i| <= τ_i (b p50 + σ_b(e))`` (Coulomb: the
  slip strength grows with the load, from a base share ``b``); while it sticks its stress moves
  with the compression at the stiffness ``k_i (1 + (e / e_s)²)`` — the springs stiffen as the
  fibres/cells are pressed together, so minor loops at high compression are steeper and
  narrower than at low compression (not congruent: no Preisach model reproduces this law
  exactly).
- **Viscoplastic relaxation** of the element stresses: ``dσ_i/dt = -σ_i |σ_i / τ_i|^n / t_v``
  (a held compression loses pressure, a held pressure creeps), strongest near slip.

The pressure is ``scale × (σ_b + Σ σ_i)``, clipped at 0 (the surface lifts off).
Stresses in N/cm², compressions in fractions of the thickness, times in s.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError
from texsense.sensor.materials import IwanMaterial

__all__ = ["IwanBank"]


class IwanBank:
    """The mechanical state of N specimens of an :class:`IwanMaterial` (the interface of the
    core's ``SpacerBank``: displacement and pressure control, ramps, backbone)."""

    def __init__(self, material: IwanMaterial, scale: npt.NDArray[np.float64]) -> None:
        self.m = material
        self.scale = np.asarray(scale, dtype=np.float64).ravel()
        self.E = material.stiffness()
        self.k = np.array([k for k, _ in material.elements]) * self.E
        self.tau = np.array([t for _, t in material.elements])
        self.e = np.zeros(self.scale.size)
        self.sigma = np.zeros((self.scale.size, self.k.size))

    @property
    def n_elements(self) -> int:
        """Specimens."""
        return int(self.scale.size)

    def backbone(self, e: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Backbone stress (no elements) at strains ``e`` (nominal specimen)."""
        x = np.asarray(e, dtype=np.float64)
        return self.E * x * (1 + self.m.cubic * x * x) / (1 - x / self.m.densification)

    def creep_strain(self) -> npt.NDArray[np.float64]:
        """No permanent set in this law."""
        return np.zeros(self.n_elements)

    def _trial(self, e_new: np.ndarray, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Element stresses after moving from the current strain to ``e_new``."""
        e0 = self.e[rows]
        mid = 0.5 * (e0 + e_new)
        stiff = self.k[None, :] * (1 + (mid / self.m.stiffening_strain) ** 2)[:, None]
        s = self.sigma[rows] + stiff * (e_new - e0)[:, None]
        limit = self._limit(e_new)
        return np.clip(s, -limit, limit)

    def _limit(self, e: np.ndarray) -> np.ndarray:
        """Slip strengths (N, elements) at strains ``e``."""
        load = self.m.base_load * self.m.p50_ncm2 + self.backbone(e)
        return self.tau[None, :] * load[:, None]

    def _pressure(self, e: np.ndarray, sigma: np.ndarray, rows: np.ndarray | slice) -> np.ndarray:
        return np.maximum(self.scale[rows] * (self.backbone(e) + sigma.sum(axis=1)), 0.0)

    def _relax(self, dt: float) -> None:
        if dt <= 0:
            return
        ratio = np.abs(self.sigma) / self._limit(self.e)
        self.sigma *= np.exp(-dt / self.m.relax_s * ratio**self.m.relax_exponent)

    def _move(self, e_new: np.ndarray) -> np.ndarray:
        s = self._trial(e_new)
        self.sigma, self.e = s, e_new.copy()
        return self._pressure(self.e, self.sigma, slice(None))

    def run_displacement(
        self, dt: npt.NDArray[np.float64], compression: npt.NDArray[np.float64]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pressures and strains (T, N) for strains (T, N)."""
        e = np.asarray(compression, dtype=np.float64)
        p = np.empty_like(e)
        for t in range(e.shape[0]):
            self._relax(float(dt[t]))
            p[t] = self._move(e[t])
        return p, e.copy()

    def _solve_strain(self, target: np.ndarray) -> np.ndarray:
        """The strain that carries ``target`` from the current state (bisection; the
        pressure rises with the strain)."""
        lo = np.zeros(self.n_elements)
        hi = np.full(self.n_elements, self.m.densification * (1 - 1e-6))
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            above = self._pressure(mid, self._trial(mid), slice(None)) >= target
            hi = np.where(above, mid, hi)
            lo = np.where(above, lo, mid)
        return hi

    def run_pressure(
        self, dt: npt.NDArray[np.float64], pressure: npt.NDArray[np.float64]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Strains and pressures reached (T, N) for target pressures (T, N)."""
        target = np.asarray(pressure, dtype=np.float64)
        e = np.empty_like(target)
        reached = np.empty_like(target)
        for t in range(target.shape[0]):
            self._relax(float(dt[t]))
            e[t] = self._solve_strain(target[t])
            reached[t] = self._move(e[t])
        return e, reached

    def ramp_until(
        self, dt: float, rate: float, target: float, max_steps: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """Move specimen 0 at ``rate`` (strain/s) until its pressure crosses ``target``:
        strains, pressures and specimen strains of every step, and whether it arrived."""
        if self.n_elements != 1:
            raise ParameterError("ramp_until drives one specimen")
        rising = rate > 0
        # one specimen, step by step: plain floats (numpy's per-call cost would dominate)
        m = self.m
        k = [float(x) for x in self.k]
        tau = [float(x) for x in self.tau]
        sig = [float(x) for x in self.sigma[0]]
        scale = float(self.scale[0])
        e = float(self.e[0])
        e_max = m.densification * (1 - 1e-6)
        base = m.base_load * m.p50_ncm2
        decay = dt / m.relax_s
        n_exp = m.relax_exponent
        E, cubic, dens, es2 = self.E, m.cubic, m.densification, m.stiffening_strain
        es_out: list[float] = []
        ps_out: list[float] = []
        done = False
        for _ in range(max_steps):
            load0 = base + E * e * (1 + cubic * e * e) / (1 - e / dens)
            for i in range(len(sig)):  # viscoplastic relaxation over dt
                ratio = abs(sig[i]) / (tau[i] * load0)
                sig[i] *= float(np.exp(-decay * ratio**n_exp)) if ratio > 1e-12 else 1.0
            e_new = min(max(e + rate * dt, 0.0), e_max)
            mid = 0.5 * (e + e_new)
            stiff = 1 + (mid / es2) ** 2
            bb = E * e_new * (1 + cubic * e_new * e_new) / (1 - e_new / dens)
            load = base + bb
            total = bb
            for i in range(len(sig)):
                lim = tau[i] * load
                v = sig[i] + k[i] * stiff * (e_new - e)
                sig[i] = lim if v > lim else (-lim if v < -lim else v)
                total += sig[i]
            e = e_new
            p = max(scale * total, 0.0)
            es_out.append(e)
            ps_out.append(p)
            if (rising and p >= target) or (not rising and (p <= target or e <= 0.0)):
                done = True
                break
        self.e[0] = e
        self.sigma[0] = sig
        out = np.asarray(es_out)
        return out, np.asarray(ps_out), out.copy(), done
