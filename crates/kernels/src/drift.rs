//! Drift as a superposition of step responses in a recursive form that needs no history
//! (thesis §5.2, eq. 5.4/5.8), one element.
//!
//! Eq. 5.8 adds to the Preisach output `h(t)` the drift of every past change of it,
//! `d(t) = γ Σ_i Δh_i k(t - t_i)`. With a kernel that is a sum of exponentials,
//! `k(t) = Σ_j c_j (1 - exp(-t / τ_j))`, the sum over the history collapses into one state
//! per time constant:
//!
//! `d(t) = γ Σ_j c_j (H(t) - z_j(t))`, `H(t) = Σ_i Δh_i`, `z_j(t) = Σ_i Δh_i exp(-(t - t_i)/τ_j)`,
//!
//! and `z_j` is updated exactly per sample: `z_j ← z_j exp(-Δt / τ_j) + Δh`. Each element
//! keeps K states and each sample costs O(K), however long the history. Options, as the
//! chain file holds them: the *rest clock* (an element's clock slowed by its own rate of
//! change, `dt / (1 + |v| / rest_rate)`), a second superposition on the time clock
//! (`gamma_time`), and Schapery's level power (the steps of `max(h, 0)^q`).

use crate::error::{ensure, KernelError};
use crate::real::Real;

/// The kernel and the options shared by every element of a drift stage.
#[derive(Debug, Clone, Copy)]
pub struct Settings<'a, T> {
    weights: &'a [T],
    taus: &'a [T],
    gamma: T,
    weight_sum: T,
    rest_rate: T,
    rest_window: T,
    gamma_time: T,
    exponent: T,
}

/// The state of one element beside its K kernel states (`repr(C)`, plain data for every
/// bit pattern).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct Element<T> {
    /// `H`: the sum of the level's steps.
    pub total: T,
    /// The last level.
    pub last_h: T,
    /// The averaged rate of change (the rest clock).
    pub smooth: T,
    /// 1 once the element has had a valid input.
    pub started: u32,
}

impl<T: Real> Default for Element<T> {
    fn default() -> Self {
        Self {
            total: T::ZERO,
            last_h: T::ZERO,
            smooth: T::ZERO,
            started: 0,
        }
    }
}

impl<'a, T: Real> Settings<'a, T> {
    /// A kernel `Σ_j c_j (1 - exp(-t / τ_j))` (`weights` c_j >= 0, `taus` τ_j > 0, at least
    /// one term) with drift factor `gamma`; the thesis's time clock, no second clock, level
    /// power 1 (see the `with_` methods).
    pub fn new(weights: &'a [T], taus: &'a [T], gamma: T) -> Result<Self, KernelError> {
        ensure(weights.len() == taus.len(), "taus", "one per weight")?;
        ensure(!weights.is_empty(), "kernel", "needs at least one term")?;
        ensure(
            weights.iter().all(|w| !w.is_nan() && *w >= T::ZERO)
                && taus.iter().all(|t| !t.is_nan() && *t > T::ZERO),
            "kernel",
            "weights must be >= 0 and time constants > 0",
        )?;
        ensure(gamma.is_finite(), "gamma", "must be finite")?;
        let mut weight_sum = T::ZERO;
        for &w in weights {
            weight_sum += w;
        }
        Ok(Self {
            weights,
            taus,
            gamma,
            weight_sum,
            rest_rate: T::ZERO,
            rest_window: T::HALF,
            gamma_time: T::ZERO,
            exponent: T::ONE,
        })
    }

    /// The rest clock: `rest_rate` (>= 0; 0 is the time clock) and the window (s, > 0) of
    /// the averaged rate of change.
    pub fn with_rest_rate(mut self, rest_rate: T, rest_window: T) -> Result<Self, KernelError> {
        ensure(
            rest_rate.is_finite() && rest_rate >= T::ZERO,
            "rest_rate",
            "must be finite and >= 0",
        )?;
        ensure(
            rest_window.is_finite() && rest_window > T::ZERO,
            "rest_window",
            "must be finite and > 0 s",
        )?;
        self.rest_rate = rest_rate;
        self.rest_window = rest_window;
        Ok(self)
    }

    /// A second superposition on the time clock with factor `gamma_time` (only beside the
    /// rest clock; its states are the `z_time` of [`step`]).
    pub fn with_time_component(mut self, gamma_time: T) -> Result<Self, KernelError> {
        ensure(gamma_time.is_finite(), "gamma_time", "must be finite")?;
        self.gamma_time = gamma_time;
        Ok(self)
    }

    /// Superpose the steps of `max(h, 0)^exponent` (Schapery; 1 is eq. 5.8).
    pub fn with_exponent(mut self, exponent: T) -> Result<Self, KernelError> {
        ensure(
            exponent.is_finite() && exponent >= T::from_f64(0.25) && exponent <= T::from_f64(8.0),
            "exponent",
            "must lie in [0.25, 8]",
        )?;
        self.exponent = exponent;
        Ok(self)
    }

    /// Number of kernel terms K.
    #[inline]
    pub fn terms(&self) -> usize {
        self.weights.len()
    }

    /// The kernel's weights.
    pub fn weights(&self) -> &'a [T] {
        self.weights
    }

    /// The kernel's time constants.
    pub fn taus(&self) -> &'a [T] {
        self.taus
    }

    /// γ.
    pub fn gamma(&self) -> T {
        self.gamma
    }

    /// `Σ_j c_j`, summed in the order of the terms (what [`step`] multiplies `H` by).
    pub fn weight_sum(&self) -> T {
        self.weight_sum
    }

    /// The rest clock's rate (0: the time clock) and window.
    pub fn rest(&self) -> (T, T) {
        (self.rest_rate, self.rest_window)
    }

    /// The second clock's factor.
    pub fn gamma_time(&self) -> T {
        self.gamma_time
    }

    /// The level power.
    pub fn exponent(&self) -> T {
        self.exponent
    }

    /// True when the time clock runs beside the rest clock (its states are used).
    #[inline]
    pub fn two_clocks(&self) -> bool {
        self.gamma_time != T::ZERO && self.rest_rate > T::ZERO
    }

    /// True when the stage keeps the second clock's states (`gamma_time != 0`).
    #[inline]
    pub fn has_time_states(&self) -> bool {
        self.gamma_time != T::ZERO
    }

    /// The level whose steps the kernel superposes: the hysteresis output itself (`q = 1`,
    /// eq. 5.8), or its `q`-th power (below zero the level is 0).
    #[inline]
    fn level(&self, h: T) -> T {
        if self.exponent == T::ONE {
            h
        } else {
            h.max(T::ZERO).powf(self.exponent)
        }
    }
}

/// Start a frame `dt` seconds after the previous one: `decay_j = exp(-dt / τ_j)` (once per
/// frame for all elements of a stage, before their steps).
#[inline]
pub fn frame<T: Real>(decay: &mut [T], taus: &[T], dt: T) {
    for (d, &tau) in decay.iter_mut().zip(taus) {
        *d = (-dt / tau).exp();
    }
}

/// One element in the frame started by [`frame`] with `dt`: hysteresis output `h` in,
/// drift-corrected output out (eq. 5.8). An invalid or NaN input keeps the state (time still
/// passes for it) and gives NaN. `z` holds the element's K states; `z_time` the K states of
/// the second clock (empty without one).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn step<T: Real>(
    s: &Settings<'_, T>,
    el: &mut Element<T>,
    z: &mut [T],
    z_time: &mut [T],
    decay: &[T],
    dt: T,
    h: T,
    valid: bool,
) -> T {
    step_strided(s, el, z, z_time, 1, decay, dt, h, valid)
}

/// [`step`] on states stored `stride` apart: term `j` at `z[j * stride]` (and
/// `z_time[j * stride]`), as when the states of several elements are interleaved term by
/// term (the desktop's groups of elements across SIMD lanes). The same operations in the
/// same order for any stride.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn step_strided<T: Real>(
    s: &Settings<'_, T>,
    el: &mut Element<T>,
    z: &mut [T],
    z_time: &mut [T],
    stride: usize,
    decay: &[T],
    dt: T,
    h: T,
    valid: bool,
) -> T {
    // the second clock only runs beside the rest clock
    let two_clocks = !z_time.is_empty() && s.rest_rate > T::ZERO;
    if !(valid && h.is_finite()) {
        // time still passes for the element's states (at rest: nothing is known)
        decay_and_add(z, stride, decay, None);
        if two_clocks {
            decay_and_add(z_time, stride, decay, None);
        }
        return T::NAN;
    }
    let x = s.level(h);
    let change = if el.started != 0 { x - el.last_h } else { x };
    el.started = 1;
    el.last_h = x;
    el.total += change;
    // Σ w_j (H - z_j) = H Σ w_j - Σ w_j z_j
    let weighted = if s.rest_rate > T::ZERO && dt > T::ZERO {
        // this element's clock: slowed by its own (averaged) rate of change
        el.smooth += (change / dt - el.smooth) * (T::ONE - (-dt / s.rest_window).exp());
        let clock = dt / (T::ONE + el.smooth.abs() / s.rest_rate);
        for (zj, &tau) in z.iter_mut().step_by(stride).zip(s.taus) {
            *zj = *zj * (-clock / tau).exp() + change;
        }
        dot(s.weights, z, stride)
    } else {
        decay_and_add(z, stride, decay, Some(change));
        dot(s.weights, z, stride)
    };
    let mut out = h + s.gamma * (el.total * s.weight_sum - weighted);
    if two_clocks {
        decay_and_add(z_time, stride, decay, Some(change));
        out += s.gamma_time * (el.total * s.weight_sum - dot(s.weights, z_time, stride));
    }
    out
}

/// `z_j <- z_j d_j + change` for every term (`z_j d_j` without a change: time passes).
#[inline(always)]
fn decay_and_add<T: Real>(z: &mut [T], stride: usize, decay: &[T], change: Option<T>) {
    let k = decay.len();
    assert!(
        k == 0 || z.len() > (k - 1) * stride,
        "K states, `stride` apart"
    );
    match change {
        Some(c) => (0..k).for_each(|j| z[j * stride] = z[j * stride] * decay[j] + c),
        None => (0..k).for_each(|j| z[j * stride] = z[j * stride] * decay[j]),
    }
}

/// `Σ w_j z_j` in four independent partial sums over the whole fours of terms (term `j`
/// into sum `j mod 4`), then the remaining terms in order (the terms are added in a tree,
/// not one long chain of dependent additions).
#[inline(always)]
fn dot<T: Real>(w: &[T], z: &[T], stride: usize) -> T {
    let k = w.len();
    assert!(
        k == 0 || z.len() > (k - 1) * stride,
        "K states, `stride` apart"
    );
    let whole = k / 4 * 4;
    let (mut a0, mut a1, mut a2, mut a3) = (T::ZERO, T::ZERO, T::ZERO, T::ZERO);
    for j in (0..whole).step_by(4) {
        a0 += w[j] * z[j * stride];
        a1 += w[j + 1] * z[(j + 1) * stride];
        a2 += w[j + 2] * z[(j + 2) * stride];
        a3 += w[j + 3] * z[(j + 3) * stride];
    }
    let mut tail = T::ZERO;
    for j in whole..k {
        tail += w[j] * z[j * stride];
    }
    (a0 + a1) + (a2 + a3) + tail
}
