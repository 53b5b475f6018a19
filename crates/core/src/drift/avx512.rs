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

/// Words of 8 bytes from one element to the next.
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
    // SAFETY: AVX-512 F/DQ/VL (this function's features); els holds 8 (asserted)
    unsafe { store_heads(els, live, live & !started, hv, total) };
}

/// The eight elements of a group two to a register (`Element<f64>` is four words: `total`,
/// `last_h`, `smooth`, `started` and its padding), register `r` holding elements `2 r` and
/// `2 r + 1`.
const PAIRS: usize = LANES / 2;
const _: () = assert!(ELEMENT_WORDS == 4);

/// The words of lanes 0-3 from `a` and 4-7 from `b` of [`permutex2var`]: `total` of four
/// elements, then their `last_h`, from two registers of two elements each.
#[inline(always)]
fn pick_heads() -> [i64; LANES] {
    [0, 4, 8, 12, 1, 5, 9, 13]
}

/// The last level, the sum of steps and the `started` flags of eight elements: `total`,
/// `last_h` and `started` by four masked loads (two elements each; `smooth` and the padding
/// not read) and six permutes (issue 34, fifteenth round: gathers of the two f64 fields
/// before; eighteenth round: `started` by the same loads instead of a gather of eight u32,
/// the drift row 1.12-1.19 x on the timing binary on an AMD Zen 5).
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
    let base = els.as_ptr().cast::<f64>();
    // the dwords of `total`, `last_h` and `started` of two elements (not the padding
    // after `started`, whose dword loads as zero: the word of `started` is its value)
    const STARTED: usize = offset_of!(Element<f64>, started) / 4;
    const _: () = assert!(STARTED == 6, "`started` in the low half of the fourth word");
    const FIELDS: u16 = 0b0000_1111 | 1 << STARTED;
    // SAFETY: register r reads those of elements 2 r and 2 r + 1 (all inside `els`: 8
    // elements of 4 words)
    let e: [__m512d; PAIRS] = std::array::from_fn(|r| unsafe {
        _mm512_castsi512_pd(_mm512_maskz_loadu_epi32(
            FIELDS | FIELDS << 8,
            base.add(8 * r).cast(),
        ))
    });
    let pick = |v: [i64; LANES]| _mm512_loadu_si512(v.as_ptr().cast());
    let heads = pick(pick_heads());
    // lanes 0-3: total of elements 0-3 (4-7), lanes 4-7: their last_h
    let low = _mm512_permutex2var_pd(e[0], heads, e[1]);
    let high = _mm512_permutex2var_pd(e[2], heads, e[3]);
    let total = _mm512_permutex2var_pd(low, pick([0, 1, 2, 3, 8, 9, 10, 11]), high);
    let last = _mm512_permutex2var_pd(low, pick([4, 5, 6, 7, 12, 13, 14, 15]), high);
    // the words of `started` (the fourth of each element)
    let fourth = pick([3, 7, 11, 15, 3, 7, 11, 15]);
    let word = |a: __m512d, b: __m512d| _mm512_castpd_si512(_mm512_permutex2var_pd(a, fourth, b));
    let st = _mm512_mask_blend_epi64(0xF0, word(e[0], e[1]), word(e[2], e[3]));
    (last, total, _mm512_test_epi64_mask(st, st))
}

/// The `live` lanes' new heads into their elements: `started = 1`, `last_h = h`, `total`,
/// by four permutes and eight masked stores (two elements per register; a store per field
/// and lane before).
///
/// # Safety
/// The processor must have AVX2 and AVX-512 F/DQ/VL.
///
/// # Panics
/// When `els` is not eight elements.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn store_heads(
    els: &mut [Element<f64>],
    live: __mmask8,
    starts: __mmask8,
    h: __m512d,
    total: __m512d,
) {
    assert_eq!(els.len(), LANES);
    let base = els.as_mut_ptr().cast::<f64>();
    let one = _mm512_set1_epi32(1);
    let started_dword = offset_of!(Element<f64>, started) / 4;
    for r in 0..PAIRS {
        let (a, b) = (2 * r as i64, 2 * r as i64 + 1);
        // words of elements 2 r and 2 r + 1: total and last_h where the element has them
        let idx = _mm512_setr_epi64(a, LANES as i64 + a, 0, 0, b, LANES as i64 + b, 0, 0);
        let words = _mm512_permutex2var_pd(total, idx, h);
        let (la, lb) = (live >> (2 * r) & 1, live >> (2 * r + 1) & 1);
        let fields = (la * 0b0000_0011) | (lb * 0b0011_0000);
        let (sa, sb) = (starts >> (2 * r) & 1, starts >> (2 * r + 1) & 1);
        let started = u16::from(sa) << started_dword | u16::from(sb) << (started_dword + 8);
        // SAFETY: the two elements' 8 words are inside `els` (r < 4); the masks write
        // only their `total`, `last_h` and `started`
        unsafe {
            let at = base.add(8 * r);
            _mm512_mask_storeu_pd(at, fields, words);
            if started != 0 {
                _mm512_mask_storeu_epi32(at.cast(), started, one);
            }
        }
    }
}
