use super::*;
use crate::preisach::tests::Rng;

/// A row of values with NaN, infinities, zeros of both signs and the largest finite
/// numbers, and codes that are mostly the valid one.
fn row(rng: &mut Rng, w: usize) -> (Vec<f64>, Vec<u8>) {
    let values = (0..w)
        .map(|_| match rng.next() % 10 {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => f64::NEG_INFINITY,
            3 => -0.0,
            4 => f64::MAX,
            5 => -f64::MIN_POSITIVE,
            _ => rng.unit() * 4.0 - 1.0,
        })
        .collect();
    let codes = (0..w)
        .map(|_| match rng.next() % 6 {
            0 => 2,
            1 => 255,
            2 => 4,
            _ => 0,
        })
        .collect();
    (values, codes)
}

/// What the four functions give on one path: the inputs and flags, the codes, the last
/// values, the list of readings not available and the finite flags.
type Outputs = (
    Vec<u64>,
    Vec<bool>,
    Vec<u8>,
    Vec<u64>,
    Vec<usize>,
    Vec<bool>,
);

/// What each function gives on one path.
fn on(path: Path, values: &[f64], codes: &[u8], last: &[f64]) -> Outputs {
    simd::set_limit(path);
    let w = values.len();
    let (mut x, mut ok) = (vec![7.0; w], vec![true; w]);
    coded_inputs(values, codes, 0, &mut x, &mut ok);
    let mut c = codes.to_vec();
    code_not_finite(values, &mut c, 0, 2);
    let (mut l, mut failed) = (last.to_vec(), vec![99]);
    keep_available(values, codes, 0, &mut l, &mut failed);
    let mut finite = vec![true; w];
    finite_flags(values, &mut finite);
    simd::set_enabled(true);
    let bits = |v: &[f64]| v.iter().map(|a| a.to_bits()).collect::<Vec<_>>();
    (bits(&x), ok, c, bits(&l), failed, finite)
}

#[test]
fn every_path_gives_the_scalar_loops_bits() {
    let _guard = simd::testing::lock();
    let mut rng = Rng(5);
    let mut paths = vec![Path::Avx2, Path::Avx512];
    paths.retain(|&p| p <= simd::detected());
    for case in 0..300 {
        let w = (rng.next() % 140) as usize;
        let (values, codes) = row(&mut rng, w);
        let last: Vec<f64> = (0..w).map(|_| rng.unit()).collect();
        let scalar = on(Path::Scalar, &values, &codes, &last);
        // the scalar loops themselves against their rules
        for i in 0..w {
            let good = codes[i] == 0;
            assert_eq!(scalar.1[i], good);
            let x = if good { values[i] } else { f64::NAN };
            assert_eq!(scalar.0[i], x.to_bits());
            assert_eq!(scalar.5[i], values[i].is_finite());
        }
        for &p in &paths {
            assert_eq!(on(p, &values, &codes, &last), scalar, "case {case}, {p:?}");
        }
    }
}
