//! Tests of the preisach module.

use super::*;
use crate::simd::{Lookup, Path};
use proptest::prelude::*;

/// The Everett function of a uniform (non-negative) Preisach density: F = (α - β)² / 2.
fn uniform(k: usize) -> Everett {
    let mut t = vec![0.0; k * k];
    let h = 1.0 / (k - 1) as f64;
    for i in 0..k {
        for j in 0..i {
            let d = (i - j) as f64 * h;
            t[i * k + j] = 0.5 * d * d;
        }
    }
    Everett::new(k, 0.0, 1.0, t).unwrap()
}

fn run1(bank: &mut PreisachBank, path: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; path.len()];
    bank.run(path, &vec![true; path.len()], &mut out).unwrap();
    out
}

#[test]
fn major_loop_of_a_uniform_density() {
    let mut bank = PreisachBank::new(uniform(101), 1, 64).unwrap();
    let out = run1(&mut bank, &[0.5, 1.0, 0.5, 0.0]);
    // rising from saturation: 2 F(u, 0) = u²
    assert!((out[0] - 0.25).abs() < 1e-12);
    assert!((out[1] - 1.0).abs() < 1e-12);
    // falling from 1: 1 - 2 F(1, u) = 1 - (1 - u)²
    assert!((out[2] - 0.75).abs() < 1e-12);
    assert!(out[3].abs() < 1e-12);
    assert_eq!(bank.depth()[0], 1);
}

#[test]
fn clamping_nan_and_invalid() {
    let mut bank = PreisachBank::new(uniform(11), 2, 8).unwrap();
    let mut out = [0.0; 2];
    bank.step(&[2.0, 0.5], &[true, true], &mut out).unwrap();
    assert_eq!(bank.clamped(), &[1, 0]);
    assert!((out[0] - 1.0).abs() < 1e-12);
    bank.step(&[f64::NAN, 0.2], &[true, false], &mut out)
        .unwrap();
    assert!(out[0].is_nan() && out[1].is_nan());
    // state untouched: continuing gives the same as if the NaN frame had not happened
    bank.step(&[0.5, 0.5], &[true, true], &mut out).unwrap();
    assert!((out[1] - 0.25).abs() < 1e-12);
}

#[test]
fn set_state_hits_the_target_between_the_branches() {
    let mut bank = PreisachBank::new(uniform(201), 1, 16).unwrap();
    // at u = 0.5 the rising branch gives 0.25 and the falling major branch 0.75
    for target in [0.3, 0.5, 0.74] {
        let got = bank.set_state(0, 0.5, target);
        assert!((got - target).abs() < 1e-9, "{got} vs {target}");
    }
    assert!((bank.set_state(0, 0.5, 0.1) - 0.25).abs() < 1e-12); // below: clamped
    assert!((bank.set_state(0, 0.5, 0.9) - 0.75).abs() < 1e-9); // above: clamped
}

#[test]
fn capacity_policy_forgets_the_innermost_loop() {
    let mut bank = PreisachBank::new(uniform(101), 1, 4).unwrap();
    // ever-shrinking oscillation: 1, 0, 0.9, 0.1, 0.8, 0.2, ...
    let path: Vec<f64> = (0..12)
        .map(|k| {
            let a = 0.05 * (k / 2) as f64;
            if k % 2 == 0 {
                1.0 - a
            } else {
                a
            }
        })
        .collect();
    let out = run1(&mut bank, &path);
    assert!(bank.forgotten()[0] > 0);
    assert!(bank.depth()[0] <= 4);
    assert!(out.iter().all(|v| v.is_finite()));
}

fn arb_path() -> impl Strategy<Value = Vec<f64>> {
    proptest::collection::vec(0.0f64..1.0, 1..60)
}

proptest! {
    #[test]
    fn streaming_equals_batch(path in arb_path()) {
        let mut a = PreisachBank::new(uniform(51), 1, 256).unwrap();
        let batch = run1(&mut a, &path);
        let mut b = PreisachBank::new(uniform(51), 1, 256).unwrap();
        let mut o = [0.0];
        for (k, &u) in path.iter().enumerate() {
            b.step(&[u], &[true], &mut o).unwrap();
            prop_assert_eq!(o[0].to_bits(), batch[k].to_bits());
        }
    }

    #[test]
    fn return_point_memory(path in arb_path(), lo in 0.0f64..0.5, span in 0.05f64..0.5) {
        // after any history, go to an extremum M, make a minor excursion inside
        // [m, M] and come back to M: the output at M is the same as before
        let mut bank = PreisachBank::new(uniform(51), 1, 256).unwrap();
        let mut hist = path.clone();
        let m = lo;
        let big = (lo + span).min(1.0);
        hist.push(0.0); // the extremum before `big`
        hist.push(big);
        let before = run1(&mut bank, &hist);
        let at_m = *before.last().unwrap();
        let after = run1(&mut bank, &[m, (m + big) / 2.0, m + 0.01 * span, big]);
        prop_assert!((after[3] - at_m).abs() < 1e-9);
    }

    #[test]
    fn wiping_out(path in arb_path()) {
        // any history inside [0, 1] is erased by going to 1 and back to a value:
        // the output equals that of a fresh model doing the same
        let mut bank = PreisachBank::new(uniform(51), 1, 256).unwrap();
        run1(&mut bank, &path);
        let a = run1(&mut bank, &[1.0, 0.3]);
        let mut fresh = PreisachBank::new(uniform(51), 1, 256).unwrap();
        let b = run1(&mut fresh, &[1.0, 0.3]);
        prop_assert!((a[1] - b[1]).abs() < 1e-12);
        prop_assert!(bank.depth()[0] == fresh.depth()[0]);
    }

    #[test]
    fn congruent_minor_loops(
        p1 in arb_path(), p2 in arb_path(), lo in 0.2f64..0.5, span in 0.05f64..0.3,
    ) {
        // minor loops between the same extrema, after different histories that stay
        // above lo + span, differ only by a constant
        let hi = lo + span;
        let lift = |p: &Vec<f64>| -> Vec<f64> { p.iter().map(|v| hi + v * (1.0 - hi)).collect() };
        let loop_path: Vec<f64> = (0..=20).map(|k| lo + span * (k as f64 / 20.0))
            .chain((0..=20).map(|k| hi - span * (k as f64 / 20.0))).collect();
        let mut a = PreisachBank::new(uniform(51), 1, 256).unwrap();
        let mut b = PreisachBank::new(uniform(51), 1, 256).unwrap();
        let mut ha = lift(&p1); ha.push(lo);
        let mut hb = lift(&p2); hb.push(lo);
        run1(&mut a, &ha);
        run1(&mut b, &hb);
        let la = run1(&mut a, &loop_path);
        let lb = run1(&mut b, &loop_path);
        let shift = la[0] - lb[0];
        for (x, y) in la.iter().zip(lb.iter()) {
            prop_assert!((x - y - shift).abs() < 1e-9);
        }
    }
}

proptest! {
    #[test]
    fn everett_terms_reproduce_the_bank(path in arb_path()) {
        let e = uniform(41);
        let mut bank = PreisachBank::new(e.clone(), 1, 256).unwrap();
        let out = run1(&mut bank, &path);
        let terms = everett_terms(&path, 0.0, 1.0).unwrap();
        prop_assert_eq!(terms.indptr.len(), path.len() + 1);
        for (t, h) in out.iter().enumerate() {
            let r = terms.indptr[t]..terms.indptr[t + 1];
            let sum: f64 = r
                .map(|q| terms.coef[q] * e.value(terms.alpha[q], terms.beta[q]))
                .sum();
            prop_assert!((sum - h).abs() < 1e-9, "sample {}: {} vs {}", t, sum, h);
        }
    }
}

/// A decaying oscillation nests `2 * turns` extrema: deeper than the in-place stack.
fn nested(turns: usize, wobble: f64) -> Vec<f64> {
    let mut path = Vec::new();
    for k in 0..turns {
        let a = 0.45 * (1.0 - k as f64 / turns as f64);
        path.push(0.5 + a + wobble * (k % 3) as f64);
        path.push(0.5 - a + 0.5 * wobble * (k % 2) as f64);
    }
    // and unwind them again, wiping out level after level
    path.extend([0.97, 0.02, 0.6, 0.4, 0.55]);
    path
}

#[test]
fn deep_stacks_move_to_the_heap_and_back_without_changing_the_output() {
    let e = uniform(41);
    let path = nested(30, 1e-3);
    let mut bank = PreisachBank::new(e.clone(), 1, 256).unwrap();
    let before = bank.state_bytes();
    let mut deepest = 0;
    let mut out = Vec::new();
    for &u in &path {
        let mut o = [0.0];
        bank.step(&[u], &[true], &mut o).unwrap();
        out.push(o[0]);
        deepest = deepest.max(bank.depth()[0]);
        if bank.depth()[0] > INLINE_EXTREMA {
            assert!(
                bank.state_bytes() > before,
                "a deep stack lives on the heap"
            );
            // the heads' bit for a stack on the heap is not part of the counter
            assert_eq!(bank.clamped(), [0]);
            let mut w = Writer::default();
            bank.save(&mut w);
            let mut copy = PreisachBank::new(e.clone(), 1, 256).unwrap();
            copy.load(&mut Reader::new(&w.buf)).unwrap();
            assert_eq!(copy.clamped(), [0]);
        }
    }
    assert!(
        deepest > INLINE_EXTREMA + 20,
        "the path nests {deepest} extrema"
    );
    assert_eq!(bank.state_bytes(), before, "back in place once shallow");
    assert_eq!(bank.forgotten()[0], 0);
    let terms = everett_terms(&path, 0.0, 1.0).unwrap();
    for (t, h) in out.iter().enumerate() {
        let sum: f64 = (terms.indptr[t]..terms.indptr[t + 1])
            .map(|q| terms.coef[q] * e.value(terms.alpha[q], terms.beta[q]))
            .sum();
        assert!((sum - h).abs() < 1e-9, "sample {t}: {sum} vs {h}");
    }
}

/// Frame after frame of `u` and `ok` (frames of the bank's elements) through a copy of `bank`
/// on the scalar kernel and one on the best SIMD path, in `schedule`: the same outputs and
/// states, and the same stacks on the heap (`state_bytes`), after every frame (asserted);
/// `each` sees the SIMD copy after every frame. Returns the scalar and the SIMD copy.
fn frames_against_scalar(
    bank: &PreisachBank,
    u: &[f64],
    ok: &[bool],
    schedule: Schedule,
    mut each: impl FnMut(&PreisachBank),
) -> (PreisachBank, PreisachBank) {
    let n = bank.len();
    let (mut a, mut b) = (bank.clone(), bank.clone());
    for (r, (x, v)) in u.chunks_exact(n).zip(ok.chunks_exact(n)).enumerate() {
        let step = |bank: &mut PreisachBank, path: Path| {
            crate::simd::set_limit(path);
            let mut out = vec![0.0; n];
            bank.run_scheduled(x, v, &mut out, schedule).unwrap();
            crate::simd::set_enabled(true);
            let mut w = Writer::default();
            bank.save(&mut w);
            let bits = out.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            (bits, w.buf, bank.state_bytes())
        };
        assert!(
            step(&mut a, Path::Scalar) == step(&mut b, Path::Avx512),
            "{schedule:?}, frame {r}: outputs, states or bytes on the heap differ"
        );
        each(&b);
    }
    (a, b)
}

/// Groups with stacks on the heap step side by side with their neighbours on the SIMD path
/// (issue 34, seventeenth round): three lanes of every group (other lanes in every group, so
/// that each of the eight places nests in some group) nest deeper than the in-place stack and
/// unwind again, the others walk; frame after frame and in blocks, the outputs, counters,
/// states and the stacks on the heap equal the scalar kernel's at every frame.
#[test]
fn stacks_on_the_heap_step_beside_other_groups_as_the_scalar_kernel() {
    let _guard = crate::simd::testing::lock();
    let e = uniform(41);
    let n = 48;
    let path = nested(30, 1e-3);
    let mut rng = Rng(7);
    let mut walk: Vec<f64> = (0..n).map(|_| rng.unit()).collect();
    let t = 2 * path.len();
    let mut u = Vec::with_capacity(t * n);
    for r in 0..t {
        for (i, w) in walk.iter_mut().enumerate() {
            u.push(if (i + i / 8) % 8 < 3 {
                path[(r + i) % path.len()] + 1e-4 * i as f64
            } else {
                *w = (*w + (rng.unit() - 0.5) * 0.1).clamp(0.0, 1.0);
                *w
            });
        }
    }
    let ok = vec![true; t * n];
    let bank = PreisachBank::new(e, n, 256).unwrap();
    for schedule in [Schedule::FrameOrder, Schedule::Blocks] {
        let mut deepest = 0;
        let (a, b) = frames_against_scalar(&bank, &u, &ok, schedule, |b| {
            deepest = deepest.max(*b.depth().iter().max().unwrap());
        });
        assert!(
            deepest > INLINE_EXTREMA + 10,
            "the deepest stack held {deepest}"
        );
        assert_eq!(a.state_bytes(), b.state_bytes());
    }
}

/// Groups whose lanes all hold still (the same input, an input clamped to the same end of the
/// range, a reading that is not a number or flagged invalid) take the SIMD path's short step
/// (issue 34, seventeenth round): the outputs, clamping counters and states equal the scalar
/// kernel's at every frame, also when the groups move again.
#[test]
fn groups_at_rest_step_as_the_scalar_kernel() {
    let _guard = crate::simd::testing::lock();
    let e = uniform(41);
    let (n, t) = (40, 90);
    let mut rng = Rng(5);
    let mut walk: Vec<f64> = (0..n).map(|_| rng.unit()).collect();
    let (mut u, mut ok) = (Vec::with_capacity(t * n), Vec::with_capacity(t * n));
    for r in 0..t {
        for (i, w) in walk.iter_mut().enumerate() {
            *w = (*w + (rng.unit() - 0.5) * 0.2).clamp(0.0, 1.0);
            // the first 24 elements (three groups) rest from frame 20 to 60: held, below or
            // above the range (clamped: counted every frame), NaN or flagged invalid
            let rest = i < 24 && (20..60).contains(&r);
            u.push(match (rest, i % 6) {
                (false, _) => *w,
                (true, 0) => -0.5,
                (true, 1) => 1.5,
                (true, 2) => f64::NAN,
                _ => 0.0, // held: set below
            });
            ok.push(!(rest && i % 6 == 5));
        }
        if (20..60).contains(&r) {
            // the held lanes keep one input over the rest
            for i in (0..24).filter(|i| i % 6 >= 3) {
                u[r * n + i] = 0.25 + 0.01 * i as f64;
            }
        }
    }
    let bank = PreisachBank::new(e, n, 64)
        .and_then(|b| b.with_output(0.1, -1.0))
        .unwrap();
    for schedule in [Schedule::FrameOrder, Schedule::Blocks] {
        let (a, b) = frames_against_scalar(&bank, &u, &ok, schedule, |_| {});
        assert_eq!(a.clamped(), b.clamped());
        assert!(
            b.clamped()[0] >= 40 && b.clamped()[1] >= 40,
            "{:?}",
            b.clamped()
        );
    }
}

#[test]
fn every_schedule_gives_the_same_outputs() {
    let e = uniform(41);
    let (n, t) = (3 * crate::par::MAX_BLOCK + 7, 120);
    let mut inputs = Vec::with_capacity(n * t);
    let mut valid = Vec::with_capacity(n * t);
    for r in 0..t {
        for i in 0..n {
            let x = (r as f64 * 0.37 + i as f64 * 0.11).sin() * (1.0 + (i % 5) as f64 * 0.1);
            inputs.push(0.5 + 0.45 * x * ((r * 7 + i) % 11) as f64 / 10.0);
            valid.push((r * 13 + i * 7) % 17 != 0);
        }
    }
    let mut reference = None;
    for schedule in [Schedule::FrameOrder, Schedule::Blocks, Schedule::Parallel] {
        let mut bank = PreisachBank::new(e.clone(), n, 16).unwrap();
        let mut out = vec![0.0; n * t];
        bank.run_scheduled(&inputs, &valid, &mut out, schedule)
            .unwrap();
        let bits: Vec<u64> = out.iter().map(|v| v.to_bits()).collect();
        match &reference {
            None => reference = Some((bits, bank.depth())),
            Some((r, d)) => {
                assert!(r == &bits, "{schedule:?} differs");
                assert_eq!(d, &bank.depth());
            }
        }
    }
}

#[test]
fn everett_terms_reject_nan_and_bad_ranges() {
    assert!(everett_terms(&[0.1, f64::NAN], 0.0, 1.0).is_err());
    assert!(everett_terms(&[0.1], 1.0, 1.0).is_err());
}

/// A small deterministic generator for the SIMD property tests (splitmix64).
pub(crate) struct Rng(pub(crate) u64);

impl Rng {
    pub(crate) fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub(crate) fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `t` frames of `n` elements over [lo, hi]: random walks, nested shrinking oscillations
/// (deep stacks: forgetting and the heap), repeats, values out of the range and at its ends,
/// -0.0, NaN, infinities and readings flagged invalid.
pub(crate) fn hostile_history(
    rng: &mut Rng,
    t: usize,
    n: usize,
    lo: f64,
    hi: f64,
) -> (Vec<f64>, Vec<bool>) {
    let span = hi - lo;
    let mut x: Vec<f64> = (0..n).map(|_| lo + rng.unit() * span).collect();
    let nested: Vec<bool> = (0..n).map(|_| rng.next().is_multiple_of(3)).collect();
    let (mut u, mut ok) = (Vec::with_capacity(t * n), Vec::with_capacity(t * n));
    for r in 0..t {
        for i in 0..n {
            let v = if nested[i] {
                let k = (r / 2) as f64;
                let amp = 0.5 * span * 0.93f64.powf(k);
                lo + 0.5 * span + if r % 2 == 0 { amp } else { -amp }
            } else {
                match rng.next() % 40 {
                    0 => f64::NAN,
                    1 => f64::INFINITY,
                    2 => f64::NEG_INFINITY,
                    3 => lo - rng.unit() * span,
                    4 => hi + rng.unit() * span,
                    5 => lo,
                    6 => hi,
                    7 => -0.0,
                    8..=11 => x[i], // the same input again
                    _ => {
                        x[i] = (x[i] + (rng.unit() - 0.5) * 0.3 * span).clamp(lo, hi);
                        x[i]
                    }
                }
            };
            u.push(v);
            ok.push(!rng.next().is_multiple_of(25));
        }
    }
    (u, ok)
}

/// A random Everett table over [lo, hi] (non-negative, not symmetric in any way).
pub(crate) fn random_everett(rng: &mut Rng, k: usize, lo: f64, hi: f64) -> Everett {
    let t: Vec<f64> = (0..k * k).map(|_| rng.unit() * 3.0).collect();
    Everett::new(k, lo, hi, t).unwrap()
}

/// Outputs, counters and the state's bytes of a bank after a batch (on the best path up
/// to `best`).
fn simd_run(
    best: Path,
    bank: &PreisachBank,
    u: &[f64],
    ok: &[bool],
    schedule: Schedule,
) -> (Vec<u64>, Vec<u64>, Vec<u64>, Vec<u8>) {
    crate::simd::set_limit(best);
    let mut b = bank.clone();
    let mut out = vec![0.0; u.len()];
    b.run_scheduled(u, ok, &mut out, schedule).unwrap();
    crate::simd::set_enabled(true);
    let mut w = Writer::default();
    b.save(&mut w);
    let bits = out.iter().map(|v| v.to_bits()).collect();
    (bits, b.clamped(), b.forgotten(), w.buf)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn simd_path_equals_the_scalar_kernel_bit_for_bit(
        seed in any::<u64>(),
        n in 1usize..70,
        t in 1usize..90,
        k in 2usize..40,
        capacity in prop::sample::select(vec![4usize, 5, 9, 13, 64]),
        sign in prop::sample::select(vec![1.0f64, -1.0]),
    ) {
        let _guard = crate::simd::testing::lock();
        let mut rng = Rng(seed);
        // a range from +0 in one case of four (an input of -0 is then below the range's
        // start by its sign alone)
        let lo = if seed % 4 == 0 { 0.0 } else { -0.3 + rng.unit() };
        let hi = 1.0 + 2.0 * rng.unit();
        let e = random_everett(&mut rng, k, lo, hi);
        // the SIMD path reads the table by cell, or gathers from it (large grids)
        let e = if seed % 3 == 0 { e.without_cells() } else { e };
        let bank = PreisachBank::new(e, n, capacity)
            .and_then(|b| b.with_output(rng.unit() - 0.5, sign))
            .unwrap();
        let (u, ok) = hostile_history(&mut rng, t, n, lo, hi);
        let scalar = simd_run(Path::Scalar, &bank, &u, &ok, Schedule::Blocks);
        // AVX2 forced (also on an AVX-512 processor), then the best path
        let avx2 = simd_run(Path::Avx2, &bank, &u, &ok, Schedule::Blocks);
        prop_assert!(scalar == avx2, "AVX2: outputs, counters or states differ");
        let simd = simd_run(Path::Avx512, &bank, &u, &ok, Schedule::Blocks);
        prop_assert!(scalar == simd, "best path: outputs, counters or states differ");
        // AVX-512's Everett corners by either lookup (the processor's is the run above)
        for lookup in Lookup::ALL {
            crate::simd::set_lookup(Some(lookup));
            let by = simd_run(Path::Avx512, &bank, &u, &ok, Schedule::Blocks);
            crate::simd::set_lookup(None);
            prop_assert!(scalar == by, "{}: outputs, counters or states differ", lookup.name());
        }
        // and both are the frame-order kernel's
        let frames = simd_run(Path::Scalar, &bank, &u, &ok, Schedule::FrameOrder);
        prop_assert!(frames == simd);
        prop_assert!(simd_run(Path::Avx512, &bank, &u, &ok, Schedule::FrameOrder) == simd);
    }
}

#[test]
fn the_lookup_is_loads_on_amd_processors_and_gathers_elsewhere() {
    let _guard = crate::simd::testing::lock();
    // the vendor as Linux reports it (the cpuid constants of `simd::detected_lookup`)
    if let Ok(info) = std::fs::read_to_string("/proc/cpuinfo") {
        let amd = info
            .lines()
            .any(|l| l.starts_with("vendor_id") && l.contains("AuthenticAMD"));
        let expected = if amd { Lookup::Loads } else { Lookup::Gather };
        assert_eq!(crate::simd::detected_lookup(), expected);
        assert_eq!(crate::simd::lookup(), expected);
    }
    crate::simd::set_lookup(Some(Lookup::Gather));
    assert_eq!(crate::simd::lookup(), Lookup::Gather);
    crate::simd::set_lookup(Some(Lookup::Loads));
    assert_eq!(crate::simd::lookup(), Lookup::Loads);
    crate::simd::set_lookup(None);
    assert_eq!(crate::simd::lookup(), crate::simd::detected_lookup());
}

#[test]
fn this_machine_runs_the_best_path_it_has() {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        assert!(crate::simd::detected() >= crate::simd::Path::Avx2);
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512dq")
        && std::arch::is_x86_feature_detected!("avx512vl")
    {
        assert_eq!(crate::simd::detected(), crate::simd::Path::Avx512);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn both_paths_equal_the_kernel_of_one_element(
        seed in any::<u64>(),
        n in 1usize..40,
        t in 1usize..90,
        capacity in prop::sample::select(vec![4usize, 7, 16, 64]),
    ) {
        // the bank (heads in groups of eight, stacks in place or on the heap) against the
        // microcontroller's kernel on one plain stack per element
        let _guard = crate::simd::testing::lock();
        let mut rng = Rng(seed);
        let (lo, hi) = (-0.5 + rng.unit(), 1.0 + rng.unit());
        let k = 2 + (rng.next() % 30) as usize;
        let e = random_everett(&mut rng, k, lo, hi);
        let (u, ok) = hostile_history(&mut rng, t, n, lo, hi);
        let view = e.view();
        let mut want = vec![0.0; t * n];
        for i in 0..n {
            let mut head = Head::new(lo);
            let mut stack = vec![[0.0; 2]; capacity + 1];
            kernel::start(&mut head, &mut stack, lo);
            for r in 0..t {
                let x = u[r * n + i];
                want[r * n + i] = if ok[r * n + i] && x.is_finite() {
                    kernel::step(&mut head, &mut stack, capacity, &view, x).0
                } else {
                    f64::NAN
                };
            }
        }
        let bank = PreisachBank::new(e.clone(), n, capacity).unwrap();
        let want: Vec<u64> = want.iter().map(|v| v.to_bits()).collect();
        for best in [Path::Scalar, Path::Avx2, Path::Avx512] {
            let (bits, _, _, _) = simd_run(best, &bank, &u, &ok, Schedule::FrameOrder);
            prop_assert!(bits == want, "{:?}: outputs differ from the kernel", best);
        }
    }
}
