//! The local repairs of failed readings (thesis §6.5.2.5), one kernel for the compiled chain
//! and for the repair stage alike.
//!
//! Eq. 6.14: `p_i = (p_l + p_r + p_t + p_b) / n_a`, the sum running over the `n_a`
//! neighbours that are available in the same frame. "If all four are unavailable, the last
//! value available (real or reconstructed) of the sensor element is taken." The other local
//! methods: `zero` (a failed reading reads 0), `last-value` (the element's last value, real
//! or repaired) and `weighted` (a weighted mean of the available neighbours with fixed
//! weights, e.g. inverse squared distance over the 8-neighbourhood, `idw8`).
//!
//! A reading is *available* when it is flagged valid and is a finite number. Only available
//! readings enter a mean: a neighbour that is itself being repaired in the same frame does
//! not contribute. Where no neighbour is available the element's last value is held; an
//! element that has never had a value stays NaN (*missing*).
//!
//! A batch runs frame after frame over all elements, in place: the fills of a frame are
//! computed from its readings as they came in and written after them, so no fill sees
//! another.

use texsense_kernels::repair::{self as kernel, outcome as how_of};

use crate::error::{check_len, frames_of, CoreError};
use crate::snapshot::{Reader, Writer};
use crate::topology::Neighbours;

/// What happened to one reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum RepairOutcome {
    /// The reading was available and passed through unchanged.
    Measured = 0,
    /// Filled by the method (a neighbour mean, or 0).
    Filled = 1,
    /// Nothing to fill from: the last value (real or repaired) was held.
    LastValue = 2,
    /// Nothing to fill from and no earlier value: the output is NaN.
    Missing = 3,
}

/// The local repair methods.
#[derive(Debug, Clone)]
pub enum Method {
    /// Failed readings read 0.
    Zero,
    /// Hold the last value (real or repaired).
    LastValue,
    /// Eq. 6.14: the mean of the available 4-neighbours.
    NeighbourMean(Neighbours),
    /// A weighted mean of the available neighbours (`weights` parallel to the neighbours'
    /// indices).
    Weighted(Neighbours, Vec<f64>),
}

/// A local repair with its state: the last value (real or repaired) of every element.
#[derive(Debug, Clone)]
pub struct LocalRepair {
    method: Method,
    last: Vec<f64>,
    /// The fills of a frame until all are known (scratch).
    fills: Vec<f64>,
    /// The readings of a frame that are not available (scratch).
    failed: Vec<usize>,
}

impl LocalRepair {
    /// A repair of `n` elements; the graph of a neighbour method must have `n` elements and
    /// the weights one entry per neighbour.
    pub fn new(method: Method, n: usize) -> Result<Self, CoreError> {
        match &method {
            Method::NeighbourMean(nb) => check_len("repair neighbours", nb.len(), n)?,
            Method::Weighted(nb, w) => {
                check_len("repair neighbours", nb.len(), n)?;
                check_len("repair weights", w.len(), nb.nnz())?;
                if w.iter().any(|v| !v.is_finite() || *v < 0.0) {
                    return Err(CoreError::Parameter {
                        what: "repair weights",
                        why: "must be finite and >= 0".into(),
                    });
                }
            }
            Method::Zero | Method::LastValue => {}
        }
        Ok(Self {
            method,
            last: vec![f64::NAN; n],
            fills: vec![0.0; n],
            failed: Vec::new(),
        })
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.last.len()
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.last.is_empty()
    }

    /// The last value (real or repaired) of every element; NaN where none was seen yet.
    pub fn last_values(&self) -> &[f64] {
        &self.last
    }

    /// Forget all last values.
    pub fn reset(&mut self) {
        self.last.fill(f64::NAN);
    }

    /// Bytes of state per element.
    pub fn state_bytes_per_element(&self) -> usize {
        std::mem::size_of::<f64>()
    }

    /// The method.
    pub fn method(&self) -> &Method {
        &self.method
    }

    /// The kernels' view of the method.
    pub fn view(&self) -> kernel::Method<'_, f64> {
        self.method.kernel()
    }

    /// Every element's state into a snapshot.
    pub(crate) fn save(&self, w: &mut Writer) {
        w.u32(self.len() as u32);
        w.f64s(&self.last);
    }

    /// Every element's state from a snapshot of a repair of the same size.
    pub(crate) fn load(&mut self, r: &mut Reader<'_>) -> Result<(), CoreError> {
        r.expect("repair elements", self.len())?;
        r.f64s(&mut self.last)
    }

    /// Repair a batch (T x N, row-major) in place: a reading is available when `ok(index)`
    /// and it is a number; the others are filled. `outcome` (T x N), when given, gets a
    /// [`RepairOutcome`] per reading.
    ///
    /// Frame after frame over all elements (the kernel's `repair_frame`); the fills of a
    /// frame are written once all of them are known, so a fill reads only the readings as
    /// they came in.
    pub fn run<F>(
        &mut self,
        values: &mut [f64],
        ok: F,
        mut outcome: Option<&mut [u8]>,
    ) -> Result<(), CoreError>
    where
        F: Fn(usize) -> bool,
    {
        let n = self.len();
        if n == 0 {
            return Ok(());
        }
        frames_of("values", values.len(), n)?;
        if let Some(o) = outcome.as_deref() {
            check_len("outcome", o.len(), values.len())?;
        }
        let Self {
            method,
            last,
            fills,
            failed,
        } = self;
        let method = method.kernel();
        for (r, frame) in values.chunks_exact_mut(n).enumerate() {
            let row = r * n;
            let o = outcome.as_deref_mut().map(|o| &mut o[row..row + n]);
            repair_listed(&method, last, frame, |j| ok(row + j), fills, failed, o);
        }
        Ok(())
    }

    /// [`LocalRepair::run`] in a chain, without outcomes: a reading is flagged valid when its
    /// code is `ok_code`; the first pass over each frame (keep the last value of every
    /// available reading, list the others) in SIMD lanes ([`crate::lanes::keep_available`]).
    /// The same values and last values as `run`.
    pub fn run_coded(
        &mut self,
        values: &mut [f64],
        codes: &[u8],
        ok_code: u8,
    ) -> Result<(), CoreError> {
        let n = self.len();
        if n == 0 {
            return Ok(());
        }
        frames_of("values", values.len(), n)?;
        check_len("codes", codes.len(), values.len())?;
        let Self {
            method,
            last,
            fills,
            failed,
        } = self;
        let method = method.kernel();
        for (frame, c) in values.chunks_exact_mut(n).zip(codes.chunks_exact(n)) {
            crate::lanes::keep_available(frame, c, ok_code, last, failed);
            fill_listed(
                &method,
                last,
                frame,
                |j| c[j] == ok_code,
                fills,
                failed,
                None,
            );
        }
        Ok(())
    }
}

impl Method {
    /// The kernel's method of this one.
    fn kernel(&self) -> kernel::Method<'_, f64> {
        match self {
            Method::Zero => kernel::Method::Zero,
            Method::LastValue => kernel::Method::LastValue,
            Method::NeighbourMean(nb) => kernel::Method::NeighbourMean(nb.graph()),
            Method::Weighted(nb, w) => kernel::Method::Weighted(nb.graph(), w),
        }
    }
}

/// The kernel's `repair_frame` (same values, last values and outcomes), visiting the
/// readings that are not available alone after one pass over the frame: the pass keeps the
/// last value of every available reading and lists the others; their fills read the frame
/// as it came in and their own last value (which the pass left alone), then go in.
fn repair_listed(
    method: &kernel::Method<'_, f64>,
    last: &mut [f64],
    frame: &mut [f64],
    ok: impl Fn(usize) -> bool,
    fills: &mut [f64],
    failed: &mut Vec<usize>,
    mut outcome: Option<&mut [u8]>,
) {
    failed.clear();
    for (i, (&v, l)) in frame.iter().zip(last.iter_mut()).enumerate() {
        if ok(i) && v.is_finite() {
            *l = v;
            if let Some(o) = outcome.as_deref_mut() {
                o[i] = how_of::MEASURED;
            }
        } else {
            failed.push(i);
        }
    }
    fill_listed(method, last, frame, ok, fills, failed, outcome);
}

/// The second part of [`repair_listed`]: the readings listed in `failed` filled (their
/// last values and outcomes kept), from the frame as it came in.
fn fill_listed(
    method: &kernel::Method<'_, f64>,
    last: &mut [f64],
    frame: &mut [f64],
    ok: impl Fn(usize) -> bool,
    fills: &mut [f64],
    failed: &[usize],
    mut outcome: Option<&mut [u8]>,
) {
    if failed.is_empty() {
        return;
    }
    let frame_in: &[f64] = frame;
    let available = |j: usize| {
        let v = frame_in[j];
        (ok(j) && v.is_finite()).then_some(v)
    };
    for (f, &i) in fills.iter_mut().zip(failed.iter()) {
        let (v, how) = kernel::fill(method, i, last[i], &available);
        if v.is_finite() {
            last[i] = v;
        }
        *f = v;
        if let Some(o) = outcome.as_deref_mut() {
            o[i] = how;
        }
    }
    for (&f, &i) in fills.iter().zip(failed.iter()) {
        frame[i] = f;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn run_all(rep: &mut LocalRepair, frames: &[f64], valid: &[bool]) -> (Vec<f64>, Vec<u8>) {
        let mut out = frames.to_vec();
        let mut oc = vec![9; frames.len()];
        rep.run(&mut out, |i| valid[i], Some(&mut oc)).unwrap();
        (out, oc)
    }

    fn mean4(rows: usize, cols: usize) -> LocalRepair {
        let g = Neighbours::grid4(rows, cols);
        LocalRepair::new(Method::NeighbourMean(g), rows * cols).unwrap()
    }

    #[test]
    fn centre_of_3x3_is_mean_of_its_four_neighbours() {
        let mut rep = mean4(3, 3);
        let frame = [9.0, 1.0, 9.0, 2.0, 0.0, 4.0, 9.0, 5.0, 9.0];
        let mut valid = [true; 9];
        valid[4] = false;
        let (out, oc) = run_all(&mut rep, &frame, &valid);
        assert_eq!(out[4], 3.0); // (1 + 2 + 4 + 5) / 4, corners ignored
        assert_eq!(oc[4], RepairOutcome::Filled as u8);
        assert_eq!(&out[..4], &frame[..4]);
        assert_eq!(oc[0], RepairOutcome::Measured as u8);
    }

    #[test]
    fn only_available_neighbours_count() {
        let mut rep = mean4(3, 3);
        let frame = [0.0, 1.0, 0.0, f64::NAN, 0.0, 4.0, 0.0, 5.0, 0.0];
        let mut valid = [true; 9];
        valid[4] = false;
        valid[1] = false; // flagged although it has a value
        let (out, _) = run_all(&mut rep, &frame, &valid);
        assert_eq!(out[4], 4.5); // (4 + 5) / 2: element 1 flagged, element 3 NaN
    }

    #[test]
    fn all_neighbours_failed_takes_last_value_real_or_repaired() {
        let mut rep = mean4(1, 3);
        // frame 0: all measured; frame 1: everything failed -> last real values;
        // frame 2: element 1 repaired from 0 and 2; frame 3: all failed -> last repaired value.
        let frames = [
            1.0, 2.0, 3.0, //
            7.0, 7.0, 7.0, //
            10.0, 0.0, 20.0, //
            0.0, 0.0, 0.0,
        ];
        let valid = [
            true, true, true, //
            false, false, false, //
            true, false, true, //
            false, false, false,
        ];
        let (out, oc) = run_all(&mut rep, &frames, &valid);
        assert_eq!(&out[3..6], &[1.0, 2.0, 3.0]);
        assert_eq!(oc[4], RepairOutcome::LastValue as u8);
        assert_eq!(out[7], 15.0);
        assert_eq!(&out[9..12], &[10.0, 15.0, 20.0]);
    }

    #[test]
    fn never_seen_and_isolated_stays_missing() {
        let mut rep = LocalRepair::new(Method::NeighbourMean(Neighbours::empty(2)), 2).unwrap();
        let (out, oc) = run_all(&mut rep, &[1.0, 0.0], &[true, false]);
        assert!(out[1].is_nan());
        assert_eq!(oc[1], RepairOutcome::Missing as u8);
        assert_eq!(out[0], 1.0);
    }

    #[test]
    fn zero_last_value_and_weighted() {
        let valid = [true, false, true, true, true, true, false, false, false];
        let frames = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
        let mut zero = LocalRepair::new(Method::Zero, 3).unwrap();
        assert_eq!(run_all(&mut zero, &frames, &valid).0[1], 0.0);
        let mut last = LocalRepair::new(Method::LastValue, 3).unwrap();
        let (out, oc) = run_all(&mut last, &frames, &valid);
        assert!(out[1].is_nan() && oc[1] == RepairOutcome::Missing as u8);
        assert_eq!(&out[6..], &[4.0, 5.0, 6.0]);
        // weights 1 to the left neighbour, 3 to the right one
        let g = Neighbours::new(vec![0, 1, 3, 4], vec![1, 0, 2, 1]).unwrap();
        let mut w = LocalRepair::new(Method::Weighted(g, vec![1.0, 1.0, 3.0, 1.0]), 3).unwrap();
        assert_eq!(
            run_all(&mut w, &frames, &valid).0[1],
            (1.0 + 3.0 * 3.0) / 4.0
        );
    }

    #[test]
    fn shape_errors_are_reported() {
        let mut rep = mean4(2, 2);
        let e = rep.run(&mut [0.0; 7], |_| true, None);
        assert!(matches!(e, Err(CoreError::Shape { what: "values", .. })));
        let e = rep.run(&mut [0.0; 8], |_| true, Some(&mut [0; 4]));
        assert!(matches!(
            e,
            Err(CoreError::Shape {
                what: "outcome",
                ..
            })
        ));
        let g = Neighbours::grid4(2, 2);
        let e = LocalRepair::new(Method::Weighted(g, vec![1.0; 3]), 4);
        assert!(matches!(e, Err(CoreError::Shape { .. })));
    }

    #[test]
    fn a_large_batch_equals_frame_after_frame() {
        let (rows, cols, t) = (64, 64, 12);
        let n = rows * cols;
        let vals: Vec<f64> = (0..n * t)
            .map(|k| ((k * 7919) % 1000) as f64 / 100.0)
            .collect();
        let valid: Vec<bool> = (0..n * t).map(|k| (k * 104_729) % 9 != 0).collect();
        let (batch, oc_b) = run_all(&mut mean4(rows, cols), &vals, &valid);
        let mut stream = mean4(rows, cols);
        for r in 0..t {
            let (out, oc) = run_all(
                &mut stream,
                &vals[r * n..(r + 1) * n],
                &valid[r * n..(r + 1) * n],
            );
            for i in 0..n {
                assert_eq!(out[i].to_bits(), batch[r * n + i].to_bits());
                assert_eq!(oc[i], oc_b[r * n + i]);
            }
        }
    }

    proptest! {
        /// The listed path gives the kernel's `repair_frame` bit for bit: values, last
        /// values and outcomes, over frames with NaN, infinite and flagged readings, for
        /// every method.
        #[test]
        fn listed_repair_equals_the_kernel_frame(
            vals in proptest::collection::vec(
                prop_oneof![8 => -5.0f64..5.0, 1 => Just(f64::NAN), 1 => Just(f64::INFINITY)],
                5 * 12,
            ),
            mask in proptest::collection::vec(prop::bool::weighted(0.7), 5 * 12),
            which in 0usize..4,
        ) {
            let (n, g) = (12, Neighbours::grid4(3, 4));
            let weights: Vec<f64> = (0..g.nnz()).map(|q| 0.5 + (q % 3) as f64).collect();
            let method = [
                Method::Zero,
                Method::LastValue,
                Method::NeighbourMean(g.clone()),
                Method::Weighted(g, weights),
            ][which].clone();
            let mut rep = LocalRepair::new(method, n).unwrap();
            let mut last = vec![f64::NAN; n];
            let mut fills = vec![0.0; n];
            for t in 0..5 {
                let (v, m) = (&vals[t * n..(t + 1) * n], &mask[t * n..(t + 1) * n]);
                let (out, oc) = run_all(&mut rep, v, m);
                let mut frame = v.to_vec();
                let mut oc_k = vec![9; n];
                kernel::repair_frame(
                    &rep.view(), &mut last, &mut frame, |i| m[i], &mut fills, Some(&mut oc_k),
                );
                let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                prop_assert_eq!(bits(&out), bits(&frame));
                prop_assert_eq!(&oc, &oc_k);
                prop_assert_eq!(bits(rep.last_values()), bits(&last));
            }
        }

        /// The chain's path (`run_coded`: validity from codes, the first pass in SIMD
        /// lanes) gives `run`'s values and last values bit for bit on every path.
        #[test]
        fn coded_repair_equals_run_on_every_path(
            vals in proptest::collection::vec(
                prop_oneof![
                    8 => -5.0f64..5.0,
                    1 => Just(f64::NAN),
                    1 => Just(f64::INFINITY),
                    1 => Just(f64::NEG_INFINITY),
                ],
                4 * 20,
            ),
            codes in proptest::collection::vec(prop_oneof![6 => Just(0u8), 1 => Just(2u8), 1 => Just(255u8)], 4 * 20),
            which in 0usize..4,
        ) {
            let _guard = crate::simd::testing::lock();
            let (n, g) = (20, Neighbours::grid4(4, 5));
            let weights: Vec<f64> = (0..g.nnz()).map(|q| 0.5 + (q % 3) as f64).collect();
            let method = [
                Method::Zero,
                Method::LastValue,
                Method::NeighbourMean(g.clone()),
                Method::Weighted(g, weights),
            ][which].clone();
            let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            let mut rep = LocalRepair::new(method, n).unwrap();
            let mut want = vals.clone();
            rep.run(&mut want, |i| codes[i] == 0, None).unwrap();
            let want = (bits(&want), bits(rep.last_values()));
            for path in [crate::simd::Path::Scalar, crate::simd::Path::Avx2, crate::simd::Path::Avx512] {
                crate::simd::set_limit(path);
                rep.reset();
                let mut got = vals.clone();
                rep.run_coded(&mut got, &codes, 0).unwrap();
                crate::simd::set_enabled(true);
                prop_assert_eq!((bits(&got), bits(rep.last_values())), want.clone(), "{:?}", path);
            }
        }

        #[test]
        fn streaming_equals_batch(
            vals in proptest::collection::vec(-5.0f64..5.0, 4 * 12),
            mask in proptest::collection::vec(any::<bool>(), 4 * 12),
        ) {
            let n = 12;
            let (out_b, oc_b) = run_all(&mut mean4(3, 4), &vals, &mask);
            let mut stream = mean4(3, 4);
            for t in 0..4 {
                let (out, oc) = run_all(&mut stream, &vals[t * n..(t + 1) * n], &mask[t * n..(t + 1) * n]);
                for i in 0..n {
                    prop_assert_eq!(out[i].to_bits(), out_b[t * n + i].to_bits());
                    prop_assert_eq!(oc[i], oc_b[t * n + i]);
                }
            }
        }

        #[test]
        fn repaired_value_lies_within_neighbour_range(
            vals in proptest::collection::vec(0.0f64..10.0, 25),
            mask in proptest::collection::vec(any::<bool>(), 25),
        ) {
            let g = Neighbours::grid4(5, 5);
            let (out, oc) = run_all(&mut mean4(5, 5), &vals, &mask);
            for i in 0..25 {
                if oc[i] == RepairOutcome::Filled as u8 {
                    let avail: Vec<f64> = g.of(i).iter().map(|&j| j as usize)
                        .filter(|&j| mask[j]).map(|j| vals[j]).collect();
                    let lo = avail.iter().cloned().fold(f64::INFINITY, f64::min);
                    let hi = avail.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                    prop_assert!(out[i] >= lo && out[i] <= hi);
                } else if mask[i] {
                    prop_assert_eq!(out[i], vals[i]);
                }
            }
        }
    }
}
