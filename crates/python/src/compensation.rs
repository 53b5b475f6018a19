//! `Compensation`: a Preisach bank followed by a drift bank, in one pass per frame.

use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use texsense_core::Compensation;

use crate::arrays::{element_bank, run_detached, Batch};
use crate::convert::PyCurve;
use crate::drift::PyDriftBank;
use crate::errors::to_py;
use crate::preisach::PyPreisachBank;

/// Preisach then drift, in one pass per frame (the combined compensation stage), built from
/// a Preisach bank and an optional drift bank of the same size (both copied, fresh state as
/// they are).
#[pyclass(name = "Compensation", module = "texsense._core")]
pub(crate) struct PyCompensation {
    pub(crate) inner: Compensation,
}

element_bank!(
    PyCompensation,
    reset = "Both stages back to their initial state.",
    {
        #[new]
        #[pyo3(signature = (preisach, drift=None, level=None))]
        fn new(
            preisach: PyRef<'_, PyPreisachBank>,
            drift: Option<PyRef<'_, PyDriftBank>>,
            level: Option<PyRef<'_, PyCurve>>,
        ) -> PyResult<Self> {
            let mut inner =
                Compensation::new(preisach.inner.clone(), drift.map(|d| d.inner.clone()))
                    .map_err(to_py)?;
            if let Some(curve) = level {
                inner = inner.with_level(curve.inner.clone()).map_err(to_py)?;
            }
            Ok(Self { inner })
        }

        /// Samples clamped into the identified range, per element.
        fn clamped<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
            self.inner.preisach().clamped().into_pyarray(py)
        }

        /// Batch: dt (T,), inputs (T, N), valid (T, N) -> compensated outputs (T, N).
        fn run<'py>(
            &mut self,
            py: Python<'py>,
            dt: PyReadonlyArray1<'py, f64>,
            inputs: PyReadonlyArray2<'py, f64>,
            valid: PyReadonlyArray2<'py, bool>,
        ) -> PyResult<Bound<'py, PyArray2<f64>>> {
            let b = Batch::new(
                "compensation run",
                self.inner.len(),
                Some(&dt),
                &inputs,
                &valid,
            )?;
            let inner = &mut self.inner;
            run_detached(py, b.t, b.n, |out| inner.run(b.dt, b.values, b.valid, out))
        }
    }
);
