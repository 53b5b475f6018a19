//! The drift step of eq. 5.8 (time clock, linear level) for eight elements at once: a
//! group of the states' layout (`super::at`, [`GROUP`] = 8 elements per group) in one
//! AVX-512 register of eight f64, so a kernel term costs a load, a multiply, an add, a
//! store and the weighted add for eight elements. The operations are the scalar kernel's (`texsense_kernels::drift::step`,
//! as in `super::avx2`) in the same order, without fused multiply-adds, so every output and
//! state is the scalar kernel's, bit for bit.

use std::arch::x86_64::*;
use std::mem::{offset_of, size_of};

use texsense_kernels::drift::{Element, Settings};

use super::GROUP;

/// Elements per step: a group.
pub(super) const LANES: usize = GROUP;

/// Whole groups of a block (the arguments of `super::avx2::groups`, `h` a whole
/// number of [`LANES`]).
///
/// # Safety
/// The processor must have AVX2 and AVX-512 F, DQ and VL.
///
/// # Panics
/// When `h` is not whole groups, or a slice is shorter than the block needs.
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
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
    assert!(elements.len() >= n && z.len() >= n * k && decay.len() == k);
    for g in 0..n / LANES {
        let at = g * LANES;
        // SAFETY: AVX2, AVX-512 F/DQ/VL (this function's features); the group's states are
        // z[at * k .. (at + LANES) * k] (checked above)
        unsafe {
            pair(
                s,
                &mut elements[at..at + LANES],
                &mut z[at * k..(at + LANES) * k],
                decay,
                &h[at..at + LANES],
                &ok[at..at + LANES],
                &mut out[at..at + LANES],
            )
        };
    }
}

/// Words of 8 bytes from one element to the next (the fields are gathered with it).
const ELEMENT_WORDS: usize = size_of::<Element<f64>>() / 8;
const _: () = assert!(size_of::<Element<f64>>() == 8 * ELEMENT_WORDS);

/// A group of eight elements (the arguments of [`groups`], one group's share).
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn pair(
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
    assert!(els.len() == LANES && ok.len() == LANES);
    let hv = _mm512_loadu_pd(h.as_ptr());
    // the eight validity bytes (0 or 1) as lane bits, in one load
    // SAFETY: ok holds LANES = 8 bytes (asserted)
    let bytes = unsafe { _mm_loadl_epi64(ok.as_ptr().cast()) };
    let ok_k = _mm512_test_epi64_mask(_mm512_cvtepu8_epi64(bytes), _mm512_set1_epi64(1));
    // valid and finite (h - h is 0 for a finite h, NaN otherwise)
    let finite = _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(_mm512_sub_pd(hv, hv), _mm512_setzero_pd());
    let live = ok_k & finite;
    // SAFETY: AVX2, AVX-512 F/DQ/VL (this function's features); els holds 8 (asserted)
    let (last, total, started) = unsafe { heads(els) };
    // the level is h itself (power 1); the first valid level is a step from 0
    let change = _mm512_mask_sub_pd(hv, started, hv, last);
    let total = _mm512_add_pd(total, change);
    // z_j <- z_j d_j + change (live), z_j d_j + -0 (time passes; see `super::avx2`)
    let cm = _mm512_mask_blend_pd(live, _mm512_set1_pd(-0.0), change);
    let p = z.as_mut_ptr();
    let term = |j: usize| {
        // SAFETY: term j of the group at z[8 j .. 8 j + 8] (z holds 8 k; j < k =
        // decay.len() = w.len(), checked by the caller's asserts and `Settings`)
        unsafe {
            let at = p.add(GROUP * j);
            let zd = _mm512_mul_pd(_mm512_loadu_pd(at), _mm512_set1_pd(*decay.get_unchecked(j)));
            let zn = _mm512_add_pd(zd, cm);
            _mm512_storeu_pd(at, zn);
            _mm512_mul_pd(_mm512_set1_pd(*w.get_unchecked(j)), zn)
        }
    };
    let zero = _mm512_setzero_pd();
    let (mut a0, mut a1, mut a2, mut a3) = (zero, zero, zero, zero);
    let whole = k / 4 * 4;
    for j in (0..whole).step_by(4) {
        a0 = _mm512_add_pd(a0, term(j));
        a1 = _mm512_add_pd(a1, term(j + 1));
        a2 = _mm512_add_pd(a2, term(j + 2));
        a3 = _mm512_add_pd(a3, term(j + 3));
    }
    let mut tail = zero;
    for j in whole..k {
        tail = _mm512_add_pd(tail, term(j));
    }
    let weighted = _mm512_add_pd(
        _mm512_add_pd(_mm512_add_pd(a0, a1), _mm512_add_pd(a2, a3)),
        tail,
    );
    let wsum = _mm512_set1_pd(s.weight_sum());
    let drift = _mm512_sub_pd(_mm512_mul_pd(total, wsum), weighted);
    let y = _mm512_add_pd(hv, _mm512_mul_pd(_mm512_set1_pd(s.gamma()), drift));
    let nan = _mm512_set1_pd(f64::NAN);
    _mm512_storeu_pd(out.as_mut_ptr(), _mm512_mask_blend_pd(live, nan, y));
    let mut totals = [0.0; LANES];
    _mm512_storeu_pd(totals.as_mut_ptr(), total);
    for (l, el) in els.iter_mut().enumerate() {
        if live >> l & 1 != 0 {
            el.started = 1;
            el.last_h = h[l];
            el.total = totals[l];
        }
    }
}

/// The last level, the sum of steps and the `started` flags of eight elements, gathered
/// (an element is `ELEMENT_WORDS` words apart), not stored lane by lane and loaded as a
/// register (a store-forwarding stall each; issue 34, eleventh round).
///
/// # Safety
/// The processor must have AVX2 and AVX-512 F/DQ/VL.
///
/// # Panics
/// When `els` is not eight elements.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn heads(els: &[Element<f64>]) -> (__m512d, __m512d, __mmask8) {
    assert_eq!(els.len(), LANES);
    let base = els.as_ptr().cast::<u8>();
    let words = _mm512_mullo_epi64(
        _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 6, 7),
        _mm512_set1_epi64(ELEMENT_WORDS as i64),
    );
    let quads = _mm256_mullo_epi32(
        _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
        _mm256_set1_epi32(2 * ELEMENT_WORDS as i32),
    );
    // SAFETY: lane l reads the field of els[l] (l < 8 = els.len(), asserted), an f64 at
    // its offset in the #[repr(C)] element, and the u32 `started` (quads of bytes)
    unsafe {
        let field = |offset: usize| base.add(offset).cast::<f64>();
        let last = _mm512_i64gather_pd::<8>(words, field(offset_of!(Element<f64>, last_h)));
        let total = _mm512_i64gather_pd::<8>(words, field(offset_of!(Element<f64>, total)));
        let at = base.add(offset_of!(Element<f64>, started)).cast::<i32>();
        let st = _mm256_i32gather_epi32::<4>(at, quads);
        (last, total, _mm256_test_epi32_mask(st, st))
    }
}
