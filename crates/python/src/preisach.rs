//! `PreisachBank` (thesis eq. 4.15-4.22) and the Everett terms of an input history.

use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use texsense_core::preisach::f32x8::Bank32;
use texsense_core::preisach::Schedule;
use texsense_core::{everett_terms, CoreError, Everett, PreisachBank};

use crate::arrays::{element_bank, run_detached, Batch};
use crate::errors::to_py;

/// Preisach stacks of N elements over one Everett table (thesis eq. 4.15-4.22).
#[pyclass(name = "PreisachBank", module = "texsense._core")]
pub(crate) struct PyPreisachBank {
    pub(crate) inner: PreisachBank,
}

element_bank!(PyPreisachBank, reset = "Back to lower saturation.", {
    /// The model's output is `sign (h + offset)` with `h` the Preisach sum (sign +1 or -1).
    #[new]
    #[pyo3(signature = (u_min, u_max, table, n_elements, capacity, offset=0.0, sign=1.0))]
    fn new(
        u_min: f64,
        u_max: f64,
        table: PyReadonlyArray2<'_, f64>,
        n_elements: usize,
        capacity: usize,
        offset: f64,
        sign: f64,
    ) -> PyResult<Self> {
        let everett = square_table(&table, u_min, u_max)?;
        let inner = PreisachBank::new(everett, n_elements, capacity)
            .and_then(|b| b.with_output(offset, sign))
            .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Everett function F(alpha, beta) at points (same-shape 1-D arrays), in the units of
    /// the Preisach sum (before offset and sign).
    fn everett<'py>(
        &self,
        py: Python<'py>,
        alpha: PyReadonlyArray1<'py, f64>,
        beta: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (a, b) = (alpha.as_slice()?, beta.as_slice()?);
        if a.len() != b.len() {
            return Err(to_py(CoreError::Shape {
                what: "beta",
                expected: format!("length {}", a.len()),
                got: format!("length {}", b.len()),
            }));
        }
        let e = self.inner.everett();
        let out: Vec<f64> = a.iter().zip(b).map(|(&x, &y)| e.value(x, y)).collect();
        Ok(out.into_pyarray(py))
    }

    /// Batch: inputs (T, N), valid (T, N) -> outputs (T, N), NaN where skipped.
    /// `schedule`: "parallel" (default), "blocks" or "frames" (one thread, frame after
    /// frame): identical outputs, for the benchmark's step-by-step table. `out`: a
    /// C-contiguous float64 array (T, N) to write into (and return) instead of a new one.
    #[pyo3(signature = (inputs, valid, schedule="parallel", out=None))]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        inputs: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
        schedule: &str,
        out: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let schedule = match schedule {
            "parallel" => Schedule::Parallel,
            "blocks" => Schedule::Blocks,
            "frames" => Schedule::FrameOrder,
            other => {
                return Err(to_py(CoreError::Parameter {
                    what: "schedule",
                    why: format!("'parallel', 'blocks' or 'frames', got {other:?}"),
                }))
            }
        };
        let b = Batch::new("inputs", self.inner.len(), None, &inputs, &valid)?;
        let inner = &mut self.inner;
        into_out(py, &b, out, |o| {
            inner.run_scheduled(b.values, b.valid, o, schedule)
        })
    }

    /// Bytes of state of the whole bank (elements and stacks moved to the heap).
    fn state_bytes(&self) -> usize {
        self.inner.state_bytes()
    }

    /// Set elements to an input with a given output (§6.4.4, the model's output); returns
    /// the outputs set.
    fn set_state<'py>(
        &mut self,
        py: Python<'py>,
        inputs: PyReadonlyArray1<'py, f64>,
        outputs: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (u, h) = (inputs.as_slice()?, outputs.as_slice()?);
        if u.len() != self.inner.len() || h.len() != self.inner.len() {
            return Err(to_py(CoreError::Shape {
                what: "set_state",
                expected: format!("{} inputs and outputs", self.inner.len()),
                got: format!("{} and {}", u.len(), h.len()),
            }));
        }
        let got: Vec<f64> = (0..u.len())
            .map(|i| self.inner.set_state(i, u[i], h[i]))
            .collect();
        Ok(got.into_pyarray(py))
    }

    /// Samples clamped into the input range, per element.
    fn clamped<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        self.inner.clamped().into_pyarray(py)
    }

    /// Minor loops forgotten at full stacks, per element.
    fn forgotten<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        self.inner.forgotten().into_pyarray(py)
    }

    /// Stack depth per element.
    fn depth<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        let d: Vec<u64> = self.inner.depth().iter().map(|&v| v as u64).collect();
        d.into_pyarray(py)
    }

    /// Last output per element.
    fn outputs<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.last_outputs().into_pyarray(py)
    }
});

/// The Everett function of a square (K, K) table over [u_min, u_max].
fn square_table(table: &PyReadonlyArray2<'_, f64>, u_min: f64, u_max: f64) -> PyResult<Everett> {
    let shape = table.shape();
    if shape[0] != shape[1] {
        return Err(to_py(CoreError::Shape {
            what: "everett table",
            expected: "a square (K, K) table".into(),
            got: format!("{shape:?}"),
        }));
    }
    Everett::new(shape[0], u_min, u_max, table.as_slice()?.to_vec()).map_err(to_py)
}

/// A batch's outputs into `out` (a C-contiguous float64 array (T, N), not an input), or
/// into a new array: `kernel` runs with the GIL released.
fn into_out<'py, F>(
    py: Python<'py>,
    b: &Batch<'_>,
    out: Option<Bound<'py, PyAny>>,
    kernel: F,
) -> PyResult<Bound<'py, PyArray2<f64>>>
where
    F: FnOnce(&mut [f64]) -> Result<(), CoreError> + Send,
{
    let Some(out) = out else {
        return run_detached(py, b.t, b.n, kernel);
    };
    let wrong = |got: String| {
        to_py(CoreError::Shape {
            what: "out",
            expected: format!(
                "a C-contiguous float64 array ({}, {}), not an input",
                b.t, b.n
            ),
            got,
        })
    };
    let out = out.cast_into::<PyArray2<f64>>().map_err(|e| {
        let obj = e.into_inner();
        wrong(match obj.getattr("dtype") {
            Ok(d) => format!("dtype {d}"),
            Err(_) => format!("{}", obj.get_type()),
        })
    })?;
    if out.shape() != [b.t, b.n] || !out.is_c_contiguous() {
        return Err(wrong(format!(
            "shape {:?}, strides {:?}",
            out.shape(),
            out.strides()
        )));
    }
    {
        let mut w = out
            .try_readwrite()
            .map_err(|e| wrong(format!("an array it cannot write into ({e})")))?;
        let o = w.as_slice_mut()?;
        py.detach(|| kernel(o)).map_err(to_py)?;
    }
    Ok(out)
}

/// Experimental (issue 34): the Preisach model of N elements in float32, eight elements
/// in the lanes of one AVX2 register (`texsense_core::preisach::f32x8`), a memory of 28
/// turning points per element, frame after frame on one thread. Its outputs are the
/// float32 scalar kernel's bit for bit, and differ from `PreisachBank`'s by float32's
/// rounding; no pipeline uses it.
#[pyclass(name = "PreisachBank32", module = "texsense._core")]
pub(crate) struct PyPreisachBank32 {
    inner: Bank32,
}

element_bank!(PyPreisachBank32, reset = "Back to lower saturation.", {
    /// The model's output is `sign (h + offset)`, in float32.
    #[new]
    #[pyo3(signature = (u_min, u_max, table, n_elements, offset=0.0, sign=1.0))]
    fn new(
        u_min: f64,
        u_max: f64,
        table: PyReadonlyArray2<'_, f64>,
        n_elements: usize,
        offset: f64,
        sign: f64,
    ) -> PyResult<Self> {
        let everett = square_table(&table, u_min, u_max)?;
        let inner = Bank32::new(&everett, n_elements)
            .and_then(|b| b.with_output(offset, sign))
            .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Batch: inputs (T, N), valid (T, N) -> outputs (T, N) as float64, NaN where
    /// skipped; `out` as for `PreisachBank.run`.
    #[pyo3(signature = (inputs, valid, out=None))]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        inputs: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
        out: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let b = Batch::new("inputs", self.inner.len(), None, &inputs, &valid)?;
        let inner = &mut self.inner;
        into_out(py, &b, out, |o| inner.run(b.values, b.valid, o))
    }
});

/// The Everett terms of an input history (identification): (indptr, alpha, beta, coef).
#[pyfunction(name = "everett_terms")]
#[allow(clippy::type_complexity)]
pub(crate) fn py_everett_terms<'py>(
    py: Python<'py>,
    inputs: PyReadonlyArray1<'py, f64>,
    u_min: f64,
    u_max: f64,
) -> PyResult<(
    Bound<'py, PyArray1<u64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
)> {
    let u = inputs.as_slice()?;
    let terms = py
        .detach(|| everett_terms(u, u_min, u_max))
        .map_err(to_py)?;
    let indptr: Vec<u64> = terms.indptr.iter().map(|&v| v as u64).collect();
    Ok((
        indptr.into_pyarray(py),
        terms.alpha.into_pyarray(py),
        terms.beta.into_pyarray(py),
        terms.coef.into_pyarray(py),
    ))
}
