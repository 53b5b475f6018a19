//! `LocalRepair`: the local repairs of failed readings (thesis §6.5.2.5, eq. 6.14).

use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use texsense_core::{CoreError, LocalRepair, RepairMethod};

use crate::arrays::{element_bank, neighbours_from, run_detached2, Batch};
use crate::errors::to_py;

/// A local repair with its state (the last value of every element). `method`: "zero",
/// "last-value", "neighbour-mean" (eq. 6.14; needs indptr, indices) or "weighted" (needs
/// indptr, indices and weights parallel to indices).
#[pyclass(name = "LocalRepair", module = "texsense._core")]
pub(crate) struct PyLocalRepair {
    pub(crate) inner: LocalRepair,
}

element_bank!(PyLocalRepair, reset = "Forget all last values.", {
    #[new]
    #[pyo3(signature = (method, n_elements, indptr=None, indices=None, weights=None))]
    fn new(
        method: &str,
        n_elements: usize,
        indptr: Option<PyReadonlyArray1<'_, i64>>,
        indices: Option<PyReadonlyArray1<'_, i64>>,
        weights: Option<PyReadonlyArray1<'_, f64>>,
    ) -> PyResult<Self> {
        let graph = || match (&indptr, &indices) {
            (Some(p), Some(i)) => neighbours_from(p.clone(), i.clone()),
            _ => Err(to_py(CoreError::Parameter {
                what: "repair",
                why: format!("{method:?} needs the neighbour graph (indptr, indices)"),
            })),
        };
        let method = match method {
            "zero" => RepairMethod::Zero,
            "last-value" => RepairMethod::LastValue,
            "neighbour-mean" => RepairMethod::NeighbourMean(graph()?),
            "weighted" => {
                let w = weights.as_ref().ok_or_else(|| {
                    to_py(CoreError::Parameter {
                        what: "repair",
                        why: "\"weighted\" needs weights".into(),
                    })
                })?;
                RepairMethod::Weighted(graph()?, w.as_slice()?.to_vec())
            }
            other => {
                return Err(to_py(CoreError::Parameter {
                    what: "repair",
                    why: format!("unknown local repair {other:?}"),
                }))
            }
        };
        let inner = LocalRepair::new(method, n_elements).map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Last value (real or repaired) per element, NaN where none was seen yet.
    fn last_values<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.last_values().to_vec().into_pyarray(py)
    }

    /// Batch: values (T, N), valid (T, N) -> (repaired (T, N), outcome (T, N) uint8) with
    /// outcome 0 measured, 1 filled, 2 last value, 3 missing.
    #[allow(clippy::type_complexity)]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        values: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<u8>>)> {
        let b = Batch::new("values", self.inner.len(), None, &values, &valid)?;
        let inner = &mut self.inner;
        run_detached2(py, b.t, b.n, |out, outcome| {
            out.copy_from_slice(b.values);
            inner.run(out, |i| b.valid[i], Some(outcome))
        })
    }
});
