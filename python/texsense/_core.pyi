"""Type stubs of the compiled core ``texsense._core`` (crates/python)."""

import numpy as np
import numpy.typing as npt

__version__: str

class ShapeError(ValueError): ...
class NeighbourIndexError(IndexError): ...
class ParameterError(ValueError): ...

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

F64 = npt.NDArray[np.float64]
Bools = npt.NDArray[np.bool_]
U8 = npt.NDArray[np.uint8]
I64 = npt.NDArray[np.int64]

class PreisachBank:
    """Preisach stacks of N elements (crates/core/src/preisach.rs); output sign (h + offset)."""

    def __init__(
        self,
        u_min: float,
        u_max: float,
        table: F64,
        n_elements: int,
        capacity: int,
        offset: float = 0.0,
        sign: float = 1.0,
    ) -> None: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def everett(self, alpha: F64, beta: F64) -> F64: ...
    def run(self, inputs: F64, valid: Bools, schedule: str = "parallel") -> F64: ...
    def state_bytes(self) -> int: ...
    def set_state(self, inputs: F64, outputs: F64) -> F64: ...
    def clamped(self) -> npt.NDArray[np.uint64]: ...
    def forgotten(self) -> npt.NDArray[np.uint64]: ...
    def depth(self) -> npt.NDArray[np.uint64]: ...
    def outputs(self) -> F64: ...

class DriftBank:
    """Recursive drift superposition of N elements (crates/core/src/drift.rs)."""

    def __init__(
        self,
        weights: F64,
        taus: F64,
        gamma: float,
        n_elements: int,
        rest_rate: float = 0.0,
        rest_window: float = 0.5,
        gamma_time: float = 0.0,
    ) -> None: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def run(self, dt: F64, h: F64, valid: Bools) -> F64: ...

class Compensation:
    """Preisach then drift in one pass (crates/core/src/compensation.rs)."""

    def __init__(self, preisach: PreisachBank, drift: DriftBank | None = None) -> None: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def clamped(self) -> npt.NDArray[np.uint64]: ...
    def run(self, dt: F64, inputs: F64, valid: Bools) -> F64: ...

class FailureDetector:
    """Failure codes of raw capacitance (crates/core/src/detect.rs)."""

    def __init__(
        self,
        indptr: I64,
        indices: I64,
        jump_pf: F64,
        baseline_pf: F64 | None,
        max_pf: F64 | None,
        min_pf: float,
        low_share: float,
        high_share: float,
        stuck_frames: int,
        stuck_pf: float,
        neighbour_change_pf: float,
        stuck_floor_pf: float = ...,
    ) -> None: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def run(self, readings: F64, valid: Bools) -> U8: ...

class Curve:
    """A piecewise-linear curve held at its ends (crates/core/src/convert.rs)."""

    def __init__(self, x: F64, y: F64) -> None: ...
    def at(self, values: F64) -> F64: ...

class Converter:
    """Capacitance -> compression per element, eq. 2.1 (crates/core/src/convert.rs)."""

    def __init__(self, offset: F64, gain: F64, curve: Curve | None = None) -> None: ...
    @property
    def n_elements(self) -> int: ...
    def run(self, readings: F64, valid: Bools) -> F64: ...

class LocalRepair:
    """zero, last-value, eq. 6.14 neighbour mean, weighted mean (crates/core/src/repair.rs)."""

    def __init__(
        self,
        method: str,
        n_elements: int,
        indptr: I64 | None = None,
        indices: I64 | None = None,
        weights: F64 | None = None,
    ) -> None: ...
    @property
    def n_elements(self) -> int: ...
    def last_values(self) -> F64: ...
    def reset(self) -> None: ...
    def run(self, values: F64, valid: Bools) -> tuple[F64, U8]: ...

class Chain:
    """detect -> convert -> compensation -> repair in one pass (crates/core/src/chain.rs)."""

    def __init__(
        self,
        converter: Converter,
        *,
        detector: FailureDetector | None = None,
        compensation: Compensation | None = None,
        loading: Curve | None = None,
        repair: LocalRepair | None = None,
    ) -> None: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def state_bytes_per_element(self) -> int: ...
    def run(self, dt: F64, readings: F64, valid: Bools) -> tuple[F64, U8]: ...

def everett_terms(
    inputs: npt.NDArray[np.float64], u_min: float, u_max: float
) -> tuple[
    npt.NDArray[np.uint64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
]:
    """The Everett terms (indptr, alpha, beta, coef) of every sample of an input history."""
