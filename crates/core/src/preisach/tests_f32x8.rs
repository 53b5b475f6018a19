//! The float32 lanes against the scalar kernel in float32 (bit for bit) and in float64
//! (within the stated bound).

use proptest::prelude::*;
use texsense_kernels::preisach::{self as kernel, Head, Output, FORGOT};

use super::{Bank32, ROOM};
use crate::preisach::tests::{hostile_history, random_everett, Rng};
use crate::preisach::Everett;

/// Outputs of the scalar kernel in `T` on one plain stack per element (room [`ROOM`]),
/// as f64, with each element's clamping count and whether its stack forgot a loop.
fn kernel_run<T: texsense_kernels::real::Real>(
    e: &Everett,
    out_map: (f64, f64),
    u: &[f64],
    ok: &[bool],
    n: usize,
) -> (Vec<f64>, Vec<u64>, Vec<bool>) {
    let table: Vec<T> = e.table.iter().map(|&v| T::from_f64(v)).collect();
    let (lo, hi) = (T::from_f64(e.u_min), T::from_f64(e.u_max));
    let view = texsense_kernels::everett::Everett::new(e.k, lo, hi, &table).unwrap();
    let output = Output {
        offset: T::from_f64(out_map.0),
        sign: T::from_f64(out_map.1),
    };
    let t = u.len() / n;
    let mut want = vec![0.0; t * n];
    let (mut clamped, mut forgot) = (vec![0; n], vec![false; n]);
    for i in 0..n {
        let mut head = Head::new(lo);
        let mut stack = vec![[T::ZERO; 2]; ROOM + 1];
        kernel::start(&mut head, &mut stack, lo);
        for r in 0..t {
            let x = T::from_f64(u[r * n + i]);
            want[r * n + i] = if ok[r * n + i] && x.is_finite() {
                let (h, flags) = kernel::step(&mut head, &mut stack, ROOM, &view, x);
                clamped[i] += u64::from(flags & kernel::CLAMPED != 0);
                forgot[i] |= flags & FORGOT != 0;
                output.of(h).to_f64()
            } else {
                f64::NAN
            };
        }
    }
    (want, clamped, forgot)
}

fn bank_run(bank: &mut Bank32, u: &[f64], ok: &[bool]) -> Vec<f64> {
    let n = bank.len();
    let mut got = vec![0.0; u.len()];
    for ((f, v), o) in u
        .chunks_exact(n)
        .zip(ok.chunks_exact(n))
        .zip(got.chunks_exact_mut(n))
    {
        bank.row(f, v, o);
    }
    got
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn f32_lanes_equal_the_f32_kernel_bit_for_bit(
        seed in any::<u64>(),
        n in 1usize..60,
        t in 1usize..90,
        k in 2usize..40,
        sign in prop::sample::select(vec![1.0f64, -1.0]),
        simd in any::<bool>(),
    ) {
        let _guard = crate::simd::testing::lock();
        let mut rng = Rng(seed);
        let lo = if seed % 4 == 0 { 0.0 } else { -0.3 + rng.unit() };
        let hi = 1.0 + 2.0 * rng.unit();
        let e = random_everett(&mut rng, k, lo, hi);
        let offset = rng.unit() - 0.5;
        let (u, ok) = hostile_history(&mut rng, t, n, lo, hi);
        let (want, clamped, _) = kernel_run::<f32>(&e, (offset, sign), &u, &ok, n);
        crate::simd::set_enabled(simd);
        let mut bank = Bank32::new(&e, n).and_then(|b| b.with_output(offset, sign)).unwrap();
        let got = bank_run(&mut bank, &u, &ok);
        crate::simd::set_enabled(true);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        prop_assert!(bits(&got) == bits(&want), "outputs differ");
        prop_assert_eq!(bank.clamped(), clamped);
    }

    #[test]
    fn f32_lanes_stay_within_the_bound_of_the_f64_kernel(
        seed in any::<u64>(),
        n in 1usize..40,
        t in 1usize..200,
        k in 2usize..120,
    ) {
        // valid inputs in the range (a random walk, repeats, the ends); the bound is
        // |y32 - y64| <= 2^-24 (2 D + 1) F_max (8 G + 8): D the stack's depth (at most
        // ROOM), F_max the table's largest |entry|, G = (|u_min| + |u_max|) (K - 1) /
        // (u_max - u_min) the largest grid position an input's rounding reaches
        let _guard = crate::simd::testing::lock();
        let mut rng = Rng(seed);
        let lo = -1.0 + 2.0 * rng.unit();
        let hi = lo + 0.1 + 4.0 * rng.unit();
        let e = random_everett(&mut rng, k, lo, hi);
        let mut x: Vec<f64> = (0..n).map(|_| lo + rng.unit() * (hi - lo)).collect();
        let mut u = Vec::with_capacity(t * n);
        for _ in 0..t {
            for xi in x.iter_mut() {
                match rng.next() % 10 {
                    0 => *xi = lo,
                    1 => *xi = hi,
                    2 => {}
                    _ => *xi = (*xi + (rng.unit() - 0.5) * 0.4 * (hi - lo)).clamp(lo, hi),
                }
                u.push(*xi);
            }
        }
        let ok = vec![true; t * n];
        let (want, _, forgot) = kernel_run::<f64>(&e, (0.0, 1.0), &u, &ok, n);
        let mut bank = Bank32::new(&e, n).unwrap();
        let got = bank_run(&mut bank, &u, &ok);
        let f_max = e.table.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let g = (lo.abs() + hi.abs()) * (k - 1) as f64 / (hi - lo);
        let tol = (2.0 * ROOM as f64 + 1.0) * f_max * (8.0 * g + 8.0) / (1u64 << 24) as f64;
        for i in (0..n).filter(|&i| !forgot[i]) {
            for r in 0..t {
                let (a, b) = (got[r * n + i], want[r * n + i]);
                prop_assert!((a - b).abs() <= tol, "{a} vs {b}: {} > {tol}", (a - b).abs());
            }
        }
    }
}
