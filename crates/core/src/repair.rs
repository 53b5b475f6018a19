//! Replacing failed elements by the mean of their available neighbours (thesis §6.5.2.5).
//!
//! Eq. 6.14: `p_i = (p_l + p_r + p_t + p_b) / n_a`, the sum running over the `n_a`
//! neighbours that are available in the same frame. "If all four are unavailable, the last
//! value available (real or reconstructed) of the sensor element is taken."
//!
//! A reading is *available* when it is flagged valid and is a finite number. Only available
//! readings enter the mean: a neighbour that is itself being repaired in the same frame does
//! not contribute. An element that has never had a value (no neighbours available and no
//! earlier value) stays NaN and is reported as not repaired.

use crate::error::{check_len, CoreError};
use crate::topology::Neighbours;

/// Streaming state of the eq. 6.14 repair: the last value (real or repaired) per element.
#[derive(Debug, Clone)]
pub struct NeighbourMeanRepair {
    neighbours: Neighbours,
    last: Vec<f32>,
}

/// What happened to one element in one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum RepairOutcome {
    /// The reading was available and passed through unchanged.
    Measured = 0,
    /// Replaced by the mean of at least one available neighbour.
    NeighbourMean = 1,
    /// No neighbour available: the last value (real or repaired) was held.
    LastValue = 2,
    /// No neighbour and no earlier value: the output is NaN.
    Missing = 3,
}

impl NeighbourMeanRepair {
    /// A fresh repair stage for the given neighbour graph; no element has a last value yet.
    pub fn new(neighbours: Neighbours) -> Self {
        let n = neighbours.len();
        Self {
            neighbours,
            last: vec![f32::NAN; n],
        }
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.neighbours.len()
    }

    /// True when there are no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The last value (real or repaired) of every element; NaN where none was seen yet.
    pub fn last_values(&self) -> &[f32] {
        &self.last
    }

    /// Forget all last values.
    pub fn reset(&mut self) {
        self.last.iter_mut().for_each(|v| *v = f32::NAN);
    }

    /// Repair one frame. `frame` and `valid` have one entry per element; the repaired frame
    /// goes to `out` and the outcome per element to `outcome`.
    pub fn step(
        &mut self,
        frame: &[f32],
        valid: &[bool],
        out: &mut [f32],
        outcome: &mut [RepairOutcome],
    ) -> Result<(), CoreError> {
        let n = self.len();
        check_len("frame", frame.len(), n)?;
        check_len("valid", valid.len(), n)?;
        check_len("out", out.len(), n)?;
        check_len("outcome", outcome.len(), n)?;
        self.step_unchecked(frame, valid, out, outcome);
        Ok(())
    }

    /// Repair a batch of frames stored row-major (`frames.len() == n_frames * n`), exactly as
    /// if `step` had been called for each frame in turn.
    pub fn run(
        &mut self,
        frames: &[f32],
        valid: &[bool],
        out: &mut [f32],
        outcome: &mut [RepairOutcome],
    ) -> Result<(), CoreError> {
        let n = self.len();
        if n == 0 {
            return Ok(());
        }
        if !frames.len().is_multiple_of(n) {
            return Err(CoreError::Shape {
                what: "frames",
                expected: format!("a multiple of {n} elements"),
                got: format!("length {}", frames.len()),
            });
        }
        let total = frames.len();
        check_len("valid", valid.len(), total)?;
        check_len("out", out.len(), total)?;
        check_len("outcome", outcome.len(), total)?;
        for (((f, v), o), k) in frames
            .chunks_exact(n)
            .zip(valid.chunks_exact(n))
            .zip(out.chunks_exact_mut(n))
            .zip(outcome.chunks_exact_mut(n))
        {
            self.step_unchecked(f, v, o, k);
        }
        Ok(())
    }

    #[inline]
    fn step_unchecked(
        &mut self,
        frame: &[f32],
        valid: &[bool],
        out: &mut [f32],
        outcome: &mut [RepairOutcome],
    ) {
        let available = |j: usize| valid[j] && frame[j].is_finite();
        for i in 0..frame.len() {
            if available(i) {
                out[i] = frame[i];
                outcome[i] = RepairOutcome::Measured;
                self.last[i] = frame[i];
                continue;
            }
            // eq. 6.14: the mean of the available neighbours, accumulated in f64.
            let mut sum = 0.0f64;
            let mut count = 0u32;
            for &j in self.neighbours.of(i) {
                let j = j as usize;
                if available(j) {
                    sum += f64::from(frame[j]);
                    count += 1;
                }
            }
            if count > 0 {
                let v = (sum / f64::from(count)) as f32;
                out[i] = v;
                outcome[i] = RepairOutcome::NeighbourMean;
                self.last[i] = v;
            } else if self.last[i].is_finite() {
                out[i] = self.last[i];
                outcome[i] = RepairOutcome::LastValue;
            } else {
                out[i] = f32::NAN;
                outcome[i] = RepairOutcome::Missing;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn run_all(
        rep: &mut NeighbourMeanRepair,
        frames: &[f32],
        valid: &[bool],
    ) -> (Vec<f32>, Vec<RepairOutcome>) {
        let mut out = vec![0.0; frames.len()];
        let mut oc = vec![RepairOutcome::Measured; frames.len()];
        rep.run(frames, valid, &mut out, &mut oc).unwrap();
        (out, oc)
    }

    #[test]
    fn centre_of_3x3_is_mean_of_its_four_neighbours() {
        let mut rep = NeighbourMeanRepair::new(Neighbours::grid4(3, 3));
        let frame = [9.0, 1.0, 9.0, 2.0, 0.0, 4.0, 9.0, 5.0, 9.0];
        let mut valid = [true; 9];
        valid[4] = false;
        let (out, oc) = run_all(&mut rep, &frame, &valid);
        assert_eq!(out[4], 3.0); // (1 + 2 + 4 + 5) / 4, corners ignored
        assert_eq!(oc[4], RepairOutcome::NeighbourMean);
        assert_eq!(&out[..4], &frame[..4]);
    }

    #[test]
    fn only_available_neighbours_count() {
        let mut rep = NeighbourMeanRepair::new(Neighbours::grid4(3, 3));
        let frame = [0.0, 1.0, 0.0, f32::NAN, 0.0, 4.0, 0.0, 5.0, 0.0];
        let mut valid = [true; 9];
        valid[4] = false;
        valid[1] = false; // flagged although it has a value
        let (out, _) = run_all(&mut rep, &frame, &valid);
        assert_eq!(out[4], 4.5); // (4 + 5) / 2: element 1 flagged, element 3 NaN
    }

    #[test]
    fn all_neighbours_failed_takes_last_value_real_or_repaired() {
        let mut rep = NeighbourMeanRepair::new(Neighbours::grid4(1, 3));
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
        assert_eq!(oc[4], RepairOutcome::LastValue);
        assert_eq!(out[7], 15.0);
        assert_eq!(&out[9..12], &[10.0, 15.0, 20.0]);
    }

    #[test]
    fn never_seen_and_isolated_stays_missing() {
        let mut rep = NeighbourMeanRepair::new(Neighbours::empty(2));
        let (out, oc) = run_all(&mut rep, &[1.0, 0.0], &[true, false]);
        assert!(out[1].is_nan());
        assert_eq!(oc[1], RepairOutcome::Missing);
        assert_eq!(out[0], 1.0);
    }

    #[test]
    fn shape_errors_are_reported() {
        let mut rep = NeighbourMeanRepair::new(Neighbours::grid4(2, 2));
        let mut out = vec![0.0; 8];
        let mut oc = vec![RepairOutcome::Measured; 8];
        let e = rep.run(&[0.0; 7], &[true; 7], &mut out[..7], &mut oc[..7]);
        assert!(matches!(e, Err(CoreError::Shape { what: "frames", .. })));
        let e = rep.run(&[0.0; 8], &[true; 4], &mut out, &mut oc);
        assert!(matches!(e, Err(CoreError::Shape { what: "valid", .. })));
    }

    proptest! {
        #[test]
        fn streaming_equals_batch(
            vals in proptest::collection::vec(-5.0f32..5.0, 4 * 12),
            mask in proptest::collection::vec(any::<bool>(), 4 * 12),
        ) {
            let n = 12;
            let mut batch = NeighbourMeanRepair::new(Neighbours::grid4(3, 4));
            let (out_b, oc_b) = run_all(&mut batch, &vals, &mask);
            let mut stream = NeighbourMeanRepair::new(Neighbours::grid4(3, 4));
            let mut out = vec![0.0f32; n];
            let mut oc = vec![RepairOutcome::Measured; n];
            for t in 0..4 {
                stream.step(&vals[t * n..(t + 1) * n], &mask[t * n..(t + 1) * n], &mut out, &mut oc).unwrap();
                for i in 0..n {
                    prop_assert_eq!(out[i].to_bits(), out_b[t * n + i].to_bits());
                    prop_assert_eq!(oc[i], oc_b[t * n + i]);
                }
            }
        }

        #[test]
        fn repaired_value_lies_within_neighbour_range(
            vals in proptest::collection::vec(0.0f32..10.0, 25),
            mask in proptest::collection::vec(any::<bool>(), 25),
        ) {
            let g = Neighbours::grid4(5, 5);
            let mut rep = NeighbourMeanRepair::new(g.clone());
            let (out, oc) = run_all(&mut rep, &vals, &mask);
            for i in 0..25 {
                if oc[i] == RepairOutcome::NeighbourMean {
                    let avail: Vec<f32> = g.of(i).iter().map(|&j| j as usize)
                        .filter(|&j| mask[j]).map(|j| vals[j]).collect();
                    let lo = avail.iter().cloned().fold(f32::INFINITY, f32::min);
                    let hi = avail.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
                    prop_assert!(out[i] >= lo && out[i] <= hi);
                } else if mask[i] {
                    prop_assert_eq!(out[i], vals[i]);
                }
            }
        }
    }
}
