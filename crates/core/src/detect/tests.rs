//! Tests of the detect module.

use super::*;

fn params() -> DetectorParams {
    DetectorParams {
        min_pf: 0.05,
        low_share: 0.5,
        high_share: 1.2,
        stuck_frames: 5,
        stuck_pf: 1e-4,
        neighbour_change_pf: 0.05,
        stuck_floor_pf: f64::NEG_INFINITY,
    }
}

#[test]
fn codes_each_kind_and_batch_equals_frames() {
    let (rows, cols) = (3, 3);
    let n = rows * cols;
    let nb = Neighbours::grid4(rows, cols);
    let base = vec![10.0; n];
    let max = vec![20.0; n];
    let mk = || {
        FailureDetector::new(
            params(),
            nb.clone(),
            vec![5.0; n],
            Some(base.clone()),
            Some(max.clone()),
        )
        .unwrap()
    };
    let t = 12;
    let mut readings = Vec::new();
    let mut valid = Vec::new();
    for r in 0..t {
        for i in 0..n {
            let moving = 12.0 + 0.5 * ((r * 3 + i) % 4) as f64;
            let v = match i {
                0 => 0.01,               // short
                1 => 30.0,               // out of range
                2 => 12.0,               // stuck while neighbours move
                3 if r == 6 => 19.0,     // a jump
                4 if r == 3 => f64::NAN, // not a number
                _ => moving,
            };
            readings.push(v);
            valid.push(!(i == 5 && r == 2));
        }
    }
    let mut det = mk();
    let mut codes = vec![0u8; t * n];
    det.run(&readings, &valid, &mut codes, &mut Changes::default())
        .unwrap();
    let at = |r: usize, i: usize| codes[r * n + i];
    assert!((0..t).all(|r| at(r, 0) == code::SHORT_OR_BREAK));
    assert!((0..t).all(|r| at(r, 1) == code::OUT_OF_RANGE));
    assert_eq!(at(3, 2), code::OK);
    assert!((5..t).all(|r| at(r, 2) == code::STUCK), "{:?}", &codes);
    assert_eq!(at(6, 3), code::JUMP);
    assert_eq!(at(3, 4), code::SHORT_OR_BREAK);
    assert_eq!(at(2, 5), code::OUT_OF_RANGE);
    assert_eq!(at(0, 8), code::OK);
    // frame after frame gives the same
    let mut det = mk();
    let mut scratch = Changes::default();
    for r in 0..t {
        let mut c = vec![0u8; n];
        let rr = r * n..(r + 1) * n;
        det.run(
            &readings[rr.clone()],
            &valid[rr.clone()],
            &mut c,
            &mut scratch,
        )
        .unwrap();
        assert_eq!(&c[..], &codes[rr]);
    }
}

/// The codes in SIMD lanes (`detect::avx2`, groups where no reading holds still) equal
/// the scalar kernel's, with the elements' states, on random histories: readings that
/// hold still, jump, are not numbers, infinite, at the floor or beyond the range, flagged
/// invalid; with and without unloaded and largest readings; both validity modes.
#[test]
fn lanes_give_the_scalar_codes_and_states() {
    use crate::preisach::tests::Rng;
    let _guard = crate::simd::testing::lock();
    let mut rng = Rng(11);
    let mut seen = std::collections::BTreeSet::<u8>::new();
    // the last cases' blocks hold more elements than one call of the lane kernel takes
    // (`KERNEL_ROW`): a block's row in several parts, the last one short
    let wide = [(17, 31), (32, 32), (3, 100)];
    for case in 0..24 + wide.len() {
        let (rows, cols) = match case.checked_sub(24) {
            Some(w) => wide[w],
            None => (1 + (rng.next() % 6) as usize, 1 + (rng.next() % 9) as usize),
        };
        let n = rows * cols;
        let t = 30;
        let mut p = params();
        p.stuck_frames = 2 + (rng.next() % 4) as u32;
        p.stuck_pf = [1e-4, 0.25][case % 2];
        let limits = |v: f64| (case % 3 != 2).then(|| vec![v; n]);
        let mk = || {
            let jump = (0..n).map(|i| 1.0 + (i % 5) as f64).collect();
            let nb = Neighbours::grid4(rows, cols);
            FailureDetector::new(p, nb, jump, limits(10.0), limits(20.0)).unwrap()
        };
        let mut last = vec![12.0; n];
        let mut readings = Vec::with_capacity(t * n);
        for _ in 0..t {
            for (i, l) in last.iter_mut().enumerate() {
                // every third element mostly holds still (stuck codes), the others move
                let r = rng.next() % 12;
                *l = match r {
                    _ if i % 3 == 0 && r < 10 => *l,
                    0 => f64::NAN,
                    1 => [f64::INFINITY, f64::NEG_INFINITY, 0.01, 30.0][(rng.next() % 4) as usize],
                    2 => *l + 6.0,  // a jump
                    3 => *l,        // holds still
                    4 => *l + 0.25, // a change of stuck_pf exactly
                    // eighths: changes that equal the limits exactly
                    _ => 11.0 + (rng.next() % 24) as f64 / 8.0,
                };
                readings.push(*l);
            }
        }
        let valid: Vec<bool> = (0..t * n).map(|_| !rng.next().is_multiple_of(7)).collect();
        let given: Vec<u8> = (0..t * n)
            .map(|_| [0, 0, 0, 2, 9][(rng.next() % 5) as usize])
            .collect();
        let run = |path: crate::simd::Path| {
            crate::simd::set_limit(path);
            let (mut a, mut b) = (mk(), mk());
            let mut codes = vec![0u8; t * n];
            a.run(&readings, &valid, &mut codes, &mut Changes::default())
                .unwrap();
            let mut merged = given.clone();
            b.run_on_codes(&readings, &mut merged, 9, &mut Changes::default())
                .unwrap();
            crate::simd::set_enabled(true);
            let bits = |d: &FailureDetector| {
                d.elements
                    .iter()
                    .map(|e| (e.last.to_bits(), e.still, e.moved.to_bits()))
                    .collect::<Vec<_>>()
            };
            (codes, merged, bits(&a), bits(&b))
        };
        use crate::simd::Path;
        let scalar = run(Path::Scalar);
        // the AVX2 lanes forced, then the best path (eight AVX-512 lanes where present)
        assert_eq!(scalar, run(Path::Avx2), "case {case}, AVX2");
        assert_eq!(scalar, run(Path::Avx512), "case {case}, best path");
        // frame after frame (a live step: on AVX-512 the changes and codes in one pass)
        let stepped = (scalar.0.clone(), scalar.2.clone());
        for path in [Path::Scalar, Path::Avx512] {
            let frames = frame_after_frame(path, mk(), &readings, &valid);
            assert_eq!(stepped, frames, "case {case}, frames, {path:?}");
        }
        seen.extend(scalar.0.iter().chain(&scalar.1));
    }
    assert_eq!(seen.into_iter().collect::<Vec<_>>(), [0, 1, 2, 3, 4]);
}

/// The codes of `readings` and the elements' states after them, one frame at a time on
/// `path`.
fn frame_after_frame(
    path: crate::simd::Path,
    mut det: FailureDetector,
    readings: &[f64],
    valid: &[bool],
) -> (Vec<u8>, Vec<(u64, u32, u64)>) {
    let n = det.len();
    crate::simd::set_limit(path);
    let mut codes = vec![0u8; readings.len()];
    let mut scratch = Changes::default();
    for ((r, v), c) in readings
        .chunks_exact(n)
        .zip(valid.chunks_exact(n))
        .zip(codes.chunks_exact_mut(n))
    {
        det.run(r, v, c, &mut scratch).unwrap();
    }
    crate::simd::set_enabled(true);
    let bits = det
        .elements
        .iter()
        .map(|e| (e.last.to_bits(), e.still, e.moved.to_bits()));
    (codes, bits.collect())
}

#[test]
fn median_of_even_and_odd_counts() {
    use texsense_kernels::detect::median;
    assert_eq!(median::<f64>(&mut []), 0.0);
    assert_eq!(median(&mut [3.0]), 3.0);
    assert_eq!(median(&mut [4.0, 1.0, 3.0]), 3.0);
    assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
    assert_eq!(median(&mut [f64::INFINITY, 1.0]), f64::INFINITY);
    // every order of 3, 4 and 5 values against a sorted median
    let vals = [0.3, -1.0, 2.5, 0.3, 7.0];
    for len in 3..=5 {
        let mut idx: Vec<usize> = (0..len).collect();
        for _ in 0..120 {
            let mut v: Vec<f64> = idx.iter().map(|&q| vals[q]).collect();
            let mut s = v.clone();
            s.sort_by(f64::total_cmp);
            let want = 0.5 * (s[(len - 1) / 2] + s[len / 2]);
            assert_eq!(median(&mut v).to_bits(), want.to_bits(), "{idx:?}");
            idx.rotate_left(1);
            idx.swap(0, len / 2);
        }
    }
}
