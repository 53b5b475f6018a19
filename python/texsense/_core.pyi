"""Type stubs of the compiled core ``texsense._core`` (crates/python)."""

import numpy as np
import numpy.typing as npt

__version__: str

class ShapeError(ValueError): ...
class NeighbourIndexError(IndexError): ...
class ParameterError(ValueError): ...

class NeighbourMeanRepair:
    """Streaming eq. 6.14 repair over a CSR neighbour graph."""

    def __init__(self, indptr: npt.NDArray[np.int64], indices: npt.NDArray[np.int64]) -> None: ...
    @property
    def n_elements(self) -> int: ...
    def last_values(self) -> npt.NDArray[np.float32]: ...
    def reset(self) -> None: ...
    def run(
        self, frames: npt.NDArray[np.float32], valid: npt.NDArray[np.bool_]
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]: ...

class SpacerBank:
    """Spacer mechanics of N specimens (crates/core/src/spacer.rs)."""

    def __init__(
        self,
        backbone_a: float,
        backbone_m: float,
        densification: float,
        linear: float,
        friction: npt.NDArray[np.float64],
        creep_a: float,
        creep_tc: float,
        rest_rate: float,
        clutch_w: float,
        clutch_a: float,
        viscous: npt.NDArray[np.float64],
        kelvin: npt.NDArray[np.float64],
        recovery_factor: float,
        creep_p_ref: float,
        softening: npt.NDArray[np.float64],
        softening_recovery_s: float,
        scale: npt.NDArray[np.float64],
    ) -> None: ...
    @property
    def n_elements(self) -> int: ...
    def backbone(self, e: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
    def creep_strain(self) -> npt.NDArray[np.float64]: ...
    def run_displacement(
        self, dt: npt.NDArray[np.float64], compression: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def run_pressure(
        self, dt: npt.NDArray[np.float64], pressure: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def ramp_until(
        self, dt: float, rate: float, target: float, max_steps: int
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], bool]: ...

class PreisachBank:
    """Preisach stacks of N elements (crates/core/src/preisach.rs)."""

    def __init__(
        self,
        u_min: float,
        u_max: float,
        table: npt.NDArray[np.float64],
        n_elements: int,
        capacity: int,
    ) -> None: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def everett(
        self, alpha: npt.NDArray[np.float64], beta: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]: ...
    def run(
        self, inputs: npt.NDArray[np.float64], valid: npt.NDArray[np.bool_]
    ) -> npt.NDArray[np.float64]: ...
    def set_state(
        self, inputs: npt.NDArray[np.float64], outputs: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]: ...
    def clamped(self) -> npt.NDArray[np.uint64]: ...
    def forgotten(self) -> npt.NDArray[np.uint64]: ...
    def depth(self) -> npt.NDArray[np.uint64]: ...
    def outputs(self) -> npt.NDArray[np.float64]: ...

class DriftBank:
    """Recursive drift superposition of N elements (crates/core/src/drift.rs)."""

    def __init__(
        self,
        weights: npt.NDArray[np.float64],
        taus: npt.NDArray[np.float64],
        gamma: float,
        n_elements: int,
        rest_rate: float = 0.0,
        rest_window: float = 0.5,
        gamma_time: float = 0.0,
    ) -> None: ...
    def reset(self) -> None: ...
    def run(
        self,
        dt: npt.NDArray[np.float64],
        h: npt.NDArray[np.float64],
        valid: npt.NDArray[np.bool_],
    ) -> npt.NDArray[np.float64]: ...

class Compensation:
    """Preisach then drift in one pass (crates/core/src/compensation.rs)."""

    def __init__(
        self,
        u_min: float,
        u_max: float,
        table: npt.NDArray[np.float64],
        n_elements: int,
        capacity: int,
        offset: float,
        sign: float,
        gamma: float,
        weights: npt.NDArray[np.float64] | None = None,
        taus: npt.NDArray[np.float64] | None = None,
        rest_rate: float = 0.0,
        rest_window: float = 0.5,
        gamma_time: float = 0.0,
    ) -> None: ...
    def reset(self) -> None: ...
    def clamped(self) -> npt.NDArray[np.uint64]: ...
    def run(
        self,
        dt: npt.NDArray[np.float64],
        inputs: npt.NDArray[np.float64],
        valid: npt.NDArray[np.bool_],
    ) -> npt.NDArray[np.float64]: ...

def everett_terms(
    inputs: npt.NDArray[np.float64], u_min: float, u_max: float
) -> tuple[
    npt.NDArray[np.uint64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
]:
    """The Everett terms (indptr, alpha, beta, coef) of every sample of an input history."""
