//! The combined compensation stage: Preisach model, then drift (thesis eq. 5.8), frame by
//! frame in one pass, so a batch needs no intermediate array.

use crate::drift::DriftBank;
use crate::error::{check_len, CoreError};
use crate::preisach::PreisachBank;

/// Preisach output `sign (h + offset)`, followed by an optional drift stage.
#[derive(Debug, Clone)]
pub struct Compensation {
    preisach: PreisachBank,
    drift: Option<DriftBank>,
    offset: f64,
    sign: f64,
    frame: Vec<f64>,
}

impl Compensation {
    /// Combine the stages; both must have the same number of elements.
    pub fn new(
        preisach: PreisachBank,
        drift: Option<DriftBank>,
        offset: f64,
        sign: f64,
    ) -> Result<Self, CoreError> {
        if let Some(d) = &drift {
            check_len("drift elements", d.len(), preisach.len())?;
        }
        let n = preisach.len();
        Ok(Self {
            preisach,
            drift,
            offset,
            sign,
            frame: vec![0.0; n],
        })
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

    /// A batch of T frames: time steps `dt` (T,), inputs and validity (T x N) -> outputs.
    pub fn run(
        &mut self,
        dt: &[f64],
        inputs: &[f64],
        valid: &[bool],
        out: &mut [f64],
    ) -> Result<(), CoreError> {
        let n = self.len();
        check_len("inputs", inputs.len(), dt.len() * n)?;
        check_len("valid", valid.len(), dt.len() * n)?;
        check_len("out", out.len(), dt.len() * n)?;
        for (t, &d) in dt.iter().enumerate() {
            let r = t * n..(t + 1) * n;
            self.preisach
                .step(&inputs[r.clone()], &valid[r.clone()], &mut self.frame)?;
            for h in self.frame.iter_mut() {
                *h = self.sign * (*h + self.offset);
            }
            match &mut self.drift {
                Some(drift) => {
                    let ok: &[bool] = &valid[r.clone()];
                    drift.step(d, &self.frame, ok, &mut out[r])?;
                }
                None => out[r].copy_from_slice(&self.frame),
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drift::Kernel;
    use crate::preisach::Everett;

    #[test]
    fn equals_the_stages_run_one_after_the_other() {
        let k = 21;
        let mut table = vec![0.0; k * k];
        for i in 0..k {
            for j in 0..i {
                let d = (i - j) as f64 / 20.0;
                table[i * k + j] = 0.5 * d * d;
            }
        }
        let e = Everett::new(k, 0.0, 1.0, table).unwrap();
        let kernel = Kernel::new(vec![0.5, 0.5], vec![1.0, 100.0]).unwrap();
        let inputs: Vec<f64> = (0..40)
            .map(|t| 0.5 + 0.4 * (t as f64 * 0.7).sin())
            .collect();
        let dt = vec![0.5; 40];
        let valid = vec![true; 40];
        let mut combined = Compensation::new(
            PreisachBank::new(e.clone(), 1, 32).unwrap(),
            Some(DriftBank::new(kernel.clone(), -0.025, 1).unwrap()),
            0.2,
            1.0,
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
}
