"""An AD7745/AD7746-class capacitance-to-digital converter behind a multiplexer (§3.2.3.6).

The converter measures ±4.096 pF around a CAPDAC offset (0-17 pF, 7 bit) as a 24-bit code
(0x800000 = the CAPDAC value), at one of eight conversion rates (9.1-90.9 Hz), with a
factory accuracy of about 4 fF and noise that falls with the conversion time (down to ~4 aF
rms at 9.1 Hz; the values in :data:`NOISE_AF_RMS` are approximations of the datasheet's
resolution table). A multiplexer connects one element at a time, so a frame of N elements takes
N x (conversion time + settling) and every element has its own time stamp: 96 elements at
83.8 Hz with 4.7 ms settling take 1.6 s, as in the thesis (§6.2.1).

A capacitance to the shield of 100-150 pF (§3.3) is tolerated by the two-port measurement;
the datasheet's 0.5 fF (Cp1) and 5 fF (Cp2) per 200 pF are added as offsets, < 0.1 % of the
sensor range (§3.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from texsense.exceptions import ParameterError

__all__ = ["CAPDAC_LSB_PF", "CDC", "CONVERSION_RATES_HZ", "NOISE_AF_RMS", "RANGE_PF"]

#: Input range around the CAPDAC offset, pF.
RANGE_PF = 4.096
#: CAPDAC step: 17 pF over 7 bits.
CAPDAC_LSB_PF = 17.0 / 127.0
#: Conversion rates of the capacitance channel, Hz.
CONVERSION_RATES_HZ = (90.9, 83.8, 50.0, 26.7, 16.1, 13.2, 10.5, 9.1)
#: Approximate rms noise per conversion rate, aF.
NOISE_AF_RMS = {
    90.9: 16.0,
    83.8: 15.0,
    50.0: 10.0,
    26.7: 7.5,
    16.1: 5.5,
    13.2: 5.0,
    10.5: 4.5,
    9.1: 4.0,
}


@dataclass(frozen=True)
class CDC:
    """Converter settings.

    Parameters
    ----------
    rate_hz : float
        Conversion rate, one of :data:`CONVERSION_RATES_HZ`.
    settle_ms : float
        Multiplexer switching and settling time per element, ms.
    capdac_pF : float
        CAPDAC offset (rounded to its 7-bit step); the measurable window is
        capdac ± 4.096 pF.
    accuracy_fF : float
        Spread of the fixed per-channel offset error (uniform ± this), fF.
    cp1_pF, cp2_pF : float
        Parasitic capacitances to the shield on the excitation and input side, pF.
    noise_scale : float
        Multiplies the datasheet noise (1 = datasheet; the textile sensor's own noise can be
        added on top).
    """

    rate_hz: float = 83.8
    settle_ms: float = 4.7
    capdac_pF: float = 4.9
    accuracy_fF: float = 4.0
    cp1_pF: float = 125.0
    cp2_pF: float = 20.0
    noise_scale: float = 1.0

    def __post_init__(self) -> None:
        if self.rate_hz not in CONVERSION_RATES_HZ:
            raise ParameterError(
                f"rate_hz must be one of {CONVERSION_RATES_HZ} (AD7745), got {self.rate_hz}"
            )
        if not 0 <= self.capdac_pF <= 17.0:
            raise ParameterError(f"capdac_pF must lie in 0..17 pF, got {self.capdac_pF}")
        if self.settle_ms < 0 or self.accuracy_fF < 0 or self.noise_scale < 0:
            raise ParameterError("settle_ms, accuracy_fF and noise_scale must be >= 0")
        if self.cp1_pF < 0 or self.cp2_pF < 0:
            raise ParameterError("parasitic capacitances must be >= 0 pF")

    @property
    def capdac_effective_pF(self) -> float:
        """The CAPDAC value actually set (7-bit steps)."""
        return round(self.capdac_pF / CAPDAC_LSB_PF) * CAPDAC_LSB_PF

    @property
    def element_time_s(self) -> float:
        """Time per element: one conversion plus settling, s."""
        return 1.0 / self.rate_hz + self.settle_ms / 1000.0

    def frame_time_s(self, n_elements: int, converters: int = 1) -> float:
        """Time for one frame of ``n_elements`` read by ``converters`` converters in parallel."""
        return int(np.ceil(n_elements / converters)) * self.element_time_s

    @property
    def parasitic_offset_pF(self) -> float:
        """Offset caused by the parasitic capacitances (datasheet: 0.5 fF and 5 fF per 200 pF)."""
        return (0.5 * self.cp1_pF / 200.0 + 5.0 * self.cp2_pF / 200.0) * 1e-3

    def channel_offsets(self, n: int, rng: np.random.Generator) -> npt.NDArray[np.float64]:
        """Fixed per-channel offset errors (pF) within ± accuracy."""
        return rng.uniform(-self.accuracy_fF, self.accuracy_fF, n) * 1e-3

    def convert(
        self,
        capacitance_pF: npt.ArrayLike,
        rng: np.random.Generator,
        offsets_pF: npt.ArrayLike | float = 0.0,
    ) -> tuple[npt.NDArray[np.uint32], npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
        """Convert true capacitances to 24-bit codes.

        Returns
        -------
        codes : ndarray of uint32
            24-bit codes.
        measured_pF : ndarray
            The capacitance the codes stand for.
        saturated : ndarray of bool
            True where the input was outside the CAPDAC ± 4.096 pF window.
        """
        c = np.asarray(capacitance_pF, dtype=np.float64)
        noise = rng.normal(0.0, NOISE_AF_RMS[self.rate_hz] * 1e-6 * self.noise_scale, c.shape)
        x = c + noise + np.asarray(offsets_pF) + self.parasitic_offset_pF
        full = 2**23
        raw = np.round(full + (x - self.capdac_effective_pF) / RANGE_PF * full)
        saturated = (raw < 0) | (raw > 2**24 - 1)
        codes = np.clip(raw, 0, 2**24 - 1).astype(np.uint32)
        measured = self.capdac_effective_pF + (codes.astype(np.float64) - full) / full * RANGE_PF
        return codes, measured, saturated
