//! The drift step of eq. 5.8 (time clock, linear level) in float32, eight elements in the
//! lanes of one AVX2 register (issue 34, seventh round): an **experimental bank** that
//! measures what float32 lanes give; no pipeline uses it (`examples/drift_time.rs` times it
//! beside the float64 bank).
//!
//! Its numbers are those of the scalar kernel in float32
//! (`texsense_kernels::drift::step::<f32>`) bit for bit: the states of eight elements term
//! after term (`[group][term][lane]`), the kernel's operations in the same order, no fused
//! multiply-adds. Against the float64 kernel they differ by float32's rounding of the level,
//! the kernel and the sums (the bound the test holds is stated there). An input counts as
//! a number when its float32 rounding is finite.

use texsense_kernels::drift::{self as kernel, Element, Settings};

use super::check_time_steps;
use crate::error::{check_len, CoreError};

/// Elements per group: the f32 lanes of an AVX2 register.
pub const WIDTH: usize = 8;

/// N elements of one drift kernel in float32 (see the module's text).
#[derive(Debug, Clone)]
pub struct Drift32 {
    weights: Vec<f32>,
    taus: Vec<f32>,
    gamma: f32,
    n: usize,
    elements: Vec<Element<f32>>,
    /// Term `j` of element `8 g + l` at `(g k + j) 8 + l`.
    z: Vec<f32>,
    decay: Vec<f32>,
}

impl Drift32 {
    /// N elements of the kernel `Σ_j c_j (1 - exp(-t / τ_j))` and factor γ, rounded to
    /// float32, on the time clock with the linear level (eq. 5.8 as printed).
    pub fn new(weights: &[f64], taus: &[f64], gamma: f64, n: usize) -> Result<Self, CoreError> {
        let w: Vec<f32> = weights.iter().map(|&v| v as f32).collect();
        let t: Vec<f32> = taus.iter().map(|&v| v as f32).collect();
        Settings::new(&w, &t, gamma as f32).map_err(|e| CoreError::Parameter {
            what: "drift",
            why: format!("{e:?} in float32"),
        })?;
        let k = w.len();
        Ok(Self {
            decay: vec![1.0; k],
            weights: w,
            taus: t,
            gamma: gamma as f32,
            n,
            elements: vec![Element::default(); n.div_ceil(WIDTH) * WIDTH],
            z: vec![0.0; n.div_ceil(WIDTH) * WIDTH * k],
        })
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.n
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Forget the history.
    pub fn reset(&mut self) {
        self.elements.fill(Element::default());
        self.z.fill(0.0);
    }

    /// A batch (T x N row-major) with time steps `dt` (T,), frame after frame.
    pub fn run(
        &mut self,
        dt: &[f64],
        h: &[f64],
        ok: &[bool],
        out: &mut [f64],
    ) -> Result<(), CoreError> {
        let n = self.n;
        check_time_steps(dt)?;
        check_len("h", h.len(), dt.len() * n)?;
        check_len("valid", ok.len(), dt.len() * n)?;
        check_len("out", out.len(), dt.len() * n)?;
        if n == 0 {
            return Ok(());
        }
        for (r, &d) in dt.iter().enumerate() {
            let at = r * n..(r + 1) * n;
            self.row(d, &h[at.clone()], &ok[at.clone()], &mut out[at]);
        }
        Ok(())
    }

    /// One frame `dt` s after the previous one: levels `h` (rounded to float32) and their
    /// validity -> outputs (NaN where invalid or not a number; time passes for every
    /// element's states); on AVX2 eight elements at a time.
    ///
    /// # Panics
    /// When a slice does not hold one value per element.
    pub fn row(&mut self, dt: f64, h: &[f64], ok: &[bool], out: &mut [f64]) {
        let n = self.n;
        assert!(h.len() == n && ok.len() == n && out.len() == n);
        let dt = dt as f32;
        kernel::frame(&mut self.decay, &self.taus, dt);
        #[cfg(target_arch = "x86_64")]
        let lanes = crate::simd::avx2();
        #[cfg(not(target_arch = "x86_64"))]
        let lanes = false;
        let whole = if lanes { n / WIDTH * WIDTH } else { 0 };
        let s = Settings::new(&self.weights, &self.taus, self.gamma).expect("checked by new");
        #[cfg(target_arch = "x86_64")]
        if whole > 0 {
            // SAFETY: AVX2 (detected); the slices hold n >= whole values, whole groups
            unsafe {
                avx2::groups(
                    &s,
                    &mut self.elements,
                    &mut self.z,
                    &self.decay,
                    &h[..whole],
                    &ok[..whole],
                    &mut out[..whole],
                )
            };
        }
        let k = self.weights.len();
        for i in whole..n {
            let at = (i / WIDTH * k) * WIDTH + i % WIDTH;
            let y = kernel::step_strided(
                &s,
                &mut self.elements[i],
                &mut self.z[at..],
                &mut [],
                WIDTH,
                &self.decay,
                dt,
                h[i] as f32,
                ok[i],
            );
            out[i] = f64::from(y);
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    use texsense_kernels::drift::{Element, Settings};

    use super::WIDTH;

    /// The eight elements' started flags (as lane masks), last levels and sums of steps.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn heads(els: &[Element<f32>]) -> (__m256i, __m256, __m256) {
        let started: [i32; WIDTH] = std::array::from_fn(|l| els[l].started as i32);
        let last: [f32; WIDTH] = std::array::from_fn(|l| els[l].last_h);
        let total: [f32; WIDTH] = std::array::from_fn(|l| els[l].total);
        let s = _mm256_loadu_si256(started.as_ptr().cast());
        (
            _mm256_cmpgt_epi32(s, _mm256_setzero_si256()),
            _mm256_loadu_ps(last.as_ptr()),
            _mm256_loadu_ps(total.as_ptr()),
        )
    }

    /// The live lanes' elements take their level and sum of steps.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn store_heads(els: &mut [Element<f32>], live: __m256, hv: __m256, total: __m256) {
        let mut totals = [0.0f32; WIDTH];
        let mut levels = [0.0f32; WIDTH];
        _mm256_storeu_ps(totals.as_mut_ptr(), total);
        _mm256_storeu_ps(levels.as_mut_ptr(), hv);
        let lives = _mm256_movemask_ps(live);
        for (l, el) in els.iter_mut().enumerate() {
            if lives >> l & 1 != 0 {
                el.started = 1;
                el.last_h = levels[l];
                el.total = totals[l];
            }
        }
    }

    /// Whole groups of eight: levels `h`, validity `ok` -> outputs `out`.
    ///
    /// # Safety
    /// The processor must have AVX2.
    ///
    /// # Panics
    /// When `h` is not whole groups, or a slice is shorter than the groups need.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn groups(
        s: &Settings<'_, f32>,
        elements: &mut [Element<f32>],
        z: &mut [f32],
        decay: &[f32],
        h: &[f64],
        ok: &[bool],
        out: &mut [f64],
    ) {
        let (n, k) = (h.len(), s.terms());
        assert!(n.is_multiple_of(WIDTH) && ok.len() == n && out.len() == n);
        assert!(elements.len() >= n && z.len() >= n * k && decay.len() == k);
        let w = s.weights();
        let wsum = _mm256_set1_ps(s.weight_sum());
        let gamma = _mm256_set1_ps(s.gamma());
        let zero = _mm256_setzero_ps();
        for g in 0..n / WIDTH {
            let at = g * WIDTH;
            let els: &mut [Element<f32>; WIDTH] = (&mut elements[at..at + WIDTH])
                .try_into()
                .expect("a whole group");
            let p = h.as_ptr().add(at);
            let lo = _mm256_cvtpd_ps(_mm256_loadu_pd(p));
            let hi = _mm256_cvtpd_ps(_mm256_loadu_pd(p.add(4)));
            let hv = _mm256_set_m128(hi, lo);
            let okg: &[bool; WIDTH] = ok[at..at + WIDTH].try_into().expect("a whole group");
            let bytes = u64::from_le_bytes(okg.map(u8::from));
            let ok_m = _mm256_cmpgt_epi32(
                _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(bytes as i64)),
                _mm256_setzero_si256(),
            );
            let finite = _mm256_cmp_ps::<_CMP_EQ_OQ>(_mm256_sub_ps(hv, hv), zero);
            let live = _mm256_and_ps(_mm256_castsi256_ps(ok_m), finite);
            let (started, last, total) = heads(els);
            let change =
                _mm256_blendv_ps(hv, _mm256_sub_ps(hv, last), _mm256_castsi256_ps(started));
            let total = _mm256_add_ps(total, change);
            // z d + change (live) or z d + -0 (time passes: the same value as z d)
            let cm = _mm256_blendv_ps(_mm256_set1_ps(-0.0), change, live);
            let zp = z.as_mut_ptr().add(at * k);
            let term = |j: usize| {
                // SAFETY: term j of the group: zp[8 j .. 8 j + 8] (z holds 8 k a group;
                // j < k = decay.len() = w.len(), checked above)
                unsafe {
                    let q = zp.add(WIDTH * j);
                    let zd =
                        _mm256_mul_ps(_mm256_loadu_ps(q), _mm256_set1_ps(*decay.get_unchecked(j)));
                    let zn = _mm256_add_ps(zd, cm);
                    _mm256_storeu_ps(q, zn);
                    _mm256_mul_ps(_mm256_set1_ps(*w.get_unchecked(j)), zn)
                }
            };
            let (mut a0, mut a1, mut a2, mut a3) = (zero, zero, zero, zero);
            let whole = k / 4 * 4;
            for j in (0..whole).step_by(4) {
                a0 = _mm256_add_ps(a0, term(j));
                a1 = _mm256_add_ps(a1, term(j + 1));
                a2 = _mm256_add_ps(a2, term(j + 2));
                a3 = _mm256_add_ps(a3, term(j + 3));
            }
            let mut tail = zero;
            for j in whole..k {
                tail = _mm256_add_ps(tail, term(j));
            }
            let weighted = _mm256_add_ps(
                _mm256_add_ps(_mm256_add_ps(a0, a1), _mm256_add_ps(a2, a3)),
                tail,
            );
            let drift = _mm256_sub_ps(_mm256_mul_ps(total, wsum), weighted);
            let y = _mm256_add_ps(hv, _mm256_mul_ps(gamma, drift));
            let y = _mm256_blendv_ps(_mm256_set1_ps(f32::NAN), y, live);
            let o = out.as_mut_ptr().add(at);
            _mm256_storeu_pd(o, _mm256_cvtps_pd(_mm256_castps256_ps128(y)));
            _mm256_storeu_pd(o.add(4), _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(y)));
            store_heads(els, live, hv, total);
        }
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use texsense_kernels::drift::{self as kernel, Element, Settings};

    use super::Drift32;
    use crate::preisach::tests::Rng;

    /// The scalar kernel in `T`, one element after the other on its own states.
    fn kernel_run<T: texsense_kernels::real::Real>(
        w: &[f64],
        taus: &[f64],
        gamma: f64,
        dt: &[f64],
        h: &[f64],
        ok: &[bool],
        n: usize,
    ) -> Vec<f64> {
        let w: Vec<T> = w.iter().map(|&v| T::from_f64(v)).collect();
        let taus: Vec<T> = taus.iter().map(|&v| T::from_f64(v)).collect();
        let s = Settings::new(&w, &taus, T::from_f64(gamma)).unwrap();
        let mut decay = vec![T::ONE; w.len()];
        let mut out = vec![0.0; h.len()];
        let mut els = vec![Element::<T>::default(); n];
        let mut z = vec![T::ZERO; n * w.len()];
        for (r, &d) in dt.iter().enumerate() {
            kernel::frame(&mut decay, &taus, T::from_f64(d));
            for i in 0..n {
                let zi = &mut z[i * w.len()..(i + 1) * w.len()];
                let (x, v) = (T::from_f64(h[r * n + i]), ok[r * n + i]);
                let y = kernel::step(&s, &mut els[i], zi, &mut [], &decay, T::from_f64(d), x, v);
                out[r * n + i] = y.to_f64();
            }
        }
        out
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        #[test]
        fn f32_drift_lanes_equal_the_f32_kernel_and_stay_near_f64(
            seed in any::<u64>(),
            n in 1usize..40,
            t in 1usize..120,
            k in 1usize..18,
            simd in any::<bool>(),
        ) {
            let _guard = crate::simd::testing::lock();
            let mut rng = Rng(seed);
            let w: Vec<f64> = (0..k).map(|_| rng.unit()).collect();
            let taus: Vec<f64> = (0..k).map(|_| 0.5 + 500.0 * rng.unit()).collect();
            let gamma = (rng.unit() - 0.5) * 0.1;
            let dt: Vec<f64> = (0..t)
                .map(|_| if rng.next().is_multiple_of(9) { 0.0 } else { 2.0 * rng.unit() })
                .collect();
            let mut x: Vec<f64> = (0..n).map(|_| 5.0 * rng.unit()).collect();
            let (mut h, mut ok) = (Vec::new(), Vec::new());
            for _ in 0..t {
                for xi in x.iter_mut() {
                    *xi = (*xi + rng.unit() - 0.5).clamp(0.0, 10.0);
                    h.push(match rng.next() % 30 {
                        0 => f64::NAN,
                        1 => f64::INFINITY,
                        _ => *xi,
                    });
                    ok.push(!rng.next().is_multiple_of(20));
                }
            }
            let want = kernel_run::<f32>(&w, &taus, gamma, &dt, &h, &ok, n);
            crate::simd::set_enabled(simd);
            let mut bank = Drift32::new(&w, &taus, gamma, n).unwrap();
            let mut got = vec![0.0; h.len()];
            for (r, &d) in dt.iter().enumerate() {
                let row = r * n..(r + 1) * n;
                bank.row(d, &h[row.clone()], &ok[row.clone()], &mut got[row]);
            }
            crate::simd::set_enabled(true);
            let bits = |v: &[f64]| v.iter().map(|y| y.to_bits()).collect::<Vec<_>>();
            prop_assert!(bits(&got) == bits(&want), "outputs differ");
            // against f64: |y32 - y64| <= 2^-24 (4 H + 8 |γ| W H (T + K + 4)), H the
            // largest level, W = Σ c_j (float32's rounding of the level and of the sums)
            let exact = kernel_run::<f64>(&w, &taus, gamma, &dt, &h, &ok, n);
            let (big, wsum) = (10.0, w.iter().sum::<f64>());
            let tol = (4.0 * big + 8.0 * gamma.abs() * wsum * big * (t + k + 4) as f64)
                / (1u64 << 24) as f64;
            for (a, b) in got.iter().zip(&exact) {
                prop_assert!(a.is_nan() == b.is_nan());
                prop_assert!(a.is_nan() || (a - b).abs() <= tol, "{a} vs {b} > {tol}");
            }
        }
    }
}
