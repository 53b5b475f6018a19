//! The local repairs of failed readings (thesis §6.5.2.5), one frame.
//!
//! Eq. 6.14: `p_i = (p_l + p_r + p_t + p_b) / n_a`, the sum running over the `n_a`
//! neighbours that are available in the same frame. "If all four are unavailable, the last
//! value available (real or reconstructed) of the sensor element is taken." The other local
//! methods: `zero` (a failed reading reads 0), `last-value` (the element's last value, real
//! or repaired) and `weighted` (a weighted mean of the available neighbours with fixed
//! weights, e.g. inverse squared distance over the 8-neighbourhood).
//!
//! A reading is *available* when it is flagged valid and is a finite number. Only available
//! readings enter a mean: a neighbour that is itself being repaired in the same frame does
//! not contribute. Where no neighbour is available the element's last value is held; an
//! element that has never had a value stays NaN (*missing*). The fills of a frame are
//! computed from its readings as they came in and written after them, so no fill sees
//! another.

use crate::error::{ensure, KernelError};
use crate::graph::Graph;
use crate::real::Real;

/// What happened to one reading.
pub mod outcome {
    /// Available: passed through unchanged.
    pub const MEASURED: u8 = 0;
    /// Filled by the method (a neighbour mean, or 0).
    pub const FILLED: u8 = 1;
    /// Nothing to fill from: the last value (real or repaired) was held.
    pub const LAST_VALUE: u8 = 2;
    /// Nothing to fill from and no earlier value: NaN.
    pub const MISSING: u8 = 3;
}

/// A local repair method.
#[derive(Debug, Clone, Copy)]
pub enum Method<'a, T> {
    /// Failed readings read 0.
    Zero,
    /// Hold the last value (real or repaired).
    LastValue,
    /// Eq. 6.14: the mean of the available neighbours.
    NeighbourMean(Graph<'a>),
    /// A weighted mean of the available neighbours (weights parallel to the graph's
    /// indices).
    Weighted(Graph<'a>, &'a [T]),
}

impl<T: Real> Method<'_, T> {
    /// Check the method against `n` elements: the graph of a neighbour method has `n`
    /// elements, and the weights one finite non-negative entry per neighbour.
    pub fn check(&self, n: usize) -> Result<(), KernelError> {
        match self {
            Method::NeighbourMean(g) => ensure(g.len() == n, "repair neighbours", "wrong size"),
            Method::Weighted(g, w) => {
                ensure(g.len() == n, "repair neighbours", "wrong size")?;
                ensure(w.len() == g.nnz(), "repair weights", "one per neighbour")?;
                ensure(
                    w.iter().all(|v| v.is_finite() && *v >= T::ZERO),
                    "repair weights",
                    "must be finite and >= 0",
                )
            }
            Method::Zero | Method::LastValue => Ok(()),
        }
    }
}

/// The fill of element `i` with its last value `last`: the method's value from the readings
/// of the frame that are `available` (their value, or None), else the last value; and the
/// [`outcome`].
#[inline]
pub fn fill<T: Real>(
    method: &Method<'_, T>,
    i: usize,
    last: T,
    available: &impl Fn(usize) -> Option<T>,
) -> (T, u8) {
    let mean = match method {
        Method::Zero => Some(T::ZERO),
        Method::LastValue => None,
        Method::NeighbourMean(nb) => {
            let (mut sum, mut count) = (T::ZERO, 0u32);
            for &j in nb.of(i) {
                if let Some(v) = available(j as usize) {
                    sum += v;
                    count += 1;
                }
            }
            if count > 0 {
                Some(sum / T::from_usize(count as usize))
            } else {
                None
            }
        }
        Method::Weighted(nb, w) => {
            let (mut num, mut den) = (T::ZERO, T::ZERO);
            let lo = nb.start(i);
            for (q, &j) in nb.of(i).iter().enumerate() {
                if let Some(v) = available(j as usize) {
                    num += w[lo + q] * v;
                    den += w[lo + q];
                }
            }
            if den > T::ZERO {
                Some(num / den)
            } else {
                None
            }
        }
    };
    match mean {
        Some(v) => (v, outcome::FILLED),
        None if last.is_finite() => (last, outcome::LAST_VALUE),
        None => (T::NAN, outcome::MISSING),
    }
}

/// Repair one frame in place: a reading is available when `ok(i)` and it is a number; the
/// others are filled ([`fill`]) and every element's last value (`last`) kept up to date.
/// `fills` (one per element) holds the fills until all are known; `outcome`, when given,
/// gets an [`outcome`] per element.
pub fn repair_frame<T: Real>(
    method: &Method<'_, T>,
    last: &mut [T],
    frame: &mut [T],
    ok: impl Fn(usize) -> bool,
    fills: &mut [T],
    mut outcome: Option<&mut [u8]>,
) {
    let n = last.len();
    let frame_in: &[T] = frame;
    let available = |j: usize| {
        let v = frame_in[j];
        if ok(j) && v.is_finite() {
            Some(v)
        } else {
            None
        }
    };
    let mut any = false;
    for i in 0..n {
        let how = match available(i) {
            Some(v) => {
                last[i] = v;
                outcome::MEASURED
            }
            None => {
                let (v, how) = fill(method, i, last[i], &available);
                if v.is_finite() {
                    last[i] = v;
                }
                fills[i] = v;
                any = true;
                how
            }
        };
        if let Some(o) = outcome.as_deref_mut() {
            o[i] = how;
        }
    }
    if any {
        for i in 0..n {
            if !(ok(i) && frame[i].is_finite()) {
                frame[i] = fills[i];
            }
        }
    }
}
