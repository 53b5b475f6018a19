//! Eight lanes' values from memory at each lane's own place, by loads per lane and a
//! transpose instead of gathers ([`super::Lookup::Loads`]; issue 34, eighteenth round: on an
//! AMD Zen 5 four gathers of eight f64 take four times as long as [`rows_of_four`],
//! `examples/gather_time.rs`). Each gives the values a gather would, bit for bit.

use std::arch::x86_64::*;

/// Lanes of a register of f64.
const LANES: usize = 8;

/// The places of the lanes (f64 from the base) as integers.
#[inline]
#[target_feature(enable = "avx512f")]
fn places(at: __m512i) -> [i64; LANES] {
    let mut idx = [0i64; LANES];
    // SAFETY: eight i64 into an array of eight
    unsafe { _mm512_storeu_si512(idx.as_mut_ptr().cast(), at) };
    idx
}

/// The four f64 from `base + at[l]` of every lane `l`, as four registers (the first value of
/// every lane, then the second, ...): a 32-byte load per lane, two lanes to a register, and a
/// transpose.
///
/// # Safety
/// The processor must have AVX-512 F; the four f64 of every lane are inside one allocation
/// from `base`.
#[inline]
#[target_feature(enable = "avx2,avx512f")]
pub unsafe fn rows_of_four(base: *const f64, at: __m512i) -> [__m512d; 4] {
    let idx = places(at);
    // SAFETY: the caller's
    let row = |l: usize| unsafe { _mm256_loadu_pd(base.offset(idx[l] as isize)) };
    let two = |a: usize, b: usize| _mm512_insertf64x4::<1>(_mm512_castpd256_pd512(row(a)), row(b));
    let (z01, z23, z45, z67) = (two(0, 1), two(2, 3), two(4, 5), two(6, 7));
    // [first value of lanes 0-3, second value of lanes 0-3], [third ..., fourth ...]
    let first = _mm512_set_epi64(13, 9, 5, 1, 12, 8, 4, 0);
    let third = _mm512_set_epi64(15, 11, 7, 3, 14, 10, 6, 2);
    let a = _mm512_permutex2var_pd(z01, first, z23);
    let b = _mm512_permutex2var_pd(z45, first, z67);
    let c = _mm512_permutex2var_pd(z01, third, z23);
    let d = _mm512_permutex2var_pd(z45, third, z67);
    [
        _mm512_shuffle_f64x2::<0x44>(a, b),
        _mm512_shuffle_f64x2::<0xEE>(a, b),
        _mm512_shuffle_f64x2::<0x44>(c, d),
        _mm512_shuffle_f64x2::<0xEE>(c, d),
    ]
}

/// The two f64 from `base + at[l]` of every lane `l`, as two registers: a 16-byte load per
/// lane and a transpose.
///
/// # Safety
/// The processor must have AVX-512 F; the two f64 of every lane are inside one allocation
/// from `base`.
#[inline]
#[target_feature(enable = "avx2,avx512f")]
pub unsafe fn pairs(base: *const f64, at: __m512i) -> (__m512d, __m512d) {
    let idx = places(at);
    // SAFETY: the caller's
    let pair = |l: usize| unsafe { _mm_loadu_pd(base.offset(idx[l] as isize)) };
    let four = |l: usize| {
        let lo = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(pair(l)), pair(l + 1));
        let hi = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(pair(l + 2)), pair(l + 3));
        _mm512_insertf64x4::<1>(_mm512_castpd256_pd512(lo), hi)
    };
    let (z0, z1) = (four(0), four(4));
    (
        _mm512_permutex2var_pd(z0, _mm512_set_epi64(14, 12, 10, 8, 6, 4, 2, 0), z1),
        _mm512_permutex2var_pd(z0, _mm512_set_epi64(15, 13, 11, 9, 7, 5, 3, 1), z1),
    )
}

/// `_mm512_mask_i64gather_pd(src, lanes, at, base)` by a load per lane of `lanes` (the lowest
/// set bit, then the next): for masks with few lanes set.
///
/// # Safety
/// The processor must have AVX-512 F; each lane of `lanes` reads an f64 at `at` from `base`
/// inside one allocation.
#[inline]
#[target_feature(enable = "avx2,avx512f")]
pub unsafe fn few(src: __m512d, lanes: __mmask8, at: __m512i, base: *const f64) -> __m512d {
    let idx = places(at);
    let mut got = [0.0f64; LANES];
    let mut bits = lanes;
    while bits != 0 {
        let l = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        // SAFETY: the caller's
        got[l] = unsafe { *base.offset(idx[l] as isize) };
    }
    // SAFETY: eight f64 from an array of eight
    _mm512_mask_blend_pd(lanes, src, unsafe { _mm512_loadu_pd(got.as_ptr()) })
}
