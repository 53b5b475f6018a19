//! The Everett function of the Preisach model (thesis eq. 4.12) on a uniform `K x K` grid.
//!
//! `F(α, β) = (h_α - h_αβ) / 2` is tabulated over the identified input range
//! `[u_min, u_max]` (row = α, column = β, defined for β <= α). Between grid points it is
//! interpolated bilinearly; in the cells on the diagonal, whose upper half lies outside the
//! Preisach triangle, linearly on the lower triangle, so that `F(u, u) = 0` holds exactly.

use crate::error::{ensure, KernelError};
use crate::real::Real;

/// A checked view of an Everett table.
#[derive(Debug, Clone, Copy)]
pub struct Everett<'a, T> {
    k: usize,
    u_min: T,
    u_max: T,
    inv_step: T,
    table: &'a [T],
}

/// Zero the entries on and above the diagonal of a row-major `k x k` table and check that
/// the others are finite.
pub fn prepare_table<T: Real>(k: usize, table: &mut [T]) -> Result<(), KernelError> {
    ensure(
        table.len() == k * k,
        "everett table",
        "must hold k x k entries",
    )?;
    for i in 0..k {
        for j in 0..k {
            let v = &mut table[i * k + j];
            if j >= i {
                *v = T::ZERO;
            } else {
                ensure(v.is_finite(), "everett table", "an entry is not finite")?;
            }
        }
    }
    Ok(())
}

impl<'a, T: Real> Everett<'a, T> {
    /// View a row-major `k x k` table (2 <= k <= 2^20; row α, column β, see
    /// [`prepare_table`]) over `[u_min, u_max]` (finite, `u_min < u_max`).
    pub fn new(k: usize, u_min: T, u_max: T, table: &'a [T]) -> Result<Self, KernelError> {
        ensure(
            (2..=1 << 20).contains(&k),
            "everett",
            "the grid needs 2 ..= 2^20 points",
        )?;
        ensure(
            table.len() == k * k,
            "everett table",
            "must hold k x k entries",
        )?;
        ensure(
            u_min.is_finite() && u_max.is_finite() && u_max > u_min,
            "input range",
            "need finite u_min < u_max",
        )?;
        let inv_step = T::from_usize(k - 1) / (u_max - u_min);
        ensure(
            inv_step.is_finite(),
            "input range",
            "too narrow for the grid",
        )?;
        Ok(Self {
            k,
            u_min,
            u_max,
            inv_step,
            table,
        })
    }

    /// Grid size K.
    pub fn size(&self) -> usize {
        self.k
    }

    /// Lower end of the input range (the saturation input `m_0`).
    pub fn u_min(&self) -> T {
        self.u_min
    }

    /// Upper end of the input range.
    pub fn u_max(&self) -> T {
        self.u_max
    }

    /// `(K - 1) / (u_max - u_min)`: grid steps per unit of input.
    pub fn inv_step(&self) -> T {
        self.inv_step
    }

    /// The table.
    pub fn table(&self) -> &'a [T] {
        self.table
    }

    /// `F(α, β)` for `u_min <= β <= α <= u_max` (interpolated; NaN for NaN).
    #[inline]
    pub fn value(&self, alpha: T, beta: T) -> T {
        if alpha.is_nan() || beta.is_nan() {
            return T::NAN;
        }
        self.value_of_numbers(alpha, beta)
    }

    /// [`Everett::value`] for inputs that are numbers (not NaN; infinities are clamped).
    ///
    /// Branch-free: both the bilinear and the diagonal-cell formula are computed and the
    /// right one selected, since on a real input which cell is hit is unpredictable (a
    /// mispredicted branch costs more than the few extra multiplications).
    #[inline(always)]
    pub fn value_of_numbers(&self, alpha: T, beta: T) -> T {
        let last = T::from_usize(self.k - 1);
        let a = ((alpha - self.u_min) * self.inv_step).clamp(T::ZERO, last);
        let b = ((beta - self.u_min) * self.inv_step).clamp(T::ZERO, last);
        // SAFETY: a and b are in [0, k - 1] (clamped; not NaN since alpha, beta and the
        // finite inv_step are numbers), so the truncation is a floor that fits in u32
        let (ia, ib) = unsafe { (a.floor_u32_unchecked(), b.floor_u32_unchecked()) };
        let top = (self.k - 2) as u32;
        let (i0, j0) = (ia.min(top) as usize, ib.min(top) as usize);
        let wa = a - T::from_usize(i0);
        let wb = b - T::from_usize(j0);
        let q = i0 * self.k + j0;
        // SAFETY: i0, j0 <= k - 2, so q + 1 and q + k + 1 are below k * k = table.len()
        // (checked by `new`)
        let (f00, f01, f10, f11) = unsafe {
            let t = self.table.as_ptr().add(q);
            (*t, *t.add(1), *t.add(self.k), *t.add(self.k + 1))
        };
        let one = T::ONE;
        let bilinear =
            (one - wa) * ((one - wb) * f00 + wb * f01) + wa * ((one - wb) * f10 + wb * f11);
        // diagonal cell: linear on the lower triangle, F = 0 on the diagonal
        let diagonal = (wa - wb) * f10;
        let v = if i0 == j0 { diagonal } else { bilinear };
        if b >= a {
            T::ZERO
        } else {
            v
        }
    }
}
