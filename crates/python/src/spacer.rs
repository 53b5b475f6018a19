//! `SpacerBank`: the virtual sensor's spacer mechanics (texsense.sim.spacer).

use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use texsense_core::{
    BoucWenBank, BoucWenParams, CoreError, SpacerBank, SpacerBatch, SpacerLaw, SpacerParams,
};

use crate::arrays::{element_bank, pairs, run_detached2, Batch};
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

element_bank!(PySpacerBank, {
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
        let b = Batch::unmasked("compression", self.inner.len(), &dt, &compression)?;
        let (t, n) = (b.t, b.n);
        let inner = &mut self.inner;
        run_detached2(py, t, n, |p, s| {
            inner.run_displacement(b.dt, b.values, p, s)
        })
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
        let b = Batch::unmasked("pressure", self.inner.len(), &dt, &pressure)?;
        let (t, n) = (b.t, b.n);
        let inner = &mut self.inner;
        run_detached2(py, t, n, |e, reached| {
            inner.run_pressure(b.dt, b.values, e, reached)
        })
    }
});

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
}
