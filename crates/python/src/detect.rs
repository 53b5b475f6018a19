//! `FailureDetector`: failure codes of raw capacitance readings (thesis §6.5.2.5).

use numpy::{PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use texsense_core::detect::{Changes, DetectorParams, FailureDetector};

use crate::arrays::{element_bank, neighbours_from, run_detached, Batch};
use crate::errors::to_py;

/// Failure detection on raw capacitance (thesis §6.5.2.5): codes 0 ok, 1 short/break,
/// 2 out of range, 3 stuck, 4 jump.
#[pyclass(name = "FailureDetector", module = "texsense._core")]
#[derive(Clone)]
pub(crate) struct PyFailureDetector {
    pub(crate) inner: FailureDetector,
    changes: Changes,
}

element_bank!(PyFailureDetector, reset = "Forget the history.", {
    #[new]
    #[pyo3(signature = (indptr, indices, jump_pf, baseline_pf, max_pf, min_pf, low_share, high_share, stuck_frames, stuck_pf, neighbour_change_pf, stuck_floor_pf=f64::NEG_INFINITY))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        indptr: PyReadonlyArray1<'_, i64>,
        indices: PyReadonlyArray1<'_, i64>,
        jump_pf: PyReadonlyArray1<'_, f64>,
        baseline_pf: Option<PyReadonlyArray1<'_, f64>>,
        max_pf: Option<PyReadonlyArray1<'_, f64>>,
        min_pf: f64,
        low_share: f64,
        high_share: f64,
        stuck_frames: u32,
        stuck_pf: f64,
        neighbour_change_pf: f64,
        stuck_floor_pf: f64,
    ) -> PyResult<Self> {
        let params = DetectorParams {
            min_pf,
            low_share,
            high_share,
            stuck_frames,
            stuck_pf,
            neighbour_change_pf,
            stuck_floor_pf,
        };
        let vec = |a: Option<PyReadonlyArray1<'_, f64>>| -> PyResult<Option<Vec<f64>>> {
            a.map(|a| Ok(a.as_slice()?.to_vec())).transpose()
        };
        let inner = FailureDetector::new(
            params,
            neighbours_from(indptr, indices)?,
            jump_pf.as_slice()?.to_vec(),
            vec(baseline_pf)?,
            vec(max_pf)?,
        )
        .map_err(to_py)?;
        Ok(Self {
            inner,
            changes: Changes::default(),
        })
    }

    /// Codes (T, N) uint8 of readings (T, N) with the converter's validity (T, N).
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        readings: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<Bound<'py, PyArray2<u8>>> {
        let b = Batch::new("readings", self.inner.len(), None, &readings, &valid)?;
        let (t, n, r, v) = (b.t, b.n, b.values, b.valid);
        let (inner, changes) = (&mut self.inner, &mut self.changes);
        run_detached(py, t, n, |codes| inner.run(r, v, codes, changes))
    }
});
