//! Failure detection on raw capacitance (thesis §6.5.2.5), one element of one frame.
//!
//! Per reading, in this order of precedence (the later wins):
//! - `stuck` (3): no change larger than `stuck_pf` for `stuck_frames` frames while the median
//!   change of the element's neighbours added up to more than `neighbour_change_pf` (readings
//!   at or below `stuck_floor_pf` are never stuck);
//! - `jump` (4): a change larger than the element's jump limit between two readings;
//! - `out of range` (2): flagged invalid, or beyond `high_share` times the largest
//!   capacitance the calibration expects;
//! - `short/break` (1): not a number, at or below `min_pf`, or below `low_share` of the
//!   element's unloaded capacitance.
//!
//! 0 means healthy. A frame takes two passes: the change of every reading first
//! ([`change`], each element on its own), then the codes ([`code`], which read the median
//! change of the neighbours in the same frame, [`neighbour_move`]).

use crate::error::{ensure, KernelError};
use crate::real::Real;

/// Failure codes.
pub mod codes {
    /// Healthy.
    pub const OK: u8 = 0;
    /// Short or break.
    pub const SHORT_OR_BREAK: u8 = 1;
    /// Out of range (saturated or far beyond the expected maximum).
    pub const OUT_OF_RANGE: u8 = 2;
    /// Stuck while the neighbours move.
    pub const STUCK: u8 = 3;
    /// A jump faster than a body moves the spacer.
    pub const JUMP: u8 = 4;
}

/// Thresholds of the detector (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params<T> {
    /// Readings at or below this are shorts or breaks (pF).
    pub min_pf: T,
    /// Readings below this share of the unloaded value are shorts or breaks.
    pub low_share: T,
    /// Readings beyond this multiple of the expected maximum are out of range.
    pub high_share: T,
    /// Frames without change before an element counts as stuck.
    pub stuck_frames: u32,
    /// A change at or below this (pF) is no change.
    pub stuck_pf: T,
    /// The neighbours' accumulated median change that makes a still element stuck (pF).
    pub neighbour_change_pf: T,
    /// Readings at or below this never count as stuck (an unloaded element of a mat that
    /// reads 0 without load holds still legitimately); minus infinity for capacitance.
    pub stuck_floor_pf: T,
}

impl<T: Real> Params<T> {
    /// Check the thresholds: `stuck_frames >= 2`, `0 < low_share < 1`.
    pub fn check(&self) -> Result<(), KernelError> {
        ensure(
            self.stuck_frames >= 2 && self.low_share > T::ZERO && self.low_share < T::ONE,
            "detector",
            "stuck_frames >= 2 and 0 < low_share < 1 needed",
        )
    }
}

/// The state of one element (`repr(C)`, plain data for every bit pattern).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct Element<T> {
    /// The last reading that was a number (NaN before the first).
    pub last: T,
    /// Frames held still.
    pub still: u32,
    /// The neighbours' median change added up while still.
    pub moved: T,
}

impl<T: Real> Default for Element<T> {
    fn default() -> Self {
        Self {
            last: T::NAN,
            still: 0,
            moved: T::ZERO,
        }
    }
}

/// Pass 1: the change of reading `c` since the element's last one that was a number (NaN
/// for the element's first reading, or a reading that is not a number).
#[inline]
pub fn change<T: Real>(el: &mut Element<T>, c: T) -> T {
    let d = (c - el.last).abs();
    if c.is_finite() {
        el.last = c;
    }
    d
}

/// A change as movement: 0 where unknown (NaN).
#[inline]
pub fn moved<T: Real>(d: T) -> T {
    if d.is_nan() {
        T::ZERO
    } else {
        d
    }
}

/// The median movement of the neighbours `nbs` in a frame whose changes are
/// `delta[row + j]` (`scratch` holds at least `nbs.len()` values).
#[inline]
pub fn neighbour_move<T: Real>(nbs: &[u32], delta: &[T], row: usize, scratch: &mut [T]) -> T {
    for (f, &j) in scratch.iter_mut().zip(nbs) {
        *f = moved(delta[row + j as usize]);
    }
    median(&mut scratch[..nbs.len()])
}

/// Per-element limits: the jump limit, and the unloaded and largest expected reading (if
/// known).
#[derive(Debug, Clone, Copy)]
pub struct Limits<T> {
    /// A change beyond it is a jump (pF).
    pub jump: T,
    /// The unloaded reading.
    pub baseline: Option<T>,
    /// The largest expected reading.
    pub max: Option<T>,
}

/// Whether reading `c` with its change `delta` (from [`change`]) holds still: the only
/// case in which [`code`] reads the neighbours' movement (a caller may skip computing it
/// otherwise).
#[inline]
pub fn holds_still<T: Real>(p: &Params<T>, c: T, delta: T) -> bool {
    !delta.is_nan() && delta <= p.stuck_pf && c > p.stuck_floor_pf
}

/// Pass 2: the code of reading `c` (`valid`: not flagged invalid before) with its change
/// `delta` (from [`change`]) and its neighbours' median movement (`nb_move`; `has_nbs`:
/// whether it has neighbours).
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn code<T: Real>(
    p: &Params<T>,
    el: &mut Element<T>,
    lim: Limits<T>,
    c: T,
    valid: bool,
    delta: T,
    nb_move: T,
    has_nbs: bool,
) -> u8 {
    let is_first = delta.is_nan();
    let d = moved(delta);
    let still = holds_still(p, c, delta);
    if still {
        el.still = el.still.saturating_add(1);
        el.moved += nb_move;
    } else {
        el.still = 0;
        el.moved = T::ZERO;
    }
    let mut k = codes::OK;
    if el.still >= p.stuck_frames && el.moved > p.neighbour_change_pf && has_nbs {
        k = codes::STUCK;
    }
    if !is_first && d > lim.jump {
        k = codes::JUMP;
    }
    let high = !valid || lim.max.map_or(false, |m| c > p.high_share * m);
    if high {
        k = codes::OUT_OF_RANGE;
    }
    let low =
        !c.is_finite() || c <= p.min_pf || lim.baseline.map_or(false, |b| c < p.low_share * b);
    if low {
        k = codes::SHORT_OR_BREAK;
    }
    k
}

/// Median of a few values (0 for none): the mean of the two middle ones of an even count.
/// Up to four values (a grid's neighbours) by comparisons that select rather than branch;
/// more by an insertion sort in place.
#[inline]
pub fn median<T: Real>(v: &mut [T]) -> T {
    match *v {
        [] => T::ZERO,
        [a] => a,
        [a, b] => T::HALF * (a + b),
        [a, b, c] => a.min(b).max(a.max(b).min(c)),
        [a, b, c, d] => {
            // the middle two of four: the larger of the pairs' minima and the smaller of
            // the pairs' maxima, for the pairs (a, b) and (c, d)
            T::HALF * (a.min(b).max(c.min(d)) + a.max(b).min(c.max(d)))
        }
        _ => {
            for i in 1..v.len() {
                let mut j = i;
                while j > 0 && v[j - 1] > v[j] {
                    v.swap(j - 1, j);
                    j -= 1;
                }
            }
            let len = v.len();
            T::HALF * (v[(len - 1) / 2] + v[len / 2])
        }
    }
}
