//! `texsense._core`: the thin PyO3 binding of `texsense-core`, one module per class.
//!
//! Only array conversion and error mapping live here; every algorithm is in the core crate.
//! Each `CoreError` variant maps to its own exception class, re-exported by
//! `texsense.exceptions`. This file only registers the classes.

use pyo3::prelude::*;

mod arrays;
mod chain;
mod compensation;
mod convert;
mod detect;
mod drift;
mod errors;
mod live;
mod preisach;
mod repair;
mod simd;
mod spacer;
mod stats;
mod text;

/// The compiled core of texsense.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<spacer::PySpacerBank>()?;
    m.add_class::<preisach::PyPreisachBank>()?;
    m.add_class::<preisach::PyPreisachBank32>()?;
    m.add_class::<drift::PyDriftBank>()?;
    m.add_class::<drift::PyDriftBank32>()?;
    m.add_class::<compensation::PyCompensation>()?;
    m.add_class::<detect::PyFailureDetector>()?;
    m.add_class::<convert::PyCurve>()?;
    m.add_class::<convert::PyConverter>()?;
    m.add_class::<repair::PyLocalRepair>()?;
    m.add_class::<chain::PyChain>()?;
    m.add_class::<stats::PyGridStats>()?;
    m.add_class::<live::PyMotionTest>()?;
    m.add_function(wrap_pyfunction!(preisach::py_everett_terms, m)?)?;
    m.add_function(wrap_pyfunction!(chain::py_mcu_blob_info, m)?)?;
    m.add_function(wrap_pyfunction!(simd::py_simd_path, m)?)?;
    m.add_function(wrap_pyfunction!(simd::py_set_simd, m)?)?;
    m.add_function(wrap_pyfunction!(simd::py_set_simd_path, m)?)?;
    m.add_function(wrap_pyfunction!(simd::py_simd_lookup, m)?)?;
    m.add_function(wrap_pyfunction!(simd::py_set_simd_lookup, m)?)?;
    m.add_function(wrap_pyfunction!(text::py_parse_row, m)?)?;
    m.add_function(wrap_pyfunction!(text::py_parse_json_numbers, m)?)?;
    m.add_function(wrap_pyfunction!(text::py_parse_json_frame, m)?)?;
    m.add_function(wrap_pyfunction!(live::py_frame_bounds, m)?)?;
    m.add_function(wrap_pyfunction!(live::py_first_off_scale, m)?)?;
    m.add_function(wrap_pyfunction!(live::py_exposure_advance, m)?)?;
    let py = m.py();
    m.add("ShapeError", py.get_type::<errors::ShapeError>())?;
    m.add(
        "NeighbourIndexError",
        py.get_type::<errors::NeighbourIndexError>(),
    )?;
    m.add("ParameterError", py.get_type::<errors::ParameterError>())?;
    Ok(())
}
