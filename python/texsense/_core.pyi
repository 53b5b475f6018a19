"""Type stubs of the compiled core ``texsense._core`` (crates/python), checked against the
module by ``stubtest`` in scripts/test.sh."""

from collections.abc import Sequence
from typing import Self, final

import numpy as np
import numpy.typing as npt

_F64 = npt.NDArray[np.float64]
_Bools = npt.NDArray[np.bool_]
_U8 = npt.NDArray[np.uint8]
_F32 = npt.NDArray[np.float32]
_U64 = npt.NDArray[np.uint64]
_I64 = npt.NDArray[np.int64]

__all__ = [
    "Chain",
    "Compensation",
    "Converter",
    "Curve",
    "DriftBank",
    "DriftBank32",
    "FailureDetector",
    "GridStats",
    "LocalRepair",
    "MotionTest",
    "NeighbourIndexError",
    "ParameterError",
    "PreisachBank",
    "PreisachBank32",
    "ShapeError",
    "SpacerBank",
    "__version__",
    "everett_terms",
    "exposure_advance",
    "first_off_scale",
    "frame_bounds",
    "mcu_blob_info",
    "parse_json_frame",
    "parse_json_numbers",
    "parse_row",
    "set_simd",
    "set_simd_lookup",
    "set_simd_path",
    "simd_lookup",
    "simd_path",
]

__version__: str

class ShapeError(ValueError):
    """An array has the wrong shape or length."""

class NeighbourIndexError(IndexError):
    """A neighbour index points outside the layout."""

class ParameterError(ValueError):
    """A parameter is outside its domain."""

@final
class SpacerBank:
    """Spacer mechanics of N specimens (crates/core/src/spacer.rs, bouc_wen.rs)."""

    def __new__(
        cls,
        backbone_a: float,
        backbone_m: float,
        densification: float,
        linear: float,
        friction: _F64,
        creep_a: float,
        creep_tc: float,
        rest_rate: float,
        clutch_w: float,
        clutch_a: float,
        viscous: _F64,
        kelvin: _F64,
        recovery_factor: float,
        creep_p_ref: float,
        softening: _F64,
        softening_recovery_s: float,
        scale: _F64,
    ) -> Self: ...
    @staticmethod
    def bouc_wen(
        stiffness: float,
        exponent: float,
        densification: float,
        friction: float,
        slip: float,
        bw_n: float,
        bw_beta: float,
        creep_share: float,
        creep_rate: float,
        creep_exponent: float,
        scale: _F64,
    ) -> SpacerBank: ...
    @property
    def n_elements(self) -> int: ...
    def backbone(self, e: _F64) -> _F64: ...
    def creep_strain(self) -> _F64: ...
    def run_displacement(self, dt: _F64, compression: _F64) -> tuple[_F64, _F64]: ...
    def run_pressure(self, dt: _F64, pressure: _F64) -> tuple[_F64, _F64]: ...
    def ramp_until(
        self, dt: float, rate: float, target: float, max_steps: int
    ) -> tuple[_F64, _F64, _F64, bool]: ...

@final
class PreisachBank:
    """Preisach stacks of N elements (crates/core/src/preisach.rs); output sign (h + offset)."""

    def __new__(
        cls,
        u_min: float,
        u_max: float,
        table: _F64,
        n_elements: int,
        capacity: int,
        offset: float = 0.0,
        sign: float = 1.0,
    ) -> Self: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def everett(self, alpha: _F64, beta: _F64) -> _F64: ...
    def run(
        self, inputs: _F64, valid: _Bools, schedule: str = "parallel", out: _F64 | None = None
    ) -> _F64: ...
    def state_bytes(self) -> int: ...
    def set_state(self, inputs: _F64, outputs: _F64) -> _F64: ...
    def clamped(self) -> _U64: ...
    def forgotten(self) -> _U64: ...
    def depth(self) -> _U64: ...
    def outputs(self) -> _F64: ...

@final
class PreisachBank32:
    """Experimental: the Preisach model in float32, eight elements per AVX2 register
    (crates/core/src/preisach/f32x8.rs); 28 turning points per element, one thread."""

    def __new__(
        cls,
        u_min: float,
        u_max: float,
        table: _F64,
        n_elements: int,
        offset: float = 0.0,
        sign: float = 1.0,
    ) -> Self: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def run(self, inputs: _F64, valid: _Bools, out: _F64 | None = None) -> _F64: ...

@final
class DriftBank:
    """Recursive drift superposition of N elements (crates/core/src/drift.rs)."""

    def __new__(
        cls,
        weights: _F64,
        taus: _F64,
        gamma: float,
        n_elements: int,
        rest_rate: float = 0.0,
        rest_window: float = 0.5,
        gamma_time: float = 0.0,
        exponent: float = 1.0,
    ) -> Self: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def run(self, dt: _F64, h: _F64, valid: _Bools) -> _F64: ...

@final
class DriftBank32:
    """Experimental: eq. 5.8 on the time clock in float32, eight elements per AVX2 register
    (crates/core/src/drift/f32x8.rs), one thread."""

    def __new__(cls, weights: _F64, taus: _F64, gamma: float, n_elements: int) -> Self: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def run(self, dt: _F64, h: _F64, valid: _Bools) -> _F64: ...

@final
class Compensation:
    """Preisach then drift in one pass (crates/core/src/compensation.rs)."""

    def __new__(
        cls, preisach: PreisachBank, drift: DriftBank | None = None, level: Curve | None = None
    ) -> Self: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def clamped(self) -> _U64: ...
    def run(self, dt: _F64, inputs: _F64, valid: _Bools) -> _F64: ...

@final
class FailureDetector:
    """Failure codes of raw capacitance (crates/core/src/detect.rs)."""

    def __new__(
        cls,
        indptr: _I64,
        indices: _I64,
        jump_pf: _F64,
        baseline_pf: _F64 | None,
        max_pf: _F64 | None,
        min_pf: float,
        low_share: float,
        high_share: float,
        stuck_frames: int,
        stuck_pf: float,
        neighbour_change_pf: float,
        stuck_floor_pf: float = ...,
    ) -> Self: ...
    @property
    def n_elements(self) -> int: ...
    def reset(self) -> None: ...
    def run(self, readings: _F64, valid: _Bools) -> _U8: ...

@final
class Curve:
    """A piecewise-linear curve held at its ends (crates/core/src/convert.rs)."""

    def __new__(cls, x: _F64, y: _F64) -> Self: ...
    def at(self, values: _F64) -> _F64: ...

@final
class Converter:
    """Capacitance -> compression per element, eq. 2.1 (crates/core/src/convert.rs)."""

    def __new__(cls, offset: _F64, gain: _F64, curve: Curve | None = None) -> Self: ...
    @property
    def n_elements(self) -> int: ...
    def run(self, readings: _F64, valid: _Bools) -> _F64: ...

@final
class LocalRepair:
    """zero, last-value, eq. 6.14 neighbour mean, weighted mean (crates/core/src/repair.rs)."""

    def __new__(
        cls,
        method: str,
        n_elements: int,
        indptr: _I64 | None = None,
        indices: _I64 | None = None,
        weights: _F64 | None = None,
    ) -> Self: ...
    @property
    def n_elements(self) -> int: ...
    def last_values(self) -> _F64: ...
    def reset(self) -> None: ...
    def run(self, values: _F64, valid: _Bools) -> tuple[_F64, _U8]: ...

_ChainStage = FailureDetector | Converter | Compensation | DriftBank | Curve | LocalRepair

@final
class Chain:
    """A mat's stages compiled, run in order (crates/core/src/chain.rs)."""

    def __new__(cls, n_elements: int, stages: Sequence[_ChainStage]) -> Self: ...
    @property
    def n_elements(self) -> int: ...
    @property
    def stage_names(self) -> list[str]: ...
    def reset(self) -> None: ...
    def state_bytes_per_element(self) -> int: ...
    def run(self, dt: _F64, readings: _F64, valid: _Bools) -> tuple[_F64, _U8]: ...
    def run_f32(self, dt: _F64, readings: _F32, valid: _Bools) -> tuple[_F32, _U8]:
        """``run`` on float32 readings: its values rounded to float32, bit for bit."""
    def step(
        self,
        dt: float,
        readings: _F64,
        valid: _Bools | None,
        out: _F64,
        codes: _U8,
        measured: _Bools,
    ) -> None:
        """One frame into arrays the caller holds: values, codes and measured (code 0)."""
    def step_new(self, dt: float, readings: _F64, valid: _Bools | None) -> tuple[_F64, _U8, _Bools]:
        """One frame into new arrays: (values, codes, measured)."""
    @property
    def last_t(self) -> float | None: ...
    @last_t.setter
    def last_t(self, t: float | None) -> None: ...
    def step_at(self, t: float, readings: object, valid: object) -> tuple[_F64, _U8, _Bools] | None:
        """One frame at time ``t`` into new arrays, or None when the inputs need converting."""
    def snapshot(self) -> bytes: ...
    def restore(self, state: bytes) -> None: ...
    def mcu_blob(self) -> bytes: ...

@final
class GridStats:
    """One frame's pressure statistics on a grid layout (crates/core/src/stats.rs)."""

    def __new__(
        cls, area: _F64, xy: _F64, cells: _I64, rows: int, cols: int, window: int
    ) -> Self: ...
    def frame(
        self, pressure: _F64, threshold: float
    ) -> tuple[float, float, float, float, float, float, float, float] | None:
        """(load, contact area, peak, ppi, cof x, cof y, cof row, cof column), or None."""

@final
class MotionTest:
    """The in-use drift estimator's empty count and movement test (crates/core/src/live.rs)."""

    def __new__(cls, blocks: _I64, area: _F64) -> Self: ...
    def forget(self) -> None:
        """Forget the last frame."""

    def step(
        self,
        x: _F64,
        gain: _F64,
        ok: _Bools,
        empty: float,
        empty_count: int,
        floor: float,
        motion: float,
    ) -> tuple[_F64, str]:
        """``x * gain`` and "empty", "moved" or "still"."""

def first_off_scale(t: _F64, limit: float) -> int | None:
    """The index of the first time not a number or beyond ``limit`` in size, or None."""

def frame_bounds(
    values: _F64,
    ok: _Bools,
    drift: float,
    edges: _F64,
    scale: _F64,
    mult_edges: _F64,
    mult: _F64,
    multiplier: float | None,
    r_repaired: float,
    range_max: float | None,
) -> tuple[_F64, _F64]:
    """The lower and upper bounds of one frame (``intervals.bounds``, the same bits)."""

def exposure_advance(
    pressure: _F64,
    lower: _F64 | None,
    upper: _F64 | None,
    threshold: float,
    count_possible: bool,
    offload_s: float,
    reposition_s: float,
    dt: float,
    skipped: bool,
    exposure: _F64,
    relief: _F64,
    loaded_last: _Bools,
    confident: _Bools,
    possible: _Bools,
) -> tuple[bool, int, float]:
    """One exposure step of single elements, in place: (any loaded, at the reposition time,
    largest exposure)."""

def mcu_blob_info(blob: bytes) -> tuple[int, list[str], int, int, int, int]:
    """(elements, stage names, memory bytes, state bytes per element, scratch bytes per
    element, fixed bytes) of a model blob, checked as the C side checks it."""

def simd_path() -> tuple[str, str]:
    """(path in use, best path of this processor): "avx512", "avx2" or "scalar" each."""

def set_simd(enabled: bool) -> None:
    """Allow (True, the default) or forbid the SIMD kernels process-wide (same numbers)."""

def set_simd_path(best: str) -> None:
    """The best SIMD path batches may take: "avx512" (default), "avx2" or "scalar"."""

def simd_lookup() -> tuple[str, str]:
    """(lookup in use, this processor's faster lookup): "gather" or "loads" each."""

def set_simd_lookup(lookup: str) -> None:
    """How the AVX-512 kernels read table cells: "gather", "loads" or "auto" (default)."""

def parse_row(line: str, sep: str, expected: int) -> npt.NDArray[np.float32] | None:
    """Exactly ``expected`` numbers separated by ``sep``, as float32, or None (the fast path)."""

def parse_json_frame(
    payload: bytes, expected: int
) -> tuple[int, float, str | None, float | None, npt.NDArray[np.float64]] | None:
    """A whole frame payload of the plain form: (seq, t, unit, dt, values), or None (the
    station's JSON parse then reads it)."""

def parse_json_numbers(text: bytes, expected: int) -> npt.NDArray[np.float64] | None:
    """The inside of a JSON list of ``expected`` numbers or nulls (NaN), or None (the fast
    path of a frame's values)."""

def everett_terms(inputs: _F64, u_min: float, u_max: float) -> tuple[_U64, _F64, _F64, _F64]:
    """The Everett terms (indptr, alpha, beta, coef) of every sample of an input history."""
