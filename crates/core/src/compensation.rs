//! The combined compensation stage: Preisach model, then drift (thesis eq. 5.8), frame by
//! frame in one pass, so a batch needs no intermediate array.

use crate::aligned::Row;
use crate::convert::Curve;
use crate::drift::{check_time_steps, DriftBank, DriftBlock};
use crate::error::{check_len, CoreError};
use crate::par::{run_frames, FrameBlock, MAX_BLOCK};
use crate::preisach::{PreisachBank, PreisachBlock};

/// The Preisach model's output (its offset and sign included), followed by an optional drift
/// stage. With a `level` curve (quasi-linear viscoelasticity, Fung) the drift superposes the
/// steps of the elastic response `level(u)` of the input instead of the Preisach output,
/// and its drift (its output minus its input) is added to the Preisach output.
#[derive(Debug, Clone)]
pub struct Compensation {
    preisach: PreisachBank,
    drift: Option<DriftBank>,
    level: Option<Box<Curve>>,
}

/// One block of elements of a [`Compensation`], for a parallel batch.
pub struct CompensationBlock<'a> {
    preisach: PreisachBlock<'a>,
    drift: Option<DriftBlock<'a>>,
    level: Option<texsense_kernels::convert::Curve<'a, f64>>,
}

impl CompensationBlock<'_> {
    /// Number of elements in the block.
    pub fn len(&self) -> usize {
        self.preisach.len()
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.preisach.is_empty()
    }

    /// Start a frame `dt` seconds after the previous one.
    #[inline]
    pub fn frame(&mut self, dt: f64) {
        if let Some(d) = &mut self.drift {
            d.frame(dt);
        }
    }

    /// Element `i` of the block reads the input `u` in the current frame; NaN when skipped.
    #[inline]
    pub fn step(&mut self, i: usize, dt: f64, u: f64, valid: bool) -> f64 {
        self.stage(i, dt, u, valid).0
    }

    /// Element `i`'s stages (hysteresis, then drift) with the validity rules of a chain
    /// (`texsense_kernels::stage`): value and validity in, the same out.
    #[inline(always)]
    pub fn stage(&mut self, i: usize, dt: f64, u: f64, valid: bool) -> (f64, bool) {
        let h = self.preisach.step(i, u, valid);
        let ok = h.is_finite();
        match (&mut self.drift, &self.level) {
            (Some(d), Some(curve)) => d.step_on_level(i, dt, curve, u, h, ok),
            (Some(d), None) => {
                let y = d.step(i, dt, h, ok);
                (y, ok && y.is_finite())
            }
            (None, _) => (h, ok),
        }
    }

    /// One frame of the block, stage after stage over the row (values only): the Preisach
    /// row ([`PreisachBlock::row`], SIMD across elements where the processor has it), then
    /// the drift row; the same values as [`CompensationBlock::stage`] per element.
    pub fn row(&mut self, dt: f64, u: &[f64], valid: &[bool], out: &mut [f64]) {
        out.copy_from_slice(u);
        self.row_in_place(dt, valid, out);
    }

    /// [`CompensationBlock::row`] with the inputs in `values`, which take the outputs (a
    /// chain's segment hands over its row without an array of its own for the inputs).
    pub fn row_in_place(&mut self, dt: f64, valid: &[bool], values: &mut [f64]) {
        let w = values.len();
        // on a cache line, as the rows' other arrays ([`crate::aligned`])
        let mut h = Row([0.0; MAX_BLOCK]);
        let h = &mut h.0[..w];
        self.preisach.row(values, valid, h);
        match (&mut self.drift, &self.level) {
            (Some(d), Some(curve)) => {
                for (i, slot) in values.iter_mut().enumerate() {
                    let ok = h[i].is_finite();
                    *slot = d.step_on_level(i, dt, curve, *slot, h[i], ok).0;
                }
            }
            // the drift's input is valid where the Preisach output is a number (`stage`);
            // the drift takes `valid && h.is_finite()`, which is that: the Preisach row gives
            // NaN for every reading not `valid` (no flags of its own needed: issue 34,
            // fifteenth round)
            (Some(d), None) => d.row(dt, h, valid, values),
            (None, _) => values.copy_from_slice(h),
        }
    }
}

impl FrameBlock for CompensationBlock<'_> {
    #[inline]
    fn frame(&mut self, dt: f64) {
        CompensationBlock::frame(self, dt);
    }

    #[inline]
    fn step(&mut self, i: usize, dt: f64, u: f64, valid: bool) -> f64 {
        CompensationBlock::step(self, i, dt, u, valid)
    }

    fn row(&mut self, dt: f64, x: &[f64], ok: &[bool], out: &mut [f64]) {
        CompensationBlock::row(self, dt, x, ok, out);
    }
}

impl Compensation {
    /// Combine the stages; both must have the same number of elements.
    pub fn new(preisach: PreisachBank, drift: Option<DriftBank>) -> Result<Self, CoreError> {
        if let Some(d) = &drift {
            check_len("drift elements", d.len(), preisach.len())?;
        }
        Ok(Self {
            preisach,
            drift,
            level: None,
        })
    }

    /// Let the drift superpose the steps of `level(u)` (the elastic response of the input)
    /// instead of the Preisach output (quasi-linear viscoelasticity); needs a drift stage.
    pub fn with_level(mut self, level: Curve) -> Result<Self, CoreError> {
        if self.drift.is_none() {
            return Err(CoreError::Parameter {
                what: "level",
                why: "a level curve needs a drift stage".into(),
            });
        }
        self.level = Some(Box::new(level));
        Ok(self)
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.preisach.len()
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.preisach.is_empty()
    }

    /// Both stages back to their initial state.
    pub fn reset(&mut self) {
        self.preisach.reset();
        if let Some(d) = &mut self.drift {
            d.reset();
        }
    }

    /// The Preisach stage (for its counters).
    pub fn preisach(&self) -> &PreisachBank {
        &self.preisach
    }

    /// The drift stage, if any, and the level curve it runs on (QLV), if any.
    pub fn drift(&self) -> (Option<&DriftBank>, Option<&Curve>) {
        (self.drift.as_ref(), self.level.as_deref())
    }

    /// Every element's state into a snapshot.
    pub(crate) fn save(&self, w: &mut crate::snapshot::Writer) {
        self.preisach.save(w);
        w.u32(u32::from(self.drift.is_some()));
        if let Some(d) = &self.drift {
            d.save(w);
        }
    }

    /// Every element's state from a snapshot of a compensation of the same shape.
    pub(crate) fn load(&mut self, r: &mut crate::snapshot::Reader<'_>) -> Result<(), CoreError> {
        self.preisach.load(r)?;
        r.expect("drift stages", usize::from(self.drift.is_some()))?;
        if let Some(d) = &mut self.drift {
            d.load(r)?;
        }
        Ok(())
    }

    /// Bytes of state per element (both stages).
    pub fn state_bytes_per_element(&self) -> usize {
        let n = self.len().max(1);
        self.preisach.state_bytes() / n
            + self
                .drift
                .as_ref()
                .map_or(0, DriftBank::state_bytes_per_element)
    }

    /// The drift's decay factors of a time step `dt` computed once for the next blocks
    /// ([`DriftBank::prepare`]).
    pub fn prepare(&mut self, dt: f64) {
        if let Some(d) = &mut self.drift {
            d.prepare(dt);
        }
    }

    /// Both stages split into blocks of [`crate::par::block_size`] elements.
    pub fn blocks(&mut self) -> impl Iterator<Item = CompensationBlock<'_>> {
        let mut drift = self.drift.as_mut().map(DriftBank::blocks);
        let level = self.level.as_deref().map(Curve::view);
        self.preisach
            .blocks()
            .map(move |preisach| CompensationBlock {
                preisach,
                drift: drift.as_mut().and_then(Iterator::next),
                level,
            })
    }

    /// A batch of T frames: time steps `dt` (T,), inputs and validity (T x N) -> outputs;
    /// large batches run in parallel over blocks of elements.
    pub fn run(
        &mut self,
        dt: &[f64],
        inputs: &[f64],
        valid: &[bool],
        out: &mut [f64],
    ) -> Result<(), CoreError> {
        let n = self.len();
        check_time_steps(dt)?;
        check_len("inputs", inputs.len(), dt.len() * n)?;
        check_len("valid", valid.len(), dt.len() * n)?;
        check_len("out", out.len(), dt.len() * n)?;
        if let Some(&first) = dt.first() {
            self.prepare(first);
        }
        run_frames(out, n, self.blocks(), dt, |idx, _| {
            valid[idx].then_some(inputs[idx])
        });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drift::Kernel;

    #[test]
    fn equals_the_stages_run_one_after_the_other() {
        let e = crate::everett::quadratic(21, 1.0);
        let kernel = Kernel::new(vec![0.5, 0.5], vec![1.0, 100.0]).unwrap();
        let inputs: Vec<f64> = (0..40)
            .map(|t| 0.5 + 0.4 * (t as f64 * 0.7).sin())
            .collect();
        let dt = vec![0.5; 40];
        let valid = vec![true; 40];
        let mut combined = Compensation::new(
            PreisachBank::new(e.clone(), 1, 32)
                .and_then(|p| p.with_output(0.2, 1.0))
                .unwrap(),
            Some(DriftBank::new(kernel.clone(), -0.025, 1).unwrap()),
        )
        .unwrap();
        let mut out = vec![0.0; 40];
        combined.run(&dt, &inputs, &valid, &mut out).unwrap();
        let mut p = PreisachBank::new(e, 1, 32).unwrap();
        let mut h = vec![0.0; 40];
        p.run(&inputs, &valid, &mut h).unwrap();
        h.iter_mut().for_each(|v| *v += 0.2);
        let mut d = DriftBank::new(kernel, -0.025, 1).unwrap();
        let mut expected = vec![0.0; 40];
        d.run(&dt, &h, &valid, &mut expected).unwrap();
        for (a, b) in out.iter().zip(&expected) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
    }

    #[test]
    fn a_level_curve_drifts_the_elastic_response() {
        let e = crate::everett::quadratic(21, 1.0);
        let kernel = Kernel::new(vec![0.5, 0.5], vec![1.0, 100.0]).unwrap();
        let curve = Curve::new(vec![0.0, 1.0], vec![0.0, 3.0]).unwrap();
        let inputs: Vec<f64> = (0..40)
            .map(|t| 0.5 + 0.4 * (t as f64 * 0.7).sin())
            .collect();
        let (dt, valid) = (vec![0.5; 40], vec![true; 40]);
        let preisach = PreisachBank::new(e, 1, 32).unwrap();
        let drift = DriftBank::new(kernel, -0.025, 1).unwrap();
        let mut qlv = Compensation::new(preisach.clone(), Some(drift.clone()))
            .and_then(|c| c.with_level(curve.clone()))
            .unwrap();
        let mut out = vec![0.0; 40];
        qlv.run(&dt, &inputs, &valid, &mut out).unwrap();
        // expected: Preisach output + (drift bank on the level - the level)
        let (mut p, mut d) = (preisach.clone(), drift);
        let mut h = vec![0.0; 40];
        p.run(&inputs, &valid, &mut h).unwrap();
        let b: Vec<f64> = inputs.iter().map(|&u| curve.at(u)).collect();
        let mut db = vec![0.0; 40];
        d.run(&dt, &b, &valid, &mut db).unwrap();
        for k in 0..40 {
            assert_eq!(out[k].to_bits(), (h[k] + (db[k] - b[k])).to_bits());
        }
        assert!(Compensation::new(preisach, None)
            .and_then(|c| c.with_level(curve))
            .is_err());
    }

    #[test]
    fn simd_and_scalar_paths_give_the_same_bits_with_and_without_a_level() {
        let _guard = crate::simd::testing::lock();
        let mut rng = crate::preisach::tests::Rng(11);
        let kernel = Kernel::new(vec![0.3, 0.5, 0.2], vec![0.5, 10.0, 300.0]).unwrap();
        let curve = Curve::new(vec![0.0, 0.4, 1.0], vec![0.0, 1.0, 3.0]).unwrap();
        for case in 0..12 {
            let n = 1 + (rng.next() % 60) as usize;
            let t = 1 + (rng.next() % 50) as usize;
            let preisach = PreisachBank::new(crate::everett::quadratic(17, 1.0), n, 8)
                .and_then(|p| p.with_output(0.1, -1.0))
                .unwrap();
            let drift = DriftBank::new(kernel.clone(), -0.025, n).unwrap();
            let mut comp = Compensation::new(preisach, Some(drift)).unwrap();
            if case % 2 == 1 {
                comp = comp.with_level(curve.clone()).unwrap();
            }
            let (u, ok) = crate::preisach::tests::hostile_history(&mut rng, t, n, 0.0, 1.0);
            let dt: Vec<f64> = (0..t).map(|_| rng.unit()).collect();
            let run = |simd: bool| {
                crate::simd::set_enabled(simd);
                let mut c = comp.clone();
                let mut out = vec![0.0; u.len()];
                c.run(&dt, &u, &ok, &mut out).unwrap();
                crate::simd::set_enabled(true);
                let mut w = crate::snapshot::Writer::default();
                c.save(&mut w);
                (out.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), w.buf)
            };
            assert_eq!(run(false), run(true), "case {case}");
        }
    }
}
