//! The element-wise stages of a chain as the chain runs them: a value and its validity in,
//! the same out, by the rules of the Python stages (`texsense.stage`), so that a compiled
//! chain (desktop or microcontroller) gives the numbers of the stages run one after the
//! other. An invalid reading leaves an element's state untouched (only time passes for its
//! drift) and comes out NaN and invalid.

use crate::convert::{convert, Curve};
use crate::drift::{self, Settings};
use crate::everett::Everett;
use crate::preisach::{self, Head, Output};
use crate::real::Real;

/// `convert` / `linear` (eq. 2.1): NaN where invalid or not a number; the validity passes.
#[inline(always)]
pub fn conversion<T: Real>(
    offset: T,
    gain: T,
    curve: Option<&Curve<'_, T>>,
    x: T,
    ok: bool,
) -> (T, bool) {
    let v = if ok && x.is_finite() {
        convert(offset, gain, curve, x)
    } else {
        T::NAN
    };
    (v, ok)
}

/// `hysteresis` (eq. 4.15-4.22): the model's output `sign (h + offset)`; also the step's
/// flags ([`preisach::CLAMPED`], [`preisach::FORGOT`]).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn hysteresis<T: Real>(
    head: &mut Head<T>,
    stack: &mut [[T; 2]],
    capacity: usize,
    e: &Everett<'_, T>,
    out: Output<T>,
    x: T,
    ok: bool,
) -> (T, bool, u8) {
    if ok && x.is_finite() {
        let (h, flags) = preisach::step(head, stack, capacity, e, x);
        let y = out.of(h);
        (y, y.is_finite(), flags)
    } else {
        (T::NAN, false, 0)
    }
}

/// `drift` (eq. 5.8) on the level of its input, in the frame [`drift::frame`] started.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn drift<T: Real>(
    s: &Settings<'_, T>,
    el: &mut drift::Element<T>,
    z: &mut [T],
    z_time: &mut [T],
    decay: &[T],
    dt: T,
    x: T,
    ok: bool,
) -> (T, bool) {
    let y = drift::step(s, el, z, z_time, decay, dt, x, ok);
    (y, ok && y.is_finite())
}

/// A QLV `drift` right after `hysteresis`: the drift of the elastic response `level(u)` of
/// the hysteresis stage's input `u`, added to its output `h` (validity `ok`, after the
/// hysteresis stage).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn drift_on_level<T: Real>(
    s: &Settings<'_, T>,
    el: &mut drift::Element<T>,
    z: &mut [T],
    z_time: &mut [T],
    decay: &[T],
    dt: T,
    level: &Curve<'_, T>,
    u: T,
    h: T,
    ok: bool,
) -> (T, bool) {
    drift_on_level_strided(s, el, z, z_time, 1, decay, dt, level, u, h, ok)
}

/// [`drift_on_level`] on states stored `stride` apart ([`drift::step_strided`]).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn drift_on_level_strided<T: Real>(
    s: &Settings<'_, T>,
    el: &mut drift::Element<T>,
    z: &mut [T],
    z_time: &mut [T],
    stride: usize,
    decay: &[T],
    dt: T,
    level: &Curve<'_, T>,
    u: T,
    h: T,
    ok: bool,
) -> (T, bool) {
    let b = if u.is_finite() { level.at(u) } else { T::NAN };
    let valid = ok && h.is_finite();
    let y = h + (drift::step_strided(s, el, z, z_time, stride, decay, dt, b, valid) - b);
    (y, ok && y.is_finite())
}

/// The first-loading curve in place of `hysteresis` (an uncompensated system).
#[inline(always)]
pub fn loading<T: Real>(curve: &Curve<'_, T>, x: T, ok: bool) -> (T, bool) {
    let y = if ok { curve.at(x) } else { T::NAN };
    (y, ok && y.is_finite())
}
