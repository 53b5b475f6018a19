//! `Curve` and `Converter`: capacitance -> compression per element (thesis eq. 2.1).

use numpy::{
    IntoPyArray, PyArray2, PyArrayDyn, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArrayDyn,
};
use pyo3::prelude::*;
use texsense_core::{Converter, Curve};

use crate::arrays::{element_bank, run_detached, Batch};
use crate::errors::to_py;

/// A piecewise-linear curve y(x) over strictly increasing x, held at its ends (what
/// `np.interp` computes, to the bit).
#[pyclass(name = "Curve", module = "texsense._core", frozen)]
pub(crate) struct PyCurve {
    pub(crate) inner: Curve,
}

#[pymethods]
impl PyCurve {
    #[new]
    fn new(x: PyReadonlyArray1<'_, f64>, y: PyReadonlyArray1<'_, f64>) -> PyResult<Self> {
        let inner = Curve::new(x.as_slice()?.to_vec(), y.as_slice()?.to_vec()).map_err(to_py)?;
        Ok(Self { inner })
    }

    /// y at every value of an array of any shape (NaN for NaN).
    fn at<'py>(
        &self,
        py: Python<'py>,
        values: PyReadonlyArrayDyn<'py, f64>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let curve = self.inner.view();
        let out = values.as_array().mapv(|v| curve.at(v));
        Ok(out.into_pyarray(py))
    }
}

/// Capacitance -> compression per element: `(C - offset_i) / gain_i` through the material
/// curve (`curve`: reference capacitance -> compression), or without a curve the scaled
/// reading itself (a linear calibration).
#[pyclass(name = "Converter", module = "texsense._core", frozen)]
pub(crate) struct PyConverter {
    pub(crate) inner: Converter,
}

element_bank!(PyConverter, {
    #[new]
    #[pyo3(signature = (offset, gain, curve=None))]
    fn new(
        offset: PyReadonlyArray1<'_, f64>,
        gain: PyReadonlyArray1<'_, f64>,
        curve: Option<PyRef<'_, PyCurve>>,
    ) -> PyResult<Self> {
        let inner = Converter::new(
            offset.as_slice()?.to_vec(),
            gain.as_slice()?.to_vec(),
            curve.map(|c| c.inner.clone()),
        )
        .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Batch: readings (T, N), valid (T, N) -> converted values (T, N), NaN where a reading
    /// is invalid or not a number.
    fn run<'py>(
        &self,
        py: Python<'py>,
        readings: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let b = Batch::new("readings", self.inner.len(), None, &readings, &valid)?;
        let inner = &self.inner;
        run_detached(py, b.t, b.n, |out| inner.run(b.values, b.valid, out))
    }
});
