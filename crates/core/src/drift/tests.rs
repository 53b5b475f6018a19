//! Tests of the drift module.

use super::*;
use crate::simd::Path;

fn log_kernel() -> Kernel {
    // a crude 2-per-decade approximation is enough for the exactness tests below,
    // which compare against the same kernel summed directly
    let taus: Vec<f64> = (0..14).map(|k| 0.1 * 10f64.powf(k as f64 / 2.0)).collect();
    Kernel::new(vec![0.4; 14], taus).unwrap()
}

#[test]
fn recursive_equals_direct_superposition() {
    let kernel = log_kernel();
    let mut bank = DriftBank::new(kernel.clone(), -0.025, 1).unwrap();
    let hs = [0.0, 2.0, 2.0, 5.0, 5.0, 1.0, 1.0, 1.0];
    let dts = [0.0, 1.0, 10.0, 3.0, 100.0, 7.0, 1000.0, 5000.0];
    let mut t = 0.0;
    let mut steps: Vec<(f64, f64)> = Vec::new();
    let mut prev = 0.0;
    let mut out = [0.0];
    for (&h, &dt) in hs.iter().zip(&dts) {
        t += dt;
        if h != prev {
            steps.push((t, h - prev));
            prev = h;
        }
        bank.step(dt, &[h], &[true], &mut out).unwrap();
        let direct: f64 = h - 0.025
            * steps
                .iter()
                .map(|(ti, dh)| dh * kernel.value(t - ti))
                .sum::<f64>();
        assert!((out[0] - direct).abs() < 1e-12, "{} vs {direct}", out[0]);
    }
}

#[test]
fn linear_in_the_steps_and_invalid_keeps_state() {
    let mut a = DriftBank::new(log_kernel(), -0.025, 2).unwrap();
    let mut out = [0.0; 2];
    a.step(0.0, &[1.0, 2.0], &[true, true], &mut out).unwrap();
    a.step(100.0, &[1.0, 2.0], &[true, true], &mut out).unwrap();
    // doubling the steps doubles the drift
    assert!(((out[1] - 2.0) - 2.0 * (out[0] - 1.0)).abs() < 1e-12);
    a.step(10.0, &[f64::NAN, 2.0], &[true, false], &mut out)
        .unwrap();
    assert!(out[0].is_nan() && out[1].is_nan());
    assert!(Kernel::new(vec![-1.0], vec![1.0]).is_err());
    assert!(DriftBank::new(log_kernel(), f64::NAN, 1).is_err());
    assert!(a.step(-1.0, &[1.0, 1.0], &[true, true], &mut out).is_err());
}

#[test]
fn exponent_superposes_the_powered_level() {
    // q = 2: the drift of a held level h is that of a held level h² with q = 1
    let (h, q) = (1.5_f64, 2.0);
    let mut powered = DriftBank::new(log_kernel(), -0.025, 1)
        .unwrap()
        .with_exponent(q)
        .unwrap();
    let mut linear = DriftBank::new(log_kernel(), -0.025, 1).unwrap();
    let (mut a, mut b) = ([0.0], [0.0]);
    for dt in [0.0, 1.0, 10.0, 100.0] {
        powered.step(dt, &[h], &[true], &mut a).unwrap();
        linear.step(dt, &[h.powf(q)], &[true], &mut b).unwrap();
        assert!(((a[0] - h) - (b[0] - h.powf(q))).abs() < 1e-12);
    }
    assert!((a[0] - h).abs() > 1e-3, "a held level drifts");
    // below zero the level is 0: no drift from a negative reading
    let mut neg = DriftBank::new(log_kernel(), -0.025, 1)
        .unwrap()
        .with_exponent(q)
        .unwrap();
    neg.step(0.0, &[-0.3], &[true], &mut a).unwrap();
    neg.step(100.0, &[-0.3], &[true], &mut a).unwrap();
    assert_eq!(a[0], -0.3);
    for bad in [0.0, -1.0, f64::NAN, 9.0] {
        assert!(DriftBank::new(log_kernel(), -0.025, 1)
            .unwrap()
            .with_exponent(bad)
            .is_err());
    }
}

/// The drift (output - input) at the end of `path` ((dt, h) pairs) for one element.
fn final_drift(kernel: Kernel, rest: f64, path: &[(f64, f64)]) -> f64 {
    let mut b = DriftBank::new(kernel, -0.025, 1)
        .unwrap()
        .with_rest_rate(rest, 2.0)
        .unwrap();
    let mut out = [0.0];
    for &(dt, h) in path {
        b.step(dt, &[h], &[true], &mut out).unwrap();
    }
    out[0] - path.last().unwrap().1
}

#[test]
fn rest_clock_runs_at_rest_and_stops_while_moving() {
    let run = |rest: f64, path: &[(f64, f64)]| final_drift(log_kernel(), rest, path);
    // a step then a long hold: the clock is slowed for a few windows after the step,
    // then runs with time, so after 1000 s the two clocks differ by a few seconds' worth
    let hold: Vec<(f64, f64)> = [(0.0, 0.0), (1e-3, 2.0)]
        .into_iter()
        .chain((0..1000).map(|_| (1.0, 2.0)))
        .collect();
    let (time, rest) = (run(0.0, &hold), run(0.1, &hold));
    assert!(
        rest < 0.0 && (time - rest).abs() < 0.05 * time.abs(),
        "{time} vs {rest}"
    );
    // a steady triangle wave at 10 units/s: the rest clock is the time clock run with every
    // step slowed by the averaged velocity v, dt / (1 + |v| / rest_rate)
    let wave: Vec<(f64, f64)> = (0..4000)
        .map(|k| {
            let x = (k % 200) as f64;
            (0.1, if (k / 200) % 2 == 0 { x } else { 200.0 - x })
        })
        .collect();
    let (mut v, mut prev) = (0.0, 0.0);
    let slowed: Vec<(f64, f64)> = wave
        .iter()
        .map(|&(dt, h)| {
            let d: f64 = if dt > 0.0 {
                v += ((h - prev) / dt - v) * (1.0 - (-dt / 2.0f64).exp());
                dt / (1.0 + v.abs() / 0.1)
            } else {
                dt
            };
            prev = h;
            (d, h)
        })
        .collect();
    let (wr, ws) = (run(0.1, &wave), run(0.0, &slowed));
    assert!((wr - ws).abs() < 1e-9, "rest {wr} vs slowed time {ws}");
    // with a kernel of slow terms (10 s .. 10^6 s) the moving element hardly drifts
    let slow = |rest: f64, path: &[(f64, f64)]| {
        let taus: Vec<f64> = (2..13).map(|k| 10f64.powf(k as f64 / 2.0)).collect();
        final_drift(Kernel::new(vec![0.4; 11], taus).unwrap(), rest, path)
    };
    let (st, sr) = (slow(0.0, &wave), slow(0.1, &wave));
    assert!(sr.abs() < 0.3 * st.abs(), "rest {sr} vs time {st}");
    // noise on a hold does not stop the clock
    let noisy: Vec<(f64, f64)> = hold
        .iter()
        .enumerate()
        .map(|(k, &(dt, h))| {
            (
                dt,
                if k > 1 {
                    h + 0.002 * ((k * 7919 % 13) as f64 - 6.0) / 6.0
                } else {
                    h
                },
            )
        })
        .collect();
    let rn = run(0.1, &noisy);
    assert!(
        (rn - rest).abs() < 0.05 * rest.abs(),
        "noisy {rn} vs clean {rest}"
    );
    let b = DriftBank::new(log_kernel(), -0.025, 1).unwrap();
    assert!(b.clone().with_rest_rate(-1.0, 2.0).is_err());
    assert!(b.with_rest_rate(0.1, 0.0).is_err());
}

#[test]
fn two_clocks_add_the_two_superpositions() {
    let path: Vec<(f64, f64)> = (0..600)
        .map(|k| {
            (
                0.5,
                if (k / 40) % 3 == 0 {
                    2.0
                } else {
                    (k % 17) as f64 * 0.3
                },
            )
        })
        .collect();
    let run = |bank: DriftBank| {
        let mut b = bank;
        let mut out = [0.0];
        path.iter()
            .map(|&(dt, h)| {
                b.step(dt, &[h], &[true], &mut out).unwrap();
                out[0] - h
            })
            .collect::<Vec<f64>>()
    };
    let base = || DriftBank::new(log_kernel(), -0.02, 1).unwrap();
    let rest = run(base().with_rest_rate(0.1, 0.5).unwrap());
    let time = run(DriftBank::new(log_kernel(), -0.01, 1).unwrap());
    let both = run(base()
        .with_rest_rate(0.1, 0.5)
        .unwrap()
        .with_time_component(-0.01)
        .unwrap());
    for k in 0..path.len() {
        assert!((both[k] - rest[k] - time[k]).abs() < 1e-12, "sample {k}");
    }
    assert!(base().with_time_component(f64::NAN).is_err());
}

/// Outputs and state bytes of a batch of a bank on the best path up to `best`.
fn on_path(best: Path, bank: &DriftBank, dt: &[f64], h: &[f64], ok: &[bool]) -> Vec<u8> {
    crate::simd::set_limit(best);
    let mut b = bank.clone();
    let mut out = vec![0.0; h.len()];
    b.run(dt, h, ok, &mut out).unwrap();
    crate::simd::set_enabled(true);
    let mut w = Writer::default();
    b.save(&mut w);
    out.iter()
        .flat_map(|v| v.to_le_bytes())
        .chain(w.buf)
        .collect()
}

#[test]
fn the_avx2_and_avx512_builds_of_the_kernel_equal_the_scalar_one_bit_for_bit() {
    let _guard = crate::simd::testing::lock();
    let mut rng = crate::preisach::tests::Rng(7);
    // cases 24.. on the time clock with the linear level (the path across elements in
    // groups of four): 3 ..= 14 terms, whole fours and tails
    for case in 0..36 {
        let terms = if case < 24 { 1 + case % 17 } else { case - 21 };
        let weights: Vec<f64> = (0..terms).map(|_| rng.unit()).collect();
        let taus: Vec<f64> = (0..terms).map(|_| 0.01 + 100.0 * rng.unit()).collect();
        // n from 1: pairs of groups, a lone group and a scalar tail
        let n = 1 + (rng.next() % 70) as usize;
        let t = 1 + (rng.next() % 60) as usize;
        let mut bank = DriftBank::new(Kernel::new(weights, taus).unwrap(), -0.03, n).unwrap();
        if case % 3 >= 1 && case < 24 {
            bank = bank.with_rest_rate(0.5, 0.4).unwrap();
        }
        if case % 3 == 2 {
            bank = bank.with_time_component(0.01).unwrap();
        }
        if case % 4 == 3 && case < 24 {
            bank = bank.with_exponent(1.7).unwrap();
        }
        let (h, ok) = crate::preisach::tests::hostile_history(&mut rng, t, n, -1.0, 4.0);
        let dt: Vec<f64> = (0..t)
            .map(|r| if r % 7 == 3 { 0.0 } else { 2.0 * rng.unit() })
            .collect();
        let scalar = on_path(Path::Scalar, &bank, &dt, &h, &ok);
        // AVX2 forced, then the best path (AVX-512 on a processor that has it)
        for best in [Path::Avx2, Path::Avx512] {
            let got = on_path(best, &bank, &dt, &h, &ok);
            assert!(got == scalar, "case {case}, {best:?}");
        }
    }
}

#[test]
fn grouped_states_each_element_as_on_its_own_and_snapshots_element_major() {
    // the states of groups of four elements share vectors: every element of a bank must
    // still give what a bank of that element alone gives, on both paths, and a snapshot
    // must hold each element's K states together (the format of one element per bank)
    let _guard = crate::simd::testing::lock();
    let mut rng = crate::preisach::tests::Rng(5);
    let weights: Vec<f64> = (0..14).map(|_| rng.unit()).collect();
    let taus: Vec<f64> = (0..14).map(|_| 0.01 + 100.0 * rng.unit()).collect();
    let kernel = Kernel::new(weights, taus).unwrap();
    let (n, t) = (11, 40);
    let (h, ok) = crate::preisach::tests::hostile_history(&mut rng, t, n, -1.0, 4.0);
    let dt: Vec<f64> = (0..t).map(|_| rng.unit()).collect();
    for simd in [false, true] {
        crate::simd::set_enabled(simd);
        let mut bank = DriftBank::new(kernel.clone(), -0.03, n).unwrap();
        let mut out = vec![0.0; n * t];
        bank.run(&dt, &h, &ok, &mut out).unwrap();
        let mut w = Writer::default();
        bank.save(&mut w);
        let mut all = Reader::new(&w.buf);
        all.expect("drift elements", n).unwrap();
        all.expect("drift kernel terms", 14).unwrap();
        all.expect("drift clocks", 0).unwrap();
        let heads: Vec<[f64; 3]> = (0..n)
            .map(|_| {
                let head = [all.f64().unwrap(), all.f64().unwrap(), all.f64().unwrap()];
                all.u32().unwrap();
                head
            })
            .collect();
        for i in 0..n {
            let mut one = DriftBank::new(kernel.clone(), -0.03, 1).unwrap();
            let col = |v: &[f64]| (0..t).map(|r| v[r * n + i]).collect::<Vec<_>>();
            let okc: Vec<bool> = (0..t).map(|r| ok[r * n + i]).collect();
            let mut o = vec![0.0; t];
            one.run(&dt, &col(&h), &okc, &mut o).unwrap();
            assert_eq!(
                o.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                col(&out).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                "element {i}, simd {simd}"
            );
            let mut w1 = Writer::default();
            one.save(&mut w1);
            let mut r1 = Reader::new(&w1.buf);
            (0..3).for_each(|_| {
                r1.u32().unwrap();
            });
            let head = [r1.f64().unwrap(), r1.f64().unwrap(), r1.f64().unwrap()];
            r1.u32().unwrap();
            assert_eq!(head.map(f64::to_bits), heads[i].map(f64::to_bits));
            let mut z1 = vec![0.0; 14];
            r1.f64s(&mut z1).unwrap();
            // element i's states in the bank's snapshot: after the heads, i * 14 on
            let mut zi = vec![0.0; 14];
            let mut at = Reader::new(&w.buf[12 + n * 28 + i * 14 * 8..]);
            at.f64s(&mut zi).unwrap();
            assert_eq!(z1, zi, "element {i}");
        }
        // and a snapshot loads into a fresh bank that continues the same
        let mut fresh = DriftBank::new(kernel.clone(), -0.03, n).unwrap();
        fresh.load(&mut Reader::new(&w.buf)).unwrap();
        let (mut a, mut b) = (vec![0.0; n * t], vec![0.0; n * t]);
        bank.run(&dt, &h, &ok, &mut a).unwrap();
        fresh.run(&dt, &h, &ok, &mut b).unwrap();
        assert_eq!(
            a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            b.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }
    crate::simd::set_enabled(true);
}
