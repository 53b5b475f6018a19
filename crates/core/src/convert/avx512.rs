//! Conversion (eq. 2.1) of eight elements at once in AVX-512 lanes: `super::avx2`'s lane
//! program (the kernel's operations in the same order, so the same bits) with eight f64
//! lanes and the lane conditions in mask registers.

use std::arch::x86_64::*;

use texsense_kernels::convert::Curve;

use super::ConverterView;

/// Lanes of a register.
const LANES: usize = 8;

/// Elements `start ..` of a row (the arguments and results of `super::avx2::row`): the
/// whole eights in lanes, the rest through the AVX2 row.
///
/// # Safety
/// The processor must have AVX2 and AVX-512 F, DQ and VL.
///
/// # Panics
/// When the slices differ in length or the view has fewer than `start + x.len()` elements.
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
pub(super) unsafe fn row(
    view: &ConverterView<'_>,
    start: usize,
    x: &[f64],
    ok: &[bool],
    out: &mut [f64],
) {
    let n = x.len();
    assert!(ok.len() == n && out.len() == n);
    let (offset, gain) = (&view.offset[start..start + n], &view.gain[start..start + n]);
    let whole = n / LANES * LANES;
    for i in (0..whole).step_by(LANES) {
        let xv = _mm512_loadu_pd(x[i..i + LANES].as_ptr());
        // the eight validity bytes (0 or 1) as lane bits, in one load
        // SAFETY: i + 8 <= whole <= n = ok.len()
        let bytes = unsafe { _mm_loadl_epi64(ok.as_ptr().add(i).cast()) };
        let ok_k = _mm512_test_epi64_mask(_mm512_cvtepu8_epi64(bytes), _mm512_set1_epi64(1));
        let finite = _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(_mm512_sub_pd(xv, xv), _mm512_setzero_pd());
        let live = ok_k & finite;
        let off = _mm512_loadu_pd(offset[i..i + LANES].as_ptr());
        let g = _mm512_loadu_pd(gain[i..i + LANES].as_ptr());
        let scaled = _mm512_div_pd(_mm512_sub_pd(xv, off), g);
        let v = match &view.curve {
            // SAFETY: AVX-512 (this function's features)
            Some(c) => unsafe { at(c, scaled) },
            None => scaled,
        };
        let nan = _mm512_set1_pd(f64::NAN);
        _mm512_storeu_pd(
            out[i..i + LANES].as_mut_ptr(),
            _mm512_mask_blend_pd(live, nan, v),
        );
    }
    // SAFETY: AVX2 (this function's features); the rest of the row
    unsafe {
        super::avx2::row(
            view,
            start + whole,
            &x[whole..],
            &ok[whole..],
            &mut out[whole..],
        )
    };
}

/// `Curve::at` per lane (`super::avx2::at`).
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn at(c: &Curve<'_, f64>, v: __m512d) -> __m512d {
    let (xs, ys, slope, buckets) = (c.x(), c.y(), c.slopes(), c.bucket_starts());
    let last = xs.len() - 1;
    let (x0, xl) = (_mm512_set1_pd(xs[0]), _mm512_set1_pd(xs[last]));
    let nan = _mm512_cmp_pd_mask::<_CMP_UNORD_Q>(v, v);
    let hi = _mm512_cmp_pd_mask::<_CMP_GE_OQ>(v, xl);
    let lo = _mm512_cmp_pd_mask::<_CMP_LE_OQ>(v, x0);
    let inside = !(nan | hi | lo);
    let vin = _mm512_mask_blend_pd(inside, x0, v);
    let top = _mm512_set1_pd((buckets.len() - 1) as f64);
    let pos = _mm512_min_pd(
        _mm512_mul_pd(_mm512_sub_pd(vin, x0), _mm512_set1_pd(c.inv_width())),
        top,
    );
    // 0 <= pos <= top < 2^31: truncation is the floor
    let b = _mm512_cvtepi32_epi64(_mm512_cvttpd_epi32(pos));
    let bucket = _mm512_i64gather_epi32::<4>(b, buckets.as_ptr().cast::<i32>());
    let mut j = _mm512_cvtepu32_epi64(bucket);
    let (zero_i, one_i) = (_mm512_setzero_si512(), _mm512_set1_epi64(1));
    let xp = xs.as_ptr();
    let below_last = _mm512_set1_epi64(last as i64);
    // x[j], x[j + 1] and x[j + 2] gathered at once (their addresses are known from the
    // bucket); the kernel's steps from the bucket's start are selected from them, and only a
    // step back or a third step forward (both rare) walks on one gather at a time
    let mut xj = _mm512_i64gather_pd::<8>(j, xp);
    let ahead = |k: i64| _mm512_min_epi64(_mm512_add_epi64(j, _mm512_set1_epi64(k)), below_last);
    let x1 = _mm512_i64gather_pd::<8>(ahead(1), xp);
    let x2 = _mm512_i64gather_pd::<8>(ahead(2), xp);
    let up_walk = |mut j: __m512i, mut xj: __m512d| loop {
        let next = _mm512_add_epi64(j, one_i);
        let can = inside & _mm512_cmpgt_epi64_mask(below_last, next);
        let xn = _mm512_mask_i64gather_pd::<8>(_mm512_setzero_pd(), can, next, xp);
        let up = can & _mm512_cmp_pd_mask::<_CMP_LE_OQ>(xn, vin);
        if up == 0 {
            break (j, xj);
        }
        j = _mm512_mask_add_epi64(j, up, j, one_i);
        xj = _mm512_mask_blend_pd(up, xj, xn);
    };
    let back = |j: __m512i, xj: __m512d| {
        inside & _mm512_cmpgt_epi64_mask(j, zero_i) & _mm512_cmp_pd_mask::<_CMP_GT_OQ>(xj, vin)
    };
    let down = back(j, xj);
    if down != 0 {
        // the kernel's loops: back, then forward
        j = _mm512_mask_sub_epi64(j, down, j, one_i);
        loop {
            xj = _mm512_i64gather_pd::<8>(j, xp);
            let down = back(j, xj);
            if down == 0 {
                break;
            }
            j = _mm512_mask_sub_epi64(j, down, j, one_i);
        }
        (j, xj) = up_walk(j, xj);
    } else {
        let step = |j: __m512i, can: __mmask8, xn: __m512d| {
            can & _mm512_cmpgt_epi64_mask(below_last, _mm512_add_epi64(j, one_i))
                & _mm512_cmp_pd_mask::<_CMP_LE_OQ>(xn, vin)
        };
        let up1 = step(j, inside, x1);
        j = _mm512_mask_add_epi64(j, up1, j, one_i);
        xj = _mm512_mask_blend_pd(up1, xj, x1);
        let up2 = step(j, up1, x2);
        j = _mm512_mask_add_epi64(j, up2, j, one_i);
        xj = _mm512_mask_blend_pd(up2, xj, x2);
        if up2 != 0 {
            (j, xj) = up_walk(j, xj);
        }
    }
    let yj = _mm512_i64gather_pd::<8>(j, ys.as_ptr());
    let sj = _mm512_i64gather_pd::<8>(j, slope.as_ptr());
    let line = _mm512_add_pd(_mm512_mul_pd(sj, _mm512_sub_pd(vin, xj)), yj);
    let mut r = _mm512_mask_blend_pd(_mm512_cmp_pd_mask::<_CMP_EQ_OQ>(xj, vin), line, yj);
    r = _mm512_mask_blend_pd(lo, r, _mm512_set1_pd(ys[0]));
    r = _mm512_mask_blend_pd(hi, r, _mm512_set1_pd(ys[last]));
    _mm512_mask_blend_pd(nan, r, _mm512_set1_pd(f64::NAN))
}
