//! How the AVX-512 Preisach row (`super`) reads and writes memory at each lane's own place:
//! the Everett cell's corners from the table by cell, a few lanes' stack slots, the turning
//! points onto the stacks (issue 34, seventeenth and eighteenth rounds).

use std::arch::x86_64::*;

use super::WIDE;
use crate::simd::loads::{few, rows_of_four};

/// The four corners of each lane's Everett cell `(i0, j0)` (`i0, j0 <= K - 2`) from the
/// table by cell (`super::avx2::cell_corners` on eight lanes): `F(i, j), F(i, j + 1),
/// F(i + 1, j), F(i + 1, j + 1)` across the lanes by one 32-byte load per lane and a
/// transpose ([`rows_of_four`]).
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
    // SAFETY: the caller's: every cell index is below (K - 1) K / 2
    unsafe { rows_of_four(cells, _mm512_cvtepi32_epi64(q)) }
}

/// `_mm512_mask_i64gather_pd(src, lanes, at, base)`: by a gather, or with
/// [`crate::simd::Lookup::Loads`] by a load per lane of `lanes` ([`few`]), for the few lanes
/// that wipe out a second loop or fall back to saturation (issue 34, eighteenth round:
/// 1.02-1.04 x the Preisach row each on the timing binary's walk on an AMD Zen 5; the new
/// tops after the first wipe-out, where most lanes of a group read, went 0.80-0.89 x this
/// way and are gathered).
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
    if loads {
        // SAFETY: AVX-512 (this function's features); the caller's
        unsafe { few(src, lanes, at, base) }
    } else {
        _mm512_mask_i64gather_pd::<8>(src, lanes, at, base)
    }
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
