//! The chain's glue between its kernels, a row of a frame at a time in SIMD lanes (issue 34,
//! ninth round): reading a segment's inputs from the failure codes, coding the values a
//! segment left not finite, and the repair's first pass (keep the last value of every
//! available reading, list the others). Each was a scalar loop with a branch per reading;
//! here eight readings (AVX-512) or four (AVX2) go through one mask, and the few readings
//! that fail are handled one by one. The results are the scalar loops' bit for bit (the
//! values are only moved, never computed): `tests` compares every path with the scalar one.

use crate::simd::{self, Path};

/// The inputs of a segment's row: `ok[i] = codes[i] == ok_code` and `x[i] = src[i]` where
/// `ok[i]`, NaN elsewhere.
///
/// # Panics
/// When the slices differ in length.
#[inline]
pub fn coded_inputs(src: &[f64], codes: &[u8], ok_code: u8, x: &mut [f64], ok: &mut [bool]) {
    let w = src.len();
    assert!(codes.len() == w && x.len() == w && ok.len() == w);
    let done = match simd::path() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the path is only ever Avx512 / Avx2 on a processor that has it
        Path::Avx512 => unsafe { x86::coded_inputs_512(src, codes, ok_code, x, ok) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above
        Path::Avx2 => unsafe { x86::coded_inputs_256(src, codes, ok_code, x, ok) },
        _ => 0,
    };
    for i in done..w {
        let good = codes[i] == ok_code;
        ok[i] = good;
        x[i] = if good { src[i] } else { f64::NAN };
    }
}

/// `ok[i] = values[i].is_finite()` (a Preisach row's outputs as the drift row's validity;
/// issue 34, twelfth round: a scalar loop of four readings at a time, about 2 % of a step
/// at 1024 elements before).
///
/// # Panics
/// When the slices differ in length.
#[inline]
pub fn finite_flags(values: &[f64], ok: &mut [bool]) {
    let w = values.len();
    assert!(ok.len() == w);
    let done = match simd::path() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the path is only ever Avx512 on a processor that has it
        Path::Avx512 => unsafe { x86::finite_flags_512(values, ok) },
        _ => 0,
    };
    for (o, v) in ok[done..].iter_mut().zip(&values[done..]) {
        *o = v.is_finite();
    }
}

/// After a segment: `codes[i] = to` where `codes[i] == ok_code` and `values[i]` is not a
/// finite number.
///
/// # Panics
/// When the slices differ in length.
#[inline]
pub fn code_not_finite(values: &[f64], codes: &mut [u8], ok_code: u8, to: u8) {
    let w = values.len();
    assert!(codes.len() == w);
    let done = match simd::path() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the path is only ever Avx512 / Avx2 on a processor that has it
        Path::Avx512 => unsafe { x86::code_not_finite_512(values, codes, ok_code, to) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above
        Path::Avx2 => unsafe { x86::code_not_finite_256(values, codes, ok_code, to) },
        _ => 0,
    };
    for (c, v) in codes[done..].iter_mut().zip(&values[done..]) {
        if *c == ok_code && !v.is_finite() {
            *c = to;
        }
    }
}

/// The repair's first pass over a frame: `last[i] = frame[i]` for every available reading
/// (`codes[i] == ok_code` and a finite value), and the others listed in `failed` (cleared
/// first), in ascending order.
///
/// # Panics
/// When the slices differ in length.
#[inline]
pub fn keep_available(
    frame: &[f64],
    codes: &[u8],
    ok_code: u8,
    last: &mut [f64],
    failed: &mut Vec<usize>,
) {
    let w = frame.len();
    assert!(codes.len() == w && last.len() == w);
    failed.clear();
    let done = match simd::path() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the path is only ever Avx512 / Avx2 on a processor that has it
        Path::Avx512 => unsafe { x86::keep_available_512(frame, codes, ok_code, last, failed) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above
        Path::Avx2 => unsafe { x86::keep_available_256(frame, codes, ok_code, last, failed) },
        _ => 0,
    };
    for i in done..w {
        if codes[i] == ok_code && frame[i].is_finite() {
            last[i] = frame[i];
        } else {
            failed.push(i);
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    //! The lanes; each function does the whole groups of a row and returns how many
    //! readings it did (the caller does the rest with the scalar loop).

    use std::arch::x86_64::*;

    /// Lane bit `l` of `m` (four lanes) at bit 0 of byte `l` (no carries: distinct bits).
    #[inline(always)]
    fn spread4(m: u32) -> u32 {
        m.wrapping_mul(0x0020_4081) & 0x0101_0101
    }

    /// Lane bit `l` of `m` (eight lanes) at bit 0 of byte `l`.
    #[inline(always)]
    fn spread8(m: u8) -> u64 {
        u64::from(spread4(u32::from(m & 0xf))) | u64::from(spread4(u32::from(m >> 4))) << 32
    }

    /// The lanes of eight codes equal to `ok_code`, and of eight finite values.
    #[inline(always)]
    unsafe fn masks_512(codes: &[u8], values: &[f64], i: usize, ok_code: __m512i) -> (u8, u8) {
        // SAFETY (caller): i + 8 <= the slices' length
        let c = unsafe { _mm_loadl_epi64(codes.as_ptr().add(i).cast()) };
        let good = _mm512_cmpeq_epi64_mask(_mm512_cvtepu8_epi64(c), ok_code);
        // SAFETY: as above
        let v = unsafe { _mm512_loadu_pd(values.as_ptr().add(i)) };
        let finite = _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(_mm512_sub_pd(v, v), _mm512_setzero_pd());
        (good, finite)
    }

    /// The lanes of four codes equal to `ok_code`, and of four finite values.
    #[inline(always)]
    unsafe fn masks_256(codes: &[u8], values: &[f64], i: usize, ok_code: __m256i) -> (u32, u32) {
        // SAFETY (caller): i + 4 <= the slices' length
        let word = u32::from_le_bytes(unsafe { codes.as_ptr().add(i).cast::<[u8; 4]>().read() });
        let c = _mm256_cvtepu8_epi64(_mm_cvtsi32_si128(word as i32));
        let good = _mm256_movemask_pd(_mm256_castsi256_pd(_mm256_cmpeq_epi64(c, ok_code)));
        // SAFETY: as above
        let v = unsafe { _mm256_loadu_pd(values.as_ptr().add(i)) };
        let finite = _mm256_cmp_pd::<_CMP_EQ_OQ>(_mm256_sub_pd(v, v), _mm256_setzero_pd());
        (good as u32, _mm256_movemask_pd(finite) as u32)
    }

    /// `super::finite_flags`, eight at a time.
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2")]
    pub(super) unsafe fn finite_flags_512(values: &[f64], ok: &mut [bool]) -> usize {
        let whole = values.len() / 8 * 8;
        for i in (0..whole).step_by(8) {
            // SAFETY: i + 8 <= whole <= the length of both slices (checked by the caller)
            unsafe {
                let v = _mm512_loadu_pd(values.as_ptr().add(i));
                let finite =
                    _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(_mm512_sub_pd(v, v), _mm512_setzero_pd());
                // bytes 0 or 1: valid `bool`s
                ok.as_mut_ptr()
                    .add(i)
                    .cast::<[u8; 8]>()
                    .write_unaligned(spread8(finite).to_le_bytes());
            }
        }
        whole
    }

    /// `super::coded_inputs`, eight at a time.
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2")]
    pub(super) unsafe fn coded_inputs_512(
        src: &[f64],
        codes: &[u8],
        ok_code: u8,
        x: &mut [f64],
        ok: &mut [bool],
    ) -> usize {
        let whole = src.len() / 8 * 8;
        let (okv, nan) = (
            _mm512_set1_epi64(i64::from(ok_code)),
            _mm512_set1_pd(f64::NAN),
        );
        for i in (0..whole).step_by(8) {
            // SAFETY: i + 8 <= whole <= the length of every slice (checked by the caller)
            unsafe {
                let c = _mm_loadl_epi64(codes.as_ptr().add(i).cast());
                let good = _mm512_cmpeq_epi64_mask(_mm512_cvtepu8_epi64(c), okv);
                let v = _mm512_mask_loadu_pd(nan, good, src.as_ptr().add(i));
                _mm512_storeu_pd(x.as_mut_ptr().add(i), v);
                // bytes 0 or 1: valid `bool`s
                ok.as_mut_ptr()
                    .add(i)
                    .cast::<[u8; 8]>()
                    .write_unaligned(spread8(good).to_le_bytes());
            }
        }
        whole
    }

    /// `super::coded_inputs`, four at a time.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn coded_inputs_256(
        src: &[f64],
        codes: &[u8],
        ok_code: u8,
        x: &mut [f64],
        ok: &mut [bool],
    ) -> usize {
        let whole = src.len() / 4 * 4;
        let (okv, nan) = (
            _mm256_set1_epi64x(i64::from(ok_code)),
            _mm256_set1_pd(f64::NAN),
        );
        for i in (0..whole).step_by(4) {
            // SAFETY: i + 4 <= whole <= the length of every slice (checked by the caller)
            unsafe {
                let word = u32::from_le_bytes(codes.as_ptr().add(i).cast::<[u8; 4]>().read());
                let c = _mm256_cvtepu8_epi64(_mm_cvtsi32_si128(word as i32));
                let good = _mm256_castsi256_pd(_mm256_cmpeq_epi64(c, okv));
                let v = _mm256_blendv_pd(nan, _mm256_loadu_pd(src.as_ptr().add(i)), good);
                _mm256_storeu_pd(x.as_mut_ptr().add(i), v);
                let bits = spread4(_mm256_movemask_pd(good) as u32);
                ok.as_mut_ptr()
                    .add(i)
                    .cast::<[u8; 4]>()
                    .write_unaligned(bits.to_le_bytes());
            }
        }
        whole
    }

    /// `super::code_not_finite`, eight at a time.
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2")]
    pub(super) unsafe fn code_not_finite_512(
        values: &[f64],
        codes: &mut [u8],
        ok_code: u8,
        to: u8,
    ) -> usize {
        let whole = values.len() / 8 * 8;
        let okv = _mm512_set1_epi64(i64::from(ok_code));
        for i in (0..whole).step_by(8) {
            // SAFETY: i + 8 <= whole <= the length of both slices
            let (good, finite) = unsafe { masks_512(codes, values, i, okv) };
            let mut bad = good & !finite;
            while bad != 0 {
                codes[i + bad.trailing_zeros() as usize] = to;
                bad &= bad - 1;
            }
        }
        whole
    }

    /// `super::code_not_finite`, four at a time.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn code_not_finite_256(
        values: &[f64],
        codes: &mut [u8],
        ok_code: u8,
        to: u8,
    ) -> usize {
        let whole = values.len() / 4 * 4;
        let okv = _mm256_set1_epi64x(i64::from(ok_code));
        for i in (0..whole).step_by(4) {
            // SAFETY: i + 4 <= whole <= the length of both slices
            let (good, finite) = unsafe { masks_256(codes, values, i, okv) };
            let mut bad = good & !finite;
            while bad != 0 {
                codes[i + bad.trailing_zeros() as usize] = to;
                bad &= bad - 1;
            }
        }
        whole
    }

    /// `super::keep_available`, eight at a time.
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2")]
    pub(super) unsafe fn keep_available_512(
        frame: &[f64],
        codes: &[u8],
        ok_code: u8,
        last: &mut [f64],
        failed: &mut Vec<usize>,
    ) -> usize {
        let whole = frame.len() / 8 * 8;
        let okv = _mm512_set1_epi64(i64::from(ok_code));
        // the indices of a group's readings not available packed to the front of a register
        // and stored whole after those listed so far (no branch per reading; issue 34,
        // twelfth round): `failed` has room for all `whole` of them
        failed.reserve(whole);
        let base = failed.len();
        let mut listed = base;
        let mut idx = _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 6, 7);
        let eight = _mm512_set1_epi64(8);
        const _: () = assert!(std::mem::size_of::<usize>() == 8);
        for i in (0..whole).step_by(8) {
            // SAFETY: i + 8 <= whole <= the length of every slice; listed - base <= i, so
            // the eight words from `listed` are within the capacity reserved (base + whole);
            // `usize` is a 64-bit word here
            unsafe {
                let (good, finite) = masks_512(codes, frame, i, okv);
                let keep = good & finite;
                let v = _mm512_loadu_pd(frame.as_ptr().add(i));
                _mm512_mask_storeu_pd(last.as_mut_ptr().add(i), keep, v);
                let bad = !keep;
                let packed = _mm512_maskz_compress_epi64(bad, idx);
                _mm512_storeu_si512(failed.as_mut_ptr().add(listed).cast(), packed);
                listed += bad.count_ones() as usize;
            }
            idx = _mm512_add_epi64(idx, eight);
        }
        // SAFETY: the words up to `listed` were written above (indices), within capacity
        unsafe { failed.set_len(listed) };
        whole
    }

    /// `super::keep_available`, four at a time.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn keep_available_256(
        frame: &[f64],
        codes: &[u8],
        ok_code: u8,
        last: &mut [f64],
        failed: &mut Vec<usize>,
    ) -> usize {
        let whole = frame.len() / 4 * 4;
        let okv = _mm256_set1_epi64x(i64::from(ok_code));
        for i in (0..whole).step_by(4) {
            // SAFETY: i + 4 <= whole <= the length of every slice
            unsafe {
                let (good, finite) = masks_256(codes, frame, i, okv);
                let keep = good & finite;
                if keep == 0xf {
                    let v = _mm256_loadu_pd(frame.as_ptr().add(i));
                    _mm256_storeu_pd(last.as_mut_ptr().add(i), v);
                    continue;
                }
                let mut bad = !keep & 0xf;
                let mut kept = keep;
                while kept != 0 {
                    let l = i + kept.trailing_zeros() as usize;
                    last[l] = frame[l];
                    kept &= kept - 1;
                }
                while bad != 0 {
                    failed.push(i + bad.trailing_zeros() as usize);
                    bad &= bad - 1;
                }
            }
        }
        whole
    }
}

#[cfg(test)]
mod tests;
