//! Tests of the compiled chain: equal to its kernels run one after the other in any order,
//! streaming equals batch, failed readings freeze the states, snapshots continue a stream.

use super::*;
use crate::detect::DetectorParams;
use crate::drift::Kernel;
use crate::preisach::PreisachBank;
use crate::repair::Method;
use crate::topology::Neighbours;

/// A tiny pseudo-random sequence in [0, 1) (tests need no extra crate).
fn noise(k: usize) -> f64 {
    let x = (k as u64 + 1).wrapping_mul(6_364_136_223_846_793_005);
    ((x >> 11) % 1_000_000) as f64 / 1e6
}

pub(crate) struct Mat {
    pub(crate) rows: usize,
    pub(crate) cols: usize,
}

impl Mat {
    fn n(&self) -> usize {
        self.rows * self.cols
    }

    fn converter(&self) -> Converter {
        let n = self.n();
        let curve = Curve::new(vec![10.0, 11.0, 12.5, 15.0], vec![0.0, 0.8, 1.6, 2.4]).unwrap();
        let offset = (0..n).map(|i| 0.1 * noise(i)).collect();
        let gain = (0..n).map(|i| 0.9 + 0.2 * noise(i + 99)).collect();
        Converter::new(offset, gain, Some(curve)).unwrap()
    }

    fn detector(&self) -> FailureDetector {
        let n = self.n();
        let params = DetectorParams {
            min_pf: 0.05,
            low_share: 0.5,
            high_share: 1.2,
            stuck_frames: 5,
            stuck_pf: 1e-4,
            neighbour_change_pf: 0.05,
            stuck_floor_pf: f64::NEG_INFINITY,
        };
        let nb = Neighbours::grid4(self.rows, self.cols);
        FailureDetector::new(
            params,
            nb,
            vec![3.0; n],
            Some(vec![10.0; n]),
            Some(vec![15.0; n]),
        )
        .unwrap()
    }

    fn drift(&self) -> DriftBank {
        let kernel = Kernel::new(vec![0.5, 0.5], vec![1.0, 100.0]).unwrap();
        DriftBank::new(kernel, -0.025, self.n()).unwrap()
    }

    fn compensation(&self, drift: bool) -> Compensation {
        let e = crate::everett::quadratic(21, 2.4);
        let p = PreisachBank::new(e, self.n(), 32)
            .and_then(|p| p.with_output(0.1, 1.0))
            .unwrap();
        Compensation::new(p, drift.then(|| self.drift())).unwrap()
    }

    fn repair(&self, which: usize) -> LocalRepair {
        let nb = Neighbours::grid4(self.rows, self.cols);
        let w = vec![1.0; nb.nnz()];
        let method = match which {
            0 => Method::Zero,
            1 => Method::LastValue,
            2 => Method::NeighbourMean(nb),
            _ => Method::Weighted(nb, w),
        };
        LocalRepair::new(method, self.n()).unwrap()
    }

    /// Readings (pF) of `t` frames with shorts, saturated and NaN readings.
    fn readings(&self, t: usize) -> (Vec<f64>, Vec<bool>, Vec<f64>) {
        let n = self.n();
        let mut r: Vec<f64> = (0..t * n)
            .map(|k| 10.5 + 3.0 * noise(k) * (1.0 + ((k / n) as f64 / 7.0).sin()) / 2.0)
            .collect();
        let valid: Vec<bool> = (0..t * n).map(|k| noise(k + 7) > 0.03).collect();
        for (k, v) in r.iter_mut().enumerate() {
            if noise(k + 3) < 0.03 {
                *v = 0.0;
            } else if noise(k + 5) < 0.01 {
                *v = f64::NAN;
            }
        }
        let dt = (0..t).map(|k| if k == 0 { 0.0 } else { 0.1 }).collect();
        (r, valid, dt)
    }
}

fn run(chain: &mut Chain, dt: &[f64], r: &[f64], v: &[bool]) -> (Vec<f64>, Vec<u8>) {
    let mut out = vec![0.0; r.len()];
    let mut codes = vec![0; r.len()];
    chain.run(dt, r, v, &mut out, &mut codes).unwrap();
    (out, codes)
}

fn same(a: &[f64], b: &[f64]) {
    assert_eq!(a.len(), b.len());
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        assert_eq!(x.to_bits(), y.to_bits(), "sample {k}: {x} vs {y}");
    }
}

/// The stages run one after the other through their own batch functions, with the rules of
/// the Python stages (the oracle of the compiled chain).
fn by_stages(stages: Vec<Stage>, dt: &[f64], r: &[f64], v: &[bool]) -> (Vec<f64>, Vec<bool>) {
    let mut x = r.to_vec();
    let mut ok: Vec<bool> = r.iter().zip(v).map(|(r, v)| *v && r.is_finite()).collect();
    for s in stages {
        let mut y = vec![0.0; x.len()];
        match s {
            Stage::Detect(mut d) => {
                let mut c = vec![0; x.len()];
                d.run(&x, &ok, &mut c, &mut Changes::default()).unwrap();
                ok.iter_mut().zip(&c).for_each(|(o, &c)| *o &= c == 0);
                continue;
            }
            Stage::Convert(c) => c.run(&x, &ok, &mut y).unwrap(),
            Stage::Compensation(mut c) => c.run(dt, &x, &ok, &mut y).unwrap(),
            Stage::Drift(mut d) => d.run(dt, &x, &ok, &mut y).unwrap(),
            Stage::Loading(c) => {
                for k in 0..x.len() {
                    y[k] = if ok[k] { c.at(x[k]) } else { f64::NAN };
                }
            }
            Stage::Repair(mut rep) => {
                rep.run(&mut x, |k| ok[k], None).unwrap();
                continue;
            }
        }
        x = y;
        for (o, v) in ok.iter_mut().zip(&x) {
            *o &= v.is_finite();
        }
    }
    (x, ok)
}

/// Chains of every shape: the usual one with every response and repair, and other orders.
fn shapes(mat: &Mat) -> Vec<Vec<Stage>> {
    let loading = Curve::new(vec![0.0, 1.0, 2.4], vec![0.0, 0.5, 3.0]).unwrap();
    let mut cases: Vec<Vec<Stage>> = Vec::new();
    for response in 0..4 {
        for repair in 0..5 {
            let mut s = vec![
                Stage::Detect(mat.detector()),
                Stage::Convert(mat.converter()),
            ];
            match response {
                0 => s.push(Stage::Compensation(mat.compensation(true))),
                1 => s.push(Stage::Compensation(mat.compensation(false))),
                2 => s.push(Stage::Loading(loading.clone())),
                _ => {}
            }
            if repair < 4 {
                s.push(Stage::Repair(mat.repair(repair)));
            }
            cases.push(s);
        }
    }
    cases.push(vec![Stage::Convert(mat.converter())]);
    cases.push(vec![
        Stage::Repair(mat.repair(2)),
        Stage::Detect(mat.detector()),
        Stage::Convert(mat.converter()),
        Stage::Compensation(mat.compensation(false)),
        Stage::Drift(mat.drift()),
        Stage::Repair(mat.repair(1)),
    ]);
    cases.push(vec![
        Stage::Detect(mat.detector()),
        Stage::Detect(mat.detector()),
        Stage::Convert(mat.converter()),
        Stage::Repair(mat.repair(3)),
        Stage::Compensation(mat.compensation(true)),
        Stage::Repair(mat.repair(2)),
        Stage::Drift(mat.drift()),
    ]);
    // a segment of every element-wise kind, the loading curve between two that keep state
    cases.push(vec![
        Stage::Convert(mat.converter()),
        Stage::Drift(mat.drift()),
        Stage::Loading(loading.clone()),
        Stage::Compensation(mat.compensation(true)),
        Stage::Drift(mat.drift()),
    ]);
    cases
}

/// `Chain::step`'s binding hands the chain output arrays whose bytes are not set: every
/// value and code must be written before it is read. Frame after frame, outputs filled
/// with two different patterns beforehand give the same values and codes, for chains of
/// every shape.
#[test]
fn every_value_and_code_is_written_before_it_is_read() {
    let mat = Mat { rows: 5, cols: 6 };
    let n = mat.n();
    let (r, v, dt) = mat.readings(30);
    for stages in shapes(&mat) {
        let names: Vec<_> = stages.iter().map(Stage::name).collect();
        let run_with = |fill: f64, code: u8| {
            let mut chain = Chain::new(n, stages.clone()).unwrap();
            let (mut all, mut all_codes) = (Vec::new(), Vec::new());
            for (k, &d) in dt.iter().enumerate() {
                let (mut out, mut codes) = (vec![fill; n], vec![code; n]);
                let at = k * n..(k + 1) * n;
                chain
                    .run(&[d], &r[at.clone()], &v[at], &mut out, &mut codes)
                    .unwrap();
                all.extend(out.iter().map(|x| x.to_bits()));
                all_codes.extend(codes);
            }
            (all, all_codes)
        };
        let a = run_with(f64::from_bits(0x7ff8_dead_beef_0001), 0xab);
        assert_eq!(a, run_with(7.5, 0), "{names:?}");
    }
}

#[test]
fn the_chain_equals_its_stages_run_one_after_the_other_in_any_order() {
    let mat = Mat { rows: 5, cols: 6 };
    let n = mat.n();
    let (r, v, dt) = mat.readings(60);
    let cases = shapes(&mat);
    for stages in cases {
        let names: Vec<_> = stages.iter().map(Stage::name).collect();
        let mut chain = Chain::new(n, stages.clone()).unwrap();
        let (got, codes) = run(&mut chain, &dt, &r, &v);
        let (want, ok) = by_stages(stages, &dt, &r, &v);
        same(&got, &want);
        let got_ok: Vec<bool> = codes.iter().map(|&c| c == code::OK).collect();
        assert_eq!(got_ok, ok, "{names:?}");
        assert!(ok.iter().any(|&o| !o) && ok.iter().filter(|&&o| o).count() > n);
    }
}

#[test]
fn codes_come_from_the_first_detect_stage() {
    let mat = Mat { rows: 4, cols: 4 };
    let (r, v, dt) = mat.readings(30);
    let mut det = mat.detector();
    let mut want = vec![0; r.len()];
    det.run(&r, &v, &mut want, &mut Changes::default()).unwrap();
    let stages = vec![
        Stage::Detect(mat.detector()),
        Stage::Convert(mat.converter()),
        Stage::Compensation(mat.compensation(true)),
        Stage::Repair(mat.repair(2)),
    ];
    let (_, codes) = run(&mut Chain::new(mat.n(), stages).unwrap(), &dt, &r, &v);
    assert_eq!(codes, want);
    // without a detect stage: invalid or not a number on input is out of range
    let mut plain = Chain::new(mat.n(), vec![Stage::Convert(mat.converter())]).unwrap();
    let (_, codes) = run(&mut plain, &dt, &r, &v);
    for k in 0..r.len() {
        let ok = v[k] && r[k].is_finite();
        assert_eq!(codes[k], if ok { 0 } else { code::OUT_OF_RANGE });
    }
}

pub(crate) fn usual(mat: &Mat) -> Chain {
    Chain::new(
        mat.n(),
        vec![
            Stage::Detect(mat.detector()),
            Stage::Convert(mat.converter()),
            Stage::Compensation(mat.compensation(true)),
            Stage::Repair(mat.repair(2)),
        ],
    )
    .unwrap()
}

#[test]
fn streaming_equals_batch_also_on_a_large_mat_in_parallel_blocks() {
    for mat in [Mat { rows: 4, cols: 6 }, Mat { rows: 64, cols: 64 }] {
        let n = mat.n();
        let t = 12;
        let (r, v, dt) = mat.readings(t);
        let (batch, codes) = run(&mut usual(&mat), &dt, &r, &v);
        let mut stream = usual(&mat);
        for k in 0..t {
            let rows = k * n..(k + 1) * n;
            let (out, c) = run(&mut stream, &dt[k..=k], &r[rows.clone()], &v[rows.clone()]);
            same(&out, &batch[rows.clone()]);
            assert_eq!(c, &codes[rows]);
        }
    }
}

#[test]
fn a_snapshot_continues_the_stream_in_another_chain_to_the_bit() {
    let mat = Mat { rows: 5, cols: 5 };
    let n = mat.n();
    let (r, v, dt) = mat.readings(80);
    let (whole, codes) = run(&mut usual(&mat), &dt, &r, &v);
    let mut first = usual(&mat);
    let half = 40 * n;
    run(&mut first, &dt[..40], &r[..half], &v[..half]);
    let snap = first.snapshot();
    let mut second = usual(&mat);
    second.restore(&snap).unwrap();
    let (rest, c) = run(&mut second, &dt[40..], &r[half..], &v[half..]);
    same(&rest, &whole[half..]);
    assert_eq!(c, &codes[half..]);
    assert_eq!(second.snapshot(), usual_after(&mat, &dt, &r, &v).snapshot());
    // a snapshot of another chain, a damaged or cut one, is refused and changes nothing
    let other = Chain::new(n, vec![Stage::Convert(mat.converter())]).unwrap();
    let before = second.snapshot();
    assert!(second.restore(&other.snapshot()).is_err());
    assert!(second.restore(&snap[..snap.len() - 3]).is_err());
    let mut bad = snap.clone();
    bad[8] = 9; // version
    assert!(second.restore(&bad).is_err());
    assert!(second.restore(b"nonsense").is_err());
    assert_eq!(second.snapshot(), before);
}

fn usual_after(mat: &Mat, dt: &[f64], r: &[f64], v: &[bool]) -> Chain {
    let mut c = usual(mat);
    run(&mut c, dt, r, v);
    c
}

#[test]
fn a_failed_reading_leaves_the_element_as_if_it_had_not_been_read() {
    let mat = Mat { rows: 3, cols: 4 };
    let n = mat.n();
    let t = 40;
    let r: Vec<f64> = (0..t * n).map(|k| 10.2 + 4.0 * noise(k)).collect();
    let dt: Vec<f64> = (0..t).map(|k| if k == 0 { 0.0 } else { 0.5 }).collect();
    let mut v = vec![true; t * n];
    for k in 10..20 {
        v[k * n + 5] = false;
    }
    let make = || {
        let stages = vec![
            Stage::Convert(mat.converter()),
            Stage::Compensation(mat.compensation(true)),
        ];
        Chain::new(n, stages).unwrap()
    };
    let (with_gap, codes) = run(&mut make(), &dt, &r, &v);
    assert!((10..20).all(|k| with_gap[k * n + 5].is_nan() && codes[k * n + 5] != 0));
    // element 5 alone, without the failed frames (their time added to the next step)
    let keep: Vec<usize> = (0..t).filter(|k| !(10..20).contains(k)).collect();
    let r2: Vec<f64> = keep
        .iter()
        .flat_map(|&k| r[k * n..(k + 1) * n].to_vec())
        .collect();
    let mut dt2: Vec<f64> = keep.iter().map(|&k| dt[k]).collect();
    dt2[10] += 10.0 * 0.5;
    let (without, _) = run(&mut make(), &dt2, &r2, &vec![true; r2.len()]);
    for (j, &k) in keep.iter().enumerate() {
        let (a, b) = (with_gap[k * n + 5], without[j * n + 5]);
        assert!(
            (a - b).abs() <= 1e-12 * b.abs().max(1.0),
            "frame {k}: {a} vs {b}"
        );
    }
}

#[test]
fn bad_shapes_and_time_steps_are_errors() {
    let mat = Mat { rows: 2, cols: 3 };
    let small = Mat { rows: 2, cols: 2 };
    let e = Chain::new(6, vec![Stage::Detect(small.detector())]);
    assert!(matches!(e, Err(CoreError::Shape { .. })));
    let e = Chain::new(6, vec![Stage::Repair(small.repair(2))]);
    assert!(matches!(e, Err(CoreError::Shape { .. })));
    let mut chain = Chain::new(6, vec![Stage::Convert(mat.converter())]).unwrap();
    let (mut out, mut codes) = (vec![0.0; 12], vec![0; 12]);
    let e = chain.run(&[0.0, -1.0], &[10.0; 12], &[true; 12], &mut out, &mut codes);
    assert!(matches!(e, Err(CoreError::Parameter { what: "dt", .. })));
    let e = chain.run(&[0.0, 1.0], &[10.0; 11], &[true; 12], &mut out, &mut codes);
    assert!(matches!(
        e,
        Err(CoreError::Shape {
            what: "readings",
            ..
        })
    ));
}

#[test]
fn the_curve_interpolates_as_a_binary_search_does() {
    let x: Vec<f64> = (0..50).map(|k| (k as f64).powf(1.3) + noise(k)).collect();
    let y: Vec<f64> = x.iter().map(|v| v.sqrt()).collect();
    let curve = Curve::new(x.clone(), y.clone()).unwrap();
    let reference = |v: f64| {
        if v.is_nan() {
            return f64::NAN;
        }
        if v <= x[0] {
            return y[0];
        }
        if v >= x[49] {
            return y[49];
        }
        let j = x.partition_point(|&xi| xi <= v) - 1;
        if x[j] == v {
            return y[j];
        }
        (y[j + 1] - y[j]) / (x[j + 1] - x[j]) * (v - x[j]) + y[j]
    };
    let probes = (0..2000)
        .map(|k| -5.0 + 180.0 * noise(k))
        .chain(x.iter().copied())
        .chain([f64::NAN, f64::INFINITY, f64::NEG_INFINITY]);
    for v in probes {
        let (a, b) = (curve.at(v), reference(v));
        assert!(a.to_bits() == b.to_bits(), "at {v}: {a} vs {b}");
    }
    assert!(Curve::new(vec![0.0, 0.0], vec![1.0, 2.0]).is_err());
}
