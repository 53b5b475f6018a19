//! `DriftBank`: the recursive drift superposition (thesis eq. 5.4/5.8).

use numpy::{PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use texsense_core::drift::f32x8::Drift32;
use texsense_core::{DriftBank, Kernel};

use crate::arrays::{element_bank, run_detached, Batch};
use crate::errors::to_py;

/// Recursive drift superposition for N elements (thesis eq. 5.4/5.8).
#[pyclass(name = "DriftBank", module = "texsense._core")]
pub(crate) struct PyDriftBank {
    pub(crate) inner: DriftBank,
}

element_bank!(PyDriftBank, reset = "Forget the history.", {
    #[new]
    #[allow(clippy::too_many_arguments)] // the Python constructor's keyword arguments
    #[pyo3(signature = (weights, taus, gamma, n_elements, rest_rate=0.0, rest_window=0.5, gamma_time=0.0, exponent=1.0))]
    fn new(
        weights: PyReadonlyArray1<'_, f64>,
        taus: PyReadonlyArray1<'_, f64>,
        gamma: f64,
        n_elements: usize,
        rest_rate: f64,
        rest_window: f64,
        gamma_time: f64,
        exponent: f64,
    ) -> PyResult<Self> {
        let kernel =
            Kernel::new(weights.as_slice()?.to_vec(), taus.as_slice()?.to_vec()).map_err(to_py)?;
        let inner = DriftBank::new(kernel, gamma, n_elements)
            .and_then(|b| b.with_rest_rate(rest_rate, rest_window))
            .and_then(|b| b.with_time_component(gamma_time))
            .and_then(|b| b.with_exponent(exponent))
            .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Batch: time steps dt (T,), hysteresis outputs h (T, N), valid (T, N) -> (T, N).
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        dt: PyReadonlyArray1<'py, f64>,
        h: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let b = Batch::new("drift run", self.inner.len(), Some(&dt), &h, &valid)?;
        let inner = &mut self.inner;
        run_detached(py, b.t, b.n, |out| inner.run(b.dt, b.values, b.valid, out))
    }
});

/// Experimental (issue 34): eq. 5.8 on the time clock with the linear level, in float32,
/// eight elements in the lanes of one AVX2 register (`texsense_core::drift::f32x8`), frame
/// after frame on one thread. Its outputs are the float32 scalar kernel's bit for bit and
/// differ from `DriftBank`'s by float32's rounding; no pipeline uses it.
#[pyclass(name = "DriftBank32", module = "texsense._core")]
pub(crate) struct PyDriftBank32 {
    inner: Drift32,
}

element_bank!(PyDriftBank32, reset = "Forget the history.", {
    #[new]
    fn new(
        weights: PyReadonlyArray1<'_, f64>,
        taus: PyReadonlyArray1<'_, f64>,
        gamma: f64,
        n_elements: usize,
    ) -> PyResult<Self> {
        let inner = Drift32::new(weights.as_slice()?, taus.as_slice()?, gamma, n_elements)
            .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Batch: time steps dt (T,), hysteresis outputs h (T, N), valid (T, N) -> (T, N).
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        dt: PyReadonlyArray1<'py, f64>,
        h: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let b = Batch::new("drift run", self.inner.len(), Some(&dt), &h, &valid)?;
        let inner = &mut self.inner;
        run_detached(py, b.t, b.n, |out| inner.run(b.dt, b.values, b.valid, out))
    }
});
