//! Capacitance -> compression per element (thesis eq. 2.1), the conversion that every
//! calibrated reading goes through: `C_ref = (C - a_i) / b_i`, then the compression from the
//! material curve `C_ref(e)` of a reference element, linearly interpolated and held at its
//! ends (or, without a curve, the scaled reading itself: a linear calibration).
//!
//! [`Curve`] is also the first-loading curve `p(e)` of an uncompensated chain.

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
}

impl Curve {
    /// Build from points with strictly increasing `x` (at least 2).
    pub fn new(x: Vec<f64>, y: Vec<f64>) -> Result<Self, CoreError> {
        check_len("curve y", y.len(), x.len())?;
        if x.len() < 2
            || x.len() > u32::MAX as usize
            || x.windows(2)
                .any(|w| w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater))
            || x.iter().chain(&y).any(|v| !v.is_finite())
        {
            return Err(CoreError::Parameter {
                what: "curve",
                why: "needs >= 2 finite points with strictly increasing x".into(),
            });
        }
        let last = x.len() - 1;
        let buckets = 4 * x.len();
        let width = (x[last] - x[0]) / buckets as f64;
        let bucket_start = (0..=buckets)
            .map(|b| {
                let lo = x[0] + b as f64 * width;
                (x.partition_point(|&xi| xi <= lo).max(1) - 1).min(last - 1) as u32
            })
            .collect();
        // per segment, as np.interp computes it (so the same bits)
        let slope = (0..last)
            .map(|j| (y[j + 1] - y[j]) / (x[j + 1] - x[j]))
            .collect();
        Ok(Self {
            bucket_start,
            inv_width: 1.0 / width,
            slope,
            x,
            y,
        })
    }

    /// `y` at `v` (NaN for NaN).
    #[inline]
    pub fn at(&self, v: f64) -> f64 {
        let (x, y) = (&self.x, &self.y);
        let last = x.len() - 1;
        if v.is_nan() {
            return f64::NAN;
        }
        if v >= x[last] {
            return y[last];
        }
        if v <= x[0] {
            return y[0];
        }
        let top = (self.bucket_start.len() - 1) as f64;
        let pos = ((v - x[0]) * self.inv_width).min(top);
        // SAFETY: x[0] < v and v is a number, so 0 <= pos <= top < 2^32 (a plain `as` cast
        // spends a dozen instructions on saturation that cannot happen here)
        let b = unsafe { pos.to_int_unchecked::<u32>() } as usize;
        let mut j = self.bucket_start[b] as usize;
        // the bucket's start may round either way at its edge: settle on x[j] <= v < x[j + 1]
        while j > 0 && x[j] > v {
            j -= 1;
        }
        while j + 1 < last && x[j + 1] <= v {
            j += 1;
        }
        if x[j] == v {
            return y[j];
        }
        self.slope[j] * (v - x[j]) + y[j]
    }
}

/// Capacitance -> compression per element (eq. 2.1): `C_ref = (C - offset_i) / gain_i`,
/// then the material curve from `C_ref` to the compression (or, without a curve, the
/// reading scaled per element: a linear calibration).
#[derive(Debug, Clone)]
pub struct Converter {
    offset: Vec<f64>,
    gain: Vec<f64>,
    curve: Option<Curve>,
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
            offset,
            gain,
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

    /// Element `i` reading `c`: its compression (the scaled reading without a curve).
    #[inline]
    pub fn at(&self, i: usize, c: f64) -> f64 {
        let scaled = (c - self.offset[i]) / self.gain[i];
        match &self.curve {
            Some(curve) => curve.at(scaled),
            None => scaled,
        }
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
        for (row, (r, v)) in out
            .chunks_exact_mut(n)
            .zip(readings.chunks_exact(n).zip(valid.chunks_exact(n)))
        {
            for (i, o) in row.iter_mut().enumerate() {
                *o = if v[i] && r[i].is_finite() {
                    self.at(i, r[i])
                } else {
                    f64::NAN
                };
            }
        }
        Ok(())
    }
}
