//! Capacitance -> compression per element (thesis eq. 2.1): `C_ref = (C - a_i) / b_i`, then
//! the compression from the material curve `C_ref(e)` of a reference element, linearly
//! interpolated and held at its ends (or, without a curve, the scaled reading itself: a
//! linear calibration). [`Curve`] is also the first-loading curve `p(e)` of an
//! uncompensated chain and the elastic response of a QLV drift.

use crate::error::{ensure, KernelError};
use crate::real::Real;

/// Buckets of a curve of `points` points (its table has one entry more).
#[inline]
pub const fn buckets(points: usize) -> usize {
    4 * points
}

/// A piecewise-linear curve `y(x)` over increasing `x`, held at its ends (`np.interp`), with
/// the tables that find a segment without a search: per segment its slope, and a table of
/// uniform buckets over `x` holding per bucket the last point at or below the bucket's start;
/// a step or two forward from there reaches the segment (exactly the one a binary search
/// finds).
#[derive(Debug, Clone, Copy)]
pub struct Curve<'a, T> {
    x: &'a [T],
    y: &'a [T],
    slope: &'a [T],
    bucket_start: &'a [u32],
    inv_width: T,
}

/// The derived tables of a curve (slopes, buckets) from its points, into `slope`
/// (`len - 1`) and `bucket_start` (`buckets(len) + 1`); returns `1 / bucket width`.
/// Needs >= 2 finite points with strictly increasing `x`.
pub fn tables<T: Real>(
    x: &[T],
    y: &[T],
    slope: &mut [T],
    bucket_start: &mut [u32],
) -> Result<T, KernelError> {
    let why = "needs >= 2 finite points with strictly increasing x";
    ensure(y.len() == x.len(), "curve", "x and y differ in length")?;
    ensure(x.len() >= 2 && x.len() <= u32::MAX as usize, "curve", why)?;
    ensure(
        x.windows(2).all(|w| w[1] > w[0]) && x.iter().chain(y).all(|v| v.is_finite()),
        "curve",
        why,
    )?;
    let n = x.len();
    ensure(slope.len() == n - 1, "curve slopes", "need one per segment")?;
    ensure(
        bucket_start.len() == buckets(n) + 1,
        "curve buckets",
        "wrong length",
    )?;
    let last = n - 1;
    let width = (x[last] - x[0]) / T::from_usize(buckets(n));
    for (b, start) in bucket_start.iter_mut().enumerate() {
        let lo = x[0] + T::from_usize(b) * width;
        // the number of points at or below lo (a binary search)
        let (mut a, mut z) = (0usize, n);
        while a < z {
            let mid = (a + z) / 2;
            if x[mid] <= lo {
                a = mid + 1;
            } else {
                z = mid;
            }
        }
        *start = (a.max(1) - 1).min(last - 1) as u32;
    }
    // per segment, as np.interp computes it (so the same bits)
    for (j, s) in slope.iter_mut().enumerate() {
        *s = (y[j + 1] - y[j]) / (x[j + 1] - x[j]);
    }
    Ok(T::ONE / width)
}

impl<'a, T: Real> Curve<'a, T> {
    /// View a curve and its tables ([`tables`]). Checks what keeps [`Curve::at`] in bounds
    /// (lengths, every bucket below the last segment, a finite positive bucket scale); the
    /// points' order is [`tables`]'s check.
    pub fn new(
        x: &'a [T],
        y: &'a [T],
        slope: &'a [T],
        bucket_start: &'a [u32],
        inv_width: T,
    ) -> Result<Self, KernelError> {
        let curve = Self::new_trusted(x, y, slope, bucket_start, inv_width)?;
        ensure(
            bucket_start.iter().all(|&b| (b as usize) < x.len() - 1),
            "curve buckets",
            "a bucket points past the last segment",
        )?;
        Ok(curve)
    }

    /// View a curve whose tables [`Curve::new`] accepted before, without the pass over its
    /// buckets (an inconsistent table makes [`Curve::at`] panic, never read out of bounds).
    pub fn new_trusted(
        x: &'a [T],
        y: &'a [T],
        slope: &'a [T],
        bucket_start: &'a [u32],
        inv_width: T,
    ) -> Result<Self, KernelError> {
        let n = x.len();
        ensure(n >= 2 && y.len() == n, "curve", "needs >= 2 points")?;
        ensure(slope.len() == n - 1, "curve slopes", "need one per segment")?;
        ensure(!bucket_start.is_empty(), "curve buckets", "none")?;
        ensure(
            inv_width.is_finite() && inv_width > T::ZERO,
            "curve",
            "bucket width must be finite and > 0",
        )?;
        Ok(Self {
            x,
            y,
            slope,
            bucket_start,
            inv_width,
        })
    }

    /// The points' x.
    pub fn x(&self) -> &'a [T] {
        self.x
    }

    /// The points' y.
    pub fn y(&self) -> &'a [T] {
        self.y
    }

    /// The slopes of the segments.
    pub fn slopes(&self) -> &'a [T] {
        self.slope
    }

    /// The bucket table.
    pub fn bucket_starts(&self) -> &'a [u32] {
        self.bucket_start
    }

    /// `1 / bucket width`.
    pub fn inv_width(&self) -> T {
        self.inv_width
    }

    /// `y` at `v` (NaN for NaN).
    #[inline]
    pub fn at(&self, v: T) -> T {
        let (x, y) = (self.x, self.y);
        let last = x.len() - 1;
        if v.is_nan() {
            return T::NAN;
        }
        if v >= x[last] {
            return y[last];
        }
        if v <= x[0] {
            return y[0];
        }
        let top = T::from_usize(self.bucket_start.len() - 1);
        let pos = ((v - x[0]) * self.inv_width).min(top);
        // SAFETY: x[0] < v and v is a number and inv_width > 0 is finite, so
        // 0 <= pos <= top < 2^32 (a plain `as` cast spends a dozen instructions on
        // saturation that cannot happen here)
        let b = unsafe { pos.floor_u32_unchecked() } as usize;
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

/// Element reading `c` with offset and gain (eq. 2.1): its compression through the curve,
/// or without one the scaled reading (a linear calibration).
#[inline]
pub fn convert<T: Real>(offset: T, gain: T, curve: Option<&Curve<'_, T>>, c: T) -> T {
    let scaled = (c - offset) / gain;
    match curve {
        Some(curve) => curve.at(scaled),
        None => scaled,
    }
}
