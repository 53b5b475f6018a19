//! `texsense._core`: the thin PyO3 binding of `texsense-core`.
//!
//! Only array conversion and error mapping live here; every algorithm is in the core crate.
//! Each `CoreError` variant maps to its own exception class, re-exported by
//! `texsense.exceptions`.

use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::create_exception;
use pyo3::exceptions::{PyIndexError, PyValueError};
use pyo3::prelude::*;
use texsense_core::chain::{Chain, Converter, Curve, LocalRepair, Response};
use texsense_core::detect::{Changes, DetectorParams, FailureDetector};
use texsense_core::preisach::Schedule;
use texsense_core::repair::RepairOutcome;
use texsense_core::{
    everett_terms, BoucWenBank, BoucWenParams, Compensation, CoreError, DriftBank, Everett, Kernel,
    NeighbourMeanRepair, Neighbours, PreisachBank, SpacerBank, SpacerLaw, SpacerParams,
};

create_exception!(
    _core,
    ShapeError,
    PyValueError,
    "An array has the wrong shape or length."
);
create_exception!(
    _core,
    NeighbourIndexError,
    PyIndexError,
    "A neighbour index points outside the layout."
);
create_exception!(
    _core,
    ParameterError,
    PyValueError,
    "A parameter is outside its domain."
);

fn to_py(err: CoreError) -> PyErr {
    let msg = err.to_string();
    match err {
        CoreError::Shape { .. } => ShapeError::new_err(msg),
        CoreError::Index { .. } => NeighbourIndexError::new_err(msg),
        CoreError::Parameter { .. } => ParameterError::new_err(msg),
    }
}

fn neighbours_from(
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

/// Streaming eq. 6.14 repair: failed elements become the mean of their available
/// neighbours, or their last value when none is available.
#[pyclass(name = "NeighbourMeanRepair", module = "texsense._core")]
struct PyNeighbourMeanRepair {
    inner: NeighbourMeanRepair,
}

#[pymethods]
impl PyNeighbourMeanRepair {
    #[new]
    fn new(
        indptr: PyReadonlyArray1<'_, i64>,
        indices: PyReadonlyArray1<'_, i64>,
    ) -> PyResult<Self> {
        Ok(Self {
            inner: NeighbourMeanRepair::new(neighbours_from(indptr, indices)?),
        })
    }

    /// Number of elements.
    #[getter]
    fn n_elements(&self) -> usize {
        self.inner.len()
    }

    /// Last value (real or repaired) per element, NaN where none was seen yet.
    fn last_values<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        self.inner.last_values().to_vec().into_pyarray(py)
    }

    /// Forget all last values.
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Repair a batch `[T, N]`; returns `(repaired [T, N] float32, outcome [T, N] uint8)`
    /// with outcome 0 measured, 1 neighbour mean, 2 last value, 3 missing.
    #[allow(clippy::type_complexity)]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        frames: PyReadonlyArray2<'py, f32>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<u8>>)> {
        let shape = frames.shape().to_vec();
        batch_shape("frames", self.inner.len(), &shape, valid.shape(), None)?;
        let f = frames.as_slice()?;
        let v = valid.as_slice()?;
        let mut out = vec![0.0f32; f.len()];
        let mut outcome = vec![RepairOutcome::Measured; f.len()];
        let inner = &mut self.inner;
        py.detach(|| inner.run(f, v, &mut out, &mut outcome))
            .map_err(to_py)?;
        let codes: Vec<u8> = outcome.into_iter().map(|o| o as u8).collect();
        let out = numpy::ndarray::Array2::from_shape_vec((shape[0], shape[1]), out)
            .map_err(|e| ShapeError::new_err(e.to_string()))?;
        let codes = numpy::ndarray::Array2::from_shape_vec((shape[0], shape[1]), codes)
            .map_err(|e| ShapeError::new_err(e.to_string()))?;
        Ok((out.into_pyarray(py), codes.into_pyarray(py)))
    }
}

fn pairs(what: &'static str, rows: PyReadonlyArray2<'_, f64>) -> PyResult<Vec<(f64, f64)>> {
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

/// N spacer elements of one material (the virtual sensor's mechanics), stepped together by
/// displacement or by pressure: the first law (`SpacerBank(...)`) or the Bouc–Wen / Norton
/// law (`SpacerBank.bouc_wen(...)`). See `texsense.sim.spacer` for the parameters.
#[pyclass(name = "SpacerBank", module = "texsense._core")]
struct PySpacerBank {
    inner: Box<dyn SpacerLaw + Send + Sync>,
}

type Pair<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>);
type RampVecs = (Vec<f64>, Vec<f64>, Vec<f64>, bool);
type Ramp<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    bool,
);

#[pymethods]
impl PySpacerBank {
    #[new]
    #[allow(clippy::too_many_arguments)]
    fn new(
        backbone_a: f64,
        backbone_m: f64,
        densification: f64,
        linear: f64,
        friction: PyReadonlyArray2<'_, f64>,
        creep_a: f64,
        creep_tc: f64,
        rest_rate: f64,
        clutch_w: f64,
        clutch_a: f64,
        viscous: PyReadonlyArray2<'_, f64>,
        kelvin: PyReadonlyArray2<'_, f64>,
        recovery_factor: f64,
        creep_p_ref: f64,
        softening: PyReadonlyArray2<'_, f64>,
        softening_recovery_s: f64,
        scale: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<Self> {
        let params = SpacerParams {
            backbone_a,
            backbone_m,
            densification,
            linear,
            friction: pairs("friction", friction)?,
            creep_a,
            creep_tc,
            rest_rate,
            clutch: (clutch_w, clutch_a),
            viscous: pairs("viscous", viscous)?,
            kelvin: pairs("kelvin", kelvin)?,
            recovery_factor,
            creep_p_ref,
            softening: pairs("softening", softening)?,
            softening_recovery_s,
        };
        let inner = SpacerBank::new(params, scale.as_slice()?.to_vec()).map_err(to_py)?;
        Ok(Self {
            inner: Box::new(inner),
        })
    }

    /// The second spacer law: exponential backbone, Bouc–Wen friction, Norton creep
    /// (crates/core/src/bouc_wen.rs).
    #[staticmethod]
    #[allow(clippy::too_many_arguments)]
    fn bouc_wen(
        stiffness: f64,
        exponent: f64,
        densification: f64,
        friction: f64,
        slip: f64,
        bw_n: f64,
        bw_beta: f64,
        creep_share: f64,
        creep_rate: f64,
        creep_exponent: f64,
        scale: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<Self> {
        let params = BoucWenParams {
            stiffness,
            exponent,
            densification,
            friction,
            slip,
            bw_n,
            bw_beta,
            creep_share,
            creep_rate,
            creep_exponent,
        };
        let inner = BoucWenBank::new(params, scale.as_slice()?.to_vec()).map_err(to_py)?;
        Ok(Self {
            inner: Box::new(inner),
        })
    }

    /// Number of elements.
    #[getter]
    fn n_elements(&self) -> usize {
        self.inner.len()
    }

    /// Backbone stress (N/cm²) at compression fractions `e`.
    fn backbone<'py>(
        &self,
        py: Python<'py>,
        e: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let out: Vec<f64> = e
            .as_slice()?
            .iter()
            .map(|&x| self.inner.backbone(x))
            .collect();
        Ok(out.into_pyarray(py))
    }

    /// Current creep strain (permanent set) per element, fraction of thickness.
    fn creep_strain<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.creep_strain().into_pyarray(py)
    }

    /// Displacement control over a batch: `dt` (T,) seconds per step, `compression` (T, N)
    /// fractions of thickness. Returns (pressure N/cm², spacer compression), both (T, N).
    fn run_displacement<'py>(
        &mut self,
        py: Python<'py>,
        dt: PyReadonlyArray1<'py, f64>,
        compression: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Pair<'py>> {
        let (t, n) = self.batch_shape(&dt, &compression)?;
        let dts = dt.as_slice()?;
        let e = compression.as_slice()?;
        let mut p = vec![0.0; t * n];
        let mut s = vec![0.0; t * n];
        let inner = &mut self.inner;
        py.detach(|| {
            for (k, &dt) in dts.iter().enumerate() {
                let r = k * n..(k + 1) * n;
                inner.step_displacement(dt, &e[r.clone()], &mut p[r.clone()], &mut s[r])?;
            }
            Ok::<(), CoreError>(())
        })
        .map_err(to_py)?;
        Ok((to_2d(py, p, t, n)?, to_2d(py, s, t, n)?))
    }

    /// Test-machine ramp of a one-element bank at `rate` (fraction of thickness per s) until
    /// the pressure reaches `target`; returns (compression, pressure, spacer compression,
    /// reached) with one entry per step of `dt` seconds.
    fn ramp_until<'py>(
        &mut self,
        py: Python<'py>,
        dt: f64,
        rate: f64,
        target: f64,
        max_steps: usize,
    ) -> PyResult<Ramp<'py>> {
        let (e, p, s, done) = py
            .detach(|| self.ramp_until_inner(dt, rate, target, max_steps))
            .map_err(to_py)?;
        Ok((
            e.into_pyarray(py),
            p.into_pyarray(py),
            s.into_pyarray(py),
            done,
        ))
    }

    /// Pressure control over a batch: `dt` (T,), `pressure` (T, N) in N/cm². Returns the
    /// compression (T, N) as fractions of thickness and the pressure reached (T, N).
    fn run_pressure<'py>(
        &mut self,
        py: Python<'py>,
        dt: PyReadonlyArray1<'py, f64>,
        pressure: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Pair<'py>> {
        let (t, n) = self.batch_shape(&dt, &pressure)?;
        let dts = dt.as_slice()?;
        let p = pressure.as_slice()?;
        let mut e = vec![0.0; t * n];
        let mut reached = vec![0.0; t * n];
        let inner = &mut self.inner;
        py.detach(|| {
            for (k, &dt) in dts.iter().enumerate() {
                let r = k * n..(k + 1) * n;
                inner.step_pressure(dt, &p[r.clone()], &mut e[r.clone()], &mut reached[r])?;
            }
            Ok::<(), CoreError>(())
        })
        .map_err(to_py)?;
        Ok((to_2d(py, e, t, n)?, to_2d(py, reached, t, n)?))
    }
}

impl PySpacerBank {
    /// Test-machine ramp of a one-element bank; see the Rust docs of `ramp_until`.
    fn ramp_until_inner(
        &mut self,
        dt: f64,
        rate: f64,
        target: f64,
        max_steps: usize,
    ) -> Result<RampVecs, CoreError> {
        let (mut e, mut p, mut s) = (Vec::new(), Vec::new(), Vec::new());
        let done = self
            .inner
            .ramp_until(dt, rate, target, max_steps, &mut e, &mut p, &mut s)?;
        Ok((e, p, s, done))
    }

    fn batch_shape(
        &self,
        dt: &PyReadonlyArray1<'_, f64>,
        values: &PyReadonlyArray2<'_, f64>,
    ) -> PyResult<(usize, usize)> {
        let shape = values.shape();
        if shape[1] != self.inner.len() || dt.len() != shape[0] {
            return Err(to_py(CoreError::Shape {
                what: "batch",
                expected: format!("dt (T,) and values (T, {})", self.inner.len()),
                got: format!("dt ({},) and values {shape:?}", dt.len()),
            }));
        }
        Ok((shape[0], shape[1]))
    }
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

/// Run a kernel that fills a (T, N) f64 output, with the GIL released, and return the array.
fn run_detached<'py, F>(
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

fn to_2d<T: numpy::Element>(
    py: Python<'_>,
    v: Vec<T>,
    t: usize,
    n: usize,
) -> PyResult<Bound<'_, PyArray2<T>>> {
    let a = numpy::ndarray::Array2::from_shape_vec((t, n), v)
        .map_err(|e| ShapeError::new_err(e.to_string()))?;
    Ok(a.into_pyarray(py))
}

/// Preisach stacks of N elements over one Everett table (thesis eq. 4.15-4.22).
#[pyclass(name = "PreisachBank", module = "texsense._core")]
struct PyPreisachBank {
    inner: PreisachBank,
}

#[pymethods]
impl PyPreisachBank {
    #[new]
    fn new(
        u_min: f64,
        u_max: f64,
        table: PyReadonlyArray2<'_, f64>,
        n_elements: usize,
        capacity: usize,
    ) -> PyResult<Self> {
        let shape = table.shape();
        if shape[0] != shape[1] {
            return Err(to_py(CoreError::Shape {
                what: "everett table",
                expected: "a square (K, K) table".into(),
                got: format!("{shape:?}"),
            }));
        }
        let everett =
            Everett::new(shape[0], u_min, u_max, table.as_slice()?.to_vec()).map_err(to_py)?;
        let inner = PreisachBank::new(everett, n_elements, capacity).map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Number of elements.
    #[getter]
    fn n_elements(&self) -> usize {
        self.inner.len()
    }

    /// Back to lower saturation.
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Everett function F(alpha, beta) at points (same-shape 1-D arrays).
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
    /// frame): identical outputs, for the benchmark's step-by-step table.
    #[pyo3(signature = (inputs, valid, schedule="parallel"))]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        inputs: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
        schedule: &str,
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
        let (t, n) = batch_shape(
            "inputs",
            self.inner.len(),
            inputs.shape(),
            valid.shape(),
            None,
        )?;
        let (u, v) = (inputs.as_slice()?, valid.as_slice()?);
        let inner = &mut self.inner;
        run_detached(py, t, n, |out| inner.run_scheduled(u, v, out, schedule))
    }

    /// Bytes of state of the whole bank (elements and stacks moved to the heap).
    fn state_bytes(&self) -> usize {
        self.inner.state_bytes()
    }

    /// Set elements to an input with a given output (§6.4.4); returns the outputs set.
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
}

/// Recursive drift superposition for N elements (thesis eq. 5.4/5.8).
#[pyclass(name = "DriftBank", module = "texsense._core")]
struct PyDriftBank {
    inner: DriftBank,
}

#[pymethods]
impl PyDriftBank {
    #[new]
    #[pyo3(signature = (weights, taus, gamma, n_elements, rest_rate=0.0, rest_window=0.5, gamma_time=0.0))]
    fn new(
        weights: PyReadonlyArray1<'_, f64>,
        taus: PyReadonlyArray1<'_, f64>,
        gamma: f64,
        n_elements: usize,
        rest_rate: f64,
        rest_window: f64,
        gamma_time: f64,
    ) -> PyResult<Self> {
        let kernel =
            Kernel::new(weights.as_slice()?.to_vec(), taus.as_slice()?.to_vec()).map_err(to_py)?;
        let inner = DriftBank::new(kernel, gamma, n_elements)
            .and_then(|b| b.with_rest_rate(rest_rate, rest_window))
            .and_then(|b| b.with_time_component(gamma_time))
            .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Forget the history.
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Batch: time steps dt (T,), hysteresis outputs h (T, N), valid (T, N) -> (T, N).
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        dt: PyReadonlyArray1<'py, f64>,
        h: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let (t, n) = batch_shape(
            "drift run",
            self.inner.len(),
            h.shape(),
            valid.shape(),
            Some(dt.len()),
        )?;
        let (d, x, v) = (dt.as_slice()?, h.as_slice()?, valid.as_slice()?);
        let inner = &mut self.inner;
        run_detached(py, t, n, |out| inner.run(d, x, v, out))
    }
}

/// Preisach then drift, in one pass per frame (the combined compensation stage).
#[pyclass(name = "Compensation", module = "texsense._core")]
struct PyCompensation {
    inner: Compensation,
}

#[pymethods]
impl PyCompensation {
    #[new]
    #[pyo3(signature = (u_min, u_max, table, n_elements, capacity, offset, sign, gamma, weights=None, taus=None, rest_rate=0.0, rest_window=0.5, gamma_time=0.0))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        u_min: f64,
        u_max: f64,
        table: PyReadonlyArray2<'_, f64>,
        n_elements: usize,
        capacity: usize,
        offset: f64,
        sign: f64,
        gamma: f64,
        weights: Option<PyReadonlyArray1<'_, f64>>,
        taus: Option<PyReadonlyArray1<'_, f64>>,
        rest_rate: f64,
        rest_window: f64,
        gamma_time: f64,
    ) -> PyResult<Self> {
        let shape = table.shape();
        let everett =
            Everett::new(shape[0], u_min, u_max, table.as_slice()?.to_vec()).map_err(to_py)?;
        let preisach = PreisachBank::new(everett, n_elements, capacity).map_err(to_py)?;
        let drift = match (weights, taus) {
            (Some(w), Some(t)) => {
                let kernel =
                    Kernel::new(w.as_slice()?.to_vec(), t.as_slice()?.to_vec()).map_err(to_py)?;
                Some(
                    DriftBank::new(kernel, gamma, n_elements)
                        .and_then(|b| b.with_rest_rate(rest_rate, rest_window))
                        .and_then(|b| b.with_time_component(gamma_time))
                        .map_err(to_py)?,
                )
            }
            _ => None,
        };
        let inner = Compensation::new(preisach, drift, offset, sign).map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Both stages back to their initial state.
    fn reset(&mut self) {
        self.inner.reset();
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
        let (t, n) = batch_shape(
            "compensation run",
            self.inner.len(),
            inputs.shape(),
            valid.shape(),
            Some(dt.len()),
        )?;
        let (d, u, v) = (dt.as_slice()?, inputs.as_slice()?, valid.as_slice()?);
        let inner = &mut self.inner;
        run_detached(py, t, n, |out| inner.run(d, u, v, out))
    }
}

/// Failure detection on raw capacitance (thesis §6.5.2.5): codes 0 ok, 1 short/break,
/// 2 out of range, 3 stuck, 4 jump.
#[pyclass(name = "FailureDetector", module = "texsense._core")]
#[derive(Clone)]
struct PyFailureDetector {
    inner: FailureDetector,
    changes: Changes,
}

#[pymethods]
impl PyFailureDetector {
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

    /// Forget the history.
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Codes (T, N) uint8 of readings (T, N) with the converter's validity (T, N).
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        readings: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<Bound<'py, PyArray2<u8>>> {
        let (t, n) = batch_shape(
            "readings",
            self.inner.len(),
            readings.shape(),
            valid.shape(),
            None,
        )?;
        let (r, v) = (readings.as_slice()?, valid.as_slice()?);
        let mut codes = vec![0u8; t * n];
        let (inner, changes) = (&mut self.inner, &mut self.changes);
        py.detach(|| inner.run(r, v, &mut codes, changes))
            .map_err(to_py)?;
        to_2d(py, codes, t, n)
    }
}

/// The whole chain of a mat in one compiled pass: detect -> convert -> Preisach + drift (or
/// the first-loading curve) -> local repair.
#[pyclass(name = "Chain", module = "texsense._core")]
struct PyChain {
    inner: Chain,
}

#[pymethods]
impl PyChain {
    /// `repair`: "none", "zero", "last-value", "neighbour-mean" (needs indptr, indices) or
    /// "weighted" (needs indptr, indices and weights parallel to indices).
    #[new]
    #[pyo3(signature = (offset_pf, gain, curve_capacitance_pf=None, curve_compression_mm=None, *, detector=None, compensation=None, loading=None, repair="none", indptr=None, indices=None, weights=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        offset_pf: PyReadonlyArray1<'_, f64>,
        gain: PyReadonlyArray1<'_, f64>,
        curve_capacitance_pf: Option<PyReadonlyArray1<'_, f64>>,
        curve_compression_mm: Option<PyReadonlyArray1<'_, f64>>,
        detector: Option<PyRef<'_, PyFailureDetector>>,
        compensation: Option<PyRef<'_, PyCompensation>>,
        loading: Option<(PyReadonlyArray1<'_, f64>, PyReadonlyArray1<'_, f64>)>,
        repair: &str,
        indptr: Option<PyReadonlyArray1<'_, i64>>,
        indices: Option<PyReadonlyArray1<'_, i64>>,
        weights: Option<PyReadonlyArray1<'_, f64>>,
    ) -> PyResult<Self> {
        let curve = match (curve_capacitance_pf, curve_compression_mm) {
            (Some(c), Some(e)) => {
                Some(Curve::new(c.as_slice()?.to_vec(), e.as_slice()?.to_vec()).map_err(to_py)?)
            }
            (None, None) => None,
            _ => {
                return Err(to_py(CoreError::Parameter {
                    what: "chain",
                    why: "give both curve arrays or neither".into(),
                }))
            }
        };
        let converter = Converter::new(
            offset_pf.as_slice()?.to_vec(),
            gain.as_slice()?.to_vec(),
            curve,
        )
        .map_err(to_py)?;
        let response = match (compensation, loading) {
            (Some(c), None) => Response::Compensation(c.inner.clone()),
            (None, Some((e, p))) => Response::Loading(
                Curve::new(e.as_slice()?.to_vec(), p.as_slice()?.to_vec()).map_err(to_py)?,
            ),
            (None, None) => Response::Direct,
            _ => {
                return Err(to_py(CoreError::Parameter {
                    what: "chain",
                    why: "give at most one of compensation and loading".into(),
                }))
            }
        };
        let graph = || -> PyResult<Neighbours> {
            match (&indptr, &indices) {
                (Some(p), Some(i)) => neighbours_from(p.clone(), i.clone()),
                _ => Err(to_py(CoreError::Parameter {
                    what: "repair",
                    why: format!("{repair:?} needs the neighbour graph (indptr, indices)"),
                })),
            }
        };
        let repair = match repair {
            "none" => LocalRepair::None,
            "zero" => LocalRepair::Zero,
            "last-value" => LocalRepair::LastValue,
            "neighbour-mean" => LocalRepair::NeighbourMean(graph()?),
            "weighted" => {
                let w = weights.ok_or_else(|| {
                    to_py(CoreError::Parameter {
                        what: "repair",
                        why: "\"weighted\" needs weights".into(),
                    })
                })?;
                LocalRepair::Weighted(graph()?, w.as_slice()?.to_vec())
            }
            other => {
                return Err(to_py(CoreError::Parameter {
                    what: "repair",
                    why: format!("unknown local repair {other:?}"),
                }))
            }
        };
        let inner = Chain::new(
            detector.map(|d| d.inner.clone()),
            converter,
            response,
            repair,
        )
        .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// Number of elements.
    #[getter]
    fn n_elements(&self) -> usize {
        self.inner.len()
    }

    /// Every stage back to its initial state.
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Bytes of state per element (all stages, per-element parameters included).
    fn state_bytes_per_element(&self) -> usize {
        self.inner.state_bytes_per_element()
    }

    /// Batch: dt (T,), readings (T, N) pF, valid (T, N) -> (pressure (T, N), codes (T, N)).
    #[allow(clippy::type_complexity)]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        dt: PyReadonlyArray1<'py, f64>,
        readings: PyReadonlyArray2<'py, f64>,
        valid: PyReadonlyArray2<'py, bool>,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<u8>>)> {
        let (t, n) = batch_shape(
            "chain run",
            self.inner.len(),
            readings.shape(),
            valid.shape(),
            Some(dt.len()),
        )?;
        let (d, r, v) = (dt.as_slice()?, readings.as_slice()?, valid.as_slice()?);
        let mut codes = vec![0u8; t * n];
        let inner = &mut self.inner;
        let out = run_detached(py, t, n, |out| inner.run(d, r, v, out, &mut codes))?;
        Ok((out, to_2d(py, codes, t, n)?))
    }
}

/// The Everett terms of an input history (identification): (indptr, alpha, beta, coef).
#[pyfunction(name = "everett_terms")]
#[allow(clippy::type_complexity)]
fn py_everett_terms<'py>(
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

/// The compiled core of texsense.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<PyNeighbourMeanRepair>()?;
    m.add_class::<PySpacerBank>()?;
    m.add_class::<PyPreisachBank>()?;
    m.add_class::<PyDriftBank>()?;
    m.add_class::<PyCompensation>()?;
    m.add_class::<PyFailureDetector>()?;
    m.add_class::<PyChain>()?;
    m.add_function(wrap_pyfunction!(py_everett_terms, m)?)?;
    m.add("ShapeError", m.py().get_type::<ShapeError>())?;
    m.add(
        "NeighbourIndexError",
        m.py().get_type::<NeighbourIndexError>(),
    )?;
    m.add("ParameterError", m.py().get_type::<ParameterError>())?;
    Ok(())
}
