//! What the classes of the binding share: the methods every element bank has
//! ([`element_bank!`]), shapes of batches, outputs as numpy arrays, a neighbour graph from CSR
//! arrays.

use numpy::{
    Element, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadwriteArray2,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use texsense_core::{CoreError, Neighbours};

use crate::errors::to_py;

/// The `#[pymethods]` block of an element bank (a class whose `inner` has `len()`): the
/// `n_elements` getter and, given `reset = "doc"`, a `reset` documented so, then the class's
/// own methods. Each class writes only what is its own.
macro_rules! element_bank {
    ($class:ty, reset = $reset_doc:literal, { $($own:tt)* }) => {
        $crate::arrays::element_bank!($class, {
            #[doc = $reset_doc]
            fn reset(&mut self) {
                self.inner.reset();
            }
            $($own)*
        });
    };
    ($class:ty, { $($own:tt)* }) => {
        #[pyo3::pymethods]
        impl $class {
            /// Number of elements.
            #[getter]
            fn n_elements(&self) -> usize {
                self.inner.len()
            }
            $($own)*
        }
    };
}
pub(crate) use element_bank;

pub(crate) fn neighbours_from(
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

pub(crate) fn pairs(
    what: &'static str,
    rows: PyReadonlyArray2<'_, f64>,
) -> PyResult<Vec<(f64, f64)>> {
    let shape = rows.shape();
    if shape[1] != 2 {
        return Err(to_py(CoreError::Shape {
            what,
            expected: "shape (k, 2)".into(),
            got: format!("{shape:?}"),
        }));
    }
    let v = rows.as_slice()?;
    Ok(v.chunks_exact(2).map(|c| (c[0], c[1])).collect())
}

/// Check a batch of `values` (T, N) with a `valid` mask of the same shape (and, for stages
/// that take time steps, `dt` of length T) against a bank of `n` elements; returns (T, N).
fn batch_shape(
    what: &'static str,
    n: usize,
    values: &[usize],
    valid: Option<&[usize]>,
    dt: Option<usize>,
) -> PyResult<(usize, usize)> {
    let ok = values.len() == 2
        && valid.is_none_or(|v| v == values)
        && values[1] == n
        && dt.is_none_or(|len| len == values[0]);
    if !ok {
        let dt_txt = |len: Option<usize>| len.map_or(String::new(), |l| format!("dt ({l},), "));
        return Err(to_py(CoreError::Shape {
            what,
            expected: format!(
                "{}values (T, {n}){} ({n} elements per frame)",
                if dt.is_some() { "dt (T,), " } else { "" },
                if valid.is_some() {
                    " with a valid mask of the same shape"
                } else {
                    ""
                }
            ),
            got: format!(
                "{}values {values:?}{}",
                dt_txt(dt),
                valid.map_or(String::new(), |v| format!(", valid {v:?}"))
            ),
        }));
    }
    Ok((values[0], values[1]))
}

/// The slices of a batch checked against a bank of `n` elements: values (T, N), a valid mask
/// of the same shape (empty for [`Batch::unmasked`]) and, for stages that take time steps,
/// `dt` (T,) (else empty).
/// The values are float64 unless said (a chain's float32 batch: `Batch<f32>`).
pub(crate) struct Batch<'a, T = f64> {
    pub(crate) t: usize,
    pub(crate) n: usize,
    pub(crate) dt: &'a [f64],
    pub(crate) values: &'a [T],
    pub(crate) valid: &'a [bool],
}

impl<'a, T: Element> Batch<'a, T> {
    pub(crate) fn new(
        what: &'static str,
        n: usize,
        dt: Option<&'a PyReadonlyArray1<'_, f64>>,
        values: &'a PyReadonlyArray2<'_, T>,
        valid: &'a PyReadonlyArray2<'_, bool>,
    ) -> PyResult<Self> {
        let (t, n) = batch_shape(
            what,
            n,
            values.shape(),
            Some(valid.shape()),
            dt.map(|d| d.len()),
        )?;
        Ok(Self {
            t,
            n,
            dt: match dt {
                Some(d) => d.as_slice()?,
                None => &[],
            },
            values: values.as_slice()?,
            valid: valid.as_slice()?,
        })
    }
}

impl<'a> Batch<'a> {
    /// A batch of time steps `dt` (T,) and values (T, N) without a validity mask.
    pub(crate) fn unmasked(
        what: &'static str,
        n: usize,
        dt: &'a PyReadonlyArray1<'_, f64>,
        values: &'a PyReadonlyArray2<'_, f64>,
    ) -> PyResult<Self> {
        let (t, n) = batch_shape(what, n, values.shape(), None, Some(dt.len()))?;
        Ok(Self {
            t,
            n,
            dt: dt.as_slice()?,
            values: values.as_slice()?,
            valid: &[],
        })
    }
}

/// A new (T, N) array of zeros from numpy's allocator, for a kernel to write its output into.
/// numpy asks Linux for huge pages for large arrays (`madvise`), where a Rust `Vec` of zeros
/// is memory in 4 KB pages that fault in one by one on the first write: a 4000 x 4096 float64
/// output took 32,000 such faults, and the Preisach batch that made it ran at 0.53 x the
/// rate of the same batch into an array held (issue 34, twentieth round: docs/pipeline.md).
fn zeros<'py, T: Element>(py: Python<'py>, t: usize, n: usize) -> Bound<'py, PyArray2<T>> {
    PyArray2::zeros(py, [t, n], false)
}

/// Write access to the array `a` that [`zeros`] made (new, C-contiguous, not yet handed to
/// the caller, so nothing else borrows it).
fn fill<'py, T: Element>(a: &Bound<'py, PyArray2<T>>) -> PyResult<PyReadwriteArray2<'py, T>> {
    a.try_readwrite()
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("a new array: {e}")))
}

/// Run a kernel that fills a (T, N) output (float64, or float32 for a chain's float32
/// batch, or codes), with the GIL released, and return the array ([`zeros`]).
pub(crate) fn run_detached<'py, T, F>(
    py: Python<'py>,
    t: usize,
    n: usize,
    kernel: F,
) -> PyResult<Bound<'py, PyArray2<T>>>
where
    T: Element + Send,
    F: FnOnce(&mut [T]) -> Result<(), CoreError> + Send,
{
    let out = zeros(py, t, n);
    {
        let mut w = fill(&out)?;
        let o = w.as_slice_mut()?;
        py.detach(|| kernel(o)).map_err(to_py)?;
    }
    Ok(out)
}

/// [`run_detached`] for a kernel with two (T, N) outputs.
#[allow(clippy::type_complexity)]
pub(crate) fn run_detached2<'py, T, U, F>(
    py: Python<'py>,
    t: usize,
    n: usize,
    kernel: F,
) -> PyResult<(Bound<'py, PyArray2<T>>, Bound<'py, PyArray2<U>>)>
where
    T: Element + Send,
    U: Element + Send,
    F: FnOnce(&mut [T], &mut [U]) -> Result<(), CoreError> + Send,
{
    let (a, b) = (zeros(py, t, n), zeros(py, t, n));
    {
        let (mut wa, mut wb) = (fill(&a)?, fill(&b)?);
        let (oa, ob) = (wa.as_slice_mut()?, wb.as_slice_mut()?);
        py.detach(|| kernel(oa, ob)).map_err(to_py)?;
    }
    Ok((a, b))
}
