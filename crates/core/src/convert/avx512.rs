//! Conversion (eq. 2.1) of eight elements at once in AVX-512 lanes: `super::avx2`'s lane
//! program (the kernel's operations in the same order, so the same bits) with eight f64
//! lanes and the lane conditions in mask registers.

use std::arch::x86_64::*;

use texsense_kernels::convert::Curve;

use super::ConverterView;
use crate::simd::loads;

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
    let nan = _mm512_set1_pd(f64::NAN);
    // SAFETY: AVX-512 (this function's features); a group's eight elements are within the
    // slices (i + 8 <= whole <= n, the lengths checked above)
    let scaled = |i: usize| unsafe { scale(offset, gain, x, ok, i) };
    match &view.curve {
        None => {
            for i in (0..whole).step_by(LANES) {
                let (live, v) = scaled(i);
                _mm512_storeu_pd(
                    out[i..i + LANES].as_mut_ptr(),
                    _mm512_mask_blend_pd(live, nan, v),
                );
            }
        }
        Some(c) => {
            let tables = Tables {
                by_bucket: view.by_bucket,
                by_point: view.by_point,
                loads: crate::simd::lookup() == crate::simd::Lookup::Loads,
            };
            // runs of RUN groups side by side through the curve, then the groups left one
            // by one
            let runs = n / (RUN * LANES) * (RUN * LANES);
            for i in (0..runs).step_by(RUN * LANES) {
                let got: [(__mmask8, __m512d); RUN] =
                    std::array::from_fn(|k| scaled(i + k * LANES));
                // SAFETY: AVX-512 (this function's features)
                let v = unsafe { at_n::<RUN>(c, &tables, got.map(|(_, v)| v)) };
                for (k, ((live, _), v)) in got.into_iter().zip(v).enumerate() {
                    let at = i + k * LANES;
                    _mm512_storeu_pd(
                        out[at..at + LANES].as_mut_ptr(),
                        _mm512_mask_blend_pd(live, nan, v),
                    );
                }
            }
            for i in (runs..whole).step_by(LANES) {
                let (live, v) = scaled(i);
                // SAFETY: AVX-512 (this function's features)
                let [v] = unsafe { at_n::<1>(c, &tables, [v]) };
                _mm512_storeu_pd(
                    out[i..i + LANES].as_mut_ptr(),
                    _mm512_mask_blend_pd(live, nan, v),
                );
            }
        }
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

/// Groups of eight side by side in the curve lookup: each group's lookup is a chain of
/// dependent gathers (the bucket, then the segment), and four chains interleaved keep the
/// processor busy while each waits (issue 34, sixteenth round: the step 0.952 x against one
/// group at a time, in one process; two groups 0.975 x, eight as four, sixteen 1.08 x).
const RUN: usize = 4;

/// Eight elements' validity (valid and a number) and scaled readings `(x - offset) / gain`
/// (eq. 2.1), from element `i` of the slices.
///
/// # Safety
/// The processor must have AVX-512 F/DQ/VL; `i + 8` is at most every slice's length.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn scale(
    offset: &[f64],
    gain: &[f64],
    x: &[f64],
    ok: &[bool],
    i: usize,
) -> (__mmask8, __m512d) {
    debug_assert!(i + LANES <= x.len().min(ok.len()).min(offset.len()).min(gain.len()));
    // SAFETY: i + 8 within every slice (the caller's promise)
    unsafe {
        let xv = _mm512_loadu_pd(x.as_ptr().add(i));
        // the eight validity bytes (0 or 1) as lane bits, in one load
        let bytes = _mm_loadl_epi64(ok.as_ptr().add(i).cast());
        let ok_k = _mm512_test_epi64_mask(_mm512_cvtepu8_epi64(bytes), _mm512_set1_epi64(1));
        let finite = _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(_mm512_sub_pd(xv, xv), _mm512_setzero_pd());
        let off = _mm512_loadu_pd(offset.as_ptr().add(i));
        let g = _mm512_loadu_pd(gain.as_ptr().add(i));
        (ok_k & finite, _mm512_div_pd(_mm512_sub_pd(xv, off), g))
    }
}

/// `Curve::at` per lane of `N` groups with the curve's tables ([`Tables`]; the split is
/// `super::Curve::split`): per group, the bucket's start and split read at once, the
/// start stepped once where the input is at or past the split, then the segment's `x`, `y`
/// and slope read at once (by gathers or loads, [`crate::simd::Lookup`]) — two levels of
/// dependent reads (the walk of [`at_walk`] has three), the `N` groups' reads interleaved
/// ([`RUN`]). A group with a lane whose
/// bucket may step twice (NaN split) or back goes through [`at_walk`]: the same segment as
/// the kernel's walk in every lane, so the same bits.
///
/// # Panics
/// When the tables are not one row per bucket and per point.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn at_n<const N: usize>(
    c: &Curve<'_, f64>,
    t: &Tables<'_>,
    v: [__m512d; N],
) -> [__m512d; N] {
    let (xs, ys, slope, buckets) = (c.x(), c.y(), c.slopes(), c.bucket_starts());
    assert_eq!(
        t.by_bucket.len(),
        buckets.len(),
        "one start and split per bucket"
    );
    assert_eq!(t.by_point.len(), xs.len(), "one row per point");
    let last = xs.len() - 1;
    // SAFETY: AVX-512 (this function's features)
    let mut l: [Lanes; N] = std::array::from_fn(|k| unsafe { place(c, v[k]) });
    // each lane's bucket start and split: a load per lane of both, or two gathers
    let cut: [__m512d; N] = std::array::from_fn(|k| {
        if t.loads {
            let at = _mm512_slli_epi64::<1>(l[k].b);
            // SAFETY: AVX-512 (this function's features); b < buckets, two f64 per bucket
            let (start, cut) = unsafe { loads::pairs(t.by_bucket.as_ptr().cast(), at) };
            l[k].bucket = _mm512_cvttpd_epi32(start);
            cut
        } else {
            l[k].bucket = _mm512_i64gather_epi32::<4>(l[k].b, buckets.as_ptr().cast::<i32>());
            let at = _mm512_add_epi64(_mm512_slli_epi64::<1>(l[k].b), _mm512_set1_epi64(1));
            _mm512_i64gather_pd::<8>(at, t.by_bucket.as_ptr().cast::<f64>())
        }
    });
    // the kernel's first step forward (`x[j + 1] <= v`, `j + 1 < last`: the split)
    let j: [__m512i; N] = std::array::from_fn(|k| {
        let up = l[k].inside & _mm512_cmp_pd_mask::<_CMP_LE_OQ>(cut[k], l[k].vin);
        let j0 = _mm512_cvtepu32_epi64(l[k].bucket);
        _mm512_mask_add_epi64(j0, up, j0, _mm512_set1_epi64(1))
    });
    // the segment's x, y and slope: a load per lane of the three, or three gathers
    let (xj, yj, sj): ([__m512d; N], [__m512d; N], [__m512d; N]) = if t.loads {
        // SAFETY: AVX-512 (this function's features); j <= last, four f64 per point
        let p: [[__m512d; 4]; N] = std::array::from_fn(|k| unsafe {
            loads::rows_of_four(t.by_point.as_ptr().cast(), _mm512_slli_epi64::<2>(j[k]))
        });
        (
            std::array::from_fn(|k| p[k][0]),
            std::array::from_fn(|k| p[k][1]),
            std::array::from_fn(|k| p[k][2]),
        )
    } else {
        (
            std::array::from_fn(|k| _mm512_i64gather_pd::<8>(j[k], xs.as_ptr())),
            std::array::from_fn(|k| _mm512_i64gather_pd::<8>(j[k], ys.as_ptr())),
            std::array::from_fn(|k| _mm512_i64gather_pd::<8>(j[k], slope.as_ptr())),
        )
    };
    std::array::from_fn(|k| {
        let Lanes {
            nan,
            lo,
            hi,
            inside,
            vin,
            ..
        } = l[k];
        // a bucket that may step twice, or a step back (an input rounded into the bucket
        // below its start's point): x[j] > v where j did not step (a lane that stepped has
        // x[j] <= v)
        let twice = inside & _mm512_cmp_pd_mask::<_CMP_UNORD_Q>(cut[k], cut[k]);
        let back = inside
            & _mm512_cmpgt_epi64_mask(j[k], _mm512_setzero_si512())
            & _mm512_cmp_pd_mask::<_CMP_GT_OQ>(xj[k], vin);
        if twice | back != 0 {
            // SAFETY: AVX-512 (this function's features)
            return unsafe { at_walk(c, v[k]) };
        }
        let line = _mm512_add_pd(_mm512_mul_pd(sj[k], _mm512_sub_pd(vin, xj[k])), yj[k]);
        let mut r = _mm512_mask_blend_pd(_mm512_cmp_pd_mask::<_CMP_EQ_OQ>(xj[k], vin), line, yj[k]);
        r = _mm512_mask_blend_pd(lo, r, _mm512_set1_pd(ys[0]));
        r = _mm512_mask_blend_pd(hi, r, _mm512_set1_pd(ys[last]));
        _mm512_mask_blend_pd(nan, r, _mm512_set1_pd(f64::NAN))
    })
}

/// Where eight inputs lie on a curve: not a number (`nan`), below its first point (`lo`), at or above its last
/// (`hi`), inside it (`inside`, not NaN), the input clamped inside (`vin`: the first point
/// where not inside), its bucket (`b`) and the bucket's first segment (`bucket`).
#[derive(Clone, Copy)]
struct Lanes {
    nan: __mmask8,
    lo: __mmask8,
    hi: __mmask8,
    inside: __mmask8,
    vin: __m512d,
    b: __m512i,
    bucket: __m256i,
}

/// [`place`] with the buckets' first segments gathered.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn lanes(c: &Curve<'_, f64>, v: __m512d) -> Lanes {
    // SAFETY: AVX-512 (this function's features)
    let mut l = unsafe { place(c, v) };
    let buckets = c.bucket_starts();
    l.bucket = _mm512_i64gather_epi32::<4>(l.b, buckets.as_ptr().cast::<i32>());
    l
}

/// [`Lanes`] of eight inputs but their buckets' first segments (`bucket` zero).
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn place(c: &Curve<'_, f64>, v: __m512d) -> Lanes {
    let (xs, buckets) = (c.x(), c.bucket_starts());
    let (x0, xl) = (_mm512_set1_pd(xs[0]), _mm512_set1_pd(xs[xs.len() - 1]));
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
    Lanes {
        nan,
        lo,
        hi,
        inside,
        vin,
        b,
        bucket: _mm256_setzero_si256(),
    }
}

/// The curve's tables for [`at_n`], and whether its lanes read them by loads
/// ([`crate::simd::Lookup`]).
struct Tables<'a> {
    by_bucket: &'a [[f64; 2]],
    by_point: &'a [[f64; 4]],
    loads: bool,
}

/// `Curve::at` per lane (`super::avx2::at`), walking from the bucket's start.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn at_walk(c: &Curve<'_, f64>, v: __m512d) -> __m512d {
    let (xs, ys, slope) = (c.x(), c.y(), c.slopes());
    let last = xs.len() - 1;
    // SAFETY: AVX-512 (this function's features)
    let Lanes {
        nan,
        lo,
        hi,
        inside,
        vin,
        bucket,
        ..
    } = unsafe { lanes(c, v) };
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

#[cfg(test)]
mod tests {
    use crate::convert::{Converter, Curve};
    use crate::preisach::tests::Rng;
    use crate::simd::{Lookup, Path};

    /// The points' x of case `case`: up to 400, spaced at random, smoothly uneven (as a
    /// material curve), in clusters, or evenly from 0.5 (points on buckets' edges).
    fn points(rng: &mut Rng, case: usize) -> Vec<f64> {
        let points = 2 + (rng.next() % 400) as usize;
        let mut x = vec![if case % 4 == 3 { 0.5 } else { 2.0 + rng.unit() }];
        // even steps put points on buckets' edges: inputs an ulp below them step back
        let even = [0.1, 0.25, 0.3, 1.7][(rng.next() % 4) as usize];
        for k in 1..points {
            let gap = match case % 4 {
                3 => {
                    x.push(x[0] + k as f64 * even);
                    continue;
                }
                0 => 0.5 + rng.unit(),
                1 => 0.02 + (k as f64 / points as f64).powi(2),
                _ if rng.next().is_multiple_of(5) => 1e-3 * (0.01 + rng.unit()),
                _ => 0.5 + rng.unit(),
            };
            x.push(x[k - 1] + gap);
        }
        x
    }

    /// Curves of up to 400 points spaced at random, smoothly uneven (as a material curve), in
    /// clusters, or evenly (points on buckets' edges), readings inside them (most groups on
    /// the split path), on their points and splits, an ulp or two below their points (a step
    /// back), and a few beyond the ends or not numbers: the AVX-512 lanes give the scalar
    /// kernel's bits by either lookup of the curve's tables, and most groups took the split
    /// path (no lane with a NaN split).
    #[test]
    fn split_lanes_equal_the_scalar_kernel_bit_for_bit() {
        let _guard = crate::simd::testing::lock();
        if !crate::simd::avx512() {
            return; // nothing to compare on this processor
        }
        let mut rng = Rng(12);
        let (mut groups, mut split_groups) = (0, 0);
        for case in 0..300 {
            let x = points(&mut rng, case);
            let points = x.len();
            // values of any size and sign (a line through a point then rarely rounds to it)
            let y: Vec<f64> = x
                .iter()
                .map(|_| (rng.unit() - 0.3) * 10f64.powi((rng.next() % 6) as i32))
                .collect();
            let curve = Curve::new(x.clone(), y).unwrap();
            let n = 8 * (1 + (rng.next() % 24) as usize);
            let offset = vec![0.0; n];
            let gain = vec![1.0; n];
            let conv = Converter::new(offset, gain, Some(curve.clone())).unwrap();
            let view = conv.view();
            let (lo, hi) = (x[0], x[points - 1]);
            let readings: Vec<f64> = (0..n)
                .map(|_| match rng.next() % 40 {
                    0 => x[(rng.next() % points as u64) as usize],
                    // an ulp or two below a point (rounded into the bucket above its own)
                    m @ 3..=29 if m <= 5 || case % 4 == 3 => {
                        let p = x[(rng.next() % points as u64) as usize];
                        f64::from_bits(p.to_bits() - rng.next() % 3)
                    }
                    1 => curve.split((rng.next() % curve.lane_tables().0.len() as u64) as usize),
                    2 if case % 7 == 0 => [f64::NAN, lo - 1.0, hi + 1.0][(rng.next() % 3) as usize],
                    _ => lo + (hi - lo) * rng.unit(),
                })
                .map(|v| {
                    if v.is_infinite() {
                        lo + 0.5 * (hi - lo)
                    } else {
                        v
                    }
                })
                .collect();
            let ok = vec![true; n];
            // which groups go the split way: no lane's bucket with a NaN split
            let c = curve.view();
            let top = (c.bucket_starts().len() - 1) as f64;
            for g in readings.chunks_exact(8) {
                groups += 1;
                let walk = g.iter().any(|&v| {
                    let inside = v > lo && v < hi;
                    let b = ((v - lo) * c.inv_width()).min(top) as usize;
                    inside && curve.split(b).is_nan()
                });
                split_groups += usize::from(!walk);
            }
            let run = |best: Path| {
                crate::simd::set_limit(best);
                let mut out = vec![0.0; n];
                view.row(0, &readings, &ok, &mut out);
                crate::simd::set_enabled(true);
                out.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            };
            let scalar = run(Path::Scalar);
            // the curve's tables read by either lookup
            for lookup in Lookup::ALL {
                crate::simd::set_lookup(Some(lookup));
                let simd = run(Path::Avx512);
                crate::simd::set_lookup(None);
                assert_eq!(scalar, simd, "case {case}, {}", lookup.name());
            }
        }
        assert!(
            split_groups * 2 > groups,
            "{split_groups} of {groups} groups on the split path"
        );
    }
}
