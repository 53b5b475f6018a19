//! The kernel path (scalar or SIMD) of the compiled core: `texsense_core::simd`.

use pyo3::prelude::*;

/// `(path in use, best path of this processor)`: "avx512", "avx2" or "scalar" each.
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

/// The best SIMD path batches may take from now on, process-wide: "avx512" (the default:
/// the best the processor has), "avx2" (forces the AVX2 kernels on an AVX-512 processor)
/// or "scalar"; all give the same numbers, bit for bit.
#[pyfunction]
#[pyo3(name = "set_simd_path")]
pub(crate) fn py_set_simd_path(best: &str) -> PyResult<()> {
    use texsense_core::simd::{set_limit, Path};
    let path = match best {
        "scalar" => Path::Scalar,
        "avx2" => Path::Avx2,
        "avx512" => Path::Avx512,
        _ => {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "simd path {best:?}: one of scalar, avx2, avx512"
            )))
        }
    };
    set_limit(path);
    Ok(())
}
