"""A virtual textile pressure mat: spacer elements, electrodes, multiplexed readout, failures.

:meth:`VirtualMat.scan` takes a true pressure history (T frames of N elements) and returns
what the textile sensor would deliver: the capacitance of every element read one after the
other by an AD7745-class converter (each element with its own time stamp), with failed
elements reading 0 pF — plus the ground truth (pressure, compression, failures).

Two architectures (§2.3.2): single electrodes over a common electrode (default), and
perpendicular stripes whose crossings are the elements; there a neighbour compressed to 50 %
changes an element's capacitance by 3 % (crosstalk).

Examples
--------
>>> import numpy as np
>>> mat = VirtualMat.seat(seed=1)
>>> mat.layout.n_elements, round(mat.cdc.frame_time_s(mat.layout.n_elements), 2)
(96, 1.6)
>>> scan = mat.scan(np.arange(3) * 2.0, np.full((3, 96), 1.0))
>>> scan.capacitance.element_times.shape
(3, 96)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from texsense.data.layout import Layout
from texsense.data.recording import Recording
from texsense.exceptions import ParameterError
from texsense.sensor.electrode import Electrode, wet_factor
from texsense.sensor.materials import PRESETS
from texsense.sensor.readout import CDC
from texsense.sim.failures import FailureModel, FailureState
from texsense.sim.spacer import Spacer

__all__ = ["CROSSTALK_AT_HALF", "MatScan", "VirtualMat"]

#: Relative capacitance change of a stripe crossing when one neighbour is compressed to 50 %.
CROSSTALK_AT_HALF = 0.03
#: Seat of the thesis (§6.2.1): 240 electrodes of 2 x 2 cm, 0.7 mm apart.
SEAT_ROWS, SEAT_COLS, SEAT_PITCH_CM = 15, 16, 2.07


def seat_checkerboard() -> npt.NDArray[np.bool_]:
    """The 96 active elements of the 240-element seat: a checkerboard over the 12 rows
    nearest the backrest (the thesis selected 96 of 240 elements without listing them; this
    selection keeps its count and pattern)."""
    rr, cc = np.mgrid[0:SEAT_ROWS, 0:SEAT_COLS]
    return ((rr + cc) % 2 == 0) & (rr >= SEAT_ROWS - 12)


@dataclass
class MatScan:
    """Result of :meth:`VirtualMat.scan`."""

    capacitance: Recording
    pressure: Recording
    compression: Recording
    failed: npt.NDArray[np.bool_]


class VirtualMat:
    """A textile sensor mat on the virtual bench.

    Parameters
    ----------
    layout : Layout
        Element positions (the electrodes).
    spacer : str
        Spacer preset for every element (specimen variation per element by ``seed``).
    electrode : Electrode, optional
        Electrode geometry (default 2 x 2 cm).
    cdc : CDC, optional
        Converter; default AD7745 at 83.8 Hz with 4.7 ms settling, CAPDAC centred on the
        spacer's capacitance range.
    failures : FailureModel, optional
        Failure model (default: none).
    architecture : {"electrodes", "stripes"}
        Single electrodes with a common electrode, or perpendicular stripes (crosstalk).
    converters : int
        Converters working in parallel (frame time divides accordingly).
    water_fraction : float
        Water content of a wet spacer (eq. 3.22), dried with ``drying_s``.
    element_spread : float
        Relative spread (1 sigma) of the electrode area between elements (embroidery,
        lamination): each element's plate capacitance is scaled by its own factor.
    stray_spread_pF : float
        Spread (1 sigma) of the stray capacitance between elements (line lengths), pF.
    seed : int
        Seed of specimen variation, converter offsets, noise and failures.
    """

    def __init__(
        self,
        layout: Layout,
        spacer: str = "textile-3mm",
        *,
        electrode: Electrode | None = None,
        cdc: CDC | None = None,
        failures: FailureModel | None = None,
        architecture: str = "electrodes",
        converters: int = 1,
        water_fraction: float = 0.0,
        drying_s: float = 3 * 3600.0,
        element_spread: float = 0.04,
        stray_spread_pF: float = 0.1,
        seed: int = 0,
    ) -> None:
        if spacer not in PRESETS:
            raise ParameterError(f"unknown spacer preset {spacer!r}; known: {', '.join(PRESETS)}")
        if architecture not in ("electrodes", "stripes"):
            raise ParameterError("architecture must be 'electrodes' or 'stripes'")
        if architecture == "stripes" and layout.shape is None:
            raise ParameterError("the stripe architecture needs a grid layout")
        if converters < 1:
            raise ParameterError(f"converters must be >= 1, got {converters}")
        if not 0 <= water_fraction < 0.1 or drying_s <= 0:
            raise ParameterError("water_fraction must lie in [0, 0.1) and drying_s be > 0")
        self.layout = layout
        self.spacer_name = spacer
        self.electrode = electrode or Electrode()
        thickness = PRESETS[spacer].thickness_mm
        if cdc is None:
            lo, hi = self.electrode.capacitance_pF(
                thickness, [0.0, 0.8 * PRESETS[spacer].densification * thickness]
            )
            cdc = CDC(capdac_pF=float(np.clip((lo + hi) / 2, 0.0, 17.0)))
        self.cdc = cdc
        self.failures = failures or FailureModel.none()
        self.architecture = architecture
        self.converters = int(converters)
        self.water_fraction = water_fraction
        self.drying_s = drying_s
        self.seed = seed
        self._rng = np.random.default_rng(seed)
        self.spacer = Spacer.preset(spacer, n_specimens=layout.n_elements, seed=seed)
        self.offsets_pF = self.cdc.channel_offsets(layout.n_elements, self._rng)
        if not (0 <= element_spread < 0.3 and stray_spread_pF >= 0):
            raise ParameterError("element_spread must lie in [0, 0.3), stray_spread_pF be >= 0")
        n = layout.n_elements
        self.element_gain = np.clip(1.0 + element_spread * self._rng.standard_normal(n), 0.5, 1.5)
        stray = self.electrode.stray_pF
        self.element_stray_pF = np.clip(
            stray + stray_spread_pF * self._rng.standard_normal(n), 0.0, None
        )
        self._clock = 0.0
        self._failing: FailureState | None = None  # drawn at the first scan, kept after

    @classmethod
    def seat(cls, spacer: str = "textile-3mm", **kwargs: Any) -> VirtualMat:
        """The thesis's seat sensor (§6.2.1): 96 active of 240 electrodes, 2 x 2 cm."""
        layout = Layout.grid(
            SEAT_ROWS,
            SEAT_COLS,
            pitch_cm=SEAT_PITCH_CM,
            active=seat_checkerboard(),
            element_size_cm=2.0,
        ).with_orientation("seat")  # row 0 is the front edge, the backrest is below
        return cls(layout, spacer, **kwargs)

    @classmethod
    def prototype(cls, n_elements: int, spacer: str = "textile-6mm", **kwargs: Any) -> VirtualMat:
        """One of the thesis's single-electrode prototypes (§2.3.2.2): 1, 16 (4 x 4), 30
        (5 x 6) or 240 (15 x 16) electrodes of 2 x 2 cm on a 2.07 cm pitch (0.7 mm apart)."""
        shapes = {1: (1, 1), 16: (4, 4), 30: (5, 6), 240: (SEAT_ROWS, SEAT_COLS)}
        if n_elements not in shapes:
            raise ParameterError(f"prototypes have 1, 16, 30 or 240 elements, not {n_elements}")
        rows, cols = shapes[n_elements]
        layout = Layout.grid(rows, cols, pitch_cm=SEAT_PITCH_CM, element_size_cm=2.0)
        return cls(layout, spacer, **kwargs)

    def element_offsets_s(self) -> npt.NDArray[np.float64]:
        """When each element is read within a frame (s after the frame start)."""
        slot = np.arange(self.layout.n_elements) // self.converters
        return np.asarray(slot * self.cdc.element_time_s, dtype=np.float64)

    def _crosstalk(self, cap: np.ndarray, comp_fraction: np.ndarray) -> np.ndarray:
        indptr, indices = self.layout.neighbours
        owner = np.repeat(np.arange(self.layout.n_elements), np.diff(indptr))
        extra = np.zeros_like(cap)
        np.add.at(extra.T, owner, (comp_fraction[:, indices] / 0.5).T)
        return cap * (1.0 + CROSSTALK_AT_HALF * extra)

    def scan(self, frame_times_s: npt.ArrayLike, pressure_ncm2: npt.ArrayLike) -> MatScan:
        """Scan a pressure history.

        Parameters
        ----------
        frame_times_s : array_like (T,)
            Start of each scan, s, increasing (the mat keeps its mechanical state between
            calls, so consecutive calls continue a session).
        pressure_ncm2 : array_like (T, N)
            True pressure on every element; element i is read at
            ``frame_time + element_offsets_s()[i]`` and the pressure is interpolated there.
        """
        t = np.asarray(frame_times_s, dtype=np.float64)
        p = np.asarray(pressure_ncm2, dtype=np.float64)
        n = self.layout.n_elements
        if t.ndim != 1 or p.shape != (t.size, n):
            raise ParameterError(f"pressure must have shape ({t.size}, {n}), got {p.shape}")
        if t.size and (np.any(np.diff(t) <= 0) or t[0] < self._clock):
            raise ParameterError("frame times must increase and continue the session's clock")
        if np.any(p < 0) or not np.all(np.isfinite(p)):
            raise ParameterError("pressure must be finite and >= 0")
        offsets = self.element_offsets_s()
        element_times = t[:, None] + offsets[None, :]
        if t.size > 1:
            p_at = np.empty_like(p)
            for i in range(n):
                p_at[:, i] = np.interp(element_times[:, i], t, p[:, i])
        else:
            p_at = p
        # every element sees the same period between its own samples
        comp_mm = self.spacer.drive_pressure(element_times[:, 0] if t.size else t, p_at)
        thickness = self.spacer.thickness_mm
        comp = np.minimum(comp_mm.compression_mm, thickness * (1 - 1e-9))
        cap = self.electrode.capacitance_pF(thickness, comp)
        if self.water_fraction:
            water = self.water_fraction * np.exp(-element_times / self.drying_s)
            stray = self.electrode.stray_pF
            cap = (cap - stray) * wet_factor(comp / thickness, water, self.electrode.eps_r0) + stray
        stray = self.electrode.stray_pF
        cap = (cap - stray) * self.element_gain + self.element_stray_pF
        if self.architecture == "stripes":
            cap = self._crosstalk(cap, comp / thickness)
        if self._failing is None:
            self._failing = self.failures.start(n, self._rng)
        failed = self.failures.simulate(element_times[:, 0], p_at, self._rng, self._failing)
        _, measured, saturated = self.cdc.convert(cap, self._rng, self.offsets_pF[None, :])
        measured = np.where(failed, 0.0, measured)
        self._clock = float(t[-1]) if t.size else self._clock
        meta = {
            "source": "texsense virtual mat",
            "spacer": self.spacer_name,
            "architecture": self.architecture,
            "seed": self.seed,
            "cdc_rate_hz": self.cdc.rate_hz,
            "frame_time_s": self.cdc.frame_time_s(n, self.converters),
        }
        common: dict[str, Any] = {"element_times": element_times, "meta": meta}
        return MatScan(
            capacitance=Recording(
                measured, t, self.layout, "capacitance", "pF", valid=~saturated, **common
            ),
            pressure=Recording(p_at, t, self.layout, "pressure", "N/cm2", **common),
            compression=Recording(comp, t, self.layout, "compression", "mm", **common),
            failed=failed,
        )
