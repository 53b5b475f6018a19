//! How the AVX-512 Preisach row (`super`) reads and writes memory at each lane's own place:
//! the Everett cell's corners from the table by cell, a few lanes' stack slots, the turning
//! points onto the stacks (issue 34, seventeenth and eighteenth rounds).

use std::arch::x86_64::*;

use super::WIDE;

/// The four corners of each lane's Everett cell `(i0, j0)` (`i0, j0 <= K - 2`) from the
/// table by cell (`super::avx2::cell_corners` on eight lanes): one 32-byte load per lane,
/// two lanes to a register, transposed into `F(i, j), F(i, j + 1), F(i + 1, j),
/// F(i + 1, j + 1)` across the lanes.
///
/// # Safety
/// The processor must have AVX-512 F; `cells` holds the table by cell of a grid of at most
/// `CELL_GRID_MAX` points, and `i0, j0 <= K - 2` in every lane.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
pub(super) unsafe fn cell_corners(cells: *const f64, i0: __m256i, j0: __m256i) -> [__m512d; 4] {
    // cell index i (i + 1) / 2 + j, times four f64, in 32-bit lanes
    let tri = _mm256_srli_epi32::<1>(_mm256_mullo_epi32(
        i0,
        _mm256_add_epi32(i0, _mm256_set1_epi32(1)),
    ));
    let q = _mm256_slli_epi32::<2>(_mm256_add_epi32(tri, j0));
    let mut at = [0i32; WIDE];
    _mm256_storeu_si256(at.as_mut_ptr().cast(), q);
    // SAFETY: the caller's: every cell index is below (K - 1) K / 2
    let cell = |l: usize| unsafe { _mm256_loadu_pd(cells.add(at[l] as usize)) };
    let two =
        |a: usize, b: usize| _mm512_insertf64x4::<1>(_mm512_castpd256_pd512(cell(a)), cell(b));
    let (z01, z23, z45, z67) = (two(0, 1), two(2, 3), two(4, 5), two(6, 7));
    // [F(i, j) of lanes 0-3, F(i, j + 1) of lanes 0-3] and the same of the upper corners
    let low = _mm512_set_epi64(13, 9, 5, 1, 12, 8, 4, 0);
    let high = _mm512_set_epi64(15, 11, 7, 3, 14, 10, 6, 2);
    let (a, b) = (
        _mm512_permutex2var_pd(z01, low, z23),
        _mm512_permutex2var_pd(z45, low, z67),
    );
    let (c, d) = (
        _mm512_permutex2var_pd(z01, high, z23),
        _mm512_permutex2var_pd(z45, high, z67),
    );
    [
        _mm512_shuffle_f64x2::<0x44>(a, b),
        _mm512_shuffle_f64x2::<0xEE>(a, b),
        _mm512_shuffle_f64x2::<0x44>(c, d),
        _mm512_shuffle_f64x2::<0xEE>(c, d),
    ]
}

/// `_mm512_mask_i64gather_pd(src, lanes, at, base)`: by a gather, or with
/// [`crate::simd::Lookup::Loads`] by a load per lane of `lanes` (the lowest set bit, then the
/// next), for the few lanes that wipe out a second loop or fall back to saturation (issue 34,
/// eighteenth round: 1.02-1.04 x the Preisach row each on the timing binary's walk on an AMD
/// Zen 5; the new tops after the first wipe-out, where most lanes of a group read, went 0.80-0.89 x
/// this way and are gathered).
///
/// # Safety
/// The processor must have AVX-512 F; each lane of `lanes` reads an f64 at `at` from
/// `base` inside one allocation.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
pub(super) unsafe fn few_lanes(
    loads: bool,
    src: __m512d,
    lanes: __mmask8,
    at: __m512i,
    base: *const f64,
) -> __m512d {
    if !loads {
        return _mm512_mask_i64gather_pd::<8>(src, lanes, at, base);
    }
    let mut idx = [0i64; WIDE];
    _mm512_storeu_si512(idx.as_mut_ptr().cast(), at);
    let mut got = [0.0f64; WIDE];
    let mut bits = lanes;
    while bits != 0 {
        let l = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        // SAFETY: the caller's
        got[l] = unsafe { *base.offset(idx[l] as isize) };
    }
    _mm512_mask_blend_pd(lanes, src, _mm512_loadu_pd(got.as_ptr()))
}

/// Lane `l`'s pair (`u[l]`, `h[l]`) into the two f64 at `at[l]` from `base`: eight 16-byte
/// stores (issue 34, seventeenth round: against two masked scatters of the pushing lanes,
/// 1.01-1.08 x the Preisach kernel on `preisach_inputs.py`'s shapes, in one process).
///
/// # Safety
/// The processor must have AVX-512 F and DQ; every lane's two f64 are inside one allocation
/// from `base`, writable, and no other reference to them is alive.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
pub(super) unsafe fn store_pairs(base: *mut f64, at: __m512i, u: __m512d, h: __m512d) {
    let mut idx = [0i64; WIDE];
    _mm512_storeu_si512(idx.as_mut_ptr().cast(), at);
    // lanes 0, 2, 4, 6 and 1, 3, 5, 7 as (u, h) pairs, one per 128-bit part
    let (even, odd) = (_mm512_unpacklo_pd(u, h), _mm512_unpackhi_pd(u, h));
    let pairs = [
        _mm512_extractf64x2_pd::<0>(even),
        _mm512_extractf64x2_pd::<0>(odd),
        _mm512_extractf64x2_pd::<1>(even),
        _mm512_extractf64x2_pd::<1>(odd),
        _mm512_extractf64x2_pd::<2>(even),
        _mm512_extractf64x2_pd::<2>(odd),
        _mm512_extractf64x2_pd::<3>(even),
        _mm512_extractf64x2_pd::<3>(odd),
    ];
    for (l, pair) in pairs.into_iter().enumerate() {
        // SAFETY: the caller's: lane l's two f64 at base + at[l]
        unsafe { _mm_storeu_pd(base.offset(idx[l] as isize), pair) };
    }
}
