//! `Chain`: the whole chain of a mat in one compiled pass, assembled from the kernels of its
//! stages.

use numpy::{PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use texsense_core::{Chain, CoreError, Response};

use crate::arrays::{run_detached, to_2d, Batch};
use crate::compensation::PyCompensation;
use crate::convert::{PyConverter, PyCurve};
use crate::detect::PyFailureDetector;
use crate::errors::to_py;
use crate::repair::PyLocalRepair;

/// detect -> convert -> Preisach + drift (`compensation`), the first-loading curve
/// (`loading`) or neither (a linear calibration) -> local repair. The chain copies the
/// kernels it is given (their state as it is).
#[pyclass(name = "Chain", module = "texsense._core")]
pub(crate) struct PyChain {
    inner: Chain,
}

#[pymethods]
impl PyChain {
    #[new]
    #[pyo3(signature = (converter, *, detector=None, compensation=None, loading=None, repair=None))]
    fn new(
        converter: PyRef<'_, PyConverter>,
        detector: Option<PyRef<'_, PyFailureDetector>>,
        compensation: Option<PyRef<'_, PyCompensation>>,
        loading: Option<PyRef<'_, PyCurve>>,
        repair: Option<PyRef<'_, PyLocalRepair>>,
    ) -> PyResult<Self> {
        let response = match (compensation, loading) {
            (Some(c), None) => Response::Compensation(c.inner.clone()),
            (None, Some(curve)) => Response::Loading(curve.inner.clone()),
            (None, None) => Response::Direct,
            _ => {
                return Err(to_py(CoreError::Parameter {
                    what: "chain",
                    why: "give at most one of compensation and loading".into(),
                }))
            }
        };
        let inner = Chain::new(
            detector.map(|d| d.inner.clone()),
            converter.inner.clone(),
            response,
            repair.map(|r| r.inner.clone()),
        )
        .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Number of elements.
    #[getter]
    fn n_elements(&self) -> usize {
        self.inner.len()
    }

    /// Every stage back to its initial state.
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Bytes of state per element (all stages, per-element parameters included).
    fn state_bytes_per_element(&self) -> usize {
        self.inner.state_bytes_per_element()
    }

    /// Batch: dt (T,), readings (T, N), valid (T, N) -> (values (T, N), codes (T, N)).
    #[allow(clippy::type_complexity)]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        dt: PyReadonlyArray1<'py, f64>,
        readings: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<u8>>)> {
        let b = Batch::new("chain run", self.inner.len(), Some(&dt), &readings, &valid)?;
        let mut codes = vec![0u8; b.t * b.n];
        let inner = &mut self.inner;
        let out = run_detached(py, b.t, b.n, |out| {
            inner.run(b.dt, b.values, b.valid, out, &mut codes)
        })?;
        Ok((out, to_2d(py, codes, b.t, b.n)?))
    }
}
