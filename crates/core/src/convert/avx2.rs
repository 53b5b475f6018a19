//! Conversion (eq. 2.1) of four elements at once in AVX2 lanes: `(c - a_i) / b_i`, then the
//! material curve, with the kernel's operations (`texsense_kernels::convert`: the bucket
//! table, the steps to the segment, `slope (v - x_j) + y_j`, the ends held) in the same
//! order, so the same bits. The bucket, the steps and the segment's values are gathered
//! (x[j] once: the search's load is the segment's); the steps loop while any lane still
//! moves (a step or two at most on a real curve).

use std::arch::x86_64::*;

use texsense_kernels::convert::Curve;

use super::ConverterView;

/// Lanes of a register.
const LANES: usize = 4;

/// Elements `start ..` of a row: readings `x` and their validity `ok` -> values `out` (NaN
/// where not valid or not a number; the validity itself is unchanged, as the kernel's
/// `stage::conversion`). The whole fours of the row run in lanes, the rest one by one.
///
/// # Safety
/// The processor must have AVX2.
///
/// # Panics
/// When the slices differ in length or the view has fewer than `start + x.len()` elements.
#[target_feature(enable = "avx2")]
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
        let xv = _mm256_loadu_pd(x[i..i + LANES].as_ptr());
        let m = |b: bool| -i64::from(b);
        let o = &ok[i..i + LANES];
        let ok_m = _mm256_castsi256_pd(_mm256_set_epi64x(m(o[3]), m(o[2]), m(o[1]), m(o[0])));
        let finite = _mm256_cmp_pd::<_CMP_EQ_OQ>(_mm256_sub_pd(xv, xv), _mm256_setzero_pd());
        let live = _mm256_and_pd(ok_m, finite);
        let off = _mm256_loadu_pd(offset[i..i + LANES].as_ptr());
        let g = _mm256_loadu_pd(gain[i..i + LANES].as_ptr());
        let scaled = _mm256_div_pd(_mm256_sub_pd(xv, off), g);
        let v = match &view.curve {
            // SAFETY: AVX2 (this function's feature)
            Some(c) => unsafe { at(c, scaled) },
            None => scaled,
        };
        let nan = _mm256_set1_pd(f64::NAN);
        _mm256_storeu_pd(
            out[i..i + LANES].as_mut_ptr(),
            _mm256_blendv_pd(nan, v, live),
        );
    }
    for i in whole..n {
        out[i] = view.stage(start + i, x[i], ok[i]).0;
    }
}

/// `Curve::at` per lane (NaN for NaN, the ends held).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn at(c: &Curve<'_, f64>, v: __m256d) -> __m256d {
    let (xs, ys, slope, buckets) = (c.x(), c.y(), c.slopes(), c.bucket_starts());
    let last = xs.len() - 1;
    let (x0, xl) = (_mm256_set1_pd(xs[0]), _mm256_set1_pd(xs[last]));
    let nan = _mm256_cmp_pd::<_CMP_UNORD_Q>(v, v);
    let hi = _mm256_cmp_pd::<_CMP_GE_OQ>(v, xl);
    let lo = _mm256_cmp_pd::<_CMP_LE_OQ>(v, x0);
    let inside = _mm256_castpd_si256(_mm256_andnot_pd(
        _mm256_or_pd(nan, _mm256_or_pd(hi, lo)),
        _mm256_castsi256_pd(_mm256_set1_epi64x(-1)),
    ));
    // lanes outside read bucket 0 and step nowhere (their value is the end's or NaN)
    let vin = _mm256_blendv_pd(x0, v, _mm256_castsi256_pd(inside));
    let top = _mm256_set1_pd((buckets.len() - 1) as f64);
    let pos = _mm256_min_pd(
        _mm256_mul_pd(_mm256_sub_pd(vin, x0), _mm256_set1_pd(c.inv_width())),
        top,
    );
    // 0 <= pos <= top < 2^31: truncation is the floor
    let b = _mm256_cvtepi32_epi64(_mm256_cvttpd_epi32(pos));
    let bucket = _mm256_i64gather_epi32::<4>(buckets.as_ptr().cast::<i32>(), b);
    let mut j = _mm256_cvtepu32_epi64(bucket);
    let (zero_i, one_i) = (_mm256_setzero_si256(), _mm256_set1_epi64x(1));
    let xp = xs.as_ptr();
    // the bucket's start may round either way at its edge: settle on x[j] <= v < x[j + 1]
    // (`xj`: x[j] of every lane, kept from the loads of the search)
    let mut xj;
    loop {
        xj = _mm256_i64gather_pd::<8>(xp, j);
        let down = _mm256_and_si256(
            _mm256_and_si256(inside, _mm256_cmpgt_epi64(j, zero_i)),
            _mm256_castpd_si256(_mm256_cmp_pd::<_CMP_GT_OQ>(xj, vin)),
        );
        if _mm256_testz_si256(down, down) != 0 {
            break;
        }
        j = _mm256_add_epi64(j, down); // down is -1 where a lane steps
    }
    let below_last = _mm256_set1_epi64x(last as i64);
    loop {
        let next = _mm256_add_epi64(j, one_i);
        let can = _mm256_and_si256(inside, _mm256_cmpgt_epi64(below_last, next));
        let xn =
            _mm256_mask_i64gather_pd::<8>(_mm256_setzero_pd(), xp, next, _mm256_castsi256_pd(can));
        let up = _mm256_and_si256(
            can,
            _mm256_castpd_si256(_mm256_cmp_pd::<_CMP_LE_OQ>(xn, vin)),
        );
        if _mm256_testz_si256(up, up) != 0 {
            break;
        }
        j = _mm256_sub_epi64(j, up);
        xj = _mm256_blendv_pd(xj, xn, _mm256_castsi256_pd(up));
    }
    let yj = _mm256_i64gather_pd::<8>(ys.as_ptr(), j);
    // slope j exists for inside lanes (j <= last - 1); outside lanes read slope 0
    let sj = _mm256_i64gather_pd::<8>(slope.as_ptr(), j);
    let line = _mm256_add_pd(_mm256_mul_pd(sj, _mm256_sub_pd(vin, xj)), yj);
    let mut r = _mm256_blendv_pd(line, yj, _mm256_cmp_pd::<_CMP_EQ_OQ>(xj, vin));
    r = _mm256_blendv_pd(r, _mm256_set1_pd(ys[0]), lo);
    r = _mm256_blendv_pd(r, _mm256_set1_pd(ys[last]), hi);
    _mm256_blendv_pd(r, _mm256_set1_pd(f64::NAN), nan)
}

#[cfg(test)]
mod tests {
    use crate::convert::{Converter, Curve};
    use crate::preisach::tests::Rng;
    use crate::simd::Path;

    #[test]
    fn lanes_equal_the_scalar_stage_bit_for_bit() {
        let _guard = crate::simd::testing::lock();
        let mut rng = Rng(3);
        for case in 0..200 {
            let points = 2 + (rng.next() % 60) as usize;
            // uneven spacing: several points in one bucket, empty buckets
            let mut x = vec![1.0 + rng.unit()];
            for _ in 1..points {
                let gap = if rng.next().is_multiple_of(4) {
                    1e-3
                } else {
                    0.5
                };
                x.push(x[x.len() - 1] + gap * (0.01 + rng.unit()));
            }
            let y: Vec<f64> = x.iter().map(|v| v * v - 0.3 * v).collect();
            let n = 1 + (rng.next() % 37) as usize;
            let offset: Vec<f64> = (0..n).map(|_| rng.unit() - 0.5).collect();
            let gain: Vec<f64> = (0..n).map(|_| 0.5 + rng.unit()).collect();
            let curve = (case % 5 != 4).then(|| Curve::new(x.clone(), y).unwrap());
            let conv = Converter::new(offset.clone(), gain.clone(), curve).unwrap();
            let view = conv.view();
            // readings that land on the points, beyond both ends, between, and not numbers
            let (lo, hi) = (x[0], x[x.len() - 1]);
            let readings: Vec<f64> = (0..n)
                .map(|i| {
                    let at = match rng.next() % 8 {
                        0 => x[(rng.next() % x.len() as u64) as usize],
                        1 => lo - rng.unit(),
                        2 => hi + rng.unit(),
                        3 => [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e308][i % 4],
                        _ => lo + (hi - lo) * rng.unit(),
                    };
                    // the reading whose scaled value is `at` (or the special value)
                    if at.is_finite() && at.abs() < 1e300 {
                        at * gain[i] + offset[i]
                    } else {
                        at
                    }
                })
                .collect();
            let ok: Vec<bool> = (0..n).map(|_| !rng.next().is_multiple_of(9)).collect();
            let start = (rng.next() % 3) as usize;
            let m = n - start;
            let run = |best: Path| {
                crate::simd::set_limit(best);
                let mut out = vec![0.0; m];
                view.row(start, &readings[start..], &ok[start..], &mut out);
                crate::simd::set_enabled(true);
                out.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            };
            // the AVX2 lanes forced, then the best path (AVX-512 where the processor has it)
            let scalar = run(Path::Scalar);
            assert_eq!(scalar, run(Path::Avx2), "case {case}, AVX2");
            assert_eq!(scalar, run(Path::Avx512), "case {case}, best path");
        }
    }
}
