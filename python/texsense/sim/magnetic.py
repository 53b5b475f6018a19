"""A virtual magnetic sample with sharp switching, measured as first-order reversal curves.

An ensemble of bistable particles (a Stoner–Wohlfarth-like square loop each): particle ``k``
switches up when its effective field reaches ``a_k`` and down when it falls to ``b_k``. The
switching fields come from a narrow distribution of coercivities ``(a - b) / 2`` around
``coercivity`` and of bias fields ``(a + b) / 2`` around 0. The particles **interact** through
a mean field: the effective field is ``H + interaction * M`` (M the mean moment, -1 .. 1),
found self-consistently after every field step (switching avalanches). With interaction the
sample is *not* a Preisach model in the applied field (its FORC distribution has negative
parts and the minor loops are not congruent), so identifying it is a test of the
identification and not of a model against itself.

The FORC protocol (Pike et al. 1999): from positive saturation down to each reversal field
``H_r`` (evenly spaced), then up to saturation, measuring at steps of ``step``; the first
sample of every curve is the calibration point at the top of the field range.

Examples
--------
>>> from texsense.sim.magnetic import forc_protocol
>>> field, moment, curve = forc_protocol(n_curves=10, step=0.05, seed=0)
>>> bool(moment.max() > 0.99 and moment.min() < -0.99)
True
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError

__all__ = ["ParticleEnsemble", "forc_protocol"]


class ParticleEnsemble:
    """Interacting bistable particles (see the module docstring), starting saturated down."""

    def __init__(
        self,
        n_particles: int = 4000,
        coercivity: float = 0.5,
        coercivity_spread: float = 0.03,
        bias_spread: float = 0.04,
        interaction: float = -0.1,
        seed: int | None = 0,
    ) -> None:
        if n_particles < 1:
            raise ParameterError(f"n_particles must be >= 1, got {n_particles}")
        if not coercivity > 0 or coercivity_spread < 0 or bias_spread < 0:
            raise ParameterError("coercivity must be > 0 and the spreads >= 0")
        rng = np.random.default_rng(seed)
        hc = np.abs(coercivity + coercivity_spread * rng.standard_normal(n_particles))
        hb = bias_spread * rng.standard_normal(n_particles)
        self.up = hb + hc  # switching fields
        self.down = hb - hc
        self.interaction = float(interaction)
        self.state = -np.ones(n_particles)

    def moment(self) -> float:
        """Mean moment, -1 .. 1."""
        return float(self.state.mean())

    def apply(self, fields: npt.ArrayLike) -> np.ndarray:
        """Moments after each applied field (the state continues)."""
        h = np.asarray(fields, dtype=np.float64).ravel()
        out = np.empty(h.size)
        for t, x in enumerate(h):
            for _ in range(self.state.size + 1):  # avalanche until self-consistent
                eff = x + self.interaction * self.state.mean()
                flip_up = (self.state < 0) & (eff >= self.up)
                flip_down = (self.state > 0) & (eff <= self.down)
                if not (flip_up.any() or flip_down.any()):
                    break
                self.state[flip_up] = 1.0
                self.state[flip_down] = -1.0
            out[t] = self.state.mean()
        return out


def forc_protocol(
    n_curves: int = 100,
    step: float = 0.01,
    saturation: float = 1.0,
    noise: float = 0.0,
    seed: int | None = 0,
    **ensemble: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First-order reversal curves of a :class:`ParticleEnsemble`: field, moment (with
    Gaussian ``noise``) and the curve of every sample (-1 for the calibration points at the
    top of the range). Reversal fields are evenly spaced in (-saturation, saturation)."""
    if n_curves < 2 or not step > 0 or not saturation > 0:
        raise ParameterError("need n_curves >= 2, step > 0 and saturation > 0")
    sample = ParticleEnsemble(seed=seed, **ensemble)  # type: ignore[arg-type]
    rng = np.random.default_rng(None if seed is None else seed + 1)
    fields, curves = [], []
    sample.apply(np.linspace(-saturation, saturation, 50))  # to positive saturation
    for k, hr in enumerate(np.linspace(saturation, -saturation, n_curves + 1)[1:]):
        fields.append(np.array([saturation]))
        curves.append(np.array([-1]))
        rise = np.arange(hr, saturation + step / 2, step)
        fields.append(rise)
        curves.append(np.full(rise.size, k))
    h = np.concatenate(fields)
    c = np.concatenate(curves)
    m = np.empty(h.size)
    pos = 0
    for f in fields:  # between curves the field returns to saturation (not measured)
        if f.size == 1:
            sample.apply(np.linspace(float(h[pos - 1]) if pos else saturation, saturation, 5))
        m[pos : pos + f.size] = sample.apply(f)
        pos += f.size
    return h, m + noise * rng.standard_normal(h.size), c
