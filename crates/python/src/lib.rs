//! `texsense._core`: the thin PyO3 binding of `texsense-core`.
//!
//! Only array conversion and error mapping live here; every algorithm is in the core crate.
//! Each `CoreError` variant maps to its own exception class, re-exported by
//! `texsense.exceptions`.

use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::create_exception;
use pyo3::exceptions::{PyIndexError, PyValueError};
use pyo3::prelude::*;
use texsense_core::repair::RepairOutcome;
use texsense_core::{CoreError, NeighbourMeanRepair, Neighbours};

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

fn to_py(err: CoreError) -> PyErr {
    let msg = err.to_string();
    match err {
        CoreError::Shape { .. } => ShapeError::new_err(msg),
        CoreError::Index { .. } => NeighbourIndexError::new_err(msg),
        CoreError::Parameter { .. } => ParameterError::new_err(msg),
    }
}

fn neighbours_from(
    indptr: PyReadonlyArray1<'_, i64>,
    indices: PyReadonlyArray1<'_, i64>,
) -> PyResult<Neighbours> {
    let to_usize = |what: &'static str, v: i64| {
        usize::try_from(v).map_err(|_| {
            to_py(CoreError::Parameter {
                what,
                why: format!("must be non-negative, got {v}"),
            })
        })
    };
    let indptr = indptr
        .as_slice()?
        .iter()
        .map(|&v| to_usize("indptr", v))
        .collect::<PyResult<Vec<usize>>>()?;
    let indices = indices
        .as_slice()?
        .iter()
        .map(|&v| to_usize("indices", v).map(|u| u as u32))
        .collect::<PyResult<Vec<u32>>>()?;
    Neighbours::new(indptr, indices).map_err(to_py)
}

/// Streaming eq. 6.14 repair: failed elements become the mean of their available
/// neighbours, or their last value when none is available.
#[pyclass(name = "NeighbourMeanRepair", module = "texsense._core")]
struct PyNeighbourMeanRepair {
    inner: NeighbourMeanRepair,
}

#[pymethods]
impl PyNeighbourMeanRepair {
    #[new]
    fn new(
        indptr: PyReadonlyArray1<'_, i64>,
        indices: PyReadonlyArray1<'_, i64>,
    ) -> PyResult<Self> {
        Ok(Self {
            inner: NeighbourMeanRepair::new(neighbours_from(indptr, indices)?),
        })
    }

    /// Number of elements.
    #[getter]
    fn n_elements(&self) -> usize {
        self.inner.len()
    }

    /// Last value (real or repaired) per element, NaN where none was seen yet.
    fn last_values<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        self.inner.last_values().to_vec().into_pyarray(py)
    }

    /// Forget all last values.
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Repair a batch `[T, N]`; returns `(repaired [T, N] float32, outcome [T, N] uint8)`
    /// with outcome 0 measured, 1 neighbour mean, 2 last value, 3 missing.
    #[allow(clippy::type_complexity)]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        frames: PyReadonlyArray2<'py, f32>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<u8>>)> {
        let shape = frames.shape().to_vec();
        if valid.shape() != shape.as_slice() {
            return Err(to_py(CoreError::Shape {
                what: "valid",
                expected: format!("shape {shape:?} like frames"),
                got: format!("shape {:?}", valid.shape()),
            }));
        }
        if shape[1] != self.inner.len() {
            return Err(to_py(CoreError::Shape {
                what: "frames",
                expected: format!("{} elements per frame", self.inner.len()),
                got: format!("{}", shape[1]),
            }));
        }
        let f = frames.as_slice()?;
        let v = valid.as_slice()?;
        let mut out = vec![0.0f32; f.len()];
        let mut outcome = vec![RepairOutcome::Measured; f.len()];
        let inner = &mut self.inner;
        py.detach(|| inner.run(f, v, &mut out, &mut outcome))
            .map_err(to_py)?;
        let codes: Vec<u8> = outcome.into_iter().map(|o| o as u8).collect();
        let out = numpy::ndarray::Array2::from_shape_vec((shape[0], shape[1]), out)
            .map_err(|e| ShapeError::new_err(e.to_string()))?;
        let codes = numpy::ndarray::Array2::from_shape_vec((shape[0], shape[1]), codes)
            .map_err(|e| ShapeError::new_err(e.to_string()))?;
        Ok((out.into_pyarray(py), codes.into_pyarray(py)))
    }
}

/// The compiled core of texsense.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<PyNeighbourMeanRepair>()?;
    m.add("ShapeError", m.py().get_type::<ShapeError>())?;
    m.add(
        "NeighbourIndexError",
        m.py().get_type::<NeighbourIndexError>(),
    )?;
    m.add("ParameterError", m.py().get_type::<ParameterError>())?;
    Ok(())
}
