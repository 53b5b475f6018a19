//! One element of the numerical Preisach model of thesis §4.4.1 (eq. 4.15-4.22).
//!
//! Each element keeps a stack of alternating input extrema, starting with the lower
//! saturation `m_0 = u_min`, together with the output at each extremum. With `x` the output
//! at the last extremum (eq. 4.18-4.22):
//!
//! - rising input after the minimum `m`: `h = x + 2 F(u, m)`  (eq. 4.16),
//! - falling input after the maximum `M`: `h = x - 2 F(M, u)` (eq. 4.17).
//!
//! When the input passes the extremum before the last one, both are wiped out (the
//! wiping-out property) and `x` becomes the output stored with the extremum now on top
//! (eq. 4.20/4.21). A step therefore costs O(1) amortised. Inputs outside `[u_min, u_max]`
//! are clamped (and reported).
//!
//! **Bounded memory.** The stack is a slice of `room + 1` slots (the extra slot takes the
//! write of a possible turning point unconditionally), `room` at most the capacity. When a
//! new turning point finds the stack full, the most recent completed minor loop (the two
//! extrema just below the top) is forgotten first — the smallest loop in the memory, whose
//! loss changes the output least. With wiping-out, the stack only grows for ever-shrinking
//! nested oscillations. A microcontroller gives every element `capacity + 1` slots; the
//! desktop starts with a few in place and grows the slice up to the capacity (it asks
//! [`turns`] before a step whether the stack would need to grow).

use crate::everett::Everett;
use crate::real::Real;

/// The step clamped its input into the identified range.
pub const CLAMPED: u8 = 1;
/// The step forgot a minor loop (the stack was full).
pub const FORGOT: u8 = 2;

/// The scalar state of one element beside its stack: the stack's depth and the last input
/// and output (`repr(C)`, plain data for every bit pattern).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct Head<T> {
    /// Extrema on the stack (>= 1: the lower saturation).
    pub len: u32,
    /// The last input.
    pub last_u: T,
    /// The last output (the Preisach sum).
    pub last_h: T,
}

impl<T: Real> Head<T> {
    /// At lower saturation (input `u_min`, output 0); the stack's first slot must hold
    /// `[u_min, 0]` ([`start`]).
    pub fn new(u_min: T) -> Self {
        Self {
            len: 1,
            last_u: u_min,
            last_h: T::ZERO,
        }
    }
}

/// An element at lower saturation: its head, and the first slot of its stack.
pub fn start<T: Real>(head: &mut Head<T>, stack: &mut [[T; 2]], u_min: T) {
    *head = Head::new(u_min);
    stack[0] = [u_min, T::ZERO];
}

/// `sign (h + offset)`: the model's output from the Preisach sum `h` (an identified model's
/// output may start above zero at lower saturation, or fall with the input).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Output<T> {
    /// Added to the sum.
    pub offset: T,
    /// +1 or -1.
    pub sign: T,
}

impl<T: Real> Output<T> {
    /// The sum itself.
    pub fn identity() -> Self {
        Self {
            offset: T::ZERO,
            sign: T::ONE,
        }
    }

    /// The output of the sum `h`.
    #[inline]
    pub fn of(self, h: T) -> T {
        self.sign * (h + self.offset)
    }

    /// The sum that gives the output `y`.
    #[inline]
    pub fn sum_for(self, y: T) -> T {
        self.sign * y - self.offset
    }
}

/// What a step does before it touches the stack ([`prepare`]).
#[derive(Debug, Clone, Copy)]
pub enum Prepared<T> {
    /// The (clamped) input equals the last one: the output is the last output.
    Same(T),
    /// The input moves: [`finish`] the step (after making room for a turning point if the
    /// stack is full and `turned`).
    Moves {
        /// The input, clamped into the range.
        u: T,
        /// Rising (else falling).
        rising: bool,
        /// The input turns at the last one: a turning point is pushed.
        turned: bool,
    },
}

/// The first half of a step: clamp the input (the flag [`CLAMPED`]) and see whether it moves
/// and turns.
#[inline(always)]
pub fn prepare<T: Real>(head: &Head<T>, e: &Everett<'_, T>, u_in: T) -> (Prepared<T>, u8) {
    let u = u_in.clamp(e.u_min(), e.u_max());
    let flags = if u != u_in { CLAMPED } else { 0 };
    let prev = head.last_u;
    if u == prev {
        return (Prepared::Same(head.last_h), flags);
    }
    let rising = u > prev;
    // the top is a minimum when len is odd (stack = m0, M1, m1, ...); a turn at `prev`
    // pushes it as a new extremum
    let turned = rising != (head.len % 2 == 1);
    (Prepared::Moves { u, rising, turned }, flags)
}

/// The second half of a step that moves (eq. 4.16-4.22): push the turning point, wipe out
/// the loops the input passes, and return the Preisach sum. `s` must have a slot beyond the
/// head's `len` extrema (the caller makes room first: [`forget`], or a larger stack).
///
/// Written so that the outcomes that are unpredictable on a real input (rising or falling,
/// turning or not, wiping out or not) select values instead of branching.
#[inline(always)]
pub fn finish<T: Real>(
    head: &mut Head<T>,
    s: &mut [[T; 2]],
    e: &Everett<'_, T>,
    u: T,
    rising: bool,
    turned: bool,
) -> T {
    let mut len = head.len as usize;
    s[len] = [head.last_u, head.last_h]; // written always, kept only on a turn
    len += usize::from(turned);
    // wiping-out: the new input passes the extremum before the top
    let dir = if rising { T::ONE } else { -T::ONE };
    // the first level without a branch (whether a step wipes out one loop is as
    // unpredictable as a coin on a real input); deeper levels are rare
    let wipes = (len >= 3) & ((u - s[len.max(2) - 2][0]) * dir >= T::ZERO);
    len = len.wrapping_sub(2 * usize::from(wipes));
    while wipes && len >= 3 && (u - s[len - 2][0]) * dir >= T::ZERO {
        len -= 2;
    }
    if len == 2 && u <= s[0][0] {
        len = 1; // back at lower saturation (only a falling input gets here)
    }
    let [top, x] = s[len - 1];
    // rising after a minimum: x + 2 F(u, m); falling after a maximum: x - 2 F(M, u)
    let odd = len % 2 == 1;
    let (alpha, beta) = if odd { (u, top) } else { (top, u) };
    let sign = if odd { T::TWO } else { -T::TWO };
    let h = x + sign * e.value_of_numbers(alpha, beta);
    head.len = len as u32;
    head.last_u = u;
    head.last_h = h;
    h
}

/// The stack is full and the input turns: forget the most recent completed minor loop (the
/// two entries below the top).
#[cold]
#[inline(never)]
pub fn forget<T: Real>(head: &mut Head<T>, s: &mut [[T; 2]]) {
    let len = head.len as usize;
    s[len - 3] = s[len - 1];
    head.len = (len - 2) as u32;
}

/// True when a step to `u_in` pushes a turning point (the input turns at the last one).
#[inline]
pub fn turns<T: Real>(head: &Head<T>, e: &Everett<'_, T>, u_in: T) -> bool {
    matches!(
        prepare(head, e, u_in).0,
        Prepared::Moves { turned: true, .. }
    )
}

/// One valid input (a number) of one element on a stack of fixed size (eq. 4.16-4.22): the
/// Preisach sum, and the flags [`CLAMPED`] and [`FORGOT`]. `stack` holds at least the head's
/// `len` extrema plus one slot; at most `capacity` (>= 4) are kept: [`prepare`], [`forget`]
/// when full and turning, [`finish`].
#[inline]
pub fn step<T: Real>(
    head: &mut Head<T>,
    stack: &mut [[T; 2]],
    capacity: usize,
    e: &Everett<'_, T>,
    u_in: T,
) -> (T, u8) {
    match prepare(head, e, u_in) {
        (Prepared::Same(h), flags) => (h, flags),
        (Prepared::Moves { u, rising, turned }, mut flags) => {
            if head.len as usize == (stack.len() - 1).min(capacity) && turned {
                forget(head, stack);
                flags |= FORGOT;
            }
            (finish(head, stack, e, u, rising, turned), flags)
        }
    }
}

/// Set an element to input `u` with the Preisach sum `target` (§6.4.4: a model started from
/// a known pressure). Reached by rising from saturation to a maximum `M >= u` and falling
/// back to `u`: `M = u` gives the rising branch, `M = u_max` the major falling branch, and
/// `M` is found by bisection for targets between the two (either orientation of the loop).
/// Targets outside are clamped to the nearer branch (NaN: the rising branch); returns the
/// sum set. `stack` needs 3 slots.
pub fn set_sum<T: Real>(
    head: &mut Head<T>,
    stack: &mut [[T; 2]],
    e: &Everett<'_, T>,
    u: T,
    target: T,
) -> T {
    let (u_min, u_max) = (e.u_min(), e.u_max());
    let u = u.clamp(u_min, u_max);
    let two = T::TWO;
    // output at u after rising to M and falling back: 2 F(M, m0) - 2 F(M, u)
    let after = |m: T| two * e.value(m, u_min) - two * e.value(m, u);
    let rising = after(u);
    let major = after(u_max);
    let (lo_val, hi_val) = (rising.min(major), rising.max(major));
    let want = if target.is_nan() {
        rising
    } else {
        target.clamp(lo_val, hi_val)
    };
    let m = if (want - rising).abs() <= T::EPSILON * rising.abs().max(T::ONE) {
        u
    } else if (want - major).abs() <= T::EPSILON * major.abs().max(T::ONE) {
        u_max
    } else {
        // after(M) runs monotonically from `rising` (M = u) to `major` (M = u_max)
        let up = major > rising;
        let (mut lo, mut hi) = (u, u_max);
        for _ in 0..100 {
            let mid = T::HALF * (lo + hi);
            if (after(mid) < want) == up {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        T::HALF * (lo + hi)
    };
    start(head, stack, u_min);
    head.last_u = u;
    let h = if m <= u {
        rising
    } else {
        stack[1] = [m, two * e.value(m, u_min)];
        head.len = 2;
        after(m)
    };
    head.last_h = h;
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::everett::Everett;
    use std::vec;
    use std::vec::Vec;

    fn table<T: Real>(k: usize) -> Vec<T> {
        let mut t = vec![T::ZERO; k * k];
        for i in 0..k {
            for j in 0..i {
                let d = (i - j) as f64 / (k - 1) as f64;
                t[i * k + j] = T::from_f64(0.5 * d * d + 0.2 * d);
            }
        }
        t
    }

    /// One element along `path`, with room for `cap` turning points.
    fn run<T: Real>(path: &[f64], cap: usize) -> Vec<f64> {
        let t = table::<T>(33);
        let e = Everett::new(33, T::ZERO, T::ONE, &t).unwrap();
        let mut head = Head::new(T::ZERO);
        let mut stack = vec![[T::ZERO; 2]; cap + 1];
        start(&mut head, &mut stack, T::ZERO);
        path.iter()
            .map(|&u| {
                step(&mut head, &mut stack, cap, &e, T::from_f64(u))
                    .0
                    .to_f64()
            })
            .collect()
    }

    #[test]
    fn f32_follows_f64_and_a_full_stack_forgets_the_innermost_loop() {
        // a random walk with turning points everywhere
        let mut x = 0.5f64;
        let path: Vec<f64> = (0..5000u64)
            .map(|k| {
                let r = ((k.wrapping_mul(6_364_136_223_846_793_005) >> 33) % 1000) as f64;
                x = (x + (r / 1000.0 - 0.5) * 0.08).clamp(-0.05, 1.05);
                x
            })
            .collect();
        let (a, b) = (run::<f64>(&path, 64), run::<f32>(&path, 64));
        let worst = a
            .iter()
            .zip(&b)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        assert!(worst < 2e-5, "f32 differs by {worst}");
        // nested, ever smaller loops, then out again (return-point memory): 4 turning points
        // keep the outer ones only, which changes the way back
        let nested: Vec<f64> = (0..20)
            .chain((0..20).rev())
            .flat_map(|k| [0.9 - 0.02 * k as f64, 0.1 + 0.02 * k as f64])
            .collect();
        let (deep, shallow) = (run::<f64>(&nested, 64), run::<f64>(&nested, 4));
        assert_eq!(deep[..4], shallow[..4]);
        assert!(deep.iter().zip(&shallow).any(|(p, q)| p != q));
    }
}
