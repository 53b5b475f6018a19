//! A second spacer law of another family, to check that the compensation is not tuned to the
//! first one ([`crate::spacer`]).
//!
//! Built from neither the compensation's models (Preisach, logarithmic step responses, Prony
//! series) nor the first law's mechanisms (friction sliders, creep only at rest):
//!
//! - **Backbone**: exponential stiffening `σ_e(e) = E (exp(b e) - 1)`.
//! - **Friction: Bouc–Wen.** A smooth differential hysteresis variable `z ∈ [-1, 1]` with
//!   `dz/de = (1 - |z|^n (β sgn(de z) + γ)) / δ` (`β + γ = 1`, `δ` the slip distance);
//!   the friction stress is `φ σ_e(e) z` (loading above unloading). Bouc–Wen loops obey neither
//!   the wiping-out nor the congruency property of a Preisach model exactly.
//! - **Creep: a Norton–Maxwell branch.** A share `w` of every backbone stress change is
//!   stored in a branch that relaxes through a power-law dashpot,
//!   `ds/dt = w dσ_e/dt - c σ_ref sgn(s) |s / σ_ref|^m`: after a step the branch decays as a
//!   power of time (`m = 2`: `s0 / (1 + c s0 t)`), not as a logarithm or a sum of
//!   exponentials, its rate depends on the amplitude (larger steps relax faster), and it
//!   relaxes on *time*, whether the spacer moves or rests.
//!
//! The dashpot is integrated implicitly (Newton, bracketed), the Bouc–Wen variable in
//! sub-steps of at most a tenth of the slip distance, so any step size is stable.

use crate::error::CoreError;
use crate::spacer::{SpacerLaw, Trial};

/// Parameters of a Bouc–Wen / Norton spacer material.
#[derive(Debug, Clone, PartialEq)]
pub struct BoucWenParams {
    /// Backbone stiffness `E` (N/cm²).
    pub stiffness: f64,
    /// Backbone exponent `b` (per unit compression).
    pub exponent: f64,
    /// Densification limit (fraction of thickness, in (0, 1)).
    pub densification: f64,
    /// Friction share `φ` of the backbone stress at full slip.
    pub friction: f64,
    /// Slip distance `δ` (fraction of thickness).
    pub slip: f64,
    /// Bouc–Wen exponent `n` and shape `β` (`γ = 1 - β`).
    pub bw_n: f64,
    /// Bouc–Wen shape `β` in (0, 1].
    pub bw_beta: f64,
    /// Share `w` of backbone stress changes stored in the creeping branch.
    pub creep_share: f64,
    /// Dashpot rate `c` (1/s at `σ_ref` = 1 N/cm²).
    pub creep_rate: f64,
    /// Dashpot exponent `m` (>= 1).
    pub creep_exponent: f64,
}

impl BoucWenParams {
    /// Check every parameter's domain.
    pub fn validate(&self) -> Result<(), CoreError> {
        let bad = |what: &'static str, why: &str| {
            Err(CoreError::Parameter {
                what,
                why: why.to_string(),
            })
        };
        if !(self.stiffness > 0.0 && self.stiffness.is_finite()) {
            return bad("stiffness", "must be > 0");
        }
        if !(self.exponent > 0.0 && self.exponent.is_finite()) {
            return bad("exponent", "must be > 0");
        }
        if !(self.densification > 0.0 && self.densification < 1.0) {
            return bad("densification", "must lie in (0, 1)");
        }
        if !(0.0..1.0).contains(&self.friction) {
            return bad("friction", "must lie in [0, 1)");
        }
        if !(self.slip > 0.0 && self.slip.is_finite()) {
            return bad("slip", "must be > 0");
        }
        if !(self.bw_n >= 1.0 && self.bw_n.is_finite()) {
            return bad("bw_n", "must be >= 1");
        }
        if !(self.bw_beta > 0.0 && self.bw_beta <= 1.0) {
            return bad("bw_beta", "must lie in (0, 1]");
        }
        if !(0.0..1.0).contains(&self.creep_share) {
            return bad("creep_share", "must lie in [0, 1)");
        }
        if !(self.creep_rate >= 0.0 && self.creep_rate.is_finite()) {
            return bad("creep_rate", "must be >= 0");
        }
        if !(self.creep_exponent >= 1.0 && self.creep_exponent.is_finite()) {
            return bad("creep_exponent", "must be >= 1");
        }
        Ok(())
    }

    /// Backbone stress (N/cm²) at compression `e`.
    pub fn backbone(&self, e: f64) -> f64 {
        if e <= 0.0 {
            return 0.0;
        }
        self.stiffness * ((self.exponent * e.min(self.densification)).exp() - 1.0)
    }
}

/// N elements of a Bouc–Wen / Norton spacer.
#[derive(Debug, Clone)]
pub struct BoucWenBank {
    p: BoucWenParams,
    scale: Vec<f64>,
    e: Vec<f64>,
    z: Vec<f64>,
    s: Vec<f64>,
}

impl BoucWenBank {
    /// `scale.len()` unloaded elements; `scale` multiplies every stress of an element.
    pub fn new(params: BoucWenParams, scale: Vec<f64>) -> Result<Self, CoreError> {
        params.validate()?;
        if scale.iter().any(|&s| s.is_nan() || s <= 0.0) {
            return Err(CoreError::Parameter {
                what: "scale",
                why: "stress scales must be > 0".into(),
            });
        }
        let n = scale.len();
        Ok(Self {
            p: params,
            scale,
            e: vec![0.0; n],
            z: vec![0.0; n],
            s: vec![0.0; n],
        })
    }

    /// Bouc–Wen variable after moving from `e0` by `de`.
    fn advance_z(&self, mut z: f64, de: f64) -> f64 {
        let p = &self.p;
        let steps = (de.abs() / (0.1 * p.slip)).ceil().max(1.0) as usize;
        let h = de / steps as f64;
        let gamma = 1.0 - p.bw_beta;
        let rate = |z: f64| {
            let dir = if h * z >= 0.0 { 1.0 } else { -1.0 };
            (1.0 - z.abs().powf(p.bw_n) * (p.bw_beta * dir + gamma)) / p.slip
        };
        for _ in 0..steps {
            // midpoint rule; z stays in [-1, 1]
            let mid = (z + 0.5 * h * rate(z)).clamp(-1.0, 1.0);
            z = (z + h * rate(mid)).clamp(-1.0, 1.0);
        }
        z
    }

    /// Implicit Norton step: `s1 = pred - dt c sgn(s1) |s1|^m`, root between 0 and `pred`.
    fn relax(&self, pred: f64, dt: f64) -> f64 {
        let (c, m) = (self.p.creep_rate, self.p.creep_exponent);
        if pred == 0.0 || c == 0.0 || dt == 0.0 {
            return pred;
        }
        let (sign, target) = (pred.signum(), pred.abs());
        // f(x) = x - target + dt c x^m on [0, target], increasing; f(0) < 0 <= f(target)
        let (mut lo, mut hi) = (0.0, target);
        let mut x = target;
        for _ in 0..60 {
            let f = x - target + dt * c * x.powf(m);
            if f.abs() <= 1e-15 * target || hi - lo <= 1e-15 * target {
                break; // converged: keep x
            }
            if f > 0.0 {
                hi = x;
            } else {
                lo = x;
            }
            let df = 1.0 + dt * c * m * x.powf(m - 1.0);
            let next = x - f / df;
            x = if next >= lo && next <= hi {
                next
            } else {
                0.5 * (lo + hi)
            };
        }
        sign * x
    }
}

impl SpacerLaw for BoucWenBank {
    fn len(&self) -> usize {
        self.e.len()
    }

    fn limit(&self) -> f64 {
        self.p.densification
    }

    /// The backbone grows with `e`, `z` with the travel (up to the sub-steps' discretisation)
    /// and the dashpot's root with its prediction: the stress does not decrease with the
    /// compression.
    fn monotone(&self) -> bool {
        true
    }

    fn current(&self, i: usize) -> f64 {
        self.e[i]
    }

    fn backbone(&self, e: f64) -> f64 {
        self.p.backbone(e)
    }

    fn creep_strain(&self) -> Vec<f64> {
        vec![0.0; self.e.len()] // no permanent set in this law
    }

    fn trial(&mut self, i: usize, dt: f64, e_new: f64, commit: bool) -> Trial {
        let k = self.scale[i];
        let (e0, z0, s0) = (self.e[i], self.z[i], self.s[i]);
        let z1 = self.advance_z(z0, e_new - e0);
        let (b0, b1) = (k * self.p.backbone(e0), k * self.p.backbone(e_new));
        let s1 = self.relax(s0 + self.p.creep_share * (b1 - b0), dt);
        let stress = (b1 * (1.0 + self.p.friction * z1) + s1).max(0.0);
        if commit {
            self.e[i] = e_new;
            self.z[i] = z1;
            self.s[i] = s1;
        }
        Trial { stress, creep: 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> BoucWenParams {
        BoucWenParams {
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
        }
    }

    fn stress_along(bank: &mut BoucWenBank, path: &[f64], dt: f64) -> Vec<f64> {
        let (mut p, mut s) = ([0.0], [0.0]);
        path.iter()
            .map(|&e| {
                bank.step_displacement(dt, &[e], &mut p, &mut s).unwrap();
                p[0]
            })
            .collect()
    }

    #[test]
    fn loading_above_unloading() {
        let mut bank = BoucWenBank::new(params(), vec![1.0]).unwrap();
        let up: Vec<f64> = (0..=100).map(|k| 0.5 * k as f64 / 100.0).collect();
        let down: Vec<f64> = up.iter().rev().copied().collect();
        let a = stress_along(&mut bank, &up, 0.01);
        let b = stress_along(&mut bank, &down, 0.01);
        // at 0.25 compression the loading branch carries more than the unloading one
        assert!(a[50] > 1.3 * b[50], "{} vs {}", a[50], b[50]);
    }

    #[test]
    fn held_compression_relaxes_as_a_power_of_time_and_cycles_relax_too() {
        let mut bank = BoucWenBank::new(params(), vec![1.0]).unwrap();
        let ramp: Vec<f64> = (1..=50).map(|k| 0.5 * k as f64 / 50.0).collect();
        let p0 = *stress_along(&mut bank, &ramp, 0.01).last().unwrap();
        let held = stress_along(&mut bank, &[0.5; 3600], 1.0);
        let lost = p0 - held[3599];
        assert!(
            lost > 0.05 * p0 && held.iter().all(|&p| p > 0.0),
            "{p0} -> {}",
            held[3599]
        );
        // the branch relaxes while moving as well: fast cycles about the same mean lose stress
        let mut c = BoucWenBank::new(params(), vec![1.0]).unwrap();
        stress_along(&mut c, &ramp, 0.01);
        // a triangle of 2 s about the same compression, ending at it
        let cyc: Vec<f64> = (0..=36000)
            .map(|k| 0.5 + 0.002 * (5.0 - ((k % 20) as f64 - 10.0).abs()))
            .collect();
        let after = stress_along(&mut c, &cyc, 0.1);
        let (s_held, s_cyc) = (bank.s[0], c.s[0]);
        assert!(
            s_held > 0.0 && (s_cyc / s_held - 1.0).abs() < 0.5,
            "{s_held} vs {s_cyc}"
        );
        assert!(after.iter().all(|p| p.is_finite()));
    }

    #[test]
    fn implicit_dashpot_step_solves_its_equation() {
        let bank = BoucWenBank::new(params(), vec![1.0]).unwrap();
        for pred in [0.152, 0.15208008003743412, -0.4, 1e-6, 3.0] {
            for dt in [1e-3, 1.0, 1e4] {
                let s = bank.relax(pred, dt);
                let resid = s - pred + dt * 1e-3 * s.signum() * s.abs().powf(2.0);
                assert!(resid.abs() < 1e-12 * pred.abs(), "{pred} {dt}: {s}");
                assert!(s * pred >= 0.0 && s.abs() <= pred.abs());
            }
        }
    }

    /// The same bank solved by plain bisection over the whole range (no local bracket).
    struct Plain(BoucWenBank);

    impl SpacerLaw for Plain {
        fn len(&self) -> usize {
            self.0.len()
        }
        fn limit(&self) -> f64 {
            self.0.limit()
        }
        fn current(&self, i: usize) -> f64 {
            self.0.current(i)
        }
        fn trial(&mut self, i: usize, dt: f64, e_new: f64, commit: bool) -> Trial {
            self.0.trial(i, dt, e_new, commit)
        }
        fn backbone(&self, e: f64) -> f64 {
            self.0.backbone(e)
        }
        fn creep_strain(&self) -> Vec<f64> {
            self.0.creep_strain()
        }
    }

    #[test]
    fn the_local_bracket_gives_what_plain_bisection_gives() {
        let scale = vec![0.8, 1.0, 1.3];
        let mut fast = BoucWenBank::new(params(), scale.clone()).unwrap();
        let mut plain = Plain(BoucWenBank::new(params(), scale).unwrap());
        let (mut e1, mut r1, mut e2, mut r2) = ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
        // loading, holding, breathing, jumps up and down, unloading to zero, a tiny load
        let mut x: u64 = 12345;
        for k in 0..600 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (x >> 11) as f64 / (1u64 << 53) as f64;
            let base = match k / 100 {
                0 => 0.02 * k as f64,
                1 => 2.0,
                2 => 2.0 * (1.0 + 0.02 * (k as f64 * 0.3).sin()),
                3 => 4.0 * u,
                4 => 0.0,
                _ => 1e-4 * u,
            };
            let p = [base, 0.5 * base, 1.5 * base];
            fast.step_pressure(10.0, &p, &mut e1, &mut r1).unwrap();
            plain.step_pressure(10.0, &p, &mut e2, &mut r2).unwrap();
            assert_eq!((e1, r1), (e2, r2), "step {k}");
        }
        // beyond densification: both refuse
        assert!(fast
            .step_pressure(1.0, &[1e9; 3], &mut e1, &mut r1)
            .is_err());
        assert!(plain
            .step_pressure(1.0, &[1e9; 3], &mut e2, &mut r2)
            .is_err());
    }

    #[test]
    fn pressure_control_inverts_and_bad_parameters_are_rejected() {
        let mut bank = BoucWenBank::new(params(), vec![1.0]).unwrap();
        let (mut e, mut reached) = ([0.0], [0.0]);
        bank.step_pressure(0.1, &[2.0], &mut e, &mut reached)
            .unwrap();
        assert!((reached[0] - 2.0).abs() < 1e-6);
        let mut bad = params();
        bad.bw_beta = 0.0;
        assert!(BoucWenBank::new(bad, vec![1.0]).is_err());
        assert!(BoucWenBank::new(params(), vec![0.0]).is_err());
    }
}
