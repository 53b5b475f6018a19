//! The kernel path (scalar or SIMD) of the compiled core: `texsense_core::simd`.

use pyo3::prelude::*;

/// `(path in use, best path of this processor)`: "avx2" or "scalar" each.
#[pyfunction]
#[pyo3(name = "simd_path")]
pub(crate) fn py_simd_path() -> (&'static str, &'static str) {
    use texsense_core::simd;
    (simd::path().name(), simd::detected().name())
}

/// Allow (True, the default) or forbid the SIMD kernels process-wide; both give the same
/// numbers, bit for bit (for benchmarks and tests that compare the two paths).
#[pyfunction]
#[pyo3(name = "set_simd")]
pub(crate) fn py_set_simd(enabled: bool) {
    texsense_core::simd::set_enabled(enabled);
}
