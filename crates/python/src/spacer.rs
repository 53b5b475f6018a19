//! `SpacerBank`: the virtual sensor's spacer mechanics (texsense.sim.spacer).

use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use texsense_core::{BoucWenBank, BoucWenParams, CoreError, SpacerBank, SpacerLaw, SpacerParams};

use crate::arrays::{pairs, to_2d};
use crate::errors::to_py;

/// N spacer elements of one material (the virtual sensor's mechanics), stepped together by
/// displacement or by pressure: the first law (`SpacerBank(...)`) or the Bouc–Wen / Norton
/// law (`SpacerBank.bouc_wen(...)`). See `texsense.sim.spacer` for the parameters.
#[pyclass(name = "SpacerBank", module = "texsense._core")]
pub(crate) struct PySpacerBank {
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
