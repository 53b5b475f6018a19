//! Capacitance -> compression per element (thesis eq. 2.1), the conversion that every
//! calibrated reading goes through: `C_ref = (C - a_i) / b_i`, then the compression from the
//! material curve `C_ref(e)` of a reference element, linearly interpolated and held at its
//! ends (or, without a curve, the scaled reading itself: a linear calibration). The kernels
//! are `texsense_kernels::convert` (one implementation with the microcontroller's); this
//! module owns their arrays.
//!
//! [`Curve`] is also the first-loading curve `p(e)` of an uncompensated chain.

use texsense_kernels::convert::{self as kernel, buckets};
use texsense_kernels::stage;

use crate::aligned::Lines;
use crate::error::{check_len, frames_of, CoreError};

/// A piecewise-linear curve `y(x)` over increasing `x`, held at its ends (`np.interp`).
///
/// The segment of an input is found without a search: a table of uniform buckets over `x`
/// holds, per bucket, the last point at or below the bucket's start, and a step or two
/// forward from there reaches the segment (exactly the one a binary search finds).
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    x: Vec<f64>,
    y: Vec<f64>,
    slope: Vec<f64>,
    bucket_start: Vec<u32>,
    inv_width: f64,
    /// Per bucket, its start and split side by side ([`Curve::split`],
    /// [`Curve::lane_tables`]).
    by_bucket: Vec<[f64; 2]>,
    /// Per point, its x, y and slope side by side ([`Curve::lane_tables`]).
    by_point: Vec<[f64; 4]>,
}

impl Curve {
    /// Build from points with strictly increasing `x` (at least 2).
    pub fn new(x: Vec<f64>, y: Vec<f64>) -> Result<Self, CoreError> {
        check_len("curve y", y.len(), x.len())?;
        let mut slope = vec![0.0; x.len().saturating_sub(1)];
        let mut bucket_start = vec![0; buckets(x.len()) + 1];
        let inv_width = kernel::tables(&x, &y, &mut slope, &mut bucket_start).map_err(|_| {
            CoreError::Parameter {
                what: "curve",
                why: "needs >= 2 finite points with strictly increasing x".into(),
            }
        })?;
        let by_bucket = by_bucket(&x, &bucket_start);
        let by_point = (0..x.len())
            .map(|j| [x[j], y[j], slope.get(j).copied().unwrap_or(0.0), 0.0])
            .collect();
        Ok(Self {
            x,
            y,
            slope,
            bucket_start,
            inv_width,
            by_bucket,
            by_point,
        })
    }

    /// Per bucket `b` of the segment table, where an input of the bucket steps once forward
    /// from the bucket's start `j`: `x[j + 1]` (infinite when `j` is the last segment), or
    /// NaN when an input of the bucket may step twice or more (a point after `x[j + 1]` within
    /// the bucket, or close to its end). The AVX-512 conversion gathers it with the bucket's
    /// start, so that the segment's `x`, `y` and slope are one gather level after the bucket
    /// (issue 34, twelfth round); a lane with NaN walks as the kernel does.
    ///
    /// # Panics
    /// When `b` is not a bucket.
    pub fn split(&self, b: usize) -> f64 {
        self.by_bucket[b][1]
    }

    /// The curve's tables for the AVX-512 lanes' loads ([`crate::simd::Lookup::Loads`]):
    /// per bucket its start (as f64) and [`Curve::split`], and per point its `x`, `y` and
    /// slope (0 at the last point) and a zero, so that a lane reads each with one load
    /// instead of a gather per value (issue 34, eighteenth round).
    pub fn lane_tables(&self) -> (&[[f64; 2]], &[[f64; 4]]) {
        (&self.by_bucket, &self.by_point)
    }

    /// The kernels' view (checked when the curve was built).
    #[inline]
    pub fn view(&self) -> kernel::Curve<'_, f64> {
        kernel::Curve::new_trusted(
            &self.x,
            &self.y,
            &self.slope,
            &self.bucket_start,
            self.inv_width,
        )
        .expect("a curve checked when built")
    }

    /// `y` at `v` (NaN for NaN).
    #[inline]
    pub fn at(&self, v: f64) -> f64 {
        self.view().at(v)
    }

    /// The points (x, y).
    pub fn points(&self) -> (&[f64], &[f64]) {
        (&self.x, &self.y)
    }
}

/// Per bucket its start (as f64) and [`Curve::split`], from a curve's points and bucket
/// table ([`kernel::tables`]).
fn by_bucket(x: &[f64], bucket_start: &[u32]) -> Vec<[f64; 2]> {
    let last = x.len() - 1;
    let buckets = (bucket_start.len() - 1) as f64;
    let width = (x[last] - x[0]) / buckets;
    bucket_start
        .iter()
        .enumerate()
        .map(|(b, &start)| {
            let j = start as usize;
            // the bucket's end with a margin far above the rounding of an input's bucket
            let end = x[0] + (b as f64 + 1.001) * width;
            let split = if j + 2 < last && x[j + 2] <= end {
                f64::NAN
            } else if j + 1 < last {
                x[j + 1]
            } else {
                f64::INFINITY
            };
            [f64::from(start), split]
        })
        .collect()
}

/// Capacitance -> compression per element (eq. 2.1): `C_ref = (C - offset_i) / gain_i`,
/// then the material curve from `C_ref` to the compression (or, without a curve, the
/// reading scaled per element: a linear calibration).
#[derive(Debug, Clone)]
pub struct Converter {
    /// Per element, on cache lines ([`Lines`]: the rows read eight at a time).
    offset: Lines<f64>,
    gain: Lines<f64>,
    curve: Option<Curve>,
}

/// A [`Converter`] seen by the kernels (built once per pass, not per element).
#[derive(Debug, Clone, Copy)]
pub struct ConverterView<'a> {
    /// Per element offset.
    pub offset: &'a [f64],
    /// Per element gain.
    pub gain: &'a [f64],
    /// The material curve.
    pub curve: Option<kernel::Curve<'a, f64>>,
    /// The curve's [`Curve::lane_tables`] (empty without a curve).
    pub by_bucket: &'a [[f64; 2]],
    /// As above.
    pub by_point: &'a [[f64; 4]],
}

impl ConverterView<'_> {
    /// Element `i` reading `c`: its compression (the scaled reading without a curve).
    #[inline]
    pub fn at(&self, i: usize, c: f64) -> f64 {
        kernel::convert(self.offset[i], self.gain[i], self.curve.as_ref(), c)
    }

    /// Element `i`'s stage: reading and validity -> value and validity.
    #[inline(always)]
    pub fn stage(&self, i: usize, c: f64, ok: bool) -> (f64, bool) {
        stage::conversion(self.offset[i], self.gain[i], self.curve.as_ref(), c, ok)
    }

    /// The stage over elements `start .. start + x.len()` of a frame: readings `x` and
    /// their validity `ok` -> values `out` (the validity stays `ok`); on AVX2 four elements
    /// at a time (eight on AVX-512: `avx512`) ([`crate::simd`]; the same bits as [`ConverterView::stage`]).
    ///
    /// # Panics
    /// When the slices differ in length or the view has too few elements.
    pub fn row(&self, start: usize, x: &[f64], ok: &[bool], out: &mut [f64]) {
        assert!(
            x.len() == ok.len() && x.len() == out.len(),
            "one per element"
        );
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx512() {
            // SAFETY: the processor has AVX2 and AVX-512 F/DQ/VL (detected by `simd::avx512`)
            unsafe { avx512::row(self, start, x, ok, out) };
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2() {
            // SAFETY: the processor has AVX2 (detected by `simd::avx2`)
            unsafe { avx2::row(self, start, x, ok, out) };
            return;
        }
        for (i, slot) in out.iter_mut().enumerate() {
            *slot = self.stage(start + i, x[i], ok[i]).0;
        }
    }
}

impl Converter {
    /// Per-element offsets and gains (> 0) and the curve from reference capacitance to
    /// compression (None: the scaled reading itself).
    pub fn new(offset: Vec<f64>, gain: Vec<f64>, curve: Option<Curve>) -> Result<Self, CoreError> {
        check_len("gain", gain.len(), offset.len())?;
        if gain.iter().any(|g| !g.is_finite() || *g <= 0.0) || offset.iter().any(|o| !o.is_finite())
        {
            return Err(CoreError::Parameter {
                what: "converter",
                why: "offsets must be finite and gains finite and > 0".into(),
            });
        }
        Ok(Self {
            offset: Lines::from_slice(&offset),
            gain: Lines::from_slice(&gain),
            curve,
        })
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.offset.len()
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.offset.is_empty()
    }

    /// Per-element offsets and gains, and the curve.
    pub fn parts(&self) -> (&[f64], &[f64], Option<&Curve>) {
        (&self.offset, &self.gain, self.curve.as_ref())
    }

    /// The kernels' view.
    pub fn view(&self) -> ConverterView<'_> {
        ConverterView {
            offset: &self.offset,
            gain: &self.gain,
            curve: self.curve.as_ref().map(Curve::view),
            by_bucket: self.curve.as_ref().map_or(&[], |c| c.lane_tables().0),
            by_point: self.curve.as_ref().map_or(&[], |c| c.lane_tables().1),
        }
    }

    /// Element `i` reading `c`: its compression (the scaled reading without a curve).
    #[inline]
    pub fn at(&self, i: usize, c: f64) -> f64 {
        self.view().at(i, c)
    }

    /// A batch (T x N): readings and validity -> converted values, NaN where a reading is
    /// invalid or not a number.
    pub fn run(&self, readings: &[f64], valid: &[bool], out: &mut [f64]) -> Result<(), CoreError> {
        let n = self.len();
        if n == 0 {
            return Ok(());
        }
        frames_of("readings", readings.len(), n)?;
        check_len("valid", valid.len(), readings.len())?;
        check_len("out", out.len(), readings.len())?;
        let view = self.view();
        for (row, (r, v)) in out
            .chunks_exact_mut(n)
            .zip(readings.chunks_exact(n).zip(valid.chunks_exact(n)))
        {
            for (i, o) in row.iter_mut().enumerate() {
                *o = view.stage(i, r[i], v[i]).0;
            }
        }
        Ok(())
    }
}
#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
