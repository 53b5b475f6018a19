//! The drift step of eq. 5.8 (time clock, linear level) for four elements at once: each
//! kernel term of a group of [`GROUP`] elements is one AVX2 vector (the states' grouped
//! layout, `super::at`), so a term costs one load, a multiply, an add and a store for four
//! elements instead of a quarter vector each. The operations are the scalar kernel's
//! (`texsense_kernels::drift::step`: `z_j d_j + Δh`, the weighted sum in four partial sums
//! and a tail, `h + γ (H Σc - Σ c_j z_j)`) in the same order, without fused multiply-adds,
//! so every output and state is the scalar kernel's, bit for bit.

use std::arch::x86_64::*;

use texsense_kernels::drift::{Element, Settings};

use super::GROUP;

/// Elements per step: half a group, the four f64 lanes of a register.
pub(super) const LANES: usize = 4;

/// Whole groups of a block: levels `h` and their validity `ok` -> outputs `out` (NaN where
/// invalid or not finite; time still passes for those elements' states), for a stage on
/// the time clock with level power 1 and `decay` of the frame.
///
/// # Safety
/// The processor must have AVX2.
///
/// # Panics
/// When `h` is not whole groups, or a slice is shorter than the block's groups need.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn groups(
    s: &Settings<'_, f64>,
    elements: &mut [Element<f64>],
    z: &mut [f64],
    decay: &[f64],
    h: &[f64],
    ok: &[bool],
    out: &mut [f64],
) {
    let (n, k) = (h.len(), s.terms());
    assert!(n.is_multiple_of(LANES) && ok.len() == n && out.len() == n);
    assert!(elements.len() >= n && z.len() >= n.div_ceil(GROUP) * GROUP * k);
    assert!(decay.len() == k);
    for at in (0..n).step_by(LANES) {
        // half `at % GROUP / LANES` of group `at / GROUP`: its terms from
        // z[at / GROUP * GROUP * k + at % GROUP], `GROUP` apart
        let first = at / GROUP * GROUP * k + at % GROUP;
        // SAFETY: AVX2 (this function's feature); the half group's states are within
        // z[first .. first + GROUP (k - 1) + LANES] (checked above)
        unsafe {
            group(
                s,
                &mut elements[at..at + LANES],
                &mut z[first..first + GROUP * (k - 1) + LANES],
                decay,
                &h[at..at + LANES],
                &ok[at..at + LANES],
                &mut out[at..at + LANES],
            )
        };
    }
}

/// One group of four elements (the arguments of [`groups`], one group's share).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn group(
    s: &Settings<'_, f64>,
    els: &mut [Element<f64>],
    z: &mut [f64],
    decay: &[f64],
    h: &[f64],
    ok: &[bool],
    out: &mut [f64],
) {
    let k = s.terms();
    let w = s.weights();
    let hv = _mm256_loadu_pd(h.as_ptr());
    let m = |b: bool| -i64::from(b);
    let ok_m = _mm256_castsi256_pd(_mm256_set_epi64x(m(ok[3]), m(ok[2]), m(ok[1]), m(ok[0])));
    // valid and finite (h - h is 0 for a finite h, NaN otherwise)
    let finite = _mm256_cmp_pd::<_CMP_EQ_OQ>(_mm256_sub_pd(hv, hv), _mm256_setzero_pd());
    let live = _mm256_and_pd(ok_m, finite);
    let started = _mm256_castsi256_pd(_mm256_set_epi64x(
        m(els[3].started != 0),
        m(els[2].started != 0),
        m(els[1].started != 0),
        m(els[0].started != 0),
    ));
    let last = _mm256_set_pd(els[3].last_h, els[2].last_h, els[1].last_h, els[0].last_h);
    let total = _mm256_set_pd(els[3].total, els[2].total, els[1].total, els[0].total);
    // the level is h itself (power 1); the first valid level is a step from 0
    let change = _mm256_blendv_pd(hv, _mm256_sub_pd(hv, last), started);
    let total = _mm256_add_pd(total, change);
    // z_j <- z_j d_j + change (live), z_j d_j (time passes: + -0, which leaves every value
    // as it is, so one add serves both); Σ c_j z_j in the kernel's four partial sums over
    // whole fours of terms (one register each), then the tail in order
    let cm = _mm256_blendv_pd(_mm256_set1_pd(-0.0), change, live);
    let p = z.as_mut_ptr();
    let term = |j: usize| {
        // SAFETY: term j of the four elements: z[8 j .. 8 j + 4] (z holds 8 (k - 1) + 4;
        // j < k = decay.len() = w.len(), checked by the caller's asserts and `Settings`)
        unsafe {
            let at = p.add(GROUP * j);
            let zd = _mm256_mul_pd(_mm256_loadu_pd(at), _mm256_set1_pd(*decay.get_unchecked(j)));
            let zn = _mm256_add_pd(zd, cm);
            _mm256_storeu_pd(at, zn);
            _mm256_mul_pd(_mm256_set1_pd(*w.get_unchecked(j)), zn)
        }
    };
    let zero = _mm256_setzero_pd();
    let (mut a0, mut a1, mut a2, mut a3) = (zero, zero, zero, zero);
    let whole = k / 4 * 4;
    for j in (0..whole).step_by(4) {
        a0 = _mm256_add_pd(a0, term(j));
        a1 = _mm256_add_pd(a1, term(j + 1));
        a2 = _mm256_add_pd(a2, term(j + 2));
        a3 = _mm256_add_pd(a3, term(j + 3));
    }
    let mut tail = zero;
    for j in whole..k {
        tail = _mm256_add_pd(tail, term(j));
    }
    let weighted = _mm256_add_pd(
        _mm256_add_pd(_mm256_add_pd(a0, a1), _mm256_add_pd(a2, a3)),
        tail,
    );
    let wsum = _mm256_set1_pd(s.weight_sum());
    let drift = _mm256_sub_pd(_mm256_mul_pd(total, wsum), weighted);
    let y = _mm256_add_pd(hv, _mm256_mul_pd(_mm256_set1_pd(s.gamma()), drift));
    let nan = _mm256_set1_pd(f64::NAN);
    _mm256_storeu_pd(out.as_mut_ptr(), _mm256_blendv_pd(nan, y, live));
    let mut totals = [0.0; LANES];
    _mm256_storeu_pd(totals.as_mut_ptr(), total);
    let lives = _mm256_movemask_pd(live);
    for (l, el) in els.iter_mut().enumerate() {
        if lives >> l & 1 != 0 {
            el.started = 1;
            el.last_h = h[l];
            el.total = totals[l];
        }
    }
}
