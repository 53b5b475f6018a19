//! The float type of a kernel: `f64` on the desktop, `f32` on a microcontroller.
//!
//! `core` of the oldest toolchain the kernels build with (Rust 1.63, for the Cortex-M build)
//! has no `abs`, `exp` or `powf` on floats: `abs` clears the sign bit (what `std` does), and
//! `exp`/`powf` call the C library's `exp`, `pow`, `expf`, `powf` — the functions `std`
//! calls on every desktop target, and that newlib provides on a microcontroller. The desktop
//! (f64) therefore computes exactly what it computed with `std`.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

mod libm {
    extern "C" {
        pub fn exp(x: f64) -> f64;
        pub fn pow(x: f64, y: f64) -> f64;
        pub fn expf(x: f32) -> f32;
        pub fn powf(x: f32, y: f32) -> f32;
    }
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// `f32` or `f64` (sealed: the state structs built on it are plain data for every bit
/// pattern, which the microcontroller's memory layout relies on).
pub trait Real:
    sealed::Sealed
    + Copy
    + Default
    + Debug
    + PartialEq
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + Send
    + Sync
    + 'static
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// 2.
    const TWO: Self;
    /// 0.5.
    const HALF: Self;
    /// Not a number.
    const NAN: Self;
    /// +∞.
    const INFINITY: Self;
    /// -∞.
    const NEG_INFINITY: Self;
    /// Machine epsilon.
    const EPSILON: Self;
    /// Bytes of one value.
    const BYTES: usize;

    /// Nearest value of an `f64`.
    fn from_f64(v: f64) -> Self;
    /// As an `f64` (exact).
    fn to_f64(self) -> f64;
    /// A count as a float (`as`).
    fn from_usize(v: usize) -> Self;
    /// True for NaN.
    fn is_nan(self) -> bool;
    /// True unless NaN or infinite.
    fn is_finite(self) -> bool;
    /// Absolute value (the sign bit cleared).
    fn abs(self) -> Self;
    /// The smaller (the number, if one is NaN).
    fn min(self, other: Self) -> Self;
    /// The larger (the number, if one is NaN).
    fn max(self, other: Self) -> Self;
    /// Clamped into `[lo, hi]` (`lo <= hi`, neither NaN).
    fn clamp(self, lo: Self, hi: Self) -> Self;
    /// `e^self` (the C library's `exp`/`expf`).
    fn exp(self) -> Self;
    /// `self^e` (the C library's `pow`/`powf`).
    fn powf(self, e: Self) -> Self;
    /// The integer part of a value in `[0, 2^32)`.
    ///
    /// # Safety
    /// `self` must be a number in `[0, 2^32)`.
    unsafe fn floor_u32_unchecked(self) -> u32;
    /// Little-endian bytes (into the first [`Real::BYTES`] of `out`).
    fn write_le(self, out: &mut [u8]);
    /// From little-endian bytes (the first [`Real::BYTES`] of `b`).
    fn read_le(b: &[u8]) -> Self;
}

macro_rules! real {
    ($t:ty, $bits:ty, $sign:expr, $exp:ident, $pow:ident) => {
        impl Real for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const TWO: Self = 2.0;
            const HALF: Self = 0.5;
            const NAN: Self = <$t>::NAN;
            const INFINITY: Self = <$t>::INFINITY;
            const NEG_INFINITY: Self = <$t>::NEG_INFINITY;
            const EPSILON: Self = <$t>::EPSILON;
            const BYTES: usize = core::mem::size_of::<$t>();

            #[inline(always)]
            fn from_f64(v: f64) -> Self {
                v as $t
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline(always)]
            fn from_usize(v: usize) -> Self {
                v as $t
            }
            #[inline(always)]
            fn is_nan(self) -> bool {
                <$t>::is_nan(self)
            }
            #[inline(always)]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                <$t>::from_bits(self.to_bits() & !$sign)
            }
            #[inline(always)]
            fn min(self, other: Self) -> Self {
                <$t>::min(self, other)
            }
            #[inline(always)]
            fn max(self, other: Self) -> Self {
                <$t>::max(self, other)
            }
            #[inline(always)]
            fn clamp(self, lo: Self, hi: Self) -> Self {
                <$t>::clamp(self, lo, hi)
            }
            #[inline(always)]
            fn exp(self) -> Self {
                // SAFETY: a pure function of the C library, defined for every input
                unsafe { libm::$exp(self) }
            }
            #[inline(always)]
            fn powf(self, e: Self) -> Self {
                // SAFETY: as above
                unsafe { libm::$pow(self, e) }
            }
            #[inline(always)]
            unsafe fn floor_u32_unchecked(self) -> u32 {
                // SAFETY: the caller's promise (a number in [0, 2^32))
                unsafe { self.to_int_unchecked::<u32>() }
            }
            #[inline]
            fn write_le(self, out: &mut [u8]) {
                out[..Self::BYTES].copy_from_slice(&self.to_le_bytes());
            }
            #[inline]
            fn read_le(b: &[u8]) -> Self {
                let mut a = [0u8; core::mem::size_of::<$t>()];
                a.copy_from_slice(&b[..Self::BYTES]);
                <$t>::from_le_bytes(a)
            }
        }
    };
}

real!(f64, u64, 1u64 << 63, exp, pow);
real!(f32, u32, 1u32 << 31, expf, powf);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn abs_exp_and_pow_are_those_of_std_for_f64() {
        for v in [
            -2.5f64,
            -0.0,
            0.0,
            1e-300,
            3.75,
            f64::INFINITY,
            -f64::INFINITY,
        ] {
            assert_eq!(Real::abs(v).to_bits(), v.abs().to_bits());
        }
        assert!(Real::abs(f64::NAN).is_nan());
        for v in [-700.0f64, -1.0, -1e-3, 0.0, 0.3, 2.0, 700.0] {
            let std_exp = std::hint::black_box(v).exp();
            assert_eq!(Real::exp(v).to_bits(), std_exp.to_bits(), "exp({v})");
            let base = v.abs() + 0.5;
            assert_eq!(Real::powf(base, 1.7).to_bits(), base.powf(1.7).to_bits());
        }
        assert_eq!(Real::exp(1.0f32), std::hint::black_box(1.0f32).exp());
    }
}
