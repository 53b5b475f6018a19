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

/// `(lookup in use, this processor's faster lookup)`: "gather" or "loads" each — how the
/// AVX-512 kernels read the Everett cells of eight elements (`texsense_core::simd::Lookup`).
#[pyfunction]
#[pyo3(name = "simd_lookup")]
pub(crate) fn py_simd_lookup() -> (&'static str, &'static str) {
    use texsense_core::simd;
    (simd::lookup().name(), simd::detected_lookup().name())
}

/// The lookup the AVX-512 kernels use from now on, process-wide: "gather", "loads", or
/// "auto" (the processor's faster one, the default); both give the same numbers, bit for
/// bit (for the benchmark and tests that compare the two).
#[pyfunction]
#[pyo3(name = "set_simd_lookup")]
pub(crate) fn py_set_simd_lookup(lookup: &str) -> PyResult<()> {
    use texsense_core::simd::{set_lookup, Lookup};
    if lookup == "auto" {
        set_lookup(None);
        return Ok(());
    }
    let chosen = Lookup::from_name(lookup).ok_or_else(|| {
        pyo3::exceptions::PyValueError::new_err(format!(
            "simd lookup {lookup:?}: one of gather, loads, auto"
        ))
    })?;
    set_lookup(Some(chosen));
    Ok(())
}
