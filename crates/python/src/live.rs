//! The per-frame arithmetic of a live mat around its chain (`texsense_core::live`): one frame's
//! bounds, the in-use estimator's movement test, the exposure tracker's step.

use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1, PyReadwriteArray1};
use pyo3::prelude::*;
use texsense_core::live::{self, BoundsOf, ExposureRule, Motion, MotionLimits, Verdict};
use texsense_core::CoreError;

use crate::errors::to_py;

/// Two float64 arrays (lower, upper).
type Pair<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

fn misfit(what: &'static str) -> PyErr {
    to_py(CoreError::Shape {
        what,
        expected: "arrays of one length (and tables of one length)".into(),
        got: "arrays or tables of other lengths".into(),
    })
}

/// The index of the first element time of `t` (float64, 1-D) that no clock has: not a number,
/// or `|t|` over `limit` (`texsense.data.times.off_scale`); None when all are on the scale.
#[pyfunction]
#[pyo3(name = "first_off_scale")]
pub(crate) fn py_first_off_scale(
    t: PyReadonlyArray1<'_, f64>,
    limit: f64,
) -> PyResult<Option<usize>> {
    Ok(live::first_off_scale(t.as_slice()?, limit))
}

/// The lower and upper bounds of one frame (`intervals.bounds` of one frame, to the bit).
#[pyfunction]
#[pyo3(name = "frame_bounds")]
#[pyo3(signature = (values, ok, drift, edges, scale, mult_edges, mult, multiplier, r_repaired, range_max))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn py_frame_bounds<'py>(
    py: Python<'py>,
    values: PyReadonlyArray1<'py, f64>,
    ok: PyReadonlyArray1<'py, bool>,
    drift: f64,
    edges: PyReadonlyArray1<'py, f64>,
    scale: PyReadonlyArray1<'py, f64>,
    mult_edges: PyReadonlyArray1<'py, f64>,
    mult: PyReadonlyArray1<'py, f64>,
    multiplier: Option<f64>,
    r_repaired: f64,
    range_max: Option<f64>,
) -> PyResult<Pair<'py>> {
    let v = values.as_slice()?;
    let of = BoundsOf {
        edges: edges.as_slice()?,
        scale: scale.as_slice()?,
        mult_edges: mult_edges.as_slice()?,
        mult: mult.as_slice()?,
        multiplier,
        r_repaired,
        range_max,
    };
    let (mut lo, mut hi) = (vec![0.0; v.len()], vec![0.0; v.len()]);
    live::frame_bounds(v, ok.as_slice()?, drift, &of, &mut lo, &mut hi)
        .ok_or_else(|| misfit("frame_bounds"))?;
    Ok((lo.into_pyarray(py), hi.into_pyarray(py)))
}

/// One step of the exposure tracker's elements, in place (`ExposureTracker.step` without
/// regions); returns (any element loaded, elements at the reposition time, largest exposure).
#[pyfunction]
#[pyo3(name = "exposure_advance")]
#[pyo3(signature = (pressure, lower, upper, threshold, count_possible, offload_s, reposition_s, dt, skipped, exposure, relief, loaded_last, confident, possible))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn py_exposure_advance(
    pressure: PyReadonlyArray1<'_, f64>,
    lower: Option<PyReadonlyArray1<'_, f64>>,
    upper: Option<PyReadonlyArray1<'_, f64>>,
    threshold: f64,
    count_possible: bool,
    offload_s: f64,
    reposition_s: f64,
    dt: f64,
    skipped: bool,
    mut exposure: PyReadwriteArray1<'_, f64>,
    mut relief: PyReadwriteArray1<'_, f64>,
    mut loaded_last: PyReadwriteArray1<'_, bool>,
    mut confident: PyReadwriteArray1<'_, bool>,
    mut possible: PyReadwriteArray1<'_, bool>,
) -> PyResult<(bool, usize, f64)> {
    let bounds = match (&lower, &upper) {
        (Some(lo), Some(hi)) => Some((lo.as_slice()?, hi.as_slice()?)),
        _ => None,
    };
    let rule = ExposureRule {
        threshold,
        count_possible,
        offload_s,
        reposition_s,
    };
    let st = live::Exposure {
        exposure: exposure.as_slice_mut()?,
        relief: relief.as_slice_mut()?,
        loaded_last: loaded_last.as_slice_mut()?,
        confident: confident.as_slice_mut()?,
        possible: possible.as_slice_mut()?,
    };
    let got = live::exposure_advance(pressure.as_slice()?, bounds, rule, dt, skipped, st)
        .ok_or_else(|| misfit("exposure_advance"))?;
    Ok((got.any_loaded, got.over, got.top))
}

/// The in-use drift estimator's test of a frame: empty, moved or still
/// (`InUseDrift.step`'s empty count and `_moved`, to the bit), with the last frame it saw.
#[pyclass(name = "MotionTest", module = "texsense._core")]
pub(crate) struct PyMotionTest {
    inner: Motion,
}

#[pymethods]
impl PyMotionTest {
    /// `blocks`: the block of every element (from 0); `area`: every element's area (cm²).
    #[new]
    fn new(blocks: PyReadonlyArray1<'_, i64>, area: PyReadonlyArray1<'_, f64>) -> PyResult<Self> {
        let blocks = blocks
            .as_slice()?
            .iter()
            .map(|&b| usize::try_from(b).ok())
            .collect::<Option<Vec<usize>>>()
            .ok_or_else(|| misfit("MotionTest blocks (negative)"))?;
        let inner = Motion::new(&blocks, area.as_slice()?).ok_or_else(|| misfit("MotionTest"))?;
        Ok(Self { inner })
    }

    /// Forget the last frame.
    fn forget(&mut self) {
        self.inner.forget();
    }

    /// `c = x * gain` (a new array) and "empty", "moved" or "still".
    #[allow(clippy::too_many_arguments)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        x: PyReadonlyArray1<'py, f64>,
        gain: PyReadonlyArray1<'py, f64>,
        ok: PyReadonlyArray1<'py, bool>,
        empty: f64,
        empty_count: usize,
        floor: f64,
        motion: f64,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, &'static str)> {
        let mut c = vec![0.0; self.inner.len()];
        let limits = MotionLimits {
            empty,
            empty_count,
            floor,
            motion,
        };
        let verdict = self
            .inner
            .step(
                x.as_slice()?,
                gain.as_slice()?,
                ok.as_slice()?,
                limits,
                &mut c,
            )
            .ok_or_else(|| misfit("MotionTest.step"))?;
        let word = match verdict {
            Verdict::Empty => "empty",
            Verdict::Moved => "moved",
            Verdict::Still => "still",
        };
        Ok((c.into_pyarray(py), word))
    }
}
