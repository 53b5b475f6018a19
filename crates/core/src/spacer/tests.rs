//! Tests of the spacer module.

use super::*;

fn textile() -> SpacerParams {
    SpacerParams {
        backbone_a: 1.0,
        backbone_m: 1.3,
        densification: 0.85,
        linear: 0.3,
        friction: vec![(0.15, 0.01), (0.15, 0.03), (0.15, 0.06)],
        creep_a: 0.08,
        creep_tc: 1.0,
        rest_rate: 1e-5,
        clutch: (0.3, 0.1),
        viscous: vec![(0.02, 0.3), (0.02, 3.0)],
        kelvin: vec![(0.01, 300.0), (0.01, 3000.0)],
        recovery_factor: 3.0,
        creep_p_ref: 2.0,
        softening: vec![(0.08, 2.0), (0.05, 0.2)],
        softening_recovery_s: 3600.0,
    }
}

fn loop_stress(bank: &mut SpacerBank, path: &[f64], dt: f64) -> Vec<f64> {
    let mut p = [0.0];
    let mut s = [0.0];
    path.iter()
        .map(|&e| {
            bank.step_displacement(dt, &[e], &mut p, &mut s).unwrap();
            p[0]
        })
        .collect()
}

#[test]
fn loading_above_unloading_at_equal_compression() {
    let mut bank = SpacerBank::new(textile(), vec![1.0]).unwrap();
    let up: Vec<f64> = (0..=100).map(|k| 0.006 * k as f64).collect();
    let rising = loop_stress(&mut bank, &up, 0.05);
    let down: Vec<f64> = up.iter().rev().cloned().collect();
    let falling = loop_stress(&mut bank, &down, 0.05);
    for k in 10..90 {
        assert!(rising[k] > falling[100 - k], "k = {k}");
    }
}

#[test]
fn held_compression_relaxes_and_never_goes_negative() {
    let mut bank = SpacerBank::new(textile(), vec![1.0]).unwrap();
    let ramp: Vec<f64> = (0..=50).map(|k| 0.01 * k as f64).collect();
    let top = *loop_stress(&mut bank, &ramp, 0.05).last().unwrap();
    let held = loop_stress(&mut bank, &[0.5; 100], 36.0);
    assert!(held[99] < top * 0.95);
    assert!(held.windows(2).all(|w| w[1] <= w[0] + 1e-12));
    assert!(held.iter().all(|&p| p > 0.0));
}

#[test]
fn huge_steps_stay_finite() {
    let mut bank = SpacerBank::new(textile(), vec![1.0, 2.0]).unwrap();
    let mut p = [0.0; 2];
    let mut s = [0.0; 2];
    for (dt, e) in [(1e6, 0.8), (1e-9, 0.0), (1e7, 0.84), (0.0, 0.3)] {
        bank.step_displacement(dt, &[e, e], &mut p, &mut s).unwrap();
        assert!(p.iter().all(|v| v.is_finite() && *v >= 0.0));
    }
}

#[test]
fn pressure_control_inverts_displacement_control() {
    let mut a = SpacerBank::new(textile(), vec![1.0]).unwrap();
    let mut b = SpacerBank::new(textile(), vec![1.0]).unwrap();
    let mut e = [0.0];
    let mut p = [0.0];
    let mut s = [0.0];
    for k in 1..=40 {
        let target = 0.25 * k as f64;
        a.step_pressure(0.1, &[target], &mut e, &mut s).unwrap();
        b.step_displacement(0.1, &e, &mut p, &mut s).unwrap();
        assert!(
            (p[0] - target).abs() < 1e-6 * target.max(1.0),
            "{} vs {target}",
            p[0]
        );
    }
}

#[test]
fn ramp_until_stops_at_the_target() {
    let mut bank = SpacerBank::new(textile(), vec![1.0]).unwrap();
    let (mut e, mut p, mut s) = (Vec::new(), Vec::new(), Vec::new());
    let done = bank
        .ramp_until(0.01, 0.01, 5.0, 1_000_000, &mut e, &mut p, &mut s)
        .unwrap();
    assert!(done);
    assert!(*p.last().unwrap() >= 5.0 && p[p.len() - 2] < 5.0);
    let done = bank
        .ramp_until(0.01, -0.01, 0.0, 1_000_000, &mut e, &mut p, &mut s)
        .unwrap();
    assert!(done && *p.last().unwrap() <= 1e-12);
}

#[test]
fn bad_input_is_rejected() {
    let mut bad = textile();
    bad.densification = 1.2;
    assert!(SpacerBank::new(bad, vec![1.0]).is_err());
    assert!(SpacerBank::new(textile(), vec![0.0]).is_err());
    let mut bank = SpacerBank::new(textile(), vec![1.0]).unwrap();
    let (mut p, mut s) = ([0.0], [0.0]);
    assert!(bank.step_displacement(0.1, &[0.9], &mut p, &mut s).is_err());
    assert!(bank
        .step_displacement(-1.0, &[0.1], &mut p, &mut s)
        .is_err());
    let mut q = [0.0];
    assert!(bank.step_pressure(0.1, &[1e30], &mut p, &mut q).is_err());
    assert!(bank.step_pressure(0.1, &[-1.0], &mut p, &mut q).is_err());
}

#[test]
fn the_factors_of_a_step_follow_its_length() {
    // steps of changing length (and none): the bank that keeps its factors from step to step
    // gives the same bits as one that computes them afresh for every trial
    let dts = [0.1, 0.5, 0.1, 0.0, 2.0, 2.0, 0.05, 30.0, 0.1];
    let targets = [0.5, 1.5, 1.2, 1.2, 2.5, 0.3, 0.0, 0.8, 1.0];
    let mut kept = SpacerBank::new(textile(), vec![1.0, 1.1]).unwrap();
    let mut fresh = kept.clone();
    for (&dt, &p) in dts.iter().zip(&targets) {
        let (mut e1, mut r1, mut e2, mut r2) = ([0.0; 2], [0.0; 2], [0.0; 2], [0.0; 2]);
        kept.step_pressure(dt, &[p, 0.7 * p], &mut e1, &mut r1)
            .unwrap();
        fresh.factors = StepFactors::default();
        for i in 0..2 {
            // the solve of element i, each trial with factors made for it
            let target = [p, 0.7 * p][i];
            let (mut lo, mut hi) = (0.0, fresh.limit() * (1.0 - 1e-6));
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                fresh.factors = StepFactors::default();
                if fresh.trial(i, dt, mid, false).stress <= target {
                    lo = mid;
                } else {
                    hi = mid;
                }
                if hi - lo < 1e-13 {
                    break;
                }
            }
            fresh.factors = StepFactors::default();
            let t = fresh.trial(i, dt, lo, true);
            e2[i] = lo.max(t.creep);
            r2[i] = t.stress;
        }
        assert_eq!(e1.map(f64::to_bits), e2.map(f64::to_bits), "dt {dt}");
        assert_eq!(r1.map(f64::to_bits), r2.map(f64::to_bits), "dt {dt}");
    }
}
