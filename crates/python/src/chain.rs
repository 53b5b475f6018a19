//! `Chain`: a mat's chain of stages compiled, assembled from the kernels of its stages in
//! order; its state as bytes; its model blob for a microcontroller.

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use texsense_core::{Chain, ChainStage, CoreError};

use crate::arrays::{element_bank, run_detached2, Batch};
use crate::compensation::PyCompensation;
use crate::convert::{PyConverter, PyCurve};
use crate::detect::PyFailureDetector;
use crate::drift::PyDriftBank;
use crate::errors::to_py;
use crate::repair::PyLocalRepair;

/// A stage of a chain from one of the binding's kernels: a `FailureDetector` (detect), a
/// `Converter` (convert or linear), a `Compensation` (hysteresis, with the drift right after
/// it), a `DriftBank` (a drift on its own), a `Curve` (the first-loading curve) or a
/// `LocalRepair` (repair).
fn stage_of(item: &Bound<'_, PyAny>, position: usize) -> PyResult<ChainStage> {
    if let Ok(d) = item.cast::<PyFailureDetector>() {
        return Ok(ChainStage::Detect(d.borrow().inner.clone()));
    }
    if let Ok(c) = item.cast::<PyConverter>() {
        return Ok(ChainStage::Convert(c.borrow().inner.clone()));
    }
    if let Ok(c) = item.cast::<PyCompensation>() {
        return Ok(ChainStage::Compensation(c.borrow().inner.clone()));
    }
    if let Ok(d) = item.cast::<PyDriftBank>() {
        return Ok(ChainStage::Drift(d.borrow().inner.clone()));
    }
    if let Ok(c) = item.cast::<PyCurve>() {
        return Ok(ChainStage::Loading(c.borrow().inner.clone()));
    }
    if let Ok(r) = item.cast::<PyLocalRepair>() {
        return Ok(ChainStage::Repair(r.borrow().inner.clone()));
    }
    Err(to_py(CoreError::Parameter {
        what: "chain",
        why: format!(
            "stage {position} is a {}, not a kernel of the chain",
            item.get_type().name()?
        ),
    }))
}

/// A mat's compiled chain: `stages`, kernels of `n_elements` elements in the order they run
/// (copied, their state as it is).
/// A frame's array of the wrong shape, or not C-contiguous: one `ShapeError` line.
fn shape_error(n: usize, what: &'static str, got: &[usize]) -> PyErr {
    to_py(CoreError::Shape {
        what,
        expected: format!("({n},), C-contiguous"),
        got: format!("{got:?}"),
    })
}

/// The inputs of one frame (`Chain.step`, `Chain.step_new`) checked against the chain's
/// `n` elements: the validity to run with (`all_valid` when none is given).
fn frame_inputs<'a>(
    n: usize,
    all_valid: &'a [bool],
    readings: &PyReadonlyArray1<'_, f64>,
    valid: &'a Option<PyReadonlyArray1<'_, bool>>,
) -> PyResult<&'a [bool]> {
    let valid = match valid {
        Some(v) if v.shape() != [n] => return Err(shape_error(n, "valid", v.shape())),
        Some(v) => v.as_slice()?,
        None => all_valid,
    };
    if readings.shape() != [n] {
        return Err(shape_error(n, "readings", readings.shape()));
    }
    Ok(valid)
}

/// `measured`: the elements whose failure code is 0, into `codes.len()` bools at `measured`
/// (a held array's, or a new numpy array's whose bytes may not be set yet: written through
/// the pointer, no reference to them made first).
///
/// # Safety
/// `measured` must be valid for writes of `codes.len()` bytes, and nothing else may read
/// or write them meanwhile.
unsafe fn write_measured(measured: *mut bool, codes: &[u8]) {
    for (i, &c) in codes.iter().enumerate() {
        // SAFETY: i < codes.len(), inside the bytes the caller vouches for
        unsafe { measured.add(i).write(c == 0) };
    }
}

#[pyclass(name = "Chain", module = "texsense._core")]
pub(crate) struct PyChain {
    inner: Chain,
    /// The validity of a frame given as None (every reading valid).
    all_valid: Vec<bool>,
    /// The time of the last frame of a stream stepped by [`PyChain::step_at`] (s; None: no
    /// frame yet).
    last_t: Option<f64>,
}

/// A live frame's readings or validity as `step_at` takes them as given: an exact numpy
/// array (not a subclass) of `T`, one-dimensional, C-contiguous, of `n` elements; None
/// for anything else (the caller converts it first).
fn as_given<'a, 'py, T: numpy::Element>(
    py: Python<'py>,
    x: &'a Bound<'py, PyAny>,
    n: usize,
) -> Option<&'a Bound<'py, PyArray1<T>>> {
    use pyo3::PyTypeInfo;
    let ndarray = numpy::PyUntypedArray::type_object(py);
    if !x.get_type().is(&ndarray) {
        return None;
    }
    let a = x.cast::<PyArray1<T>>().ok()?;
    (a.len() == n && a.is_c_contiguous()).then_some(a)
}

/// An array another borrow holds (written elsewhere meanwhile): one ShapeError line.
fn borrowed(what: &'static str, e: numpy::BorrowError) -> PyErr {
    to_py(CoreError::Shape {
        what,
        expected: "an array no one writes meanwhile".into(),
        got: e.to_string(),
    })
}

element_bank!(PyChain, {
    /// Every stage back to its initial state, and no frame time (`step_at`).
    fn reset(&mut self) {
        self.inner.reset();
        self.last_t = None;
    }

    /// The time of the last frame `step_at` stepped (s; None before the first; settable:
    /// a stream restored from a snapshot goes on from its time).
    #[getter]
    fn get_last_t(&self) -> Option<f64> {
        self.last_t
    }

    #[setter]
    fn set_last_t(&mut self, t: Option<f64>) {
        self.last_t = t;
    }

    /// One frame of a live stream at time `t` (s): readings (N,) float64 and their validity
    /// (N,) bool or None -> (values, codes, measured) in new arrays, as `step_new` with `dt`
    /// the time since the last frame (0 for the first). Frame times must be numbers and must
    /// not decrease (ParameterError). Returns None, stepping nothing, when the readings or
    /// the validity are not exact numpy arrays of their type, one-dimensional, contiguous,
    /// of N elements: the caller converts them and steps again (`Pipeline.step`: its
    /// checks and the clock in one call, issue 34, sixteenth round).
    #[pyo3(signature = (t, readings, valid))]
    #[allow(clippy::type_complexity)]
    fn step_at<'py>(
        &mut self,
        py: Python<'py>,
        t: f64,
        readings: &Bound<'py, PyAny>,
        valid: &Bound<'py, PyAny>,
    ) -> PyResult<
        Option<(
            Bound<'py, PyArray1<f64>>,
            Bound<'py, PyArray1<u8>>,
            Bound<'py, PyArray1<bool>>,
        )>,
    > {
        let dt = self.last_t.map_or(0.0, |last| t - last);
        if !(dt >= 0.0 && t.is_finite()) {
            return Err(crate::errors::ParameterError::new_err(
                "frame times must be numbers and must not decrease",
            ));
        }
        let n = self.inner.len();
        let Some(readings) = as_given::<f64>(py, readings, n) else {
            return Ok(None);
        };
        let valid = if valid.is_none() {
            None
        } else {
            match as_given::<bool>(py, valid, n) {
                Some(v) => Some(v.try_readonly().map_err(|e| borrowed("valid", e))?),
                None => return Ok(None),
            }
        };
        let readings = readings
            .try_readonly()
            .map_err(|e| borrowed("readings", e))?;
        let done = self.step_new(py, dt, readings, valid)?;
        self.last_t = Some(t);
        Ok(Some(done))
    }

    #[new]
    fn new(n_elements: usize, stages: Vec<Bound<'_, PyAny>>) -> PyResult<Self> {
        let stages = stages
            .iter()
            .enumerate()
            .map(|(k, s)| stage_of(s, k + 1))
            .collect::<PyResult<Vec<_>>>()?;
        let inner = Chain::new(n_elements, stages).map_err(to_py)?;
        Ok(Self {
            inner,
            all_valid: vec![true; n_elements],
            last_t: None,
        })
    }

    /// The stages' names in order.
    #[getter]
    fn stage_names(&self) -> Vec<&'static str> {
        self.inner.stages().iter().map(ChainStage::name).collect()
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
        let inner = &mut self.inner;
        run_detached2(py, b.t, b.n, |out, codes| {
            inner.run(b.dt, b.values, b.valid, out, codes)
        })
    }

    /// Batch of float32 readings (a recording's frames): dt (T,), readings (T, N) float32,
    /// valid (T, N) -> (values (T, N) float32, codes (T, N)); `run`'s values rounded to
    /// float32, bit for bit, without float64 copies of the batch.
    #[allow(clippy::type_complexity)]
    fn run_f32<'py>(
        &mut self,
        py: Python<'py>,
        dt: PyReadonlyArray1<'py, f64>,
        readings: PyReadonlyArray2<'py, f32>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<u8>>)> {
        let b = Batch::new("chain run", self.inner.len(), Some(&dt), &readings, &valid)?;
        let inner = &mut self.inner;
        run_detached2(py, b.t, b.n, |out, codes| {
            inner.run_f32(b.dt, b.values, b.valid, out, codes)
        })
    }

    /// One frame, for a live stream: `dt` (s since the previous frame), readings (N,) and
    /// their validity (N,; None: all valid) into arrays the caller holds and reuses: values
    /// `out` (N,) float64, failure codes `codes` (N,) uint8 and `measured` (N,) bool (code
    /// 0). The same kernels as `run` with one frame; no array is made per frame.
    #[pyo3(signature = (dt, readings, valid, out, codes, measured))]
    #[allow(clippy::too_many_arguments)]
    fn step<'py>(
        &mut self,
        dt: f64,
        readings: PyReadonlyArray1<'py, f64>,
        valid: Option<PyReadonlyArray1<'py, bool>>,
        out: &Bound<'py, PyArray1<f64>>,
        codes: &Bound<'py, PyArray1<u8>>,
        measured: &Bound<'py, PyArray1<bool>>,
    ) -> PyResult<()> {
        let n = self.inner.len();
        let valid = frame_inputs(n, &self.all_valid, &readings, &valid)?;
        for (what, got, contiguous) in [
            ("out", out.shape(), out.is_c_contiguous()),
            ("codes", codes.shape(), codes.is_c_contiguous()),
            ("measured", measured.shape(), measured.is_c_contiguous()),
        ] {
            if got != [n] || !contiguous {
                return Err(shape_error(n, what, got));
            }
        }
        // a borrow conflict (an output that is an input, or read-only) is one ShapeError line
        let taken = |what: &'static str, e: numpy::BorrowError| {
            to_py(CoreError::Shape {
                what,
                expected: "a writable array of its own".into(),
                got: e.to_string(),
            })
        };
        let mut out = out.try_readwrite().map_err(|e| taken("out", e))?;
        let mut codes = codes.try_readwrite().map_err(|e| taken("codes", e))?;
        let mut measured = measured.try_readwrite().map_err(|e| taken("measured", e))?;
        let (codes, measured) = (codes.as_slice_mut()?, measured.as_slice_mut()?);
        self.inner
            .run(
                &[dt],
                readings.as_slice()?,
                valid,
                out.as_slice_mut()?,
                codes,
            )
            .map_err(to_py)?;
        // SAFETY: `measured` is this call's writable borrow of n = codes.len() bools
        unsafe { write_measured(measured.as_mut_ptr(), codes) };
        Ok(())
    }

    /// One frame into new arrays: `dt`, readings (N,) and their validity (N,; None: all
    /// valid) -> (values (N,) float64, codes (N,) uint8, measured (N,) bool). What `step`
    /// does into arrays held, then copies of them, without the copies: the arrays are made
    /// here and written once (a live stream that keeps its frames).
    #[pyo3(signature = (dt, readings, valid))]
    #[allow(clippy::type_complexity)]
    fn step_new<'py>(
        &mut self,
        py: Python<'py>,
        dt: f64,
        readings: PyReadonlyArray1<'py, f64>,
        valid: Option<PyReadonlyArray1<'py, bool>>,
    ) -> PyResult<(
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<u8>>,
        Bound<'py, PyArray1<bool>>,
    )> {
        let n = self.inner.len();
        let valid = frame_inputs(n, &self.all_valid, &readings, &valid)?;
        // SAFETY: numpy arrays of plain numbers (any bits are a value) with their bytes not
        // set (numpy's allocator; zeroing them was 0.5 µs a frame at 1024 elements, issue 34,
        // fifteenth round): the chain writes every value and code before it reads one
        // (`chain::tests::every_value_and_code_is_written_before_it_is_read`)
        let (out, codes) = unsafe {
            (
                PyArray1::<f64>::new(py, [n], false),
                PyArray1::<u8>::new(py, [n], false),
            )
        };
        // SAFETY: as `out`; its bytes are written below through a raw pointer before
        // anything reads them (no `bool` is made of a byte not yet written)
        let measured = unsafe { PyArray1::<bool>::new(py, [n], false) };
        {
            // SAFETY: the arrays were made just above, contiguous, of n elements, and no
            // other reference to them exists yet, so no borrow can conflict
            let (o, c) = unsafe { (out.as_slice_mut()?, codes.as_slice_mut()?) };
            self.inner
                .run(&[dt], readings.as_slice()?, valid, o, c)
                .map_err(to_py)?;
            // SAFETY: `measured` owns n contiguous bytes (made above, C order)
            unsafe { write_measured(measured.data(), c) };
        }
        Ok((out, codes, measured))
    }

    /// The state of every stage as bytes (versioned).
    fn snapshot<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.inner.snapshot())
    }

    /// Continue from a snapshot of a chain of the same stages and sizes (all or nothing).
    fn restore(&mut self, state: &[u8]) -> PyResult<()> {
        self.inner.restore(state).map_err(to_py)
    }

    /// The chain as the model blob of a microcontroller (f32; each element keeps as many
    /// Preisach turning points as here).
    fn mcu_blob<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let blob = self.inner.mcu_blob().map_err(to_py)?;
        Ok(PyBytes::new(py, &blob))
    }
});

/// What a model blob holds, checked as the C side checks it: (elements, stage names, bytes
/// of memory in all, state bytes per element, scratch bytes per element, fixed bytes); a
/// damaged or foreign blob raises a ParameterError naming why.
#[pyfunction]
#[pyo3(name = "mcu_blob_info")]
#[allow(clippy::type_complexity)]
pub(crate) fn py_mcu_blob_info(
    blob: &[u8],
) -> PyResult<(usize, Vec<&'static str>, usize, usize, usize, usize)> {
    use texsense_kernels::blob::{BlobError, Model, StageView};
    // the C side reads a 4-byte aligned blob: copy it into words
    let mut words = vec![0u32; blob.len().div_ceil(4)];
    for (w, c) in words.iter_mut().zip(blob.chunks(4)) {
        let mut b = [0u8; 4];
        b[..c.len()].copy_from_slice(c);
        *w = u32::from_le_bytes(b);
    }
    // SAFETY: `words` is alive and holds at least blob.len() bytes, 4-byte aligned
    let aligned = unsafe { std::slice::from_raw_parts(words.as_ptr().cast::<u8>(), blob.len()) };
    let why = |e: BlobError| {
        to_py(CoreError::Parameter {
            what: "model blob",
            why: match e {
                BlobError::Magic => "not a texsense model blob".into(),
                BlobError::Version(v) => format!(
                    "format version {v}; this build reads version {}",
                    texsense_kernels::blob::VERSION
                ),
                BlobError::Length => "not as long as its header says (cut short?)".into(),
                BlobError::Checksum => "the checksum does not match: the blob is damaged".into(),
                BlobError::Format(k) => format!("{}: {}", k.what, k.why),
                BlobError::Alignment => "not 4-byte aligned".into(),
            },
        })
    };
    let model = Model::parse(aligned).map_err(why)?;
    let names = model
        .stages()
        .map(|s| match s {
            Ok(StageView::Detect { .. }) => "detect",
            Ok(StageView::Convert { curve: Some(_), .. }) => "convert",
            Ok(StageView::Convert { curve: None, .. }) => "linear",
            Ok(StageView::Loading(_)) => "loading curve",
            Ok(StageView::Hysteresis { .. }) => "hysteresis",
            Ok(StageView::Drift { level: Some(_), .. }) => "drift (QLV)",
            Ok(StageView::Drift { .. }) => "drift",
            Ok(StageView::Repair(_)) => "repair",
            Err(_) => "?",
        })
        .collect();
    let m = texsense_mcu::memory(&model);
    Ok((
        model.n_elements(),
        names,
        m.total(),
        m.state_per_element,
        m.scratch_per_element,
        m.fixed,
    ))
}
