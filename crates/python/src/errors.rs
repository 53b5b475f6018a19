//! The exceptions of the binding: one class per `CoreError` variant, re-exported by
//! `texsense.exceptions`.

use pyo3::create_exception;
use pyo3::exceptions::{PyIndexError, PyValueError};
use pyo3::prelude::*;
use texsense_core::CoreError;

create_exception!(
    _core,
    ShapeError,
    PyValueError,
    "An array has the wrong shape or length."
);
create_exception!(
    _core,
    NeighbourIndexError,
    PyIndexError,
    "A neighbour index points outside the layout."
);
create_exception!(
    _core,
    ParameterError,
    PyValueError,
    "A parameter is outside its domain."
);

pub(crate) fn to_py(err: CoreError) -> PyErr {
    let msg = err.to_string();
    match err {
        CoreError::Shape { .. } => ShapeError::new_err(msg),
        CoreError::Index { .. } => NeighbourIndexError::new_err(msg),
        CoreError::Parameter { .. } => ParameterError::new_err(msg),
    }
}
