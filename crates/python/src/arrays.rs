//! Array conversion shared by the classes of the binding: shapes of batches, outputs as
//! numpy arrays, a neighbour graph from CSR arrays.

use numpy::{IntoPyArray, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use texsense_core::{CoreError, Neighbours};

use crate::errors::{to_py, ShapeError};

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
    valid: &[usize],
    dt: Option<usize>,
) -> PyResult<(usize, usize)> {
    let ok = values.len() == 2
        && valid == values
        && values[1] == n
        && dt.is_none_or(|len| len == values[0]);
    if !ok {
        let dt_txt = |len: Option<usize>| len.map_or(String::new(), |l| format!("dt ({l},), "));
        return Err(to_py(CoreError::Shape {
            what,
            expected: format!(
                "{}values (T, {n}) with a valid mask of the same shape ({n} elements per frame)",
                if dt.is_some() { "dt (T,), " } else { "" }
            ),
            got: format!("{}values {values:?}, valid {valid:?}", dt_txt(dt)),
        }));
    }
    Ok((values[0], values[1]))
}

/// The slices of a batch checked against a bank of `n` elements: values (T, N), a valid mask
/// of the same shape and, for stages that take time steps, `dt` (T,) (else empty).
pub(crate) struct Batch<'a> {
    pub(crate) t: usize,
    pub(crate) n: usize,
    pub(crate) dt: &'a [f64],
    pub(crate) values: &'a [f64],
    pub(crate) valid: &'a [bool],
}

impl<'a> Batch<'a> {
    pub(crate) fn new(
        what: &'static str,
        n: usize,
        dt: Option<&'a PyReadonlyArray1<'_, f64>>,
        values: &'a PyReadonlyArray2<'_, f64>,
        valid: &'a PyReadonlyArray2<'_, bool>,
    ) -> PyResult<Self> {
        let (t, n) = batch_shape(what, n, values.shape(), valid.shape(), dt.map(|d| d.len()))?;
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

/// Run a kernel that fills a (T, N) f64 output, with the GIL released, and return the array.
pub(crate) fn run_detached<'py, F>(
    py: Python<'py>,
    t: usize,
    n: usize,
    kernel: F,
) -> PyResult<Bound<'py, PyArray2<f64>>>
where
    F: FnOnce(&mut [f64]) -> Result<(), CoreError> + Send,
{
    let mut out = vec![0.0; t * n];
    py.detach(|| kernel(&mut out)).map_err(to_py)?;
    to_2d(py, out, t, n)
}

pub(crate) fn to_2d<T: numpy::Element>(
    py: Python<'_>,
    v: Vec<T>,
    t: usize,
    n: usize,
) -> PyResult<Bound<'_, PyArray2<T>>> {
    let a = numpy::ndarray::Array2::from_shape_vec((t, n), v)
        .map_err(|e| ShapeError::new_err(e.to_string()))?;
    Ok(a.into_pyarray(py))
}
