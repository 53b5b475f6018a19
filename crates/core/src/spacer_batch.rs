//! Batches of test-machine steps for any spacer law: frame after frame of
//! [`SpacerLaw::step_displacement`] or [`SpacerLaw::step_pressure`] over (T, N) arrays.

use crate::error::CoreError;
use crate::spacer::SpacerLaw;

/// Frame after frame of one per-frame driver: `dt` (T,), `input` (T, N) row-major, two outputs
/// of the same shape.
fn frames<L, F>(
    law: &mut L,
    dt: &[f64],
    input: &[f64],
    first: &mut [f64],
    second: &mut [f64],
    mut step: F,
) -> Result<(), CoreError>
where
    L: SpacerLaw + ?Sized,
    F: FnMut(&mut L, f64, &[f64], &mut [f64], &mut [f64]) -> Result<(), CoreError>,
{
    let n = law.len();
    let size = dt.len() * n;
    for (what, len) in [
        ("input", input.len()),
        ("outputs", first.len().min(second.len())),
    ] {
        if len != size {
            return Err(CoreError::Shape {
                what,
                expected: format!("{} frames x {n} elements = {size} values", dt.len()),
                got: format!("{len} values"),
            });
        }
    }
    for (k, &step_dt) in dt.iter().enumerate() {
        let r = k * n..(k + 1) * n;
        step(
            law,
            step_dt,
            &input[r.clone()],
            &mut first[r.clone()],
            &mut second[r],
        )?;
    }
    Ok(())
}

/// The batch drivers every spacer law has.
pub trait SpacerBatch: SpacerLaw {
    /// Displacement control over T frames: `compression` (T, N) -> pressure and spacer
    /// compression (T, N).
    fn run_displacement(
        &mut self,
        dt: &[f64],
        compression: &[f64],
        pressure: &mut [f64],
        spacer_compression: &mut [f64],
    ) -> Result<(), CoreError> {
        frames(
            self,
            dt,
            compression,
            pressure,
            spacer_compression,
            |l, d, e, p, s| l.step_displacement(d, e, p, s),
        )
    }

    /// Pressure control over T frames: `pressure` (T, N) -> compression and pressure reached
    /// (T, N).
    fn run_pressure(
        &mut self,
        dt: &[f64],
        pressure: &[f64],
        compression: &mut [f64],
        reached: &mut [f64],
    ) -> Result<(), CoreError> {
        frames(self, dt, pressure, compression, reached, |l, d, p, e, r| {
            l.step_pressure(d, p, e, r)
        })
    }
}

impl<L: SpacerLaw + ?Sized> SpacerBatch for L {}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bouc_wen::{BoucWenBank, BoucWenParams};

    fn bank(n: usize) -> BoucWenBank {
        let params = BoucWenParams {
            stiffness: 0.07,
            exponent: 6.0,
            densification: 0.85,
            friction: 0.35,
            slip: 0.02,
            bw_n: 1.5,
            bw_beta: 0.6,
            creep_share: 0.3,
            creep_rate: 1e-3,
            creep_exponent: 2.0,
        };
        BoucWenBank::new(params, vec![1.0; n]).unwrap()
    }

    #[test]
    fn a_batch_is_its_frames_one_after_the_other() {
        let (t, n) = (5, 3);
        let dt = vec![0.1; t];
        let e: Vec<f64> = (0..t * n).map(|k| 0.02 * (k % 7) as f64).collect();
        let (mut p, mut s) = (vec![0.0; t * n], vec![0.0; t * n]);
        let mut batched = bank(n);
        batched.run_displacement(&dt, &e, &mut p, &mut s).unwrap();
        let mut single = bank(n);
        for (k, &d) in dt.iter().enumerate() {
            let (mut pk, mut sk) = (vec![0.0; n], vec![0.0; n]);
            let r = k * n..(k + 1) * n;
            single
                .step_displacement(d, &e[r.clone()], &mut pk, &mut sk)
                .unwrap();
            assert_eq!(&p[r.clone()], &pk[..]);
            assert_eq!(&s[r], &sk[..]);
        }
    }

    #[test]
    fn a_short_input_is_a_shape_error() {
        let mut b = bank(3);
        let (mut p, mut s) = (vec![0.0; 6], vec![0.0; 6]);
        let err = b.run_pressure(&[0.1, 0.1], &[0.5; 5], &mut p, &mut s);
        assert!(matches!(err, Err(CoreError::Shape { what: "input", .. })));
    }
}
