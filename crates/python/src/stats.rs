//! `GridStats`: one frame's pressure statistics on a grid layout (`texsense_core::stats`).

use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use texsense_core::stats::GridStats;
use texsense_core::CoreError;

use crate::errors::to_py;

/// A grid layout's elements: area (N,) cm², positions xy (N, 2) cm, the cell of each element
/// (row x cols + column), the grid's rows and columns and the PPI window.
#[pyclass(name = "GridStats", module = "texsense._core")]
pub(crate) struct PyGridStats {
    inner: GridStats,
    map: Vec<f64>,
}

#[pymethods]
impl PyGridStats {
    #[new]
    fn new(
        area: PyReadonlyArray1<'_, f64>,
        xy: PyReadonlyArray2<'_, f64>,
        cells: PyReadonlyArray1<'_, i64>,
        rows: usize,
        cols: usize,
        window: usize,
    ) -> PyResult<Self> {
        let (area, cells) = (area.as_slice()?, cells.as_slice()?);
        let xy = xy.as_array();
        let flat: Vec<f64> = xy.iter().copied().collect(); // row-major (N, 2)
        let ok = xy.ncols() == 2;
        let inner = ok
            .then(|| GridStats::new(area, &flat, cells, rows, cols, window))
            .flatten()
            .ok_or_else(|| {
                to_py(CoreError::Parameter {
                    what: "GridStats",
                    why: format!(
                        "{} elements (xy {:?}) do not fit a {rows} x {cols} grid one per cell \
                         (window {window})",
                        area.len(),
                        xy.shape()
                    ),
                })
            })?;
        Ok(Self {
            inner,
            map: Vec::new(),
        })
    }

    /// (load, contact area, peak, ppi, cof x, cof y, cof row, cof column) of one frame of
    /// pressure (N, NaN read as 0) above `threshold`, or None for a frame of another length
    /// or with a value infinite as float32.
    #[allow(clippy::type_complexity)]
    fn frame(
        &mut self,
        pressure: PyReadonlyArray1<'_, f64>,
        threshold: f64,
    ) -> PyResult<Option<(f64, f64, f64, f64, f64, f64, f64, f64)>> {
        let p = pressure.as_slice()?;
        Ok(self.inner.frame(p, threshold, &mut self.map).map(|s| {
            (
                s.load,
                s.contact_area,
                s.peak,
                s.ppi,
                s.cof_cm[0],
                s.cof_cm[1],
                s.cof_cell[0],
                s.cof_cell[1],
            )
        }))
    }
}
